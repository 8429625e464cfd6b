"""Issue 41: a window that stays interactive at any frame rate.

Frame pacing (app/frame_pacing.py) against its model, and the real window under Xvfb driven by
XTEST as a person would: holding W walks by wall-clock time, a click on the panel never picks
through it, and the panel's method combo opens and selects on plain clicks when a frame takes
seconds (full resolution, ``--target-fps 0``). The frame log (``--stats``) says what each frame
did: its state, render size, method and the camera's position."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from lobeview.app.frame_pacing import (
    FINER_MARGIN,
    MOTION_STALL_CAP_S,
    RENDER_SCALES,
    HeldKeys,
    RenderScale,
    scaled_size,
    target_frame_seconds,
)


# -- frame pacing, against a frame-cost model -----------------------------------------------------
def _simulate(target_s: float, fixed_s: float, full_pass_s: float, frames: int = 40) -> list[float]:
    """Scales chosen frame after frame when a pass costs fixed_s + full_pass_s * scale^2 and
    the rest of a frame 5 ms."""
    control, scales = RenderScale(target_s), []
    for _ in range(frames):
        scale = control.scale
        pass_s = fixed_s + full_pass_s * scale**2
        scales.append(scale)
        control.observe(scale, pass_s, pass_s + 0.005)
    return scales


@pytest.mark.parametrize("full_pass_s", [0.02, 0.3, 3.0, 40.0])
def test_render_scale_settles_on_the_finest_scale_that_holds_the_target(full_pass_s):
    target, fixed = 1 / 15, 0.01
    scales = _simulate(target, fixed, full_pass_s)
    settled = scales[-1]
    assert scales[-10:] == [settled] * 10, scales  # no flicker between two sizes
    fits = [s for s in RENDER_SCALES if fixed + full_pass_s * s**2 + 0.005 <= target]
    if not fits:
        assert settled == RENDER_SCALES[-1]
    else:
        # the finest that fits, or one step coarser when the finer one is inside the margin band
        finest = max(fits)
        index = RENDER_SCALES.index(finest)
        assert settled == finest or (
            RENDER_SCALES.index(settled) == index + 1
            and fixed + full_pass_s * finest**2 + 0.005 > FINER_MARGIN * target
        ), (settled, finest)


def test_render_scale_steps_finer_one_level_at_a_time_and_is_off_at_target_zero():
    control = RenderScale(1 / 15)
    control.observe(1.0, 10.0, 10.1)  # a 10 s frame: straight to the coarsest
    assert control.scale == RENDER_SCALES[-1]
    control.observe(control.scale, 0.001, 0.002)  # then very fast: one step per frame
    assert control.scale == RENDER_SCALES[-2]
    off = RenderScale(target_frame_seconds(0))
    off.observe(1.0, 10.0, 10.1)
    assert off.scale == 1.0
    with pytest.raises(ValueError, match="target-fps"):
        target_frame_seconds(-1)
    with pytest.raises(ValueError, match="target-fps"):
        target_frame_seconds(math.nan)
    assert scaled_size((1280, 800), 0.1) == (128, 80) and scaled_size((3, 3), 0.1) == (1, 1)


def test_held_keys_count_wall_clock_time_between_frames():
    keys = HeldKeys()
    keys.take(0.0)
    keys.press("w", 0.1)
    assert keys.take(0.5) == pytest.approx({"w": 0.4})
    keys.release("w", 0.7)  # released between two frames: still moved for the 0.2 s it was down
    keys.press("d", 0.8)
    keys.release("d", 0.9)
    assert keys.take(1.0) == pytest.approx({"w": 0.2, "d": 0.1})
    assert keys.take(2.0) == {}
    keys.press("s", 2.0)
    assert keys.take(9.0) == {"s": MOTION_STALL_CAP_S}  # a stall of seconds is cut
    keys.release("x", 9.5)  # a release without its press (pressed over the panel): nothing
    assert keys.take(10.0) == pytest.approx({"s": 1.0})


def test_a_stale_cube_map_waits_for_room_in_a_moving_frame_but_not_forever():
    from types import SimpleNamespace

    from lobeview.app.window import CUBE_REFRESH_MAX_DEFERRED, LobeviewWindow

    window = SimpleNamespace(
        renderer=SimpleNamespace(stale_cube_count=2), render_scale=RenderScale(1 / 15), cube_ms=50.0,
        cube_refresh_deferred=0,
    )  # fmt: skip
    fits = LobeviewWindow._cube_refresh_fits
    assert fits(window, moving=False, elapsed_s=1.0)  # at rest: always
    assert fits(window, moving=True, elapsed_s=0.01)  # 10 + 50 ms within 66.7 ms
    decisions = [fits(window, moving=True, elapsed_s=0.03) for _ in range(CUBE_REFRESH_MAX_DEFERRED + 1)]
    assert decisions == [False] * CUBE_REFRESH_MAX_DEFERRED + [True]
    window.renderer.stale_cube_count = 0
    assert not fits(window, moving=False, elapsed_s=0.0)  # nothing to refresh


# -- the real window ---------------------------------------------------------------------------------
xlib = pytest.importorskip("Xlib", reason="python-xlib (dev dependency) drives the pointer")


def _frames(path) -> list[dict]:
    try:
        text = path.read_text()
    except FileNotFoundError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.endswith("}")]


def _wait_frames(path, condition, timeout: float = 300.0, what: str = "") -> dict:
    deadline = time.time() + timeout
    while time.time() < deadline:
        for frame in reversed(_frames(path)):
            if condition(frame):
                return frame
        time.sleep(0.2)
    raise AssertionError(f"no frame {what} within {timeout} s; last: {(_frames(path) or [None])[-1]}")


def _centre(rect) -> tuple[int, int]:
    x, y, w, h = rect
    return int(x + w / 2), int(y + h / 2)


def test_holding_w_walks_by_wall_clock_time(xvfb, tmp_path):
    from xviewer import XViewer

    stats = tmp_path / "frames.jsonl"
    viewer = XViewer(xvfb, ["--stats", str(stats), "--view", "table"], size=(640, 400))
    try:
        first = _wait_frames(stats, lambda f: f["frame"] >= 3, what="3")
        viewer._pointer_to(600, 380)  # keyboard focus follows the pointer; outside the panel
        viewer.key("w", release=False)
        time.sleep(10.0)
        viewer.key("w", press=False)
        time.sleep(1.0)
        last = _frames(stats)[-1]
    finally:
        code = viewer.close()
    assert code == 0, viewer.stderr_tail()
    frames = _frames(stats)
    moved = float(np.linalg.norm(np.subtract(last["camera"], first["camera"])))
    speed = first["walk_speed"]
    assert moved >= 10.0 * speed / 3.0, (moved, speed)
    assert moved <= 11.5 * speed, (moved, speed)  # wall-clock, not more
    moving = [f for f in frames if f["state"] == "moving"]
    assert moving, frames[-5:]
    # Every moving frame is the window's size times its scale; the frame after rest is full size.
    for f in moving:
        assert f["render_size"] == list(scaled_size((640, 400), f["render_scale"])), f


def test_panel_clicks_never_pick_and_its_combo_works_when_a_frame_takes_seconds(xvfb, tmp_path):
    from xviewer import XViewer

    stats = tmp_path / "frames.jsonl"
    size = (1000, 700)  # full resolution every frame: the slowest this machine gives
    viewer = XViewer(xvfb, ["--stats", str(stats), "--target-fps", "0", "--no-mirrors"], size=size)
    try:
        frame = _wait_frames(stats, lambda f: "method" in f["widgets"] and f["frame"] >= 2, what="with the panel")
        assert frame["method"] == "lobe-11+norm+fit", frame  # the default lobe-N (issue 45)
        combo = frame["widgets"]["method"]
        # A click on the panel's status text, the pointer moved there just before: ImGui's
        # last answer (want_capture_mouse) was for the pointer's old place, in the scene.
        viewer._pointer_to(size[0] - 50, size[1] - 50)
        _wait_frames(stats, lambda f: f["frame"] >= frame["frame"] + 1, what="after the pointer moved")
        viewer.press_release(150, 45)
        # The method combo: a plain click (50 ms down) opens it, whatever the frame time.
        viewer.press_release(*_centre(combo))
        opened = _wait_frames(stats, lambda f: "method: fis" in f["widgets"], timeout=120, what="with the combo open")
        _wait_frames(stats, lambda f: f["frame"] > opened["frame"], what="after the combo opened")
        opened = _frames(stats)[-1]  # the popup as it stays on screen
        viewer.press_release(*_centre(opened["widgets"]["method: fis"]))
        chosen = _wait_frames(stats, lambda f: f["method"].startswith("fis"), timeout=120, what="with fis chosen")
        _wait_frames(stats, lambda f: f["frame"] >= chosen["frame"] + 2, what="after the choice")
        assert _frames(stats)[-1]["method"].startswith("fis")  # and it stays chosen
        # The combo never moved while status lines came and went above it (refinement, cube maps,
        # the bake): a click aimed at an item must land on it.
        # (its width may change: the panel's scroll bar comes with taller content, fis's)
        places = {tuple(f["widgets"]["method"][:2]) for f in _frames(stats) if "method" in f["widgets"]}
        assert len(places) == 1, places
        viewer.click(size[0] - 200, size[1] - 100)  # a click in the scene still picks (a 'picked' line)
    finally:
        code = viewer.close()
    assert code == 0, viewer.stderr_tail()
    picks = [line for line in viewer.printed if line.startswith("picked ")]
    assert len(picks) == 1, picks  # only the scene click's (its position checked by click)


def test_a_screenshot_while_moving_is_of_the_full_resolution_frame(xvfb, tmp_path):
    """F12 (here a scripted screenshot) while a key walks the camera: the saved image is the
    full-resolution frame its printed `lobeview shot` line renders, not the upsampled moving one."""
    from conftest import run_scripted_view

    stats = tmp_path / "frames.jsonl"
    script = [
        {"frame": 2, "action": "press", "key": "D"},
        {"frame": 6, "action": "screenshot", "name": "moving"},
        {"frame": 8, "action": "release", "key": "D"},
        {"frame": 10, "action": "quit"},
    ]
    args = ["--view=table", "--size=480x300", "--face-size=32", "--target-fps=15", f"--stats={stats}"]
    run_scripted_view(xvfb, tmp_path, script, args, 40)
    frames = {f["frame"]: f for f in _frames(stats)}
    assert frames[6]["state"] == "moving" and frames[6]["render_size"] == [480, 300], frames[6]
    assert (tmp_path / "moving.png").exists()
