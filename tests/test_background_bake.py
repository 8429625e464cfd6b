"""A built-in scene's first-use bake in the background (issue 42 item 2, app/background_bake.py):
the window shows the scene without lightmaps at once and swaps the baked one in when the worker
process has cached it; a failing bake is a message, not a crash."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import warnings

from lobeview.app.background_bake import BackgroundBake


def _wait(bake: BackgroundBake, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while not bake.poll():
        assert time.monotonic() < deadline, "the bake worker did not finish"
        time.sleep(0.1)


def test_a_failing_bake_reports_its_error(tmp_path):
    bake = BackgroundBake.for_builtin("builtin:nothing", tmp_path)
    _wait(bake, 120)
    assert bake.path is None and "unknown built-in scene" in bake.error
    bake.cancel()


def _frames(stats) -> list[dict]:
    """The frame log's complete lines (the window may be writing the last one)."""
    if not stats.exists():
        return []
    complete = stats.read_text().split("\n")[:-1]  # a line is complete once its newline is written
    return [json.loads(line) for line in complete if line.strip()]


def test_the_window_opens_before_the_bake_and_swaps_the_lightmaps_in(xvfb, tmp_path):
    """The demo from an empty cache: the first frame comes while the worker bakes (the frame log's
    background_bake says so), later frames after the swap (null), and the baked scene is cached
    with its objects in the unbaked scene's order (what the swap keeps per object)."""
    from lobeview.scenes.demo import demo_geometry, demo_scene_file
    from lobeview.scenes.gltf_loader import load_gltf

    stats, cache = tmp_path / "frames.jsonl", tmp_path / "cache"
    env = {**os.environ, "DISPLAY": xvfb}
    command = [sys.executable, "-m", "lobeview", "view", "--cache", str(cache), "--size", "240x150",
               "--face-size", "32", "--stats", str(stats)]  # fmt: skip
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and process.poll() is None:
            frames = _frames(stats)
            if any(f["background_bake"] is None for f in frames[1:]):
                break
            time.sleep(1.0)
        assert process.poll() is None, process.communicate()[1][-3000:]
    finally:
        process.terminate()
        _, stderr = process.communicate(timeout=60)
    frames = _frames(stats)
    assert frames, stderr[-3000:]
    assert frames[0]["background_bake"] is not None  # the scene was shown before its bake ended
    swapped = next(f for f in frames if f["background_bake"] is None)
    assert swapped["t"] > frames[0]["t"]
    baked = demo_scene_file(cache / "demo")
    assert baked.exists()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        names = [o.name for o in load_gltf(baked).objects]
    assert names == [o.name for o in demo_geometry().objects]
