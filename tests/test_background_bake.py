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


def _view_until_done(arguments: list[str], xvfb: str, stats, field: str, timeout: float) -> tuple[list[dict], str]:
    """Run `lobeview view ARGUMENTS --stats STATS` until a frame after the first has ``field``
    null in its log (the work it names ended) or ``timeout``; the frames logged and stderr."""
    command = [sys.executable, "-m", "lobeview", "view", *arguments, "--stats", str(stats)]
    env = {**os.environ, "DISPLAY": xvfb}
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and process.poll() is None:
            if any(f[field] is None for f in _frames(stats)[1:]):
                break
            time.sleep(0.5)
        assert process.poll() is None, process.communicate()[1][-3000:]
    finally:
        process.terminate()
        _, stderr = process.communicate(timeout=60)
    return _frames(stats), stderr


def test_the_window_opens_before_the_bake_and_swaps_the_lightmaps_in(xvfb, tmp_path):
    """The demo from an empty cache: the first frame comes while the worker bakes (the frame log's
    background_bake says so), later frames after the swap (null), and the baked scene is cached
    with its objects in the unbaked scene's order (what the swap keeps per object)."""
    from lobeview.scenes.demo import demo_geometry, demo_scene_file
    from lobeview.scenes.gltf_loader import load_gltf

    stats, cache = tmp_path / "frames.jsonl", tmp_path / "cache"
    arguments = ["--cache", str(cache), "--size", "240x150", "--face-size", "32"]
    frames, stderr = _view_until_done(arguments, xvfb, stats, "background_bake", 600)
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
    # the worker traced the baked scene's horizon maps too: the swapped-in renderer found them
    from lobeview.app.options import renderer_cache_folder
    from lobeview.scenes.horizon_maps import lightmap_horizon_map, square_lightmap_images

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(baked)
    images = square_lightmap_images(scene)
    assert images and all(lightmap_horizon_map(scene, i, renderer_cache_folder(cache), trace=False) is not None
                          for i in images)  # fmt: skip
    assert all(f["horizon_maps"] is None for f in frames)  # no second worker after the swap


def test_a_baked_file_opens_at_once_and_its_horizon_maps_come_from_a_worker(xvfb, tmp_path):
    """A scene file with lightmaps whose horizon maps are not cached: the first frame is drawn while
    a worker traces them (the frame log's horizon_maps says so), later frames after it ended."""
    from test_horizon_maps import _corner_scene

    from lobeview.scenes.gltf_writer import write_glb

    scene, _ = _corner_scene()
    path = write_glb(scene, tmp_path / "corner.glb", lightmap=scene.materials[0].lightmap.image)
    stats, cache = tmp_path / "frames.jsonl", tmp_path / "cache"
    arguments = [str(path), "--cache", str(cache), "--size", "160x100", "--face-size", "16"]
    frames, stderr = _view_until_done(arguments, xvfb, stats, "horizon_maps", 300)
    assert frames and frames[0]["horizon_maps"] is not None, stderr[-3000:]
    assert any(f["horizon_maps"] is None for f in frames[1:]), stderr[-3000:]
    assert len(list((cache / "cubes").glob("horizons-*.npy"))) == 1


def test_while_a_bake_runs_the_unbaked_scenes_maps_are_left_to_it():
    """The unbaked scene shown during a bake may lack horizon maps (over its texture coordinates):
    no worker is started and nothing traced in the window; its cube-map build waits (the baked
    scene replaces it); a failed bake lets the window trace them after all."""
    from types import SimpleNamespace

    from lobeview.app.finishing import SceneFinishing

    traced = []
    shading = SimpleNamespace(missing_horizon_maps=1, prepare_horizon_maps=lambda trace: traced.append(trace) or 0)
    renderer = SimpleNamespace(shading=shading, horizon_maps_traced_elsewhere=False)
    window = SimpleNamespace(renderer=renderer, session=SimpleNamespace(scene_path=None), dirty=False, message=None,
                             show_progress=lambda *a: None)  # fmt: skip
    finishing = SceneFinishing(background_bake=object())
    finishing.poll_horizon_maps(window)
    assert renderer.horizon_maps_traced_elsewhere and finishing.horizon_worker is None and not traced
    finishing.background_bake = None  # the bake failed: the scene stays
    renderer.horizon_maps_traced_elsewhere = False
    finishing.poll_horizon_maps(window)  # no scene file to give a worker: traced here
    assert traced == [True] and finishing.horizon_worker is None
