"""Real pointer events on the real viewer (issue 17: 'the viewer dies on a left click').

``lobeview view`` runs on the demo scene under Xvfb; python-xlib's XTEST extension moves the X
pointer and presses the left button over every object of the demo, as a person would, in each
renderer state: standing still with progressive refinement shown, orbit mode, walking (a key
held), and with the planar mirror passes on and off. Each click must select the object under the
pointer: the expected object is read from the G-buffer of a headless render of the same view
(``SceneRenderer.pick`` on a plain frame), so a viewer that reads the wrong attachment of its
refinement framebuffer, or indexes past the object list, fails here."""

from __future__ import annotations

import os
import queue
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

SIZE = (900, 500)
PANEL_RIGHT = 390  # the ImGui panel covers x < 370 (app/panel.py: pos 10, width 360)
PICKED = re.compile(r"^picked (None|'(.*)') at \(([-\d.]+), ([-\d.]+)\)$")

xlib = pytest.importorskip("Xlib", reason="python-xlib (dev dependency) drives the pointer")


def _click_targets():
    """(object name, x, y) per visible object: the pixel deepest inside its silhouette (outside
    the panel), from a headless render of the overview at the window's size."""
    from scipy.ndimage import distance_transform_edt

    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import scene_view
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = load_gltf(build_demo_scene())
    position, target, up, fov = scene_view(scene, "overview")
    ctx = create_headless_context()
    renderer = SceneRenderer(
        ctx,
        scene,
        load_environment(DEMO_ENVIRONMENT),
        size=SIZE,
        progress=False,
        settings=RenderSettings(cube_face_size=16),
    )
    renderer.render(Camera(position, target, up, fov), "lobe-3")
    width, height = SIZE
    ids = np.full((height, width), -1)
    for y in range(height):
        for x in range(PANEL_RIGHT, width):
            picked = renderer.pick(x, y)
            ids[y, x] = -1 if picked is None else picked
    renderer.release()
    ctx.release()
    targets = []
    for index, obj in enumerate(scene.objects):
        # Padded with background: a silhouette cut by the window's edge is not deepest there.
        depth = distance_transform_edt(np.pad(ids == index, 1))[1:-1, 1:-1]
        if depth.max() >= 3:  # at least a 5x5 patch: a click there is unambiguous
            y, x = np.unravel_index(np.argmax(depth), depth.shape)
            targets.append((obj.name, int(x), int(y)))
    return targets


class _Viewer:
    """The viewer process, its stdout as a queue of lines, and an X connection to drive it."""

    def __init__(self, display: str, extra: list[str]):
        import tempfile

        from Xlib import display as xdisplay

        # stderr into a file: a pipe nobody reads fills up with progress lines and blocks the viewer.
        self.stderr = tempfile.TemporaryFile("w+")
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "lobeview",
                "view",
                "--view",
                "overview",
                "--size",
                f"{SIZE[0]}x{SIZE[1]}",
                "--face-size",
                "16",
                "--no-vsync",
                *extra,
            ],
            env={**os.environ, "DISPLAY": display},
            stdout=subprocess.PIPE,
            stderr=self.stderr,
            text=True,
        )
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        self.x = xdisplay.Display(display)
        self.window = self._find_window(timeout=600)

    def stderr_tail(self) -> str:
        self.stderr.seek(0)
        return self.stderr.read()[-3000:]

    def _pump(self):
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def _find_window(self, timeout: float):
        root = self.x.screen().root
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.proc.poll() is not None:
                raise AssertionError(f"viewer exited early: {self.stderr_tail()}")
            for child in root.query_tree().children:
                name = child.get_wm_name()
                if isinstance(name, str) and name.startswith("lobeview") and child.get_attributes().map_state:
                    return child
            time.sleep(0.5)
        raise AssertionError("no viewer window appeared")

    def wait_for(self, pattern: str, timeout: float = 300.0) -> re.Match:
        deadline = time.time() + timeout
        while time.time() < deadline:
            try:
                line = self.lines.get(timeout=1.0)
            except queue.Empty:
                if self.proc.poll() is not None:
                    raise AssertionError(f"viewer died: {self.stderr_tail()}") from None
                continue
            match = re.search(pattern, line)
            if match:
                return match
        raise AssertionError(f"no line matching {pattern!r} within {timeout} s")

    def _pointer_to(self, x: int, y: int):
        from Xlib import X
        from Xlib.ext import xtest

        origin = self.window.translate_coords(self.x.screen().root, 0, 0)
        # translate_coords(root -> window) gives minus the window's origin on the screen.
        xtest.fake_input(self.x, X.MotionNotify, x=x - origin.x, y=y - origin.y)
        self.x.sync()

    def click(self, x: int, y: int) -> str | None:
        from Xlib import X
        from Xlib.ext import xtest

        self._pointer_to(x, y)
        time.sleep(0.05)
        xtest.fake_input(self.x, X.ButtonPress, 1)
        self.x.sync()
        time.sleep(0.05)
        xtest.fake_input(self.x, X.ButtonRelease, 1)
        self.x.sync()
        match = PICKED.match(self.wait_for(r"^picked ").string)
        assert match and abs(float(match.group(3)) - x) <= 1 and abs(float(match.group(4)) - y) <= 1, match
        return match.group(2)

    def key(self, keysym_name: str, press: bool = True, release: bool = True):
        from Xlib import XK, X
        from Xlib.ext import xtest

        code = self.x.keysym_to_keycode(XK.string_to_keysym(keysym_name))
        if press:
            xtest.fake_input(self.x, X.KeyPress, code)
        if release:
            xtest.fake_input(self.x, X.KeyRelease, code)
        self.x.sync()

    def close(self) -> int:
        if self.proc.poll() is None:
            self._pointer_to(SIZE[0] - 20, SIZE[1] - 20)  # keyboard focus follows the pointer
            self.key("Escape")
            try:
                self.proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.x.close()
        return self.proc.wait()


@pytest.fixture(scope="module")
def targets():
    return _click_targets()


def _click_all(viewer: _Viewer, targets, state: str) -> list[str]:
    wrong = []
    for name, x, y in targets:
        picked = viewer.click(x, y)
        if picked != name:
            wrong.append(f"{state}: clicked {name!r} at ({x}, {y}), picked {picked!r}")
    return wrong


def test_every_object_is_picked_by_a_real_click_in_every_state(xvfb, targets, tmp_path):
    names = [t[0] for t in targets]
    assert len(targets) >= 10 and {"chrome sphere", "floor", "scattergloss sphere"} <= set(names), names
    script = tmp_path / "script.json"
    # 'stats' at frame 12 says the first frames (and refinement samples) are drawn.
    script.write_text('[{"frame": 12, "action": "stats"}]')
    wrong = []
    for mirrors in ("--mirrors", "--no-mirrors"):
        viewer = _Viewer(xvfb, [mirrors, "--script", str(script)])
        try:
            viewer.wait_for(r"^stats frame=12 ")
            time.sleep(2.0)  # still camera: the refined image is on screen
            wrong += _click_all(viewer, targets, f"{mirrors} refined")
            viewer._pointer_to(SIZE[0] - 5, SIZE[1] - 5)
            viewer.key("o")  # orbit mode: left drags orbit, a click still picks
            wrong += _click_all(viewer, targets, f"{mirrors} orbit")
            viewer.key("o")
            if mirrors == "--mirrors":
                # Walking: W held while clicking. The view moves, so the object under the
                # pointer may change; the click must still pick something real, not crash.
                viewer._pointer_to(SIZE[0] - 5, SIZE[1] - 5)
                viewer.key("w", release=False)
                for _name, x, y in targets[:6]:
                    picked = viewer.click(x, y)
                    assert picked is None or picked in names
                viewer.key("w", press=False)
        finally:
            code = viewer.close()
        assert code == 0, viewer.stderr_tail()
    assert not wrong, "\n".join(wrong)
