"""What the window does while its scene is still being finished (issue 42 item 2: a first frame
in seconds): it swaps in the baked scene when the background bake ends (app/background_bake.py),
takes the horizon maps per lightmap texel (scenes/horizon_maps.py) from a worker that traces the
ones the cache lacks, and advances the progressive cube-map build (viewer/cube_probes.py) between
frames. The window (app/window.py) owns one :class:`SceneFinishing` and calls it once per frame."""

from __future__ import annotations

import time
from pathlib import Path

from lobeview.app.frame_pacing import REST_DELAY_S
from lobeview.app.options import apply_reflection_proxy, scene_renderer_from_args

CUBE_BUILD_REDRAW_S = 2.0  # the progressive cube-map build redraws the view this often (full resolution)


class SceneFinishing:
    """``background_bake``: the worker baking the scene's lightmaps (None: the scene is baked)."""

    def __init__(self, background_bake=None):
        self.background_bake = background_bake
        self.horizon_worker = None  # app/background_bake.BackgroundBake tracing the horizon maps
        self.horizon_maps_asked_for = None  # the renderer a horizon worker ran for (once each)
        self.cube_build_redrawn_at = 0.0  # when the progressive cube-map build last redrew the frame

    @property
    def bake_status(self) -> str | None:
        """The background bake's progress line (None: no bake running)."""
        return self.background_bake.status if self.background_bake is not None else None

    @property
    def horizon_status(self) -> str | None:
        """The horizon-map worker's progress line (None: none running)."""
        return self.horizon_worker.status if self.horizon_worker is not None else None

    def cancel(self) -> None:
        """The window closes: stop the workers."""
        for worker in (self.background_bake, self.horizon_worker):
            if worker is not None:
                worker.cancel()

    def poll_horizon_maps(self, window) -> None:
        """The renderer's missing horizon maps (SceneShading.missing_horizon_maps): a worker
        traces them into its cache folder from the scene file (not while a bake runs: that one
        traces the baked scene's), and the renderer takes them when it ends; its objects draw with
        their vertices' horizons meanwhile. A scene with no file to trace from is traced here."""
        renderer = window.renderer
        worker = self.horizon_worker
        if worker is None:
            if not renderer.shading.missing_horizon_maps:
                return
            if self.background_bake is not None:
                # the baked scene comes with its own maps: this one's cube-map build waits for them
                # (its specular bounces; the swap replaces them), nothing traced in the window
                renderer.horizon_maps_traced_elsewhere = True
                return
            if self.horizon_maps_asked_for is renderer:
                return
            self.horizon_maps_asked_for = renderer
            scene_path = window.session.scene_path
            if scene_path is None or not Path(scene_path).is_file():
                self.trace_horizon_maps_here(window)
                return
            from lobeview.app.background_bake import BackgroundBake

            self.horizon_worker = BackgroundBake.for_horizon_maps(scene_path, renderer.cache_dir, window.args.limits)
            renderer.horizon_maps_traced_elsewhere = True  # its cube-map build waits for them
            return
        if not worker.poll():
            return
        self.horizon_worker = None
        self.horizon_maps_asked_for.horizon_maps_traced_elsewhere = False
        if renderer is not self.horizon_maps_asked_for:
            return  # traced for a renderer since replaced: the new one asks again (from the cache)
        if worker.error is not None or renderer.shading.prepare_horizon_maps(trace=False):
            why = worker.error or "its maps were not found in the cache folder"
            window.message = f"the self-occlusion worker failed ({why}): traced here instead"
            self.trace_horizon_maps_here(window)
        window.dirty = True

    def trace_horizon_maps_here(self, window) -> None:
        """The renderer's missing horizon maps traced in the window's own process (a scene with no
        file, a worker that failed, a screenshot due; the loading overlay shows it). Should that
        fail too, its objects keep their vertices' horizons and the cube-map build goes on
        without writing its cache file (its cube maps would not be those `shot` makes)."""
        renderer = window.renderer
        window.show_progress("tracing the self-occlusion horizons per texel", None)
        try:
            renderer.shading.prepare_horizon_maps(trace=True)
        except Exception as exc:  # noqa: BLE001 - the viewer goes on with vertex horizons
            window.message = f"self-occlusion horizons per texel failed ({type(exc).__name__}: {exc}): vertex horizons"
            renderer.shading.missing_horizon_maps = 0
            renderer.probes.bake.cache_dir = None
        window.dirty = True

    def poll_background_bake(self, window) -> None:
        """Swap in the baked scene once the worker has written it: the same objects with
        lightmaps, the materials as edited meanwhile (by name), the panel's options and
        per-object methods kept; its cube maps start progressively again."""
        bake = self.background_bake
        if bake is None or not bake.poll():
            return
        self.background_bake = None
        if bake.error is not None:
            window.message = f"the lightmap bake failed ({bake.error}): the scene stays without lightmaps"
            window.renderer.horizon_maps_traced_elsewhere = False  # poll_horizon_maps traces its maps now
            return
        from lobeview.scenes.gltf_loader import load_gltf

        try:
            scene = load_gltf(bake.path, window.args.limits)
        except Exception as exc:  # noqa: BLE001 - the viewer keeps the scene it has
            window.message = f"the baked scene {bake.path.name} could not be loaded ({exc}); kept the unbaked one"
            window.renderer.horizon_maps_traced_elsewhere = False
            return
        edited = {m.name: m.desc for m in window.scene.materials}
        for material in scene.materials:
            if material.name in edited:
                material.desc = edited[material.name]
        apply_reflection_proxy(scene, window.args.reflection_proxy)
        old, session = window.renderer, window.session
        renderer = scene_renderer_from_args(
            window.ctx, scene, session.environment, old.size, session.cache, window.args,
            progressive_cubes=old.progressive_cubes,
        )  # fmt: skip
        renderer.configure(old.settings)
        for index, method in old.drawer.object_methods.items():
            renderer.set_object_method(index, method)
        old.release()
        window.renderer, window.scene = renderer, scene
        window.editor.renderer = renderer  # its undo stack holds object indices: the same objects
        session.scene, session.scene_path = scene, bake.path
        window.wnd.title = f"lobeview - {bake.label or bake.path.name}"
        window.message = f"lightmaps baked: {bake.path} (cached for the next start)"
        window.dirty = True

    def continue_cube_build(self, window, camera, t_frame: float) -> None:
        """One object's cube map of the progressive start (SceneRenderer continue_cube_build: the
        nearest first) in a frame where the view has rested REST_DELAY_S and no key is held (a
        step takes up to seconds without a GPU: never while the user moves), which changes the
        frame; all that is left when a screenshot is due, so that it shows what its printed
        `lobeview shot` command renders."""
        renderer = window.renderer
        if renderer.cube_build_status is None:
            return
        finish = bool(window.pending_screenshots)
        if renderer.probes.held and not finish:
            return  # waits for the horizon maps (poll_horizon_maps): nothing to draw again
        resting = not window.dirty and t_frame - window.last_change >= REST_DELAY_S and not window.held_keys.down_since
        if not (finish or resting):
            return
        if finish:
            if renderer.shading.missing_horizon_maps:  # the build's later bounces wait for them
                self.trace_horizon_maps_here(window)
            window.show_progress("finishing the cube maps for the screenshot", None)
        while True:
            renderer.continue_cube_build(0.0, camera)
            status = renderer.cube_build_status
            if status is None or not finish:
                break
        if status is None:
            window.message = "cube maps finished"  # the panel showed the build's progress
        # The frame shows the new cube maps at full resolution every CUBE_BUILD_REDRAW_S, or every
        # four full frames' time where a frame is slow (a moving frame after each step would keep
        # the view blurred at the moving scale for the whole build), and when the build ends.
        now = time.perf_counter()
        interval = max(CUBE_BUILD_REDRAW_S, 4.0 * window.pass_ms / 1000.0)
        if status is None or finish or now - self.cube_build_redrawn_at >= interval:
            self.cube_build_redrawn_at = now
            window.dirty = True
            window.full_frame_due = True
