"""Shader state of a material under a method (issue 38: one binder for both renderers): the
pass uniforms, the packed lobes and their patterns, the albedo/DFG tables, a Rational BRDF's
buffer, the radiance cube with its importance tables and the prefiltered maps. The preview
renderer and the scene renderer shade through it; the RSIBR bake (viewer/rsibr.py) too."""

from __future__ import annotations

import time
from pathlib import Path

import moderngl
import numpy as np
from scipy.stats import qmc

from lobeview.core.cache import BoundedCache
from lobeview.core.methods import MAX_LOBES, MAX_REFERENCE_SPP, Method
from lobeview.materials.blur_stack import STACK_BYTES
from lobeview.materials.fitted_pattern import may_read_fitted
from lobeview.materials.prefilter import SPLIT_SUM_LEVELS, split_sum_is_line
from lobeview.scenes.bright_sources import MAX_LIGHTS as MAX_CAP_LIGHTS

from .cubemap import RadianceCube
from .interface import (
    LOBE_MAP_MODES,
    MEASURED_BINDING,
    RATIONAL_BINDING,
    bind_sampler,
    bind_storage,
    has_uniform,
    set_uniform,
    unit,
    use_unit,
    uses_blur_stack,
    write_uniform,
)
from .material_gpu import PackedMaterial, albedo_texture_data, pack_patterns
from .mip_chain import DEFAULT_MIP_FILTER
from .prefilter_modes import LOBE_KINDS, PREFILTER_MODES, fit_plan, lobe_table, prefilter_plan, prefiltered_memory
from .prefiltered import cube_bytes
from .rsibr import bake_rsibr, rsibr_albedo, rsibr_cache_key, rsibr_layout, view_sphere_uniforms
from .shaders import ProgramCache

SOBOL_SIDE = 256  # 65536 scrambled 4D Sobol points
assert SOBOL_SIDE * SOBOL_SIDE == MAX_REFERENCE_SPP  # a reference never wraps around the table
SOBOL_SEED = 20100501
MAX_MATERIAL_TEXTURES = 64  # per-material textures kept (live material edits make new ones)


def sobol_points(count: int = SOBOL_SIDE * SOBOL_SIDE, seed: int = SOBOL_SEED) -> np.ndarray:
    """Owen-scrambled 4D Sobol points (scipy's generator), fixed seed: a frame renders the same
    image every time. Dimensions 0-1 drive BSDF sampling, 2-3 environment sampling."""
    return qmc.Sobol(d=4, scramble=True, seed=seed).random(count).astype(np.float32)


class ShadingBinder:
    """Binds what a shader variant reads of a material and a cube map. ``mip_filter``: how the
    radiance MIP chains are made (lobe-N's default LOD bias follows it); ``table_cache_root``:
    where derived tables are cached (albedo tables, lobe-map fits; None: core/paths.py's default)."""

    def __init__(
        self,
        ctx: moderngl.Context,
        programs: ProgramCache,
        mip_filter: str = DEFAULT_MIP_FILTER,
        table_cache_root: Path | None = None,
    ):
        self.ctx = ctx
        self.programs = programs
        self.mip_filter = mip_filter
        self.table_cache_root = table_cache_root
        sobol = sobol_points()
        self.sobol = ctx.texture((SOBOL_SIDE, SOBOL_SIDE), 4, sobol.tobytes(), dtype="f4")
        self.sobol.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.sobol_count = len(sobol)
        # (kind, ..., lobes_key) -> (texture, derived data); live material edits make new ones
        self.material_textures = BoundedCache(MAX_MATERIAL_TEXTURES, on_evict=lambda item: item[0].release())
        self._dummy_textures: dict = {}
        # Blur stacks built per frame (lobe-N+norm+fit): None builds every one a draw needs (shot,
        # tests: exact frames); the window gives each frame a time budget (stack_budget), and a
        # cube whose stack does not fit is read through its MIP chain that frame (pending).
        self.stack_budget_s: float | None = None
        self._stack_budget_start = 0.0
        self._stack_built_this_frame = False
        self._pending: set = set()  # ids of the cubes whose stacks the budgeted frame left unbuilt

    def stack_budget(self, seconds: float | None) -> None:
        """Start a frame whose blur-stack builds stop once it has run ``seconds`` (at least one is
        built a frame; None: no limit) and reset the pending count."""
        self.stack_budget_s = seconds
        self._stack_budget_start = time.perf_counter()
        self._stack_built_this_frame = False
        self._pending = set()

    @property
    def stacks_pending(self) -> int:
        """Cube maps read through their MIP chains in this frame for want of a built stack."""
        return len(self._pending)

    def blur_stack_for(self, cube: RadianceCube, material: PackedMaterial | None, per_pixel_lobes: bool = False):
        """The blur stack an object of ``material`` reads from ``cube`` under lobe-N+norm+fit, built
        now if the frame's budget allows; None where none of its lobes takes the fitted path
        (materials/fitted_pattern.py may_read_fitted) or the budget is spent (it reads the chain)."""
        if material is not None and not may_read_fitted(material.lobe_components, per_pixel_lobes):
            return None
        return self.budgeted_blur_stack(cube)

    def budgeted_blur_stack(self, cube: RadianceCube):
        """``cube``'s blur stack, built now if it is not and the frame's budget allows; None (and
        counted as pending) where the budget is spent."""
        return cube.blur_stack() if self._stack_fits(cube) else None

    def _stack_fits(self, cube: RadianceCube) -> bool:
        """Whether ``cube``'s blur stack is there or may be built within this frame's budget."""
        if self.stack_budget_s is None or cube.has_blur_stack:
            return True
        if self._stack_built_this_frame and time.perf_counter() - self._stack_budget_start >= self.stack_budget_s:
            self._pending.add(id(cube))
            return False
        self._stack_built_this_frame = True
        return True

    def set_material(
        self, program, material: PackedMaterial, method: Method, lod_bias: float | None, seed: int, planar=False
    ) -> None:
        self.set_material_state(program, material, method, planar)
        self.set_pass_state(program, method, lod_bias, seed)

    def set_pass_state(self, program, method: Method, lod_bias: float | None, seed: int) -> None:
        """The uniforms a pass sets alike for every material: samples, LOD bias, Sobol table, seed."""
        set_uniform(program, "u_samples", method.samples)
        set_uniform(
            program,
            "u_lod_bias",
            float(method.default_lod_bias(self.mip_filter) if lod_bias is None else lod_bias),
        )
        set_uniform(program, "u_sobol_count", self.sobol_count)
        set_uniform(program, "u_seed", int(seed))
        if method.kind == "lobe" and method.pattern == "fitted" and has_uniform(program, "u_fitted_patterns"):

            def fitted():
                from .fitted_gpu import fitted_texture

                return fitted_texture(self.ctx, method.samples), None

            table = self.material_texture(("fitted patterns", method.samples), fitted)[0]
            bind_sampler(program, "u_fitted_patterns", table)

    def set_material_state(self, program, material: PackedMaterial, method: Method, planar=False) -> None:
        """The material's lobes, patterns (for ``method`` and a ``planar`` reflector), colours and
        tables: what the scene renderer records once per object (viewer/interface.py DrawRecorder)."""
        set_uniform(program, "u_lobe_count", material.lobe_count)
        write_uniform(program, "u_lobes", material.lobes)
        if method.kind == "lobe" and has_uniform(program, "u_pattern"):
            write_uniform(program, "u_pattern", pack_patterns(material, method.samples, planar, method.pattern))
        set_uniform(program, "u_kd", tuple(float(x) for x in material.kd))
        set_uniform(program, "u_gltf_diffuse", 1.0 if material.gltf_diffuse else 0.0)
        set_uniform(program, "u_tangent_rotation", float(material.tangent_rotation))
        set_uniform(program, "u_dielectric_f0", tuple(float(x) for x in material.dielectric_f0))
        set_uniform(program, "u_specular_weight", float(material.specular_weight))
        set_uniform(program, "u_clearcoat", float(material.clearcoat))
        set_uniform(program, "u_transmission", float(material.transmission))
        set_uniform(program, "u_sheen_color", tuple(float(x) for x in material.sheen_color))
        if has_uniform(program, "u_sheen_albedo"):
            write_uniform(program, "u_sheen_albedo", np.asarray(material.sheen_table, dtype=np.float32))
        self._bind_rational(program, material)
        self._bind_measured(program, material)
        if method.kind == "lobe" and method.normalize and has_uniform(program, "u_albedo"):

            def albedo_texture():
                data = albedo_texture_data(material, self.table_cache_root)
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 3, data.tobytes(), dtype="f4")
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                tex.repeat_x = tex.repeat_y = False
                return tex, None

            bind_sampler(program, "u_albedo", self.material_texture(("albedo", material.lobes_key), albedo_texture)[0])
            # Per-pixel glTF albedo (patterns.glsl) is the scene renderer's (textured materials);
            # its table sampler still needs a 2D texture on its own unit, not unit 0's cube.
            set_uniform(program, "u_albedo_per_pixel", 0)
            bind_sampler(program, "u_dfg", self.dummy_texture("2d"))
            bind_sampler(program, "u_dfg_anisotropic", self.dummy_texture("3d"))

    def _bind_rational(self, program, material: PackedMaterial) -> None:
        """The Rational BRDF's storage buffer (shaders/rational.glsl); only HAS_RATIONAL programs
        (material.has_rational) declare it, so other materials bind nothing."""
        if material.rational is None:
            return
        data = material.rational

        def make():
            return self.ctx.buffer(data.tobytes()), None

        bind_storage(program, self.material_texture(("rational", material.lobes_key), make)[0], RATIONAL_BINDING)

    def _bind_measured(self, program, material: PackedMaterial) -> None:
        """A measured BRDF's table (3D texture) and sampler CDFs (storage buffer) for the
        HAS_MEASURED programs (shaders/measured.glsl)."""
        lobe = material.measured
        if lobe is None:
            return

        def table():
            # (theta_h, theta_d, phi_d, RGB) -> texture (width phi_d, height theta_d, depth theta_h)
            tex = self.ctx.texture3d(lobe.table.shape[2::-1], 3, np.ascontiguousarray(lobe.table).tobytes(), dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return tex, None

        def cdf():
            return self.ctx.buffer(lobe.sampler.pack().tobytes()), None

        bind_sampler(program, "u_measured_table", self.material_texture(("measured table", lobe.cache_key), table)[0])
        bind_storage(program, self.material_texture(("measured cdf", lobe.cache_key), cdf)[0], MEASURED_BINDING)

    def material_texture(self, key: tuple, make) -> tuple:
        """(texture, derived data) of a material, made by ``make()`` on first use and cached by
        content; the least recently used is released beyond MAX_MATERIAL_TEXTURES."""
        return self.material_textures.get(key, make)

    def bind_cube(
        self,
        program,
        cube: RadianceCube,
        method: Method,
        material: PackedMaterial | None = None,
        per_pixel_lobes: bool = False,
    ) -> None:
        """The radiance cube and Sobol table; the importance tables (reference only) and the
        prefiltered maps and lobe table (prefiltered only, built on first use for this cube and
        material; ``per_pixel_lobes``: textures change the lobes, so none is baked into RSIBR
        maps). Units: viewer/interface.py TEXTURE_UNITS."""
        # lobe-N+norm+fit's coarse reads: the cube's blur stack, built (a compute pass with its own
        # texture and image units) before anything of this draw is bound; a material none of whose
        # lobes can take the fitted path gets a 1-texel stand-in instead (no stack built for it)
        stack = None
        if uses_blur_stack(method) and has_uniform(program, "u_blur_stack"):
            own = self.blur_stack_for(cube, material, per_pixel_lobes)
            stack = own if own is not None else self.dummy_texture("array")
            set_uniform(program, "u_has_blur_stack", int(own is not None))
            set_uniform(program, "u_stack_layer", 0.0)  # the cube's own stack (multi-draws: the record's)
        if method.kind == "prefiltered":
            self.bind_prefiltered(program, cube, material, method, per_pixel_lobes)
        # Bright sources (viewer/cubemap.py): the reference integrates the whole radiance (the
        # lights only tell its third sampling strategy where to look), every other method the
        # cube without them plus the lights (shaders/cap_lights.glsl): lobe-N, fis-N and mc-N the
        # residual, signed where it keeps a source's shape beyond its cap, the
        # prefiltered modes, whose lobe maps read a narrow lobe in one lookup, the cube without
        # sources their maps are made from (one lookup would show the signed detail as it is:
        # miro5 under night.exr 29.6 -> 34.2 %, `lobeview bench light`), each with the lights it
        # lost (a strip light is one only for the prefiltered modes: bright_sources.py kept_whole).
        if method.kind == "reference":
            # the lights as proposals of its third strategy (env_sampling.glsl), where it samples
            # the environment: a reference drawn without (PARALLAX, MIRROR: viewer/object_drawer.py)
            # would add them to the whole cube (cap_lights.glsl)
            samples_environment = has_uniform(program, "u_env_cdf")
            radiance, lights = cube.radiance, (cube.lights if samples_environment else [])
        elif method.kind == "prefiltered":
            radiance, lights = cube.without_sources, cube.lights
        else:
            radiance, lights = cube.residual, cube.residual_lights
        bind_sampler(program, "u_radiance", radiance)
        set_uniform(program, "u_signed_residual", int(radiance is cube.residual and cube.signed_residual))
        set_uniform(program, "u_cap_light_count", len(lights))
        if lights:
            axes = np.zeros((MAX_CAP_LIGHTS, 4), dtype=np.float32)
            radiance = np.zeros((MAX_CAP_LIGHTS, 4), dtype=np.float32)
            for k, light in enumerate(lights[:MAX_CAP_LIGHTS]):
                axes[k] = (*light.direction, light.cos_radius)
                radiance[k] = (*light.radiance, light.inner_fraction)
            write_uniform(program, "u_cap_light_axis", axes)
            write_uniform(program, "u_cap_light_radiance", radiance)
        bind_sampler(program, "u_sobol", self.sobol)
        set_uniform(program, "u_face_size", float(cube.face_size))
        if stack is not None:
            bind_sampler(program, "u_blur_stack", stack)
        if method.kind == "reference":
            bind_sampler(program, "u_env_cdf", cube.env_cdf)
            bind_sampler(program, "u_env_pdf", cube.env_pdf)
            set_uniform(program, "u_env_texels", int(cube.importance.probabilities.size))
            set_uniform(program, "u_env_size", int(cube.importance.size))

    def bind_prefiltered(
        self, program, cube: RadianceCube, material: PackedMaterial, method: Method, per_pixel_lobes: bool = False
    ) -> None:
        maps = cube.prefiltered_maps(self.programs)
        plan = prefilter_plan(material, method.mode, per_pixel_lobes)
        self._bind_rsibr(program, maps, cube, material, method, per_pixel_lobes)
        for index, kind in enumerate(("beckmann", "ggx")):  # DIST_BECKMANN, DIST_GGX
            if any(LOBE_KINDS[p].split_sum and material.lobe_distributions[i].kind == kind for i, p in enumerate(plan)):
                use_unit(program, maps.split_sum(kind), unit("u_split_sum", index))
            else:
                use_unit(program, self.dummy_texture("cube"), unit("u_split_sum", index))
        set_uniform(program, "u_split_sum", [unit("u_split_sum", 0), unit("u_split_sum", 1)])
        set_uniform(program, "u_split_sum_max_level", float(SPLIT_SUM_LEVELS - 1))
        bind_sampler(program, "u_dfg", maps.dfg())
        # Split-sum's anisotropic GGX lobes take their albedo from the anisotropic table. With
        # per-pixel lobes (glTF textures) the scene renderer's material state has bound it already
        # where the material has anisotropy (viewer/scene_shading.py _bind_material), also where
        # its factors alone are isotropic (roughness factor 1).
        distributions = material.lobe_distributions
        anisotropic = any(
            LOBE_KINDS[p].split_sum
            and distributions[i].kind == "ggx"
            and split_sum_is_line(distributions[i].alpha_x, distributions[i].alpha_y)
            for i, p in enumerate(plan)
        )
        if anisotropic or not per_pixel_lobes:
            table = maps.anisotropic_dfg() if anisotropic else self.dummy_texture("3d")
            bind_sampler(program, "u_dfg_anisotropic", table)

        def lobe_table_texture():
            fitted = fit_plan(plan, material.lobe_components, self.table_cache_root)
            table, counts, fibres = lobe_table(plan, fitted)
            tex = self.ctx.texture((table.shape[1], table.shape[0]), 4, table.tobytes(), dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return tex, (fitted, counts, fibres)

        table, (fitted, counts, fibres) = self.material_texture(
            ("lobe table", method.mode, per_pixel_lobes, material.lobes_key), lobe_table_texture
        )
        bind_sampler(program, "u_lobe_table", table)
        modes = np.full(MAX_LOBES, LOBE_MAP_MODES["splitsum"], dtype=np.int32)
        depth = np.ones(MAX_LOBES, dtype=np.int32)
        direct = np.zeros(MAX_LOBES, dtype=np.float32)  # 0: never read the cube directly
        for i in range(MAX_LOBES):
            texture = None
            if i < len(plan):
                kind = LOBE_KINDS[plan[i]]
                texture = kind.texture(maps, fitted[i], f"lobe {i}")
                modes[i], depth[i], direct[i] = LOBE_MAP_MODES[kind.lookup], kind.depth(fitted[i]), kind.direct_angle
            use_unit(program, texture if texture is not None else self.dummy_texture("3d"), unit("u_lobe_maps", i))
        set_uniform(program, "u_lobe_maps", [unit("u_lobe_maps", i) for i in range(MAX_LOBES)])
        for name, values in (
            ("u_lobe_map_mode", modes),
            ("u_lobe_map_depth", depth),
            ("u_lobe_map_count", counts),
            ("u_banks_fibre", fibres),
            ("u_lobe_direct_angle", direct),
        ):
            write_uniform(program, name, values)

    def _bind_rsibr(self, program, maps, cube, material, method: Method, per_pixel_lobes: bool) -> None:
        """prefiltered-rsibr's maps and view sphere (shaders/rsibr.glsl); u_rsibr_lobes 0 in
        every other mode, and for materials with nothing to bake."""
        layout = rsibr_layout(material, per_pixel_lobes) if PREFILTER_MODES[method.mode].rsibr else None
        if layout is None or not layout.lobes:
            set_uniform(program, "u_rsibr_lobes", 0)
            bind_sampler(program, "u_rsibr_maps", self.dummy_texture("array"))
            return
        key = rsibr_cache_key(material, layout)
        texture = maps.rsibr_map(layout, key, lambda tex: bake_rsibr(self, cube, material, layout, tex))
        bind_sampler(program, "u_rsibr_maps", texture)
        for name, value in (
            ("u_rsibr_lobes", layout.lobes),
            ("u_rsibr_slices", layout.slices),
            ("u_rsibr_face_count", layout.faces),
        ):
            set_uniform(program, name, value)
        for name, values in view_sphere_uniforms(layout.subdivisions).items():
            write_uniform(program, name, values)
        write_uniform(program, "u_rsibr_albedo", rsibr_albedo(material, layout, key).astype(np.float32))

    def method_memory(self, cube: RadianceCube, material: PackedMaterial, method: Method) -> dict[str, int]:
        """Bytes of the GPU resources that shading ``material`` with ``method`` reads from one
        cube (the bench's memory column): the radiance cube with its MIP chain, plus the
        importance tables (reference), the albedo table (normalised lobe-N) and the blur stack
        (lobe-N+norm+fit, where a lobe takes the fitted path; a multi-draw holds a second copy in
        its stack arrays), or the prefiltered maps (prefiltered)."""
        face = cube.face_size
        memory = {"radiance cube": cube_bytes(face, int(np.log2(face)) + 1)}
        if method.kind == "reference":
            memory["importance tables"] = cube.importance_memory()
        if method.kind == "lobe" and method.normalize:
            memory["albedo table"] = int(albedo_texture_data(material).size * 4)
        if method.kind == "lobe" and method.pattern == "fitted" and may_read_fitted(material.lobe_components):
            memory["blur stack"] = STACK_BYTES
        if method.kind == "prefiltered":
            memory.update(prefiltered_memory(material, method.mode, face, self.table_cache_root))
        return memory

    def dummy_texture(self, kind: str):
        """A 1-texel black texture for sampler slots a material does not use."""
        if kind not in self._dummy_textures:
            if kind == "cube":
                tex = self.ctx.texture_cube((1, 1), 4, b"\0" * 16 * 6, dtype="f4")
            elif kind == "2d":
                tex = self.ctx.texture((1, 1), 4, b"\0" * 16, dtype="f4")
            elif kind == "array":
                tex = self.ctx.texture_array((1, 1, 1), 4, b"\0" * 16, dtype="f4")
            else:
                tex = self.ctx.texture3d((1, 1, 1), 4, b"\0" * 16, dtype="f4")
            self._dummy_textures[kind] = tex
        return self._dummy_textures[kind]

    def release(self) -> None:
        self.material_textures.clear()
        for tex in self._dummy_textures.values():
            tex.release()
        self.sobol.release()


def volume_uniforms(volume: dict | None, positions: np.ndarray, scale: float = 1.0) -> tuple[tuple, tuple]:
    """shaders/volume.glsl's u_volume (thickness in world units, the object's middle bounding-box
    side, ior, 1 / attenuation distance) and u_volume_attenuation for a ``volume``
    (materials/volume.py volume_of; None: thin-walled, the path disabled) on an object whose world
    vertices are ``positions``, its mesh units ``scale`` world units."""
    thickness = float(volume["thickness"]) * float(scale) if volume is not None else 0.0
    if thickness <= 0.0:
        return (0.0, 1.0, 1.5, 0.0), (1.0, 1.0, 1.0)
    sides = np.sort(np.ptp(positions, axis=0)) if len(positions) else np.zeros(3)
    # A thickness beyond the object's diagonal describes no volume the object can hold: taken as
    # the diagonal (the ball model's path and exit point then stay at the object's scale).
    thickness = min(thickness, float(np.linalg.norm(sides))) if np.any(sides > 0) else thickness
    distance = volume.get("attenuation_distance")
    colour = tuple(float(c) for c in np.broadcast_to(volume.get("attenuation_color", 1.0), 3))
    inverse_distance = 1.0 / float(distance) if distance else 0.0
    return (thickness, float(sides[1]), float(volume["ior"]), inverse_distance), colour
