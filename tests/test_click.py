"""Real pointer events on the real viewer (issue 17: 'the viewer dies on a left click').

``lobeview view`` runs on the demo scene under Xvfb; python-xlib's XTEST extension moves the X
pointer and presses the left button over every object of the demo, as a person would, in each
renderer state: standing still with progressive refinement shown, orbit mode, walking (a key
held), and with the planar mirror passes on and off. Each click must select the object under the
pointer: the expected object is read from the G-buffer of a headless render of the same view
(``SceneRenderer.pick`` on a plain frame), so a viewer that reads the wrong attachment of its
refinement framebuffer, or indexes past the object list, fails here."""

from __future__ import annotations

import time

import numpy as np
import pytest
from xviewer import XViewer

SIZE = (900, 500)
# The test collapses the ImGui panel first (a click on its title bar's arrow, as a user who wants
# to see the scene would): only its title bar, x < 440 and y < 30 (app/panel.py: pos 10,
# PANEL_WIDTH 430), then covers the scene; clicks stay clear of it with a margin.
PANEL_TITLE = (460, 40)  # (right, bottom) of what the collapsed panel covers, with the margin
COLLAPSE_ARROW = (20, 19)

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
        for x in range(width):
            if x < PANEL_TITLE[0] and y < PANEL_TITLE[1]:
                continue
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


@pytest.fixture(scope="module")
def targets():
    return _click_targets()


def _click_all(viewer: XViewer, targets, state: str) -> list[str]:
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
        viewer = XViewer(xvfb, [mirrors, "--script", str(script)], SIZE)
        try:
            viewer.wait_for(r"^stats frame=12 ")
            viewer.press_release(*COLLAPSE_ARROW)  # the panel folds to its title bar (no pick)
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
