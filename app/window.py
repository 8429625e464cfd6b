"""The walkthrough window (moderngl-window, pyglet backend): input events, the frame loop, the
progressive refinement policy and screenshots. The panel is app/panel.py, material editing
app/editor.py, the camera app/walk.py, scripted sessions app/script.py.

While the camera moves, every frame is rendered with the chosen real-time method, at the
resolution that holds the target frame rate (app/frame_pacing.py, ``--target-fps``), upsampled
to the window; once the camera, the materials and the method have stayed still for a moment the
frame is rendered at full resolution, then each frame adds a batch of unbiased quasi-random MIS
samples at another sub-pixel position to a float accumulation buffer, and the display shows the
running mean (thesis 4.4.2) once its estimated error is below the real-time frame's; refinement
stops when converged (viewer/refinement.py). A frame in which nothing changed and nothing is
refined is not rendered again: the last image is shown. Motion (keys, ``--path``) follows
wall-clock time, whatever the frame rate.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import moderngl_window as mglw
import numpy as np
from imgui_bundle import imgui, implot

from lobeview.app.editor import MaterialEditor
from lobeview.app.finishing import SceneFinishing
from lobeview.app.fit_job import FitJob, lockable_parameters
from lobeview.app.frame_pacing import (
    MOTION_STALL_CAP_S,
    REST_DELAY_S,
    HeldKeys,
    RenderScale,
    scaled_size,
    target_frame_seconds,
)
from lobeview.app.imgui_input import PanelArea, QueuedInputRenderer
from lobeview.app.options import default_screenshot_dir, scene_renderer_from_args, shot_command
from lobeview.app.panel import draw_panel
from lobeview.app.script import run_due_steps
from lobeview.app.walk import WalkCamera, walk_speed_for
from lobeview.core import progress
from lobeview.core.methods import Method
from lobeview.materials.fitted_pattern import fitted_sample_counts
from lobeview.scenes.hdrio import write_hdr_image
from lobeview.scenes.setup import scene_view
from lobeview.viewer.camera import Camera
from lobeview.viewer.display import Accumulator, RefinementBlend
from lobeview.viewer.refinement import REFINEMENT_TEXTURE_FOOTPRINT, Refinement, two_half_estimate
from lobeview.viewer.tonemap import to_uint8, tonemap

FRAME_TIME_SMOOTHING = 0.2  # exponential smoothing of the shown frame interval
STACK_BUILD_BUDGET_S = 0.1  # of a frame spent building blur stacks (at least one a frame)
CUBE_REFRESH_MAX_DEFERRED = 8  # moving frames a stale cube map waits at most for room in the budget


@dataclass
class Session:
    """What the command line gives the window (moderngl-window instantiates the class itself)."""

    scene: object
    scene_path: Path
    environment: object
    args: object
    method: Method
    cache: Path
    script: list
    original_materials: dict | None = None
    loaded_materials: list | None = None
    camera_path: object | None = None  # scenes/camera_path.CameraPath flown from frame 1 (--path)
    background_bake: object | None = None  # app/background_bake.BackgroundBake: the lightmaps on their way


class LobeviewWindow(mglw.WindowConfig):
    gl_version = (4, 5)
    title = "lobeview"
    resizable = True
    aspect_ratio = None
    # Set by app/view.py before the window opens: what builds and loads the scene (called inside
    # the window, under its loading overlay) and what the overlay calls it until then.
    load_session = None
    loading_title = "scene"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        imgui.create_context()
        # No imgui.ini in whatever folder the viewer was started from: the panel lays
        # itself out each start.
        imgui.get_io().set_ini_filename("")
        implot.create_context()
        self.imgui = QueuedInputRenderer(self.wnd)
        self.started = time.perf_counter()
        self.realtime = None  # no image yet: the loading overlay draws on a plain background
        self._overlay_shown_at = 0.0
        # Every long step (scene build and bake on first use, the scene renderer's cube maps,
        # prefiltered maps built on first use) draws the loading overlay from the first frame on
        # (core/progress.py report); removed on close.
        self._listening = progress.listening(self.show_progress)
        self._listening.__enter__()
        try:
            self.show_progress(f"loading {self.loading_title}", None)
            self.session = session = self.load_session()
        except BaseException:
            self._listening.__exit__(None, None, None)
            raise
        self.scene, self.args = session.scene, session.args
        self.wnd.title = f"lobeview - {session.scene_path.name}"
        self.panel_area = PanelArea()  # where the panel was last drawn: clicks there are its
        self.widget_rects: dict = {}  # a few widgets' rectangles (the frame log's, for tests)
        size = self.wnd.buffer_size
        # --supersample K: the frames are rendered K times the window's size each way and
        # box-filtered into it (Accumulator.add): edges, creases and glints anti-aliased.
        self.supersample = int(getattr(self.args, "supersample", 1))
        self.show_progress("scene renderer", None)
        # Without cached cube maps the window opens on previews and builds the exact ones over the
        # next frames (app/finishing.py), the nearest first: the first frame in seconds. A script
        # or a camera path gets the finished cube maps first (its frames are measured or compared).
        progressive = not self.args.script and self.args.path is None
        self.renderer = scene_renderer_from_args(self.ctx, self.scene, session.environment,
                                                 scaled_size(size, self.supersample), session.cache,
                                                 self.args, progressive_cubes=progressive)  # fmt: skip
        self._make_accumulators(size)
        self.pending_screenshots: list[str] = []
        position, target, up, fov = scene_view(self.scene, self.args.view)
        self.walk = WalkCamera.from_camera(Camera(position, target, up, fov))
        self.default_walk_speed = walk_speed_for(self.scene.bounds)
        self.walk.speed = self.default_walk_speed
        # --path: the recorded path plays from t = 0 (looping); P pauses, walking or looking takes over.
        self.camera_path = session.camera_path
        self.finishing = SceneFinishing(session.background_bake)  # app/finishing.py
        self.path_time = 0.0 if self.camera_path is not None else None
        self.path_paused_at = 0.0
        self.method = session.method
        # kept apart from the method so switching to fis-N and back keeps the choice
        self.lobe_normalize = self.args.lobe_normalize
        # the fitted reads (+fit) where N has a table: off when --method names another pattern for one
        method = self.method
        named_other = method.kind == "lobe" and method.normalize and method.pattern != "fitted"
        self.lobe_fit = self.args.lobe_fit and not (named_other and method.samples in fitted_sample_counts())
        self.exposure = 0.0
        self.tonemap = "aces"
        self.progressive = True
        self.held_keys = HeldKeys()
        self.render_scale = RenderScale(target_frame_seconds(self.args.target_fps))
        self.realtime_scale = 1.0  # the scale the shown real-time frame was rendered at
        self.last_change = time.perf_counter()  # when the view last changed (the rest delay)
        self._moving_pass = None  # (scale, seconds) of the last frame rendered while the view changed
        self.show_material_tab = False
        self.cube_refresh_deferred = 0  # moving frames since a stale cube map was due (_cube_refresh_fits)
        self.full_frame_due = False  # the next changed frame at full resolution (the build's redraws)
        self.panel_drag = False  # a left or right drag that began on the panel stays the panel's
        self._pointer = (0.0, 0.0)  # the last pointer position (scroll events carry none)
        self.selected: int | None = next(
            (i for i, o in enumerate(self.renderer.analysis.objects) if o.needs_cube_map), None
        )
        self.editor = MaterialEditor(self.renderer, session.original_materials, self.args.limits)
        self.message = ""
        self.refinement = Refinement()
        self.frame_ms = 0.0  # smoothed interval between frames (what the fps shows)
        self.pass_ms = 0.0
        self.cube_ms = 0.0
        self.frame_state = "start"
        self.stats_file = open(self.args.stats, "w", encoding="utf-8") if self.args.stats else None  # noqa: SIM115
        self._last_frame_start = None
        self.camera_index = None
        self.plot_cache = (None, None)
        self.vsync = not self.args.no_vsync
        self.frame = 0
        self.scene_passes = 0  # frames of the scene drawn (real-time and refinement passes)
        self.script = list(session.script)
        self.dirty = True
        self.closed = False
        self.quit_requested = False
        # The panel's fit (app/fit_job.py): the job, the object it will replace the material of
        # (None once applied), and the panel's inputs.
        self.fit_job: FitJob | None = None
        self.fit_target: int | None = None
        self.fit_data = ""
        self.fit_model = "thesis"
        self.fit_locks: set[str] = set()
        if session.loaded_materials is not None:
            self.message = f"loaded {', '.join(session.loaded_materials) or 'no changes'}"

    # -- state changes (keys, mouse, panel and scripts all come through here) -------------------
    def set_method(self, method: Method) -> None:
        if method.kind == "reference":
            raise ValueError("the real-time method cannot be 'reference': refinement is automatic when still")
        self.method = method
        self.dirty = True

    def select(self, index: int | None) -> None:
        if index is not None and not 0 <= index < len(self.scene.objects):
            raise IndexError(f"object {index} does not exist: the scene has {len(self.scene.objects)} objects")
        self.selected = index

    def start_fit(self, data: str, model: str, lock=(), extra=()) -> FitJob:
        """Fit a measurement to ``model`` for the selected object's material in the background,
        the parameters named in ``lock`` held at the material's current values (ValueError with
        the reason when it cannot start)."""
        if self.selected is None:
            raise ValueError("select an object first: the fit replaces its material")
        if self.fit_job is not None and self.fit_job.running:
            raise ValueError("a fit is running: cancel it first")
        if not data:
            raise ValueError("give the measurement: a .csv, a MERL .binary, virtual:MATERIAL or virtual-merl:MATERIAL")
        lockable = lockable_parameters(self.editor.desc(self.selected), model)
        unknown = sorted(set(lock) - set(lockable))
        if unknown:
            raise ValueError(f"cannot lock {', '.join(unknown)} for a {model} fit of this material")
        name = self.scene.materials[self.scene.objects[self.selected].material].name
        job = FitJob(data, model, {k: lockable[k] for k in lock}, ["--name", name, *extra])
        self.fit_job, self.fit_target = job.start(), self.selected
        self.message = f"fitting {data} ({model}) for {self.scene.objects[self.selected].name} ..."
        return job

    def poll_fit(self) -> None:
        """Apply a finished fit once (an undoable edit), or report why it did not finish."""
        job = self.fit_job
        if job is None or job.running or self.fit_target is None:
            return
        if job.state == "done":
            error = self.editor.apply(self.fit_target, job.result)
            self.message = error or f"{self.scene.objects[self.fit_target].name}: {job.status}"
            self.dirty = True
        else:
            self.message = job.status
        self.fit_target = None

    # -- events ----------------------------------------------------------------------------------
    def on_key_event(self, key, action, modifiers):
        self.imgui.key_event(key, action, modifiers)
        keys = self.wnd.keys
        if action == keys.ACTION_RELEASE:
            # Always: a key pressed for the scene and released over a text field must stop.
            self.held_keys.release(key, time.perf_counter())
            return
        if imgui.get_io().want_capture_keyboard:
            return
        if action == keys.ACTION_PRESS:
            self.held_keys.press(key, time.perf_counter())
            if key == keys.F12:
                self.save_screenshot()
            elif key == keys.O:
                self.walk.orbit = not self.walk.orbit
                self.dirty = True
            elif key == keys.P:
                self.toggle_path()
            elif key == keys.ESCAPE:
                self.wnd.close()
            elif key == keys.Z and modifiers.ctrl:
                if self.editor.undo_last():
                    self.dirty = True

    def on_mouse_position_event(self, x, y, dx, dy):
        self.imgui.mouse_position_event(x, y, dx, dy)
        self._pointer = (x, y)

    def on_mouse_drag_event(self, x, y, dx, dy):
        self.imgui.mouse_drag_event(x, y, dx, dy)
        if self.panel_drag:  # a drag that began on the panel (a slider) stays the panel's
            return
        buttons = self.wnd.mouse_states
        if buttons.right or (self.walk.orbit and buttons.left):
            self.stop_path()
            self.walk.look(dx, dy)
            self.dirty = True

    def on_mouse_scroll_event(self, x_offset, y_offset):
        self.imgui.mouse_scroll_event(x_offset, y_offset)
        x, y = self._pointer
        if not self.panel_area.captures(x, y):
            base = self.default_walk_speed  # the wheel spans 1/30 to 30 times the scene's own speed
            self.walk.speed = float(np.clip(self.walk.speed * (1.2**y_offset), base / 30.0, base * 30.0))

    def on_mouse_press_event(self, x, y, button):
        self.imgui.mouse_press_event(x, y, button)
        self._pointer = (x, y)
        self.panel_drag = self.panel_area.captures(x, y)
        if button == 1 and not self.panel_drag:
            if self.realtime_scale < 1.0:
                # The G-buffer is the moving frame's, smaller than the window: pick exactly.
                self._draw_realtime(self.walk.camera(), 1.0)
            # the renderer's pixel under the pointer: window points to buffer pixels, times the
            # supersampling, at the centre of that pixel's block
            scale = self.wnd.pixel_ratio * self.supersample
            picked = self.renderer.pick(int(x * scale) + self.supersample // 2, int(y * scale) + self.supersample // 2)
            if picked is not None and not 0 <= picked < len(self.scene.objects):
                picked = None  # a stale or foreign id buffer value: select nothing rather than crash
            if picked is not None:
                self.select(picked)
                self.show_material_tab = True  # the panel brings its editor forward
            # One line per click: what was picked (users see what a click did; the click test
            # under Xvfb reads it).
            name = self.scene.objects[picked].name if picked is not None else None
            print(f"picked {name!r} at ({x}, {y})", flush=True)

    def on_mouse_release_event(self, x, y, button):
        self.imgui.mouse_release_event(x, y, button)
        self.panel_drag = False

    def on_unicode_char_entered(self, char):
        self.imgui.unicode_char_entered(char)

    def on_resize(self, width, height):
        self.imgui.resize(width, height)
        size = self.wnd.buffer_size
        self.renderer.resize(scaled_size(size, self.realtime_scale * self.supersample))
        self._release_accumulators()
        self._make_accumulators(size)
        self.dirty = True

    def _make_accumulators(self, size) -> None:
        programs = self.renderer.programs
        self.accumulator = Accumulator(self.ctx, programs, size)  # the refinement's running mean
        self.halves = [Accumulator(self.ctx, programs, size) for _ in range(2)]  # its two-half estimate
        self.realtime = Accumulator(self.ctx, programs, size)  # the last real-time frame
        self.shown = Accumulator(self.ctx, programs, size)  # their blend (viewer/refinement.py)
        self.blend = RefinementBlend(self.ctx, programs, size)

    def _release_accumulators(self) -> None:
        for acc in (self.accumulator, *self.halves, self.realtime, self.shown, self.blend):
            acc.release()

    # -- screenshots -----------------------------------------------------------------------------
    def displayed(self) -> Accumulator:
        """The real-time frame, or once refinement has an estimate, its blend with the mean."""
        refined = self.progressive and self.refinement.estimate is not None
        return self.shown if refined else self.realtime

    def save_screenshot(self, name: str | None = None) -> None:
        """Queued: written after this frame's panel is drawn, so the window capture is complete."""
        self.pending_screenshots.append(name or time.strftime("lobeview-%Y%m%d-%H%M%S"))

    def _write_screenshot(self, stem: str) -> Path:
        from PIL import Image

        directory = Path(self.args.screenshot_dir) if self.args.screenshot_dir else default_screenshot_dir()
        directory.mkdir(parents=True, exist_ok=True)
        radiance = self.displayed().radiance()
        write_hdr_image(directory / f"{stem}.exr", radiance)
        Image.fromarray(to_uint8(tonemap(radiance, self.tonemap, self.exposure))).save(directory / f"{stem}.png")
        width, height = self.wnd.buffer_size
        screen = np.frombuffer(self.ctx.screen.read(components=3), np.uint8).reshape(height, width, 3)[::-1]
        Image.fromarray(screen).save(directory / f"{stem}-window.png")
        # A blend has no single command: the one of what it mostly shows, said so below.
        estimate = self.refinement.estimate if self.displayed() is self.shown else None
        refined = estimate is not None and estimate.refined_share >= 0.5
        method = Method.parse("reference") if refined else self.method
        materials = None
        if self.editor.edits():  # the edits travel with the screenshot, so the command reproduces it
            materials = directory / f"{stem}.materials.json"
            self.editor.save(materials)
        command = shot_command(
            self.walk.camera(),
            self.wnd.buffer_size,
            method,
            out=directory / f"{stem}-shot.png",
            scene=self.args.scene,
            spp=self.refinement.samples if refined else None,
            args=self.args,
            materials=materials,
            tonemap=self.tonemap,
            exposure=self.exposure,
        )
        note = "" if not self.renderer.drawer.object_methods else " (per-object methods are not reproduced)"
        if estimate is not None:
            note += f" (shown: {100 * estimate.refined_share:.0f} % refined, blended per pixel with {self.method})"
        print(f"screenshot {directory / stem}.exr/.png{note}: {command}", flush=True)
        return directory / f"{stem}.png"

    # -- frame -----------------------------------------------------------------------------------
    def toggle_path(self) -> None:
        """P: pause the recorded path, or resume it from where the camera left it."""
        if self.camera_path is None:
            self.message = "no camera path (start the viewer with --path FILE or --path builtin)"
        elif self.path_time is None:
            self.path_time = self.path_paused_at
            self.message = f"flying the camera path from t = {self.path_time:.1f} s"
        else:
            self.stop_path("paused")

    def set_path_time(self, t: float) -> None:
        """Jump the recorded path to ``t`` seconds (scripts); the camera follows this frame."""
        if self.camera_path is None:
            raise ValueError("no camera path (--path)")
        self.path_time = float(np.clip(t, 0.0, self.camera_path.duration))

    def _fly_path(self, frame_time: float) -> None:
        if self.path_time is None:
            return
        speed = self.walk.speed
        self.walk = WalkCamera.from_camera(Camera.from_scene_camera(self.camera_path.camera_at(self.path_time)))
        self.walk.speed = speed
        self.dirty = True
        # Wall-clock time between frames (only a stall is cut: frame_pacing.py), looping at the end.
        self.path_time = (self.path_time + min(frame_time, MOTION_STALL_CAP_S)) % self.camera_path.duration

    def stop_path(self, verb: str = "stopped") -> None:
        """Walking or looking takes the camera over from the path (P pauses it the same way)."""
        if self.path_time is not None:
            self.path_paused_at, self.path_time = self.path_time, None
            self.message = f"camera path {verb} at t = {self.path_paused_at:.1f} s (P resumes)"

    def _walk_keys(self, now: float) -> None:
        """Move by how long each motion key was held since the last frame (wall-clock)."""
        keys = self.wnd.keys
        held = self.held_keys.take(now)
        displacement = np.zeros(3)  # in direction units x seconds
        for key, vec in (
            (keys.W, (0, 0, 1)),
            (keys.S, (0, 0, -1)),
            (keys.A, (-1, 0, 0)),
            (keys.D, (1, 0, 0)),
            (keys.E, (0, 1, 0)),
            (keys.Q, (0, -1, 0)),
        ):
            displacement += np.asarray(vec, float) * held.get(key, 0.0)
        if np.any(displacement):
            self.stop_path()
            self.camera_index = None  # no longer at the scene camera the panel names
            fast = 4.0 if self.wnd.modifiers.shift else 1.0
            self.walk.move(displacement * fast, 1.0)
            self.dirty = True

    def on_render(self, time_s, frame_time):
        if self.closed:
            return
        t_frame = time.perf_counter()
        interval = None
        if self._last_frame_start is not None:
            interval = t_frame - self._last_frame_start
            interval_ms = 1000.0 * interval
            self.frame_ms += FRAME_TIME_SMOOTHING * (interval_ms - self.frame_ms) if self.frame_ms else interval_ms
            if self._moving_pass is not None:  # the last frame was the view changing: fit the next one's size
                self.render_scale.observe(*self._moving_pass, interval)
        self._moving_pass = None
        self._last_frame_start = t_frame
        run_due_steps(self, self.script)
        self._walk_keys(t_frame)
        self._fly_path(frame_time)
        self.poll_fit()

        self.finishing.poll_background_bake(self)
        self.finishing.poll_horizon_maps(self)
        camera = self.walk.camera()
        self.finishing.continue_cube_build(self, camera, t_frame)
        refinement = self.refinement
        changed = self.dirty
        if changed:
            for acc in (self.accumulator, *self.halves):
                acc.reset()
            refinement.reset()
            self.dirty = False
            self.last_change = t_frame
        t0 = time.perf_counter()
        if changed:
            self.frame_state = "moving"
            # A screenshot due this frame is taken of the full-resolution frame, as its printed
            # `lobeview shot` command renders it, not of the upsampled one.
            scale = 1.0 if self.pending_screenshots or self.full_frame_due else self.render_scale.scale
            self.full_frame_due = False
            self.pass_ms = self._draw_realtime(camera, scale)
            self._moving_pass = (scale, self.pass_ms / 1000.0)
        elif self.realtime_scale < 1.0:
            # At rest (or a screenshot is due): the full-resolution frame once the view has
            # stayed still for REST_DELAY_S, so that pausing between two key presses costs no
            # full-size frame; until then the last moving frame is shown.
            if self.pending_screenshots or t_frame - self.last_change >= REST_DELAY_S:
                self.frame_state = "rest"
                self.pass_ms = self._draw_realtime(camera, 1.0)
            else:
                self.frame_state = "waiting"
        elif (
            refinement.still_frames > 0
            and self.progressive
            and not refinement.finished
            and self.renderer.cube_build_status is None  # refining a preview would be thrown away
        ):
            self.frame_state = "refining"
            # Refinement reads level 0: faces sized for lobe-N are re-rendered at full size, one
            # per frame below, each restarting the accumulation (converges as shot's reference).
            self.renderer.request_full_faces(camera)
            self._refine(camera)
            self.ctx.finish()
            self.pass_ms = (time.perf_counter() - t0) * 1000.0
            refinement.adapt(self.pass_ms)
        else:
            self.frame_state = "idle"  # nothing changed and nothing is left to refine: shown again
        t0 = time.perf_counter()
        refreshed = self.renderer.refresh_one_stale_cube() if self._cube_refresh_fits(changed, t0 - t_frame) else None
        if refreshed is not None:
            self.cube_ms = (time.perf_counter() - t0) * 1000.0
            self.cube_refresh_deferred = 0
            self.message = f"updated the cube map of {refreshed} ({self.renderer.stale_cube_count} to go)"
            self.dirty = True
        if self.realtime_scale == 1.0:
            refinement.still_frames += 1  # frames since the full-resolution real-time frame

        self.ctx.screen.use()
        self.ctx.screen.clear(0.0, 0.0, 0.0)
        self.displayed().show(self.ctx.screen, (0, 0, *self.wnd.buffer_size), self.exposure, self.tonemap)
        draw_panel(self)
        while self.pending_screenshots:
            self._write_screenshot(self.pending_screenshots.pop(0))
        self._log_frame(t_frame, interval)
        self.frame += 1
        if self.quit_requested or (self.args.exit_after and self.frame >= self.args.exit_after):
            self.wnd.close()  # releases GPU objects (on_close): the frame is finished

    def _cube_refresh_fits(self, moving: bool, elapsed_s: float) -> bool:
        """Whether this frame re-renders a stale cube map (after a material edit): always while
        the view rests; while it changes, only where the last refresh's time fits in what is
        left of the frame-rate target, or after CUBE_REFRESH_MAX_DEFERRED frames without one (the
        edit must show up eventually)."""
        if self.renderer.stale_cube_count == 0:
            return False
        target = self.render_scale.target_s
        if not moving or target is None or elapsed_s + self.cube_ms / 1000.0 <= target:
            return True
        self.cube_refresh_deferred += 1
        return self.cube_refresh_deferred > CUBE_REFRESH_MAX_DEFERRED

    def _draw_realtime(self, camera, scale: float) -> float:
        """The real-time frame at ``scale`` times the window's size (times the supersampling),
        upsampled (bilinear) or box-filtered into the shown real-time image; returns its
        milliseconds (with glFinish)."""
        t0 = time.perf_counter()
        size = scaled_size(self.wnd.buffer_size, scale * self.supersample)
        if self.renderer.size != size:
            self.renderer.resize(size)
        self.scene_passes += 1
        # lobe-N+norm+fit's blur stacks: built within the frame's budget, the others read through
        # their MIP chains until a later frame builds them (a CPU renderer takes ~0.5 s a cube)
        self.renderer.shading.stack_budget(STACK_BUILD_BUDGET_S)
        self.renderer.draw_frame(camera, self.method)
        pending = self.renderer.shading.stacks_pending
        if pending:
            self.message = f"building blur stacks ({pending} cube maps read their MIP chains meanwhile)"
            self.dirty = True  # the next frame builds more
        self.realtime.reset()
        self.realtime.add(self.renderer.radiance_target, 1.0)
        self.ctx.finish()
        self.realtime_scale = scale
        return (time.perf_counter() - t0) * 1000.0

    def _log_frame(self, t_frame: float, interval: float | None) -> None:
        """One JSON line per frame into ``--stats FILE`` (the frame log: docs/guide.md)."""
        if self.stats_file is None:
            return
        record = {
            "frame": self.frame,
            "t": round(t_frame - self.started, 4),
            "interval_ms": None if interval is None else round(1000.0 * interval, 2),
            "state": self.frame_state,
            "pass_ms": round(self.pass_ms, 2),
            "render_scale": self.realtime_scale,
            "render_size": list(self.renderer.size),
            "method": str(self.method),
            "spp": self.refinement.samples,
            "camera": [round(float(v), 5) for v in self.walk.position],
            "walk_speed": self.walk.speed,
            "path_time": self.path_time,
            "cube_build": self.renderer.probes.pending_progress if self.renderer.cube_build_status else None,
            "background_bake": self.finishing.bake_status,
            "horizon_maps": self.finishing.horizon_status,
            "widgets": {name: [round(v, 1) for v in rect] for name, rect in self.widget_rects.items()},
        }
        self.stats_file.write(json.dumps(record) + "\n")
        self.stats_file.flush()

    def _refine(self, camera) -> None:
        """One refinement pass: a batch of reference samples at the next sub-pixel position into
        the running mean and one half; the two-half estimate when due (viewer/refinement.py)."""
        refinement = self.refinement
        plan = refinement.next_pass()
        batch = Method("reference", plan.samples)
        if self.renderer.has_rational:
            batch = batch.for_rational()
        self.scene_passes += 1
        # Its passes integrate the pixel over their sub-pixel positions: each reads the textures
        # over REFINEMENT_TEXTURE_FOOTPRINT of the pixel, as a reference of 64 passes does (a whole
        # pixel's footprint on top of the integral blurred them twice: viewer/scene_renderer.py).
        self.renderer.draw_frame(camera, batch, sample_offset=plan.sample_offset, seed=plan.half, jitter=plan.jitter,
                                 texture_footprint=REFINEMENT_TEXTURE_FOOTPRINT)  # fmt: skip
        self.accumulator.add(self.renderer.radiance_target, float(batch.samples))
        self.halves[plan.half].add(self.renderer.radiance_target, float(batch.samples))
        refinement.added(batch.samples, plan.half)
        if refinement.estimate_due:
            halves = [acc.radiance() for acc in self.halves]
            estimate = two_half_estimate(
                halves[0], refinement.weights[0], halves[1], refinement.weights[1],
                self.realtime.radiance(), self.tonemap, self.exposure,
            )  # fmt: skip
            refinement.update(estimate)
            self.blend.set_weight(estimate.weight)
        if refinement.estimate is not None:
            self.blend.blend(self.accumulator, self.realtime, self.shown)

    def show_progress(self, what: str, fraction: float | None) -> None:
        """The loading overlay: what lobeview is doing (and how far) over the last image, drawn
        and shown at once from inside the long step (at most 10 times a second). Events wait
        until the step ends (the handlers need the state the step builds)."""
        now = time.perf_counter()
        window = getattr(self.wnd, "_window", None)  # pyglet's: flip without dispatching events
        if getattr(self, "closed", False) or window is None or now - self._overlay_shown_at < 0.1:
            return
        self._overlay_shown_at = now
        ctx = self.ctx
        ctx.screen.use()  # report() comes between passes: each pass binds its own target first
        ctx.viewport = (0, 0, *self.wnd.buffer_size)
        ctx.screen.clear(0.12, 0.12, 0.14)
        if self.realtime is not None:
            self.displayed().show(ctx.screen, (0, 0, *self.wnd.buffer_size), self.exposure, self.tonemap)
        imgui.new_frame()
        width, height = self.wnd.size
        imgui.set_next_window_pos((width / 2, height / 2), imgui.Cond_.always.value, (0.5, 0.5))
        imgui.set_next_window_size((min(560, width - 20), 0))
        flags = imgui.WindowFlags_.no_decoration.value | imgui.WindowFlags_.no_inputs.value
        imgui.begin("loading", None, flags)
        name = self.session.scene_path.name if getattr(self, "session", None) else self.loading_title
        imgui.text(f"lobeview: {name} ({now - self.started:.0f} s)")
        imgui.text_wrapped(what)
        if fraction is None:
            imgui.progress_bar(-1.0 * imgui.get_time(), (-1, 0), "working ...")  # indeterminate
        else:
            imgui.progress_bar(float(min(max(fraction, 0.0), 1.0)), (-1, 0))
        imgui.end()
        imgui.render()
        self.imgui.render(imgui.get_draw_data())
        window.flip()

    def on_close(self):
        self.closed = True
        self._listening.__exit__(None, None, None)
        if self.stats_file is not None:
            self.stats_file.close()
        if self.fit_job is not None:
            self.fit_job.cancel()
        self.finishing.cancel()
        self._release_accumulators()
        self.renderer.release()
