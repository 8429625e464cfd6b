"""The scene renderer's shading binder (issue 38): what an object's draw sets besides the pass
state - its packed material (viewer/shading.py), lightmap or the environment's irradiance cube, glTF textures and
samplers, reflection proxy - recorded once per program, object and method and replayed
(viewer/interface.py DrawRecorder)."""

from __future__ import annotations

import warnings
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.cache import BoundedCache
from lobeview.core.methods import Method
from lobeview.materials.gltf import specular_f0_unclamped
from lobeview.materials.volume import volume_of
from lobeview.scenes.baker import spot_ramp
from lobeview.scenes.horizon_maps import uv1_lightmap
from lobeview.scenes.lamps import DIRECTIONAL_ANGULAR_RADIUS, LAMP_RADIUS, MAX_LAMPS, lamp_visibility, live_lamps
from lobeview.scenes.scene import (
    CLAMP_TO_EDGE,
    LINEAR_MIPMAP_LINEAR,
    LINEAR_MIPMAP_NEAREST,
    MIRRORED_REPEAT,
    TEXTURE_SLOTS,
    Scene,
    SceneMaterial,
    TextureSlot,
)
from lobeview.scenes.self_visibility import MAP_HORIZON_SECTORS

from .interface import (
    ALPHA_MODES,
    PROXY_KINDS,
    TEXTURE_UNITS,
    DrawRecorder,
    bind_sampler,
    has_uniform,
    replay,
    set_uniform,
    use_unit,
    write_uniform,
)
from .shaders import ProgramCache
from .shading import ShadingBinder, volume_uniforms

LAMP_KINDS = {"point": 0, "spot": 1, "directional": 2}  # shaders/lamps.glsl LAMP_*

MAX_SCENE_TEXTURES = 256  # lightmaps and material textures kept on the GPU
# Material textures whose sampler filters linearly between texels and MIP levels get 16x
# anisotropic filtering (the most common hardware limit); nearest-texel samplers stay as the file
# asked (pixel-art textures), without MIP levels there is nothing to choose between.
TEXTURE_ANISOTROPY = 16.0
MIPMAP_MIN_FILTERS = (LINEAR_MIPMAP_NEAREST, LINEAR_MIPMAP_LINEAR)
# Drivers whose anisotropic filter is worse than none: Mesa 22.3's llvmpipe garbles a textured
# quad seen head-on when the shader passes explicit gradients (textureGrad: columns of wrong
# texels over half the frame) and blurs it with implicit ones (0.05 mean error on a 0.5/1
# checker where trilinear filtering is exact), measured with tests/test_texture_filtering.py.
ANISOTROPY_DEFECTIVE_RENDERERS = ("llvmpipe",)


def texture_anisotropy(renderer: str, max_anisotropy: float) -> float:
    """The anisotropy of material samplers on this driver: TEXTURE_ANISOTROPY within what it
    offers (1: none), 1 on the drivers whose anisotropic filter is defective."""
    if any(renderer.lower().startswith(name) for name in ANISOTROPY_DEFECTIVE_RENDERERS):
        return 1.0
    return min(TEXTURE_ANISOTROPY, max(float(max_anisotropy), 1.0))


MAX_DRAW_RECORDS = 16384  # recorded object draw states (programs x objects x methods in use)
GL_SRGB8_ALPHA8 = 0x8C43  # colour textures: the GPU decodes sRGB before filtering (glTF 3.9.2)


def per_pixel_lobes(mat: SceneMaterial) -> bool:
    """Whether textures make a glTF material's lobes differ from pixel to pixel (shaders/scene.frag),
    so that maps baked for one set of lobe parameters (prefiltered-rsibr) cannot shade it: every
    texture but occlusion and emission, and the normal map too where a clearcoat keeps the
    geometric normal for its own lobe."""
    if mat.desc["model"] != "gltf":
        return False
    lobe_neutral = {"occlusion", "emissive"} | ({"normal"} if not mat.desc.get("clearcoat") else set())
    return bool(set(mat.textures) - lobe_neutral)


class SceneShading(ShadingBinder):
    """ShadingBinder with the scene's textures: lightmaps and glTF maps (by the image they upload;
    the image is kept with the texture so that its id() cannot be reused while the entry lives),
    sampler objects, the DFG table of per-pixel glTF albedo, and the draw records."""

    def __init__(
        self,
        ctx: moderngl.Context,
        programs: ProgramCache,
        scene: Scene,
        environment_irradiance: moderngl.TextureCube,
        mip_filter: str,
        cache_dir: Path | None = None,
    ):
        # Derived tables are cached beside the cube maps (cache_dir is the cubes' folder).
        super().__init__(ctx, programs, mip_filter, cache_dir.parent if cache_dir is not None else None)
        self.scene = scene
        self.cache_dir = cache_dir
        # Diffuse light of objects without a lightmap: the environment's irradiance cube (bound
        # for every object: a sampler the program has must always see a cube texture).
        self.environment_irradiance = environment_irradiance
        self.textures = BoundedCache(MAX_SCENE_TEXTURES, on_evict=lambda item: item[1].release())
        # Every sampler uniform gets its own unit and a texture, even when unused: two samplers
        # of different types on one unit make the draw call fail (GL_INVALID_OPERATION).
        self.white = ctx.texture((1, 1), 3, np.ones(3, np.float32).tobytes(), dtype="f4")
        self._samplers: dict = {}  # glTF sampler state -> moderngl.Sampler (a handful per scene)
        self._dfg = None  # made on first use by a textured glTF lobe under normalised lobe-N
        self._anisotropic_dfg = None  # ... and by a textured anisotropic one
        self.draw_records = True  # RenderSettings.draw_records
        self.self_occlusion = True  # RenderSettings.self_occlusion
        # The material textures' filter footprint as a share of the pixel's (shaders/
        # material_maps.glsl): 1 shades whole pixels; a box-filtered reference, which integrates
        # the pixel by moving each pass's position, sets 1 / sqrt(passes) (SceneRenderer.render).
        self.texture_footprint = 1.0
        self._records = BoundedCache(MAX_DRAW_RECORDS)
        self.record_generation = 0  # bumped when what a record holds changes
        self.record_builds = 0  # records made so far (a count for tests and benchmarks)
        # KHR_lights_punctual lamps with live reflections (scenes/lamps.py), their uniforms, and
        # how much of each object each one reaches (ray cast on first use).
        self.lamps = live_lamps(scene.lights)
        self._lamp_uniforms = lamp_uniforms(self.lamps)
        self._lamp_visibility: np.ndarray | None = None
        # The horizons per lightmap texel (scenes/horizon_maps.py) by id of the lightmap image:
        # (image, horizons), traced by prepare_horizon_maps; a sampler every draw binds.
        self.horizon_maps: dict[int, tuple] = {}
        # An object without a lightmap: its map over its texture coordinates, by object index.
        self.uv0_horizon_maps: dict[int, np.ndarray] = {}
        self._unmappable_lightmaps: set[int] = set()  # non-square: warned about once
        self.missing_horizon_maps = 0  # maps the cache lacked (not traced yet)
        self._uv0_mapped: list | None = None  # scenes/horizon_maps.py uv0_mapped_objects, found once
        self._no_horizon_map = ctx.texture_array(
            (1, 1, MAP_HORIZON_SECTORS // 4), 4, np.zeros(MAP_HORIZON_SECTORS, np.float32).tobytes(), dtype="f4"
        )

    def set_pass_state(self, program, method: Method, lod_bias: float | None, seed: int) -> None:
        """ShadingBinder's pass state and the scene's lamps (shaders/lamps.glsl)."""
        super().set_pass_state(program, method, lod_bias, seed)
        if has_uniform(program, "u_self_occlusion"):
            set_uniform(program, "u_self_occlusion", 1 if self.self_occlusion else 0)
        if has_uniform(program, "u_texture_footprint"):
            set_uniform(program, "u_texture_footprint", float(self.texture_footprint))
        if has_uniform(program, "u_lamp_count"):
            set_uniform(program, "u_lamp_count", len(self.lamps))
            for name, values in self._lamp_uniforms.items():
                write_uniform(program, name, values)

    def prepare_horizon_maps(self, trace: bool = True) -> int:
        """The horizon map of every lightmap that objects read through their own lightmap
        coordinates, and of every object without one whose texture coordinates can hold one
        (scenes/horizon_maps.py), read from the cache folder beside the visibility cones, or
        traced there unless ``trace`` is False (the viewer's first frame: a worker traces them,
        app/finishing.py); how many are still missing (their objects keep the vertices'
        horizons). A map that arrives bumps ``record_generation`` (the per-object records hold
        whether an object has one)."""
        from lobeview.scenes.horizon_maps import (
            lightmap_horizon_map,
            lightmap_images,
            uv0_horizon_map,
            uv0_mapped_objects,
        )

        missing, before = 0, len(self.horizon_maps) + len(self.uv0_horizon_maps)
        for image in lightmap_images(self.scene):
            if id(image) in self.horizon_maps or id(image) in self._unmappable_lightmaps:
                continue
            if image.shape[0] != image.shape[1]:
                self._unmappable_lightmaps.add(id(image))
                warnings.warn(
                    f"a lightmap of {image.shape[1]}x{image.shape[0]} texels is not square: its objects keep their "
                    "vertices' self-occlusion horizons (no horizon map)",
                    stacklevel=2,
                )
                continue
            horizons = lightmap_horizon_map(self.scene, image, self.cache_dir, trace=trace)
            if horizons is None:
                missing += 1
            else:
                self.horizon_maps[id(image)] = (image, horizons)
        if self._uv0_mapped is None:
            self._uv0_mapped = uv0_mapped_objects(self.scene)
        side, mapped = self._uv0_mapped
        for index, uv in mapped:
            if index not in self.uv0_horizon_maps:
                horizons = uv0_horizon_map(self.scene, index, uv, side, self.cache_dir, trace=trace)
                if horizons is None:
                    missing += 1
                else:
                    self.uv0_horizon_maps[index] = horizons
        if len(self.horizon_maps) + len(self.uv0_horizon_maps) != before:
            self.record_generation += 1
        self.missing_horizon_maps = missing
        return missing

    def horizon_map_texture(self, key) -> moderngl.TextureArray:
        """The horizon map of a lightmap (``key`` its image) or of an unbaked object (``key`` its
        index) as an RGBA32F array of MAP_HORIZON_SECTORS / 4 layers (sectors 0-3, 4-7, ...),
        linear, no MIP chain, repeating as the lightmap; a 1 x 1 one of zeros for None or a key
        without a map."""
        if isinstance(key, int):
            horizons = self.uv0_horizon_maps.get(key)
        else:
            horizons = self.horizon_maps[id(key)][1] if key is not None and id(key) in self.horizon_maps else None
        if horizons is None:
            return self._no_horizon_map

        def upload():
            height, width = horizons.shape[:2]
            count = horizons.shape[-1] // 4
            layers = np.moveaxis(horizons.reshape(height, width, count, 4), 2, 0)
            layers = np.ascontiguousarray(layers, dtype=np.float32)
            texture = self.ctx.texture_array((width, height, count), 4, layers.tobytes(), dtype="f4")
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            texture.repeat_x = texture.repeat_y = True
            return horizons, texture

        cache_key = ("horizon map", key) if isinstance(key, int) else ("horizon map", id(key))
        return self.textures.get(cache_key, upload)[1]

    def lamp_visibility_of(self, index: int) -> np.ndarray:
        """(MAX_LAMPS,) float32: the fraction of object ``index`` each live lamp reaches."""
        out = np.zeros(MAX_LAMPS, dtype=np.float32)
        if self.lamps:
            if self._lamp_visibility is None:
                self._lamp_visibility = lamp_visibility(self.scene, self.lamps)
            out[: len(self.lamps)] = self._lamp_visibility[index]
        return out

    def invalidate_records(self) -> None:
        """Make the draw records again: a material, proxy or probe centre changed."""
        self.record_generation += 1

    def lightmap_texture(self, image: np.ndarray) -> moderngl.Texture:
        def upload():
            img = np.ascontiguousarray(image, dtype=np.float32)
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = True
            return image, tex

        return self.textures.get(id(image), upload)[1]

    def _map_texture(self, slot: TextureSlot) -> moderngl.Texture:
        """A material texture on the GPU: uint8 RGBA as stored (SRGB8_ALPHA8 for colour slots),
        float RGBA for generated scenes; full MIP chain (the sampler object picks the filter)."""

        def upload():
            image = slot.image
            if image.dtype == np.uint8:
                if image.shape[-1] == 3:
                    image = np.concatenate([image, np.full(image.shape[:-1] + (1,), 255, np.uint8)], axis=-1)
                data = np.ascontiguousarray(image)
                internal = GL_SRGB8_ALPHA8 if slot.srgb else None
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes(), internal_format=internal)
            else:
                data = np.ascontiguousarray(slot.linear(), dtype=np.float32)
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes(), dtype="f4")
            tex.build_mipmaps()
            return image, tex

        return self.textures.get(("map", id(slot.image), slot.srgb), upload)[1]

    def _dfg_texture(self) -> moderngl.Texture:
        """The split-sum DFG table (viewer/prefiltered.py), for per-pixel glTF lobe albedo."""
        if self._dfg is None:
            from .prefiltered import dfg_texture

            self._dfg = dfg_texture(self.ctx, self.cache_dir)
        return self._dfg

    def _anisotropic_dfg_texture(self) -> moderngl.Texture3D:
        """The anisotropic DFG table (viewer/prefiltered.py), for textured anisotropic glTF lobes
        under normalised lobe-N; made on first use (about 20 s, then from the cache)."""
        if self._anisotropic_dfg is None:
            from .prefiltered import anisotropic_dfg_texture

            self._anisotropic_dfg = anisotropic_dfg_texture(self.ctx, self.cache_dir)
        return self._anisotropic_dfg

    def _map_sampler(self, slot: TextureSlot | None) -> moderngl.Sampler:
        """Sampler object for a slot's glTF sampler: repeat or clamp-to-edge per axis and the
        filters (glTF uses the GL enums); mirrored repeat repeats here and is folded in
        shaders/material_maps.glsl."""
        key = (slot.wrap_s, slot.wrap_t, slot.min_filter, slot.mag_filter) if slot is not None else ("white",)
        sampler = self._samplers.get(key)
        if sampler is None:
            sampler = self.ctx.sampler()
            if slot is not None:
                sampler.repeat_x = slot.wrap_s != CLAMP_TO_EDGE
                sampler.repeat_y = slot.wrap_t != CLAMP_TO_EDGE
                sampler.filter = (slot.min_filter, slot.mag_filter)
                if slot.min_filter in MIPMAP_MIN_FILTERS:
                    # Anisotropic filtering (GL 4.6 / EXT_texture_filter_anisotropic): without it
                    # a texture seen at a grazing angle takes the MIP level of its longest
                    # footprint axis and blurs across the other one too (the WaterBottle's
                    # label, issue 40).
                    sampler.anisotropy = texture_anisotropy(self.ctx.info["GL_RENDERER"], self.ctx.max_anisotropy)
            self._samplers[key] = sampler
        return sampler

    def object_state(self, program, obj, method: Method, planar: bool, proxy, probe_centre) -> None:
        """Everything an object's draw sets that the pass does not: material, textures, lightmap,
        reflection proxy. Recorded once per program, object and method (``draw_records``,
        viewer/interface.py DrawRecorder) and replayed, so a draw sends only the uniform bytes the
        program does not hold yet (issue 18: state uploaded when it changes, not per draw). The
        records are made again after a material edit or a proxy change (``record_generation``)
        and after a texture cache released a texture they bind."""
        if not self.draw_records:
            self.set_object_state(program, obj, method, planar, proxy, probe_centre)
            return
        key = (
            program,
            obj.index,
            method,
            planar,
            proxy is not None,
            self.record_generation,
            self.textures.evictions,
            self.material_textures.evictions,
        )

        def make():
            recorder = DrawRecorder(program)
            self.set_object_state(recorder, obj, method, planar, proxy, probe_centre)
            self.record_builds += 1
            return recorder.record()

        replay(program, self._records.get(key, make))

    def set_object_state(self, program, obj, method: Method, planar: bool, proxy, probe_centre) -> None:
        """object_state without the records (what a record holds; viewer/object_batches.py packs it)."""
        mat = self.scene.materials[self.scene.objects[obj.index].material]
        self.set_material_state(program, obj.material, method, planar)
        set_uniform(program, "u_emission", tuple(float(x) for x in mat.emission))
        set_uniform(program, "u_object_id", float(obj.index))
        write_uniform(program, "u_lamp_visibility", self.lamp_visibility_of(obj.index))
        lightmap = mat.lightmap
        if lightmap is not None and (lightmap.tex_coord != 1 or self.scene.objects[obj.index].uv1 is not None):
            bind_sampler(program, "u_lightmap", self.lightmap_texture(lightmap.image))
            set_uniform(program, "u_lightmap_texcoord", int(lightmap.tex_coord))
            set_uniform(program, "u_lightmap_intensity", float(lightmap.intensity))
        else:
            bind_sampler(program, "u_lightmap", self.white)
            set_uniform(program, "u_lightmap_texcoord", -1)
        # the horizons per texel of that lightmap (scenes/horizon_maps.py), where it has them
        # or over its texture coordinates where it has no lightmap
        mapped = uv1_lightmap(self.scene, self.scene.objects[obj.index])
        if mapped is not None and id(mapped) in self.horizon_maps:
            horizon_key, horizon_uv = mapped, 1
        elif obj.index in self.uv0_horizon_maps:
            horizon_key, horizon_uv = obj.index, 0
        else:
            horizon_key, horizon_uv = None, 1
        bind_sampler(program, "u_horizon_map", self.horizon_map_texture(horizon_key))
        set_uniform(program, "u_has_horizon_map", int(horizon_key is not None))
        set_uniform(program, "u_horizon_map_uv", horizon_uv)
        bind_sampler(program, "u_irradiance", self.environment_irradiance)
        self._bind_material(program, mat)
        scene_object = self.scene.objects[obj.index]
        volume, attenuation_colour = volume_uniforms(
            volume_of(mat.desc), scene_object.mesh.positions, scene_object.volume_scale
        )
        set_uniform(program, "u_volume", volume)
        set_uniform(program, "u_volume_attenuation", attenuation_colour)
        if proxy is not None:
            self._bind_proxy(program, proxy, probe_centre)

    def _bind_material(self, program, mat: SceneMaterial) -> None:
        """glTF's per-pixel inputs (shaders/scene.frag): textures, factors, alpha mode."""
        desc = mat.desc
        gltf_model = desc["model"] == "gltf"
        base = desc["base_color"] if gltf_model else [1.0, 1.0, 1.0]
        set_uniform(program, "u_gltf_model", int(gltf_model))
        set_uniform(program, "u_base_color_factor", (*(float(c) for c in base), float(mat.base_alpha)))
        set_uniform(program, "u_metallic_factor", float(desc.get("metallic", 0.0)))
        set_uniform(program, "u_roughness_factor", float(desc.get("roughness", 1.0)))
        set_uniform(program, "u_anisotropy", float(desc.get("anisotropy", 0.0)) if gltf_model else 0.0)
        set_uniform(program, "u_clearcoat_roughness", float(desc.get("clearcoat_roughness", 0.0)))
        set_uniform(program, "u_clearcoat_normal_scale", float(mat.clearcoat_normal_scale))
        raw_f0 = (
            specular_f0_unclamped(desc.get("ior", 1.5), desc.get("specular_color", (1.0, 1.0, 1.0)))
            if gltf_model
            else (0.04, 0.04, 0.04)
        )
        set_uniform(program, "u_specular_f0_raw", tuple(float(x) for x in raw_f0))
        set_uniform(program, "u_normal_scale", float(mat.normal_scale))
        set_uniform(program, "u_occlusion_strength", float(mat.occlusion_strength))
        set_uniform(program, "u_alpha_mode", ALPHA_MODES[mat.alpha_mode.lower()])
        set_uniform(program, "u_alpha_cutoff", float(mat.alpha_cutoff))
        texcoords, transforms, mirrored = [], [], []
        for i, name in enumerate(TEXTURE_SLOTS):
            slot = mat.textures.get(name)
            unit = TEXTURE_UNITS["u_material_maps"][i]
            use_unit(program, self._map_texture(slot) if slot is not None else self.white, unit)
            use_unit(program, self._map_sampler(slot), unit)
            texcoords.append(slot.tex_coord if slot is not None else -1)
            transform = np.asarray(slot.transform if slot is not None else np.eye(3), dtype=np.float32)
            transforms.append(transform.T)  # GLSL mat3 is column-major
            mirrored.append(
                [int(slot.wrap_s == MIRRORED_REPEAT), int(slot.wrap_t == MIRRORED_REPEAT)] if slot else [0, 0]
            )
        set_uniform(program, "u_material_maps", list(TEXTURE_UNITS["u_material_maps"]))
        write_uniform(program, "u_map_texcoord", np.asarray(texcoords, dtype=np.int32))
        write_uniform(program, "u_map_transform", np.asarray(transforms, dtype=np.float32))
        write_uniform(program, "u_map_mirrored", np.asarray(mirrored, dtype=np.int32))
        # Normalised lobe-N (shaders/patterns.glsl lobe_albedo); a multi-drawn program reads the
        # flag and its albedo table's layer from its records (viewer/object_records.py) but binds
        # the DFG tables all the same (its own u_albedo is unused there).
        if any(has_uniform(program, name) for name in ("u_albedo_per_pixel", "u_albedo", "u_dfg")):
            # Every texture but the normal maps, occlusion and emission changes the lobes' albedo.
            per_pixel = gltf_model and bool(set(mat.textures) - {"normal", "occlusion", "emissive", "clearcoat_normal"})
            set_uniform(program, "u_albedo_per_pixel", int(per_pixel))

            # Bound even when unused: a sampler left on unit 0 would meet the radiance cube there
            # (two sampler types on one unit fail the draw with GL_INVALID_OPERATION).
            bind_sampler(program, "u_dfg", self._dfg_texture() if per_pixel else self.white)
            anisotropic = per_pixel and (float(desc.get("anisotropy", 0.0)) > 0.0 or "anisotropy" in mat.textures)
            bind_sampler(
                program,
                "u_dfg_anisotropic",
                self._anisotropic_dfg_texture() if anisotropic else self.dummy_texture("3d"),
            )

    def _bind_proxy(self, program, proxy, probe_centre) -> None:
        """The reflection proxy (scenes/reflection_proxy.py) as shaders/integrate.glsl PARALLAX
        reads it, with ``probe_centre``: where the cube map was rendered from (a shared probe's:
        its group's)."""
        set_uniform(program, "u_cube_centre", tuple(float(x) for x in probe_centre))
        set_uniform(program, "u_proxy_kind", PROXY_KINDS[proxy.kind])
        set_uniform(program, "u_proxy_plane_count", len(proxy.planes) if proxy.kind == "planes" else 0)
        write_uniform(program, "u_proxy_planes", proxy.padded_planes())
        box = (proxy.box_min, proxy.box_max) if proxy.kind == "box" else (np.zeros(3), np.zeros(3))
        set_uniform(program, "u_proxy_box_min", tuple(float(x) for x in box[0]))
        set_uniform(program, "u_proxy_box_max", tuple(float(x) for x in box[1]))

    def release(self) -> None:
        super().release()
        self.textures.clear()
        for sampler in self._samplers.values():
            sampler.release()
        if self._dfg is not None:
            self._dfg.release()
        if self._anisotropic_dfg is not None:
            self._anisotropic_dfg.release()
        self.white.release()
        self._no_horizon_map.release()


def lamp_uniforms(lamps: list) -> dict[str, np.ndarray]:
    """shaders/lamps.glsl's per-scene arrays for ``lamps`` (scenes/lamps.py: a point or spot lamp
    is a sphere of LAMP_RADIUS, a directional one a disc of DIRECTIONAL_ANGULAR_RADIUS)."""
    position, colour, spot, shape = (np.zeros((MAX_LAMPS, 4), dtype=np.float32) for _ in range(4))
    for k, lamp in enumerate(lamps[:MAX_LAMPS]):
        direction = np.asarray(lamp.direction, dtype=np.float64)
        if lamp.type == "directional":
            position[k, :3] = -direction
        else:
            position[k, :3] = lamp.position
        position[k, 3] = LAMP_KINDS[lamp.type]
        colour[k, :3] = np.asarray(lamp.colour, dtype=np.float64) * float(lamp.intensity)
        colour[k, 3] = 0.0 if lamp.range is None else float(lamp.range)
        cos_outer, scale = spot_ramp(lamp)
        spot[k] = (*direction, cos_outer)
        shape[k] = (scale, np.sin(DIRECTIONAL_ANGULAR_RADIUS), LAMP_RADIUS, 0.0)
    return {"u_lamp_position": position, "u_lamp_colour": colour, "u_lamp_spot": spot, "u_lamp_shape": shape}
