"""The viewer survives a few hundred frames of random use without leaking (issue 17).

CI runs a short soak (bench/soak.py) under Xvfb; the long run is
``python -m lobeview.bench.soak --frames 10000`` with its report in bench/results.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from lobeview.bench import soak


def _stats(frames, gl_objects, cached, rss):
    return [
        {"frame": f, "gl_objects": g, "cached": c, "rss_mib": r}
        for f, g, c, r in zip(frames, gl_objects, cached, rss, strict=True)
    ]


def _result(stats, exit_code=0, stderr=""):
    return {"exit_code": exit_code, "traceback": "Traceback" in stderr, "stderr_tail": stderr, "stats": stats}


def test_check_tells_a_leak_from_a_filling_cache():
    frames = [50, 100, 150, 200]
    filling = _stats(frames, [200, 210, 220, 230], [20, 30, 40, 50], [400, 401, 402, 402])
    assert soak.check(_result(filling), 50, max_gl_growth=16, max_rss_growth_mib=200) == []
    leaking = _stats(frames, [200, 210, 220, 230], [20, 20, 20, 20], [400, 401, 402, 402])
    problems = soak.check(_result(leaking), 50, max_gl_growth=16, max_rss_growth_mib=200)
    assert len(problems) == 1 and "grew from 180 to 210" in problems[0]
    swelling = _stats(frames, [200] * 4, [20] * 4, [400, 500, 600, 700])
    problems = soak.check(_result(swelling), 50, max_gl_growth=16, max_rss_growth_mib=200)
    assert len(problems) == 1 and "resident memory grew from 400 to 700" in problems[0]
    crashed = soak.check(_result(filling, 1, "Traceback (most recent call last)"), 50, 16, 200)
    assert len(crashed) == 1 and "exited with 1" in crashed[0]


def test_soak_script_exercises_every_kind_of_use(tmp_path):
    objects = [("floor", 1), ("chrome", 2), ("wall", 0)]
    steps = soak.soak_script(2000, 3, objects, tmp_path, stats_every=100)
    actions = {s["action"] for s in steps}
    expected = {"move", "look", "method", "select", "set", "undo", "press", "release", "click", "save_materials"}
    expected |= {"load_materials", "screenshot", "stats", "quit"}
    assert actions == expected
    # Edits stay inside the material ranges, selections only pick objects with lobes.
    ranges = soak._lobe_ranges()
    for step in steps:
        if step["action"] == "set":
            low, high = ranges[step["path"][2]]
            assert low <= step["value"] <= high
        if step["action"] == "select":
            assert step["object"] in ("floor", "chrome")
    assert steps == soak.soak_script(2000, 3, objects, tmp_path, stats_every=100)


def test_viewer_survives_random_use_without_leaking(xvfb, tmp_path, monkeypatch):
    monkeypatch.setenv("DISPLAY", xvfb)
    result = soak.run_soak(240, seed=20261124, size=(160, 100), work=tmp_path, stats_every=40, progress=None)
    assert sum(result["actions"].get(a, 0) for a in ("set", "method", "click")) > 30, result["actions"]
    assert len(result["stats"]) >= 6
    assert soak.check(result, warmup_frame=40, max_gl_growth=16, max_rss_growth_mib=200) == []


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="Xvfb not installed")
def test_xvfb_skips_a_display_a_stale_server_holds():
    """A server left behind by a killed run keeps /tmp/.X<n>-lock: the next run takes :n+1
    instead of failing (seen: a killed CI left :259 and the next one's window tests errored)."""
    from lobeview.bench.soak import start_xvfb

    number = 700 + os.getpid() % 50
    lock = Path(f"/tmp/.X{number}-lock")
    if lock.exists() or Path(f"/tmp/.X{number + 1}-lock").exists():
        pytest.skip(f"displays :{number} / :{number + 1} are in use here")
    lock.write_text("stale\n")
    try:
        proc, display = start_xvfb(number)
        try:
            assert display == f":{number + 1}" and proc.poll() is None
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    finally:
        lock.unlink()
