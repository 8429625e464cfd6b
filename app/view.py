"""``lobeview view [SCENE]``: the interactive walkthrough window.

moderngl-window (pyglet backend) + an ImGui panel (imgui-bundle). While the camera moves, every
frame is rendered with the chosen real-time method (lobe-N by default); as soon as the camera,
the materials and the method stay still, each frame adds a batch of unbiased quasi-random MIS
samples to a float accumulation buffer and the display shows the running mean (thesis 4.4.2),
converging to what ``lobeview shot --method reference`` renders. The batch size adapts to keep
frames near a target time.

Controls: W/A/S/D move, Q/E down/up, drag with the right mouse button to look around (left
button in orbit mode), wheel changes speed (Shift: x4), O toggles orbit mode, left click in the
view selects an object, F12 saves an EXR + PNG screenshot and prints the ``lobeview shot`` flags
that reproduce the camera, Esc quits.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lobeview.materials.spec import RANGES, MaterialError, validate
from lobeview.viewer.camera import Camera

REALTIME_METHODS = ("lobe", "fis", "mc")
PREFILTERED_CHOICES = (
    "prefiltered",
    "prefiltered-splitsum",
    "prefiltered-lobe",
    "prefiltered-lobe2d",
    "prefiltered-phong",
    "prefiltered-multi",
    "prefiltered-banks",
)
METHOD_CHOICES = REALTIME_METHODS + PREFILTERED_CHOICES


def method_choice(method) -> str:
    """The panel's combo entry of a method (sample counts have their own slider)."""
    return str(method) if method.kind == "prefiltered" else method.kind


def method_from_choice(choice: str, samples: int, normalize: bool = False):
    from lobeview.viewer.render_base import Method

    if choice.startswith("prefiltered"):
        return Method.parse(choice)
    base = Method.parse(f"{choice}-{min(samples, 32) if choice == 'lobe' else samples}")
    return dataclasses.replace(base, normalize=normalize)


TARGET_FRAME_MS = 50.0
MAX_BATCH = 64
SHOW_REFINED_AFTER = 32  # spp per lobe before the refined image replaces the real-time one


def add_arguments(p) -> None:
    p.add_argument("scene", nargs="?", help="glTF scene with lightmaps (default: the built-in demo)")
    p.add_argument("--env", help="environment outside the scene (default builtin:overcast)")
    p.add_argument("--size", default="1280x800", help="window size WxH (default 1280x800)")
    p.add_argument("--method", default="lobe-11", help="real-time method while moving (default lobe-11)")
    p.add_argument(
        "--lobe-normalize",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="lobe-N: energy normalisation by each lobe's albedo (default on; --no-lobe-normalize: Eq. 4.25)",
    )
    p.add_argument("--view", help="start at this scene camera (name or index)")
    p.add_argument("--no-vsync", action="store_true", help="disable vsync")
    p.add_argument("--face-size", type=int, default=256, help="cube-map face resolution (default 256)")
    p.add_argument(
        "--reflection-proxy",
        choices=("scene", "none", "floor", "room"),
        default="scene",
        help="cube-map lookup correction for every glossy object (see lobeview shot --help)",
    )
    p.add_argument(
        "--mirrors",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="planar mirror passes for the reflectors the scene analysis lists (thesis 4.5; default on;"
        " --no-mirrors: cube maps for every object)",
    )
    p.add_argument(
        "--mirror-scale",
        type=float,
        default=1.0,
        help="mirror-buffer resolution relative to the frame, 0.05..2 (default 1)",
    )
    p.add_argument("--cache", help="cache folder (default ~/.cache/lobeview or $LOBEVIEW_CACHE)")
    p.add_argument("--screenshot-dir", default=".", help="where F12 writes screenshots (default .)")
    p.add_argument("--materials", help="load edited materials from this JSON file at start")
    p.add_argument("--script", help="JSON list of scripted actions (testing/demos): see app/view.py")
    p.add_argument("--exit-after", type=int, default=0, help="quit after this many frames (0: never)")


# -- camera controller -------------------------------------------------------------------------


@dataclass
class WalkCamera:
    position: np.ndarray
    yaw: float  # radians, 0 looks down -Z
    pitch: float
    fov_y: float = 60.0
    speed: float = 1.5  # m/s
    orbit: bool = False
    orbit_centre: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_camera(cls, camera: Camera) -> WalkCamera:
        pos = np.asarray(camera.position, dtype=np.float64)
        d = np.asarray(camera.target, dtype=np.float64) - pos
        d /= np.linalg.norm(d)
        return cls(
            pos,
            math.atan2(d[0], -d[2]),
            math.asin(np.clip(d[1], -1, 1)),
            camera.fov_y,
            orbit_centre=np.asarray(camera.target, float),
        )

    def forward(self) -> np.ndarray:
        cp = math.cos(self.pitch)
        return np.array([math.sin(self.yaw) * cp, math.sin(self.pitch), -math.cos(self.yaw) * cp])

    def camera(self) -> Camera:
        return Camera(tuple(self.position), tuple(self.position + self.forward()), (0.0, 1.0, 0.0), self.fov_y)

    def look(self, dx: float, dy: float) -> None:
        self.yaw += dx * 0.004
        self.pitch = float(np.clip(self.pitch - dy * 0.004, -1.5, 1.5))
        if self.orbit:
            distance = np.linalg.norm(self.position - self.orbit_centre)
            self.position = self.orbit_centre - self.forward() * distance

    def move(self, direction: np.ndarray, dt: float) -> None:
        f = self.forward()
        right = np.cross(f, [0.0, 1.0, 0.0])
        right /= max(np.linalg.norm(right), 1e-9)
        step = (direction[0] * right + direction[1] * np.array([0.0, 1.0, 0.0]) + direction[2] * f) * self.speed * dt
        self.position = self.position + step


# -- material editing ---------------------------------------------------------------------------


class MaterialEditor:
    """Edits of material descriptions with validation and an undo stack (last 50 edits)."""

    def __init__(self, renderer):
        self.renderer = renderer
        self.undo: list[tuple[int, dict]] = []

    def desc(self, index: int) -> dict:
        scene = self.renderer.scene
        return json.loads(json.dumps(scene.materials[scene.objects[index].material].desc))

    def apply(self, index: int, desc: dict) -> str | None:
        """Validate and apply; returns an error message instead of raising."""
        try:
            desc = validate(desc)
        except MaterialError as exc:
            return str(exc)
        self.undo.append((index, self.desc(index)))
        del self.undo[:-50]
        self.renderer.update_material(index, desc)
        return None

    def undo_last(self) -> bool:
        if not self.undo:
            return False
        index, desc = self.undo.pop()
        self.renderer.update_material(index, desc)
        return True

    def save(self, path: Path) -> None:
        scene = self.renderer.scene
        data = {m.name: m.desc for m in scene.materials}
        path.write_text(json.dumps(data, indent=2, sort_keys=True))

    def load(self, path: Path) -> list[str]:
        data = json.loads(Path(path).read_text())
        scene = self.renderer.scene
        changed = []
        for i, obj in enumerate(scene.objects):
            name = scene.materials[obj.material].name
            if name in data and data[name] != scene.materials[obj.material].desc:
                self.renderer.update_material(i, data[name])
                changed.append(name)
        return changed


def _slider(imgui, label: str, value: float, key: str) -> tuple[bool, float]:
    low, high = RANGES[key]
    flags = imgui.SliderFlags_.logarithmic.value if key in ("mx", "my", "alpha_u", "alpha_v") else 0
    return imgui.slider_float(label, float(value), float(low), float(high), "%.4g", flags)


def _scalar_or_rgb_slider(imgui, label: str, value, key: str):
    if isinstance(value, list):
        changed, new = (
            imgui.color_edit3(label, [float(v) for v in value])
            if key in ("kd", "base_color")
            else imgui.slider_float3(label, [float(v) for v in value], *RANGES[key])
        )
        return changed, [float(v) for v in new]
    return _slider(imgui, label, value, key)


def material_widgets(imgui, desc: dict) -> tuple[bool, dict]:
    """ImGui widgets for every parameter of the three models; returns (changed, new desc)."""
    changed_any = False
    d = json.loads(json.dumps(desc))
    if d["model"] == "thesis":
        c, d["kd"] = _scalar_or_rgb_slider(imgui, "kd", d["kd"], "kd")
        changed_any |= c
        for group, key in (("lobes", "ks"), ("transmission_lobes", "kt")):
            remove = None
            for i, lobe in enumerate(d[group]):
                imgui.push_id(f"{group}{i}")
                imgui.separator_text(f"{group[:-1].replace('_', ' ')} {i}")
                for name in (key, "mx", "my", "r0", "alpha"):
                    c, lobe[name] = _scalar_or_rgb_slider(imgui, name, lobe[name], name)
                    changed_any |= c
                if imgui.small_button("remove"):
                    remove = i
                imgui.pop_id()
            if remove is not None:
                d[group].pop(remove)
                changed_any = True
            if len(d[group]) < 8 and imgui.small_button(f"add {group[:-1].replace('_', ' ')}"):
                d[group].append({key: 0.5, "mx": 0.1, "my": 0.1, "r0": 0.5, "alpha": 0.0})
                changed_any = True
    elif d["model"] == "microfacet":
        for name in ("alpha_u", "alpha_v"):
            c, d[name] = _slider(imgui, name, d[name], name)
            changed_any |= c
        fr = d["fresnel"]
        if fr["type"] == "schlick":
            c, fr["r0"] = _scalar_or_rgb_slider(imgui, "r0", fr["r0"], "r0")
            changed_any |= c
        elif fr["type"] == "conductor":
            c, fr["eta"] = _scalar_or_rgb_slider(imgui, "eta", fr["eta"], "eta")
            changed_any |= c
            c, fr["k"] = _scalar_or_rgb_slider(imgui, "k", fr["k"], "k")
            changed_any |= c
    else:
        c, d["base_color"] = _scalar_or_rgb_slider(imgui, "base colour", d["base_color"], "base_color")
        changed_any |= c
        for name in ("metallic", "roughness"):
            c, d[name] = _slider(imgui, name, d[name], name)
            changed_any |= c
    return changed_any, d


def lobe_plot_values(desc: dict, theta_deg: float = 45.0, count: int = 181) -> tuple[np.ndarray, np.ndarray]:
    """(f cos)^(1/3) in the plane of incidence for a 45 deg view: the panel's live lobe plot."""
    from lobeview.materials.spec import build_bsdf
    from lobeview.materials.vec import direction_from_angles_deg

    bsdf = build_bsdf(desc)
    angle = np.linspace(-np.pi, np.pi, count)
    wi = np.stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)], -1)
    wo = np.broadcast_to(direction_from_angles_deg(theta_deg, 0.0), wi.shape)
    value = bsdf.eval(wi, wo).mean(-1) * np.abs(wi[:, 2])
    return np.degrees(angle).astype(np.float32), np.cbrt(value).astype(np.float32)


# -- the window -----------------------------------------------------------------------------


def run(args) -> int:
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print(
            "lobeview view needs a display (no DISPLAY or WAYLAND_DISPLAY is set). Render "
            "headless with `lobeview shot` instead, or run under a virtual X server: "
            "xvfb-run -s '-screen 0 1920x1080x24' lobeview view",
            file=sys.stderr,
        )
        return 2
    from lobeview.app.shot import parse_size
    from lobeview.viewer.render_base import Method

    width, height = parse_size(args.size)
    method = Method.parse(args.method)
    if method.kind == "lobe":
        method = dataclasses.replace(method, normalize=args.lobe_normalize)
    if not 0.05 <= args.mirror_scale <= 2.0:
        raise ValueError(f"--mirror-scale must be in [0.05, 2], got {args.mirror_scale}")
    if method.kind == "reference":
        raise ValueError(
            "--method must be a real-time method (lobe-N, fis-N, mc-N, prefiltered[-MODE]); refinement is automatic"
        )

    import moderngl_window as mglw

    from lobeview.app.shot import apply_reflection_proxy, load_scene_and_environment

    scene_path, scene, environment, cache = load_scene_and_environment(args.scene, args.env, args.cache)
    apply_reflection_proxy(scene, args.reflection_proxy)
    script = json.loads(Path(args.script).read_text()) if args.script else []

    config = _window_class(scene, scene_path, environment, args, method, cache, script)
    config.window_size = (width, height)
    config.vsync = not args.no_vsync
    mglw.run_window_config(config, args=["--window", "pyglet"])
    return 0


def _window_class(scene, scene_path, environment, args, initial_method, cache, script):
    import moderngl_window as mglw
    from imgui_bundle import imgui, implot
    from moderngl_window.integrations.imgui_bundle import ModernglWindowRenderer

    from lobeview.app.shot import _scene_view, scene_renderer_from_args
    from lobeview.scenes.hdrio import write_hdr_image
    from lobeview.viewer.display import Accumulator
    from lobeview.viewer.render_base import Method
    from lobeview.viewer.tonemap import TONEMAPS, to_uint8, tonemap

    class LobeviewWindow(mglw.WindowConfig):
        gl_version = (4, 5)
        title = f"lobeview - {scene_path.name}"
        resizable = True
        aspect_ratio = None

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            imgui.create_context()
            implot.create_context()
            self.imgui = ModernglWindowRenderer(self.wnd)
            size = self.wnd.buffer_size
            self.renderer = scene_renderer_from_args(self.ctx, scene, environment, size, cache, args)
            self.accumulator = Accumulator(self.ctx, self.renderer.programs, size)  # refinement
            self.realtime = Accumulator(self.ctx, self.renderer.programs, size)  # last moving frame
            self.pending_screenshots: list[str] = []
            position, target, up, fov = _scene_view(scene, args.view)
            self.walk = WalkCamera.from_camera(Camera(position, target, up, fov))
            self.method = initial_method
            # kept apart from the method so switching to fis-N and back keeps the choice
            self.lobe_normalize = args.lobe_normalize
            self.exposure = 0.0
            self.tonemap = "aces"
            self.progressive = True
            self.keys: set = set()
            self.selected: int | None = next(
                (i for i, o in enumerate(self.renderer.analysis.objects) if o.needs_cube_map), None
            )
            self.editor = MaterialEditor(self.renderer)
            self.message = ""
            self.still_frames = 0
            self.batch = 4
            self.samples = 0
            self.frame_ms = 0.0
            self.pass_ms = 0.0
            self.cube_ms = 0.0
            self.camera_index = None
            self._plot_key, self._plot = None, None
            self.vsync = not args.no_vsync
            self.frame = 0
            self.script = list(script)
            self.dirty = True
            self.closed = False
            self.quit_requested = False
            if args.materials:
                self.message = f"loaded {', '.join(self.editor.load(Path(args.materials))) or 'no changes'}"

        # -- events ----------------------------------------------------------------------
        def on_key_event(self, key, action, modifiers):
            self.imgui.key_event(key, action, modifiers)
            if imgui.get_io().want_capture_keyboard:
                return
            keys = self.wnd.keys
            if action == keys.ACTION_PRESS:
                self.keys.add(key)
                if key == keys.F12:
                    self.save_screenshot()
                elif key == keys.O:
                    self.walk.orbit = not self.walk.orbit
                    self.dirty = True
                elif key == keys.ESCAPE:
                    self.wnd.close()
                elif key == keys.Z and modifiers.ctrl:
                    if self.editor.undo_last():
                        self.dirty = True
            elif action == keys.ACTION_RELEASE:
                self.keys.discard(key)

        def on_mouse_position_event(self, x, y, dx, dy):
            self.imgui.mouse_position_event(x, y, dx, dy)

        def on_mouse_drag_event(self, x, y, dx, dy):
            self.imgui.mouse_drag_event(x, y, dx, dy)
            if imgui.get_io().want_capture_mouse:
                return
            buttons = self.wnd.mouse_states
            if buttons.right or (self.walk.orbit and buttons.left):
                self.walk.look(dx, dy)
                self.dirty = True

        def on_mouse_scroll_event(self, x_offset, y_offset):
            self.imgui.mouse_scroll_event(x_offset, y_offset)
            if not imgui.get_io().want_capture_mouse:
                self.walk.speed = float(np.clip(self.walk.speed * (1.2**y_offset), 0.05, 50.0))

        def on_mouse_press_event(self, x, y, button):
            self.imgui.mouse_press_event(x, y, button)
            if button == 1 and not imgui.get_io().want_capture_mouse:
                scale = self.wnd.pixel_ratio
                picked = self.renderer.pick(int(x * scale), int(y * scale))
                if picked is not None:
                    self.selected = picked

        def on_mouse_release_event(self, x, y, button):
            self.imgui.mouse_release_event(x, y, button)

        def on_unicode_char_entered(self, char):
            self.imgui.unicode_char_entered(char)

        def on_resize(self, width, height):
            self.imgui.resize(width, height)
            size = self.wnd.buffer_size
            self.renderer.resize(size)
            for acc in (self.accumulator, self.realtime):
                acc.release()
            self.accumulator = Accumulator(self.ctx, self.renderer.programs, size)
            self.realtime = Accumulator(self.ctx, self.renderer.programs, size)
            self.dirty = True

        # -- actions ---------------------------------------------------------------------
        def displayed(self) -> Accumulator:
            refined = self.progressive and self.samples >= SHOW_REFINED_AFTER
            return self.accumulator if refined else self.realtime

        def save_screenshot(self, name: str | None = None) -> None:
            """Queued: written after this frame's panel is drawn, so the window capture is complete."""
            self.pending_screenshots.append(name or time.strftime("lobeview-%Y%m%d-%H%M%S"))

        def _write_screenshot(self, stem: str) -> Path:
            directory = Path(args.screenshot_dir)
            directory.mkdir(parents=True, exist_ok=True)
            radiance = self.displayed().radiance()
            write_hdr_image(directory / f"{stem}.exr", radiance)
            from PIL import Image

            Image.fromarray(to_uint8(tonemap(radiance, self.tonemap, self.exposure))).save(directory / f"{stem}.png")
            screen = np.frombuffer(self.ctx.screen.read(components=3), np.uint8).reshape(
                self.wnd.buffer_size[1], self.wnd.buffer_size[0], 3
            )[::-1]
            Image.fromarray(screen).save(directory / f"{stem}-window.png")
            w, h = self.renderer.size
            refined = self.displayed() is self.accumulator
            method = f"reference --spp {self.samples}" if refined else str(self.method)
            scene_arg = "" if args.scene is None else args.scene + " "
            print(
                f"screenshot {directory / stem}.exr/.png: lobeview shot {scene_arg}"
                f"{self.walk.camera().describe()} --size {w}x{h} --method {method}",
                flush=True,
            )
            return directory / f"{stem}.png"

        def run_script(self):
            """Scripted actions, due at their frame: {"frame": N, "action": A, ...} with A one of
            press/release (key: W, S, ...), move (direction, seconds), look (dx, dy), select
            (object), set (path into the selected material, value), method (value), screenshot
            (name), save_materials (path), quit."""
            while self.script and self.script[0].get("frame", 0) <= self.frame:
                step = self.script.pop(0)
                action = step["action"]
                if action in ("press", "release"):
                    # A real key event through the window's handler (held keys move the camera).
                    keys = self.wnd.keys
                    state = keys.ACTION_PRESS if action == "press" else keys.ACTION_RELEASE
                    self.on_key_event(getattr(keys, step["key"]), state, self.wnd.modifiers)
                elif action == "move":
                    self.walk.move(np.asarray(step["direction"], float), float(step.get("seconds", 0.2)))
                elif action == "look":
                    self.walk.look(float(step["dx"]), float(step["dy"]))
                elif action == "select":
                    self.selected = next(i for i, o in enumerate(scene.objects) if o.name == step["object"])
                elif action == "set":
                    desc = self.editor.desc(self.selected)
                    target = desc
                    for part in step["path"][:-1]:
                        target = target[part]
                    target[step["path"][-1]] = step["value"]
                    self.message = self.editor.apply(self.selected, desc) or ""
                elif action == "method":
                    self.method = Method.parse(step["value"])
                    if self.method.kind == "lobe":
                        self.method = dataclasses.replace(self.method, normalize=self.lobe_normalize)
                elif action == "screenshot":
                    self.save_screenshot(step["name"])
                elif action == "save_materials":
                    self.editor.save(Path(step["path"]))
                elif action == "quit":
                    self.quit_requested = True
                self.dirty = action not in ("screenshot", "save_materials") or self.dirty

        # -- frame -----------------------------------------------------------------------
        def on_render(self, time_s, frame_time):
            if self.closed:
                return
            t_frame = time.perf_counter()
            self.run_script()
            keys = self.wnd.keys
            direction = np.zeros(3)
            for key, vec in (
                (keys.W, (0, 0, 1)),
                (keys.S, (0, 0, -1)),
                (keys.A, (-1, 0, 0)),
                (keys.D, (1, 0, 0)),
                (keys.E, (0, 1, 0)),
                (keys.Q, (0, -1, 0)),
            ):
                if key in self.keys:
                    direction += vec
            if np.any(direction):
                fast = 4.0 if self.wnd.modifiers.shift else 1.0
                self.walk.move(direction * fast, min(frame_time, 0.1))
                self.dirty = True

            camera = self.walk.camera()
            t0 = time.perf_counter()
            if self.dirty:
                self.accumulator.reset()
                self.samples = 0
                self.still_frames = 0
                self.dirty = False
            if self.still_frames == 0 or not self.progressive:
                self.renderer.draw_frame(camera, self.method)
                self.realtime.reset()
                self.realtime.add(self.renderer.targets[0], 1.0)
            else:
                batch = Method("reference", int(self.batch))
                self.renderer.draw_frame(camera, batch, sample_offset=self.samples, seed=0)
                self.accumulator.add(self.renderer.targets[0], float(batch.samples))
                self.samples += batch.samples
            self.ctx.finish()
            self.pass_ms = (time.perf_counter() - t0) * 1000.0
            t0 = time.perf_counter()
            refreshed = self.renderer.refresh_one_stale_cube()
            if refreshed is not None:
                self.cube_ms = (time.perf_counter() - t0) * 1000.0
                self.message = f"updated the cube map of {refreshed} ({len(self.renderer.stale_cubes)} to go)"
                self.dirty = True
            if self.still_frames > 0 and self.progressive:
                # Keep frames near the target time: scale the batch by the measured cost.
                ratio = TARGET_FRAME_MS / max(self.pass_ms, 1e-3)
                self.batch = int(np.clip(self.batch * np.clip(ratio, 0.5, 2.0), 1, MAX_BATCH))
            self.still_frames += 1

            self.ctx.screen.use()
            self.ctx.screen.clear(0.0, 0.0, 0.0)
            self.displayed().show(self.ctx.screen, (0, 0, *self.wnd.buffer_size), self.exposure, self.tonemap)
            self.panel()
            while self.pending_screenshots:
                self._write_screenshot(self.pending_screenshots.pop(0))
            self.frame += 1
            self.frame_ms = (time.perf_counter() - t_frame) * 1000.0
            if self.quit_requested or (args.exit_after and self.frame >= args.exit_after):
                self.wnd.close()  # releases GPU objects (on_close): the frame is finished

        def panel(self):
            imgui.new_frame()
            imgui.set_next_window_pos((10, 10), imgui.Cond_.first_use_ever.value)
            imgui.set_next_window_size((360, 620), imgui.Cond_.first_use_ever.value)
            imgui.begin("lobeview")
            io = imgui.get_io()
            imgui.text(f"{self.ctx.info['GL_RENDERER']}")
            imgui.text(f"{io.framerate:.1f} fps, frame {self.frame_ms:.1f} ms")
            imgui.text(f"shading + accumulation {self.pass_ms:.1f} ms, last cube map {self.cube_ms:.1f} ms")
            imgui.text(
                f"refined: {self.samples} spp per lobe (batch {self.batch})"
                if self.samples
                else f"moving: {self.method}"
            )
            if imgui.collapsing_header("Rendering", imgui.TreeNodeFlags_.default_open.value):
                kinds = list(METHOD_CHOICES)
                c, k = imgui.combo("method", kinds.index(method_choice(self.method)), kinds)
                c2, n = imgui.slider_int("samples N", self.method.samples, 1, 32 if self.method.kind == "lobe" else 256)
                c3, self.lobe_normalize = imgui.checkbox("lobe-N energy normalisation", self.lobe_normalize)
                if c or c2 or c3:
                    self.method = method_from_choice(kinds[k], n, self.lobe_normalize)
                    self.dirty = True
                _, self.progressive = imgui.checkbox("refine when still", self.progressive)
                c4, mirrors = imgui.checkbox("planar mirror passes", self.renderer.mirrors_enabled)
                c5, scale = imgui.slider_float("mirror resolution", self.renderer.mirror_scale, 0.1, 1.0)
                if c4 or c5:
                    self.renderer.mirrors_enabled, self.renderer.mirror_scale = mirrors, scale
                    self.dirty = True
                for line in self.renderer.mirror_report:
                    imgui.text(line)
                if scene.cameras:
                    names = [c.name for c in scene.cameras]
                    c, pick = imgui.combo("scene camera", -1 if self.camera_index is None else self.camera_index, names)
                    if c:
                        self.camera_index = pick
                        cam = scene.cameras[pick]
                        self.walk = WalkCamera.from_camera(
                            Camera(tuple(cam.position), tuple(cam.target), tuple(cam.up), cam.fov_y)
                        )
                        self.dirty = True
                c, vsync = imgui.checkbox("vsync", self.vsync)
                if c:
                    self.vsync = vsync
                    self.wnd.vsync = vsync
                _, self.exposure = imgui.slider_float("exposure", self.exposure, -6.0, 6.0)
                c, t = imgui.combo("tonemap", TONEMAPS.index(self.tonemap), list(TONEMAPS))
                self.tonemap = TONEMAPS[t]
            if imgui.collapsing_header("Objects", imgui.TreeNodeFlags_.default_open.value):
                for i, needs in enumerate(self.renderer.analysis.objects):
                    if imgui.selectable(f"{needs.name}  [{needs.kind}]##{i}", self.selected == i)[0]:
                        self.selected = i
            if self.selected is not None and imgui.collapsing_header(
                "Material", imgui.TreeNodeFlags_.default_open.value
            ):
                desc = self.editor.desc(self.selected)
                imgui.text(f"{scene.objects[self.selected].name}: {desc['model']} model")
                override = self.renderer.object_methods.get(self.selected)
                choices = ["global", *METHOD_CHOICES]
                current = 0 if override is None else choices.index(method_choice(override))
                c, k = imgui.combo("object method", current, choices)
                n = override.samples if override else self.method.samples
                c2, n = imgui.slider_int("object N", n, 1, 32)
                if c or c2:
                    if choices[k] == "global":
                        self.renderer.object_methods.pop(self.selected, None)
                    else:
                        self.renderer.object_methods[self.selected] = method_from_choice(choices[k], n)
                    self.dirty = True
                cube = self.renderer.objects[self.selected].cube
                maps = cube.built_prefiltered_maps if cube is not None else None
                if maps is not None and maps.memory:
                    imgui.text(f"prefiltered maps: {maps.total_memory() / 2**20:.1f} MB")
                    for name, size in maps.memory.items():
                        imgui.bullet_text(f"{name}: {size / 2**20:.2f} MB")
                changed, new = material_widgets(imgui, desc)
                if changed:
                    self.message = self.editor.apply(self.selected, new) or ""
                    self.dirty = True
                key = json.dumps(self.editor.desc(self.selected), sort_keys=True)
                if self._plot_key != key:  # a BSDF build + 181 evaluations: not every frame
                    self._plot_key, self._plot = key, lobe_plot_values(json.loads(key))
                x, y = self._plot
                if implot.begin_plot("lobe, 45 deg view", (-1, 160)):
                    implot.plot_line("(f cos)^1/3", x, y)
                    implot.end_plot()
                if imgui.button("undo (Ctrl+Z)") and self.editor.undo_last():
                    self.dirty = True
                imgui.same_line()
                sidecar = Path(str(scene_path) + ".materials.json")
                if imgui.button("save"):
                    self.editor.save(sidecar)
                    self.message = f"saved {sidecar}"
                imgui.same_line()
                if imgui.button("load") and sidecar.exists():
                    self.editor.load(sidecar)
                    self.dirty = True
            if self.message:
                imgui.text_wrapped(self.message)
            imgui.end()
            imgui.render()
            self.ctx.screen.use()
            self.imgui.render(imgui.get_draw_data())

        def on_close(self):
            self.closed = True
            self.realtime.release()
            self.accumulator.release()
            self.renderer.release()

    return LobeviewWindow
