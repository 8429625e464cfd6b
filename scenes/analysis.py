"""Scene analysis: decide once what each object needs, so the renderer builds only those
resources and compiles only the shader variants in use."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from lobeview.materials.bsdf import diffuse_albedo
from lobeview.materials.lobe_spread import finest_sample_solid_angle, lobe_width_face_size
from lobeview.materials.method_choice import LobeShape, MethodChoice, choose_method
from lobeview.materials.patterns import specular_lobes
from lobeview.materials.spec import build_bsdf

from .planar_mirror import reflector_decision
from .scene import Scene

ANISOTROPY_RATIO = 1.5  # a lobe counts as anisotropic above this max/min roughness ratio
DEFAULT_CUBE_FACE = 256  # SceneRenderer's default cube_face_size


@dataclass
class ObjectNeeds:
    name: str
    specular_lobes: int
    transmission_lobes: int
    anisotropic: bool
    diffuse: bool
    emissive: bool
    has_lightmap: bool
    reflection_proxy: str = "-"  # the cube-map lookup correction (scenes/reflection_proxy.py)
    mirror: str = "-"  # planar reflector decision (scenes/planar_mirror.py)
    reflector: object | None = None  # scenes.planar_mirror.PlanarReflector when it gets a mirror pass
    # Cube-map face size from the lobes' width (materials/lobe_spread.py lobe_width_face_size): the
    # smallest lobe-N sample footprint (sr) of the narrowest lobes the material can have, None
    # when unknown (full size), and the face size that gives at the analysis' full size.
    sample_solid_angle: float | None = None
    cube_face: int = DEFAULT_CUBE_FACE
    lobe_width_rule: bool = True  # False: every cube map at full size (SceneRenderer option)
    # Set by the renderer when the object reads a group's shared probe (scenes/probe_groups.py).
    shared_probe: str = ""
    # The cheapest-method rule's pick (materials/method_choice.py), when analysed with a target.
    method_choice: MethodChoice | None = None

    @property
    def needs_cube_map(self) -> bool:
        """Any view-dependent lobe is shaded from a cube map of the object's surroundings."""
        return self.specular_lobes + self.transmission_lobes > 0

    @property
    def cube_face_reason(self) -> str:
        if not self.needs_cube_map:
            return "-"
        if not self.lobe_width_rule:
            return "lobe-width rule off"
        if self.sample_solid_angle is None:
            return "footprint unknown: full size"
        return f"finest lobe-N footprint {self.sample_solid_angle * 1e3:.2g} msr"

    @property
    def kind(self) -> str:
        if not self.needs_cube_map:
            return "lightmap only"
        parts = ["specular"]
        if self.transmission_lobes:
            parts.append("transmission")
        if self.anisotropic:
            parts.append("anisotropic")
        return " + ".join(parts)


@dataclass
class SceneAnalysis:
    objects: list[ObjectNeeds]
    full_cube_face: int = DEFAULT_CUBE_FACE
    # Planar reflectors get their cube maps only when a frame shades them from one (False: at
    # start-up like every other glossy object).
    reflector_cubes_on_demand: bool = False

    @property
    def cubes_at_start(self) -> list[int]:
        """The objects whose cube maps are built at start-up."""
        on_demand = self.reflector_cubes_on_demand
        return [i for i in self.cube_mapped if not (on_demand and self.objects[i].reflector is not None)]

    @property
    def cube_mapped(self) -> list[int]:
        return [i for i, o in enumerate(self.objects) if o.needs_cube_map]

    @property
    def reflectors(self) -> dict:
        """Object index -> PlanarReflector for every object that gets a mirror pass (a copy: asked
        several times a frame, the objects are scanned once per analysis)."""
        return dict(self._reflector_map)

    @cached_property
    def _reflector_map(self) -> dict:
        return {i: o.reflector for i, o in enumerate(self.objects) if o.reflector is not None}

    @property
    def needs_specular_variant(self) -> bool:
        return bool(self.cube_mapped)

    def report(self) -> str:
        lines = [
            f"{'object':<24} {'needs':<42} {'cube map (why that size)':<42} {'lightmap':<14} "
            f"{'reflection proxy':<24} planar mirror"
        ]
        for o in self.objects:
            lobes = f"{o.kind} ({o.specular_lobes} refl, {o.transmission_lobes} trans)" if o.needs_cube_map else o.kind
            lightmap = "yes" if o.has_lightmap else "NO (fallback)"
            proxy = o.reflection_proxy if o.needs_cube_map and o.reflector is None else "-"
            cube = f"{o.cube_face}^2 ({o.cube_face_reason})" if o.needs_cube_map else "no"
            if o.needs_cube_map and o.reflector is not None and self.reflector_cubes_on_demand:
                cube = f"on demand, {o.cube_face}^2 (mirror pass)"
            if o.shared_probe:
                cube = f"shared probe {o.shared_probe}"
            lines.append(f"{o.name:<24} {lobes:<42} {cube:<42} {lightmap:<14} {proxy:<24} {o.mirror}")
        chosen = [o for o in self.objects if o.method_choice is not None]
        if chosen:
            lines.append("method by the cheapest-method rule (materials/method_choice.py):")
            lines += [f"  {o.name:<24} {o.method_choice.describe()}" for o in chosen]
        return "\n".join(lines)


def narrowest_lobe_desc(mat) -> dict:
    """The material description with the narrowest lobes its textures can give a pixel (the
    glTF roughness textures scale their factors; an anisotropy texture can only widen the
    tangent axis, so its strength counts as 0): what the cube-map face size must resolve."""
    desc = dict(mat.desc)
    if desc.get("model") != "gltf" or not mat.textures:
        return desc
    if "metallic_roughness" in mat.textures:  # roughness = factor x G
        roughness_map = mat.textures["metallic_roughness"].linear()[..., 1]
        desc["roughness"] = float(desc.get("roughness", 1.0)) * float(roughness_map.min())
    if "clearcoat" in mat.textures and desc.get("clearcoat"):  # clearcoat roughness = factor x G
        desc["clearcoat_roughness"] = float(desc.get("clearcoat_roughness", 0.0)) * float(
            mat.textures["clearcoat"].linear()[..., 1].min()
        )
    if "anisotropy" in mat.textures and desc.get("anisotropy"):
        desc["anisotropy"] = 0.0
    return desc


def analyse(
    scene: Scene,
    full_cube_face: int = DEFAULT_CUBE_FACE,
    lobe_width_cubes: bool = True,
    reflector_cubes_on_demand: bool = False,
    method_target: float | None = None,
) -> SceneAnalysis:
    """``full_cube_face``: the cube-map face size of the narrowest lobes; with ``lobe_width_cubes``
    every object's face shrinks to what its lobes' lobe-N footprints resolve (issue 18; False:
    every cube map at full size); ``reflector_cubes_on_demand``: planar reflectors' cube maps are
    not built at start-up (SceneAnalysis.cubes_at_start); ``method_target``: each view-dependent
    object's cheapest real-time method within that relative error (ObjectNeeds.method_choice;
    the lobes its textures can give count too)."""
    needs = []
    low, high = scene.bounds if scene.objects else (np.zeros(3), np.zeros(3))
    scene_diagonal = float(np.linalg.norm(high - low))
    for obj in scene.objects:
        mat = scene.materials[obj.material]
        bsdf = build_bsdf(mat.desc)
        lobes = specular_lobes(bsdf)
        transmission = sum(1 for lobe in lobes if getattr(lobe, "transmission", False))
        anisotropic = any(
            max(lobe.distribution.alpha_x, lobe.distribution.alpha_y)
            / min(lobe.distribution.alpha_x, lobe.distribution.alpha_y)
            > ANISOTROPY_RATIO
            for lobe in lobes
        )
        diffuse = bool(np.any(diffuse_albedo(bsdf) > 0))
        has_lightmap = mat.lightmap is not None and (mat.lightmap.tex_coord != 1 or obj.uv1 is not None)
        reflector, mirror = reflector_decision(obj.mesh, lobes, scene_diagonal, obj.planar_reflector)
        narrowest = narrowest_lobe_desc(mat)
        if lobes and narrowest != mat.desc:  # textures can make the lobes narrower than the factors
            lobes_for_face = specular_lobes(build_bsdf(narrowest))
        else:
            lobes_for_face = lobes
        footprint = finest_sample_solid_angle(lobes_for_face) if lobes else None
        face = lobe_width_face_size(footprint, full_cube_face) if lobe_width_cubes else int(full_cube_face)
        choice = None
        if method_target is not None and lobes and reflector is not None:
            # Its mirror pass is read by the frame's lobe-N; a prefiltered pick would swap it for a
            # cube map, and the table measured cube maps of a distant environment, not mirror buffers.
            choice = MethodChoice(None, None, 0, True, "planar reflector: its mirror pass takes the frame's method")
        elif method_target is not None and lobes:
            # The factors' lobes and, where textures can narrow them, the same lobes at their narrowest
            # (built above): both ends' errors count, each lobe's lookups once.
            extremes = None if lobes_for_face is lobes else [LobeShape.of(lobe) for lobe in lobes_for_face]
            choice = choose_method([LobeShape.of(lobe) for lobe in lobes], method_target, extremes=extremes)
        needs.append(
            ObjectNeeds(
                obj.name,
                len(lobes) - transmission,
                transmission,
                anisotropic,
                diffuse,
                bool(max(mat.emission) > 0),
                has_lightmap,
                _describe_proxy(obj.reflection_proxy),
                mirror,
                reflector,
                footprint,
                face,
                lobe_width_cubes,
                method_choice=choice,
            )
        )
    return SceneAnalysis(needs, int(full_cube_face), bool(reflector_cubes_on_demand))


def _describe_proxy(proxy) -> str:
    if proxy is None:
        return "none (distant lookup)"
    if proxy.kind == "planes":
        return f"{len(proxy.planes)} bounding plane(s)"
    return "box " + " .. ".join("(" + ", ".join(f"{v:.2f}" for v in b) + ")" for b in (proxy.box_min, proxy.box_max))
