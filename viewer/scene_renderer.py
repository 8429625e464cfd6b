"""Light-mapped scene renderer (thesis 4.3-4.4): diffuse from lightmaps, view-dependent lobes
from a cube map per object or a planar mirror buffer.

SceneRenderer orchestrates the passes of a frame over parts that each own one thing (issue 38;
docs/architecture.md):
- RenderSettings (viewer/settings.py): every option, changed only through ``configure``;
- SceneShading (viewer/scene_shading.py): what a draw binds of a material, its textures,
  lightmap and proxy, recorded once and replayed;
- ObjectDrawer (viewer/object_drawer.py): the GPU objects and the draw loop every pass uses;
- CubeProbes (viewer/cube_probes.py): the cube maps, their bake (viewer/cube_bake.py), shared
  probes, the memory budget and the stale queue after material edits;
- MirrorPasses (viewer/mirror_pass.py): buffers for the planar reflectors in view;
- accumulation and tonemapping live in viewer/display.py (the window's refinement).
Only what the scene analysis asks for is built.
"""

from __future__ import annotations

import contextlib
import hashlib
import time
import warnings
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.methods import Method
from lobeview.core.progress import report
from lobeview.materials.spec import build_bsdf
from lobeview.scenes.analysis import analyse
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.scene import Scene
from lobeview.scenes.self_visibility import NO_OCCLUSION, object_visibility_cones

from .camera import Camera, jittered
from .cube_probes import CubeProbes
from .cubemap import RadianceCube, equirect_to_cube_faces, irradiance_cube
from .material_gpu import pack_material
from .mirror_pass import MirrorPasses
from .object_drawer import ObjectDrawer
from .render_base import RendererBase, RenderResult
from .scene_shading import SceneShading
from .settings import CUBE_MAP_FIELDS, RenderSettings
from .shaders import ProgramCache

__all__ = ["RenderSettings", "SceneRenderer"]


class SceneRenderer(RendererBase):
    PLANE_STATE = True  # refinement on reflectors averages tangent planes across passes

    def __init__(
        self,
        ctx: moderngl.Context,
        scene: Scene,
        environment: EnvironmentMap,
        size=(640, 400),
        settings: RenderSettings | None = None,
        cache_dir: Path | None = None,
        progress: bool = True,
        progressive_cubes: bool = False,
    ):
        """``progressive_cubes`` (the viewer): without cached cube maps, start with preview cube
        maps and build the exact ones over later frames (``continue_cube_build``), so the first
        frame comes in seconds; ``shot`` and the benchmarks build them all first."""
        settings = settings if settings is not None else RenderSettings()
        self._settings = settings
        self.scene = scene
        self.progress = progress
        self.timings: dict = {}
        t0 = time.perf_counter()
        self.cache_dir = Path(cache_dir) if cache_dir else None
        report(f"environment {environment.name}: irradiance, radiance cube, bright sources")
        # diffuse light of objects without a lightmap: the environment's exact irradiance per normal
        self.environment_irradiance = irradiance_cube(ctx, environment)
        shading = SceneShading(ctx, ProgramCache(ctx), scene, self.environment_irradiance, settings.mip_filter,
                               self.cache_dir)  # fmt: skip
        super().__init__(ctx, size, shading)
        self.environment = RadianceCube(
            ctx,
            equirect_to_cube_faces(environment, 256),
            mip_filter=settings.mip_filter,
            bright_sources=settings.bright_sources,
        )
        self.environment_name = environment.name
        analysis = self._analyse(scene, settings, settings.cube_face_size)
        report(f"materials and geometry of {len(scene.objects)} objects")
        packed = [pack_material(build_bsdf(scene.materials[obj.material].desc)) for obj in scene.objects]
        # Visibility cones against each object itself (scenes/self_visibility.py), from the
        # cache folder where it has them.
        t_cones = time.perf_counter()
        missing = [obj for obj in scene.objects if obj.self_visibility is None]
        for obj in missing:
            object_visibility_cones(obj, self.cache_dir)
        if missing:
            with_cone = sum(int(np.count_nonzero(obj.self_visibility[:, 3] > NO_OCCLUSION)) for obj in missing)
            report(
                f"self-occlusion cones of {len(missing)} objects: {with_cone} vertices see their own object"
                f" ({time.perf_counter() - t_cones:.1f} s)"
            )
        # The horizons per lightmap texel: traced here for `shot` and the benchmarks; the viewer
        # (progressive, with a cache folder) takes what the cache has and leaves the rest to a
        # worker process (app/finishing.py), its objects on their vertices' horizons meanwhile
        # (shading.missing_horizon_maps).
        t_maps = time.perf_counter()
        shading.prepare_horizon_maps(trace=not (progressive_cubes and self.cache_dir))
        maps = len(shading.horizon_maps) + len(shading.uv0_horizon_maps)
        if maps:
            report(f"self-occlusion horizons per texel: {maps} maps ({time.perf_counter() - t_maps:.1f} s)")
        self.drawer = ObjectDrawer(ctx, scene, packed, shading, self.environment, self.frame, settings, analysis)
        shading.draw_records = settings.draw_records
        shading.self_occlusion = settings.self_occlusion
        self.objects = self.drawer.objects
        self.object_names = [obj.name for obj in self.objects]  # the mirror passes' report lines
        self.draw_counts = self.drawer.draw_counts  # objects drawn and culled per kind of pass
        self.frame_draw_calls = (0, 0, 0)  # the last draw_frame's: per-object, multi-draws, culling passes
        self._apply_method_rule()
        for needs in self.analysis.objects:
            if not needs.has_lightmap:
                warnings.warn(
                    f"object {needs.name!r} has no usable lightmap: its diffuse light is the environment's "
                    "irradiance at each normal (nothing occludes it: bake the scene for shadows)",
                    stacklevel=2,
                )
        self.timings["upload"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.bounds = scene.bounds  # static scene: near/far planes are fitted to it every frame
        env_hash = hashlib.sha256(environment.image.tobytes()).hexdigest()[:16]
        report("cube maps", 0.0)
        self.progressive_cubes = bool(progressive_cubes)
        self.probes = CubeProbes(ctx, self.drawer, settings, env_hash, progress, self.cache_dir, progressive_cubes)
        # The specular bounces draw the objects' self-occlusion: not before its horizon maps are in,
        # or the cached cube maps would not be `shot`'s. The window's worker traces them
        # (app/finishing.py sets horizon_maps_traced_elsewhere meanwhile: the build waits);
        # otherwise continue_cube_build traces them before those bounces.
        self.horizon_maps_traced_elsewhere = False
        self.probes.hold_specular_bounces = lambda: shading.missing_horizon_maps > 0
        self.mirror_passes = MirrorPasses(ctx, self.drawer, self.probes, settings.mip_filter)
        self.drawer.mirror_passes = self.mirror_passes
        self.timings["cube maps"] = time.perf_counter() - t0

    # -- settings ---------------------------------------------------------------------------------
    @property
    def settings(self) -> RenderSettings:
        return self._settings

    def configure(self, settings: RenderSettings | None = None, **changes) -> RenderSettings:
        """The one way to change options (panel, benchmarks, tests): ``settings`` replaced by
        ``changes``; takes effect on the next frame. Options that decide what the cube maps hold
        (settings.CUBE_MAP_FIELDS) are a renderer's for its life: changing one raises."""
        new = (settings or self._settings).replace(**changes)
        fixed = [name for name in CUBE_MAP_FIELDS if getattr(new, name) != getattr(self._settings, name)]
        if fixed:
            raise ValueError(f"{', '.join(fixed)} decide what the cube maps hold: make a new renderer to change them")
        rule_changed = new.method_target != self._settings.method_target
        self._settings = new
        self.drawer.settings = self.probes.settings = new
        self.shading.draw_records = new.draw_records
        self.shading.self_occlusion = new.self_occlusion
        if rule_changed:  # the rule's picks again, or (None) every object back on the frame's method
            self.drawer.analysis = self._analyse(self.scene, new, self.cube_face_size)
            if new.method_target is None:
                self.drawer.object_methods.clear()
            self._apply_method_rule()
        return new

    @property
    def analysis(self):
        """What each object needs (scenes/analysis.py), made again after a material edit; the
        drawer's, which the cube-map owner reads too."""
        return self.drawer.analysis

    @property
    def cube_face_size(self) -> int:
        return self.probes.bake.face_size

    @property
    def cube_bounces(self) -> int:
        return self.probes.bake.bounces

    # -- what the panel and the reports read ------------------------------------------------------
    @property
    def draw_report(self) -> list[str]:
        """Objects drawn and culled: by the last frame's camera and mirror passes, and by every
        cube-map face rendered since start-up; the last frame's draw calls."""
        single, multi, culls = self.frame_draw_calls
        calls = f"draw calls (last frame): {single} per object, {multi} multi-draws, {culls} GPU culling passes"
        return [*self.draw_counts.report(), calls]

    @property
    def mirror_report(self) -> list[str]:
        """What the last frame's mirror passes did, one line per reflector."""
        return self.mirror_passes.report

    @property
    def radiance_target(self):
        """The float radiance texture of the last drawn frame."""
        return self.targets[0]

    @property
    def stale_cube_count(self) -> int:
        """Cube maps still waiting to be re-rendered: made stale by a material edit, or queued for
        the full face size by request_full_faces."""
        return len(self.probes.bake.stale) + len(self.probes.bake.upgrades)

    @property
    def has_rational(self) -> bool:
        """Whether any object draws a Rational BRDF (reference passes then shrink: Method.for_rational)."""
        return any(obj.material.has_rational for obj in self.objects)

    def set_object_method(self, index: int, method: Method | None) -> None:
        """Shade object ``index`` with its own real-time method (None: the frame's method)."""
        if method is None:
            self.drawer.object_methods.pop(index, None)
        elif method.kind == "reference":
            raise ValueError("the per-object method must be a real-time one; refinement uses the reference")
        else:
            self.drawer.object_methods[index] = method

    @staticmethod
    def _analyse(scene, settings: RenderSettings, face_size: int):
        return analyse(scene, face_size, settings.lobe_width_cubes, settings.reflector_cubes_on_demand,
                       settings.method_target)  # fmt: skip

    def _apply_method_rule(self) -> None:
        """With ``settings.method_target``: each object the rule has a table for takes its pick as
        its own method (again after a material edit; the panel can still override one)."""
        if self._settings.method_target is None:
            return
        for index, needs in enumerate(self.analysis.objects):
            if needs.method_choice is not None and needs.method_choice.method is not None:
                self.set_object_method(index, Method.parse(needs.method_choice.method))

    def object_method(self, index: int) -> Method | None:
        """Object ``index``'s own method, or None when it follows the frame's."""
        return self.drawer.object_methods.get(index)

    def set_reflection_proxy(self, index: int, proxy) -> None:
        """Reflected-geometry correction for object ``index`` (scenes/reflection_proxy.py; None:
        the plain lookup). Takes effect on the next frame; the cube map itself is unchanged."""
        self.scene.objects[index].reflection_proxy = proxy
        self.shading.invalidate_records()

    def render_cube_faces(
        self, eye, exclude: int | None = None, specular: bool = False, size: int | None = None
    ) -> np.ndarray:
        """Six faces of the scene seen from ``eye`` (viewer/cube_bake.py CubeBake.render_faces)."""
        return self.probes.bake.render_faces(eye, exclude, specular, size)

    # -- planar mirror passes (thesis 4.5) --------------------------------------------------------
    def reflectors(self) -> dict:
        """Object index -> PlanarReflector of the reflectors in use (analysis, minus disabled)."""
        found = self.analysis.reflectors
        if not self._settings.mirrors:
            return {}
        enabled = self._settings.enabled_reflectors
        if enabled is not None:
            found = {i: r for i, r in found.items() if i in enabled}
        return found

    def render_mirror_passes(
        self,
        camera: Camera,
        jitters: bool = False,
        method: Method | None = None,
        lod_bias: float | None = None,
        camera_depth=None,
    ) -> dict:
        """This frame's mirror and see-through buffers (viewer/mirror_pass.py). ``jitters``: the
        frame's passes move off the pixel centres (box-filtered reference), where the occlusion
        test, exact at pixel centres, does not apply. ``method`` (the frame's) and ``lod_bias``:
        reflectors shaded by lobe-N get passes scissored to where their lookups read
        (``mirror_scissor``; None: every pass whole). ``camera_depth``: the frame's depth
        pre-pass, drawn already, for the occlusion test to read."""
        settings = self._settings
        bias = Method("lobe", 1).default_lod_bias(self.mip_filter) if lod_bias is None else float(lod_bias)
        occlusion = settings.mirror_occlusion and not jitters
        # The lookups' reach and finest footprint are found inside, for the reflectors that get a
        # pass (about one a frame): computed for every reflector of the scene each frame, they
        # were a per-object Python loop in an otherwise per-pass frame (issue 42).
        return self.mirror_passes.render(
            camera, self.size, self.reflectors(), self.object_names, settings.mirror_scale, settings.mirror_specular,
            occlusion, method if settings.mirror_scissor else None, bias,
            method if settings.mirror_lobe_sizes else None, settings.mirror_plane_sharing, camera_depth,
        )  # fmt: skip

    def invalidate_mirrors(self) -> None:
        """Draw the mirror buffers again on the next frame even if nothing changed (benchmarks)."""
        self.mirror_passes.invalidate()

    # -- frames -------------------------------------------------------------------------------------
    def draw_frame(
        self,
        camera: Camera,
        method: Method,
        sample_offset: int = 0,
        lod_bias=None,
        seed: int = 0,
        jitter=(0.0, 0.0),
        texture_footprint: float = 1.0,
    ) -> None:
        """One pass into the renderer's own float targets (radiance in ``targets[0]``), no read
        back: what the interactive viewer calls every frame. ``jitter``: this pass's sub-pixel
        position in pixels (a box-filtered reference, viewer/camera.py pixel_offset); the mirror
        passes keep the unjittered camera (they are looked up by world position).
        ``texture_footprint``: the material textures' filter footprint as a share of the pixel's
        (shaders/material_maps.glsl): 1 shades whole pixels; passes that integrate the pixel over
        their sub-pixel positions read their own share (render, the viewer's refinement); the
        camera pass only: the mirror buffers and cube faces are drawn once for all passes."""
        camera = camera.fitted_to(self.bounds)  # any scene scale, mm to km (viewer/camera.py)
        width, height = self.size
        view_proj = jittered(camera.view_projection(width / height), jitter, self.size)
        self.draw_counts.new_frame()
        calls_before = self.drawer.draw_calls.total()
        # Planar reflectors read this frame's mirror buffers; the prefiltered method is one cube
        # lookup per lobe, so there they keep their cube maps and no mirror pass is drawn.
        self.probes.restore(view_proj)
        drawer = self.drawer
        settings = self._settings
        # The depth pre-pass first where the mirror passes' occlusion test can read it (an
        # unjittered real-time frame): the test then draws no depth pass of its own.
        early_depth = (
            settings.depth_prepass and settings.mirror_occlusion and method.kind not in ("prefiltered", "reference")
            and tuple(jitter) == (0.0, 0.0) and bool(self.reflectors())
        )  # fmt: skip
        counts = self.draw_counts.of("depth pre-pass")

        def depth_prepass(clear: bool = False) -> None:
            # Opaque depth first (viewer/occlusion.py): the shading pass then integrates the lobes
            # once per pixel, not once per overlapping surface. ``clear``: drawn before the
            # frame's own clear (FrameTargets.begin keep_depth), which then keeps it.
            self.frame.begin_depth(clear)
            counts.drawn, counts.culled = drawer.draw_depth(view_proj)

        if early_depth:
            depth_prepass(clear=True)
        if method.kind == "prefiltered":
            mirrors = {}
            names = self.object_names
            self.mirror_passes.skip_all(self.reflectors(), names, "cube map (prefiltered method)")
        else:
            camera_depth = self.frame.depth_fbo if early_depth else None
            mirrors = self.render_mirror_passes(camera, method.kind == "reference", method, lod_bias, camera_depth)
        self.probes.reflector_cubes_for(method, self.reflectors())
        averages = any(drawer.averages_planes(drawer.object_method(i, method)) for i in mirrors)
        self.frame.begin(averages_planes=averages, keep_depth=early_depth)
        self.draw_background(self.environment, view_proj)
        if settings.depth_prepass:
            if not early_depth:
                depth_prepass()
            self.frame.fbo.use()
            self.ctx.depth_func = "<="
        self.shading.texture_footprint = float(texture_footprint)
        try:
            drawer.draw(view_proj, camera.position, method, True, None, lod_bias, sample_offset, seed, mirrors,
                        cull=True)  # fmt: skip
        finally:
            self.shading.texture_footprint = 1.0
        self.ctx.depth_func = "<"
        self.probes.residency.evict(self.objects)
        self.frame_draw_calls = tuple(int(x) for x in np.subtract(self.drawer.draw_calls.total(), calls_before))

    def pick(self, x: int, y: int) -> int | None:
        """Object index under pixel (x, y) (y down) of the last drawn frame, or None."""
        return self.frame.pick(x, y)

    def update_material(self, index: int, desc: dict) -> None:
        """Replace the material of object ``index`` with a (validated) description. The cube
        maps of the other glossy objects show the old appearance until refresh_one_stale_cube
        has re-rendered them (one per frame in the viewer)."""
        from lobeview.materials.spec import validate

        desc = validate(desc)
        self.mirror_passes.materials_changed()  # what the mirror buffers show changed
        self.shading.invalidate_records()  # the objects' recorded draw state
        material_index = self.scene.objects[index].material
        self.scene.materials[material_index].desc = desc
        packed = pack_material(build_bsdf(desc))
        for gpu_obj in self.objects:  # before any cube map is rendered below (and its draws recorded)
            if self.scene.objects[gpu_obj.index].material == material_index:
                gpu_obj.material = packed
        self.drawer.analysis = self._analyse(self.scene, self._settings, self.cube_face_size)
        self._apply_method_rule()
        self.probes.material_edited(material_index)

    def request_full_faces(self, camera: Camera) -> int:
        """Queue the cube maps of the objects in view whose faces were sized by their lobes for
        re-rendering at the full face size (one per ``refresh_one_stale_cube``): progressive
        refinement reads level 0, finer than the lobe-N lookups the sizes were chosen for, and
        should converge to what ``shot --method reference`` (full faces) renders. Returns how
        many were queued."""
        if not self._settings.lobe_width_cubes:
            return 0
        width, height = self.size
        return self.probes.request_full_faces(camera.fitted_to(self.bounds).view_projection(width / height))

    @property
    def cube_build_status(self) -> str | None:
        """What the progressive cube-map build has left (None: the cube maps are finished)."""
        if not self.probes.building:
            return None
        done, total = self.probes.pending_progress
        if self.probes.held:
            return f"cube maps: step {done} of {total}, the next bounce waits for the self-occlusion horizons"
        return f"cube maps: step {done} of {total} (object renders, installs, cache file; previews shown meanwhile)"

    def continue_cube_build(self, seconds: float, camera: Camera | None = None) -> int:
        """Advance the progressive cube-map build for about ``seconds`` (at least one object's
        faces; the first bounce renders the objects nearest ``camera`` first). Returns the steps
        made; any step changes what the frame shows (the mirror buffers are drawn again)."""
        if not self.probes.building:
            return 0
        if camera is not None:
            self.probes.focus = np.asarray(camera.position, dtype=np.float64)
        if self.probes.held and not self.horizon_maps_traced_elsewhere:
            self.shading.prepare_horizon_maps(trace=True)  # no worker traces them: here, before those bounces
        viewport = self.ctx.viewport
        steps = self.probes.continue_build(seconds)
        self.ctx.viewport = viewport
        self.mirror_passes.invalidate()
        return steps

    def refresh_one_stale_cube(self) -> str | None:
        """Re-render one out-of-date cube map (after a material edit changed what it sees);
        the viewer calls this once per frame so edits never freeze the UI. Returns its name."""
        return self.probes.bake.refresh_one(self.objects)

    def render(
        self,
        camera: Camera,
        method: Method | str,
        spp: int = 1024,
        lod_bias: float | None = None,
        seed: int = 0,
        pixel_filter: str = "box",
    ) -> RenderResult:
        """``pixel_filter`` as in PreviewRenderer.render: 'box' (default) makes a reference the
        pixel's integral, 'point' shades every pass at the pixel centre."""
        method = Method.parse(method) if isinstance(method, str) else method
        method, offsets = self.pass_plan(method, spp, pixel_filter, self.has_rational)
        passes = len(offsets)
        timer = self.gpu_timer()
        # A box-filtered reference integrates the pixel over its passes' positions: each reads the
        # material textures over its own share of the pixel (shaders/material_maps.glsl).
        jittered_passes = any(tuple(offset) != (0.0, 0.0) for offset in offsets)
        footprint = 1.0 / np.sqrt(passes) if jittered_passes else 1.0
        accumulated, invalid, t_shade, t_gpu, g_buffers = self._accumulate_passes(
            camera, method, offsets, lod_bias, seed, timer, footprint
        )
        return RenderResult(
            radiance=(accumulated / passes).astype(np.float32),
            position=g_buffers[0][..., :3],
            normal=g_buffers[1][..., :3],
            tangent=g_buffers[2][..., :3],
            mask=g_buffers[0][..., 3] > 0.5,
            invalid=invalid,
            timings={**self.timings, "shade": t_shade, **({"gpu shade": t_gpu} if timer is not None else {})},
            samples_per_pixel=passes * method.samples,
            object_id=np.rint(g_buffers[1][..., 3]).astype(np.int32) - 1,
        )

    def _accumulate_passes(self, camera: Camera, method: Method, offsets, lod_bias, seed: int, timer,
                           texture_footprint: float = 1.0):  # fmt: skip
        """Draw a pass at each sub-pixel offset and sum their radiance: (sum, invalid pixels,
        seconds, GPU seconds, the first pass's G-buffers)."""
        width, height = self.size
        accumulated = np.zeros((height, width, 3))
        invalid = np.zeros((height, width), dtype=bool)
        t_shade = t_gpu = 0.0
        g_buffers = None
        for p, offset in enumerate(offsets):
            t0 = time.perf_counter()
            _ = self.ctx.error  # reset the flag: only errors of this frame's passes count below
            with timer or contextlib.nullcontext():
                self.draw_frame(camera, method, p * method.samples, lod_bias, seed, jitter=offset,
                                texture_footprint=texture_footprint)  # fmt: skip
            self.ctx.finish()
            self.raise_on_gl_error(method)
            t_shade += time.perf_counter() - t0
            if timer is not None:
                t_gpu += timer.elapsed * 1e-9
            radiance = self.read(0)
            accumulated += radiance[..., :3]
            invalid |= radiance[..., 3] < 0.0
            if g_buffers is None:
                g_buffers = [self.read(i) for i in (1, 2, 3)]
        return accumulated, invalid, t_shade, t_gpu, g_buffers

    def release(self):
        super().release()
        self.mirror_passes.release()
        self.drawer.release()
        self.environment.release()
        self.environment_irradiance.release()
