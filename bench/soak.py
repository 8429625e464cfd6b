"""Soak test of the interactive viewer (issue 17): thousands of frames of random use.

    python -m lobeview.bench.soak --frames 10000          # long run, report in bench/results
    python -m lobeview.bench.soak --frames 300 --size 160x100   # what CI runs (tests/test_soak.py)

A seeded random script drives ``lobeview view`` on the demo scene through the same paths as
keys, mouse and panel (app/script.py): walking and looking, orbit mode on and off, method
switches among every real-time method, selection, material edits of every numeric lobe
parameter within its range, undo, save and load of the materials file, F12-style screenshots and
clicks. A ``stats`` step every ``--stats-every`` frames prints the live moderngl objects and the
resident memory; the run fails on an exception, a non-zero exit, or growth of either beyond the
bounds after warm-up. Needs an X display: starts Xvfb itself when $DISPLAY is unset.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# The prefiltered methods build their maps on first use and after every edit of a material:
# 90 s (prefiltered) and 190 s (prefiltered-multi) for the demo on this 2-core CPU through
# llvmpipe (measured), so the CI soak switches among the sampling methods; --all-methods adds them.
METHODS = ("lobe-8+norm", "lobe-5", "lobe-16+norm", "fis-8", "mc-8")
SLOW_METHODS = ("prefiltered", "prefiltered-splitsum", "prefiltered-multi")
LOBE_KEYS = ("ks", "mx", "my", "r0", "alpha")
STATS = re.compile(r"^stats frame=(\d+) gl_objects=(\d+) rss_mib=(\d+) cached=(\d+)")


def _lobe_ranges():
    from lobeview.materials.spec import RANGES

    return {key: RANGES[key] for key in LOBE_KEYS if key in RANGES}


def soak_script(
    frames: int, seed: int, objects: list[tuple[str, int]], work: Path, stats_every: int, methods=METHODS
) -> list[dict]:
    """Random steps for ``frames`` frames. ``objects``: (name, number of reflection lobes)."""
    rng = np.random.default_rng(seed)
    ranges = _lobe_ranges()
    glossy = [(name, n) for name, n in objects if n > 0]
    materials_file = work / "soak.materials.json"
    steps: list[dict] = [{"frame": 1, "action": "save_materials", "path": str(materials_file)}]
    selected = None
    for frame in range(2, frames):
        roll = rng.random()
        if roll < 0.25:
            direction = rng.normal(size=3)
            steps.append({"frame": frame, "action": "move", "direction": direction.tolist(), "seconds": 0.05})
        elif roll < 0.4:
            steps.append(
                {"frame": frame, "action": "look", "dx": float(rng.normal() * 20), "dy": float(rng.normal() * 8)}
            )
        elif roll < 0.47:
            steps.append({"frame": frame, "action": "method", "value": methods[int(rng.integers(len(methods)))]})
        elif roll < 0.57:
            name, lobes = glossy[int(rng.integers(len(glossy)))]
            selected = (name, lobes)
            steps.append({"frame": frame, "action": "select", "object": name})
        elif roll < 0.70 and selected is not None:
            key = LOBE_KEYS[int(rng.integers(len(LOBE_KEYS)))]
            low, high = ranges[key]
            value = (
                float(np.exp(rng.uniform(np.log(max(low, 1e-3)), np.log(high))))
                if key in ("mx", "my")
                else float(rng.uniform(low, high))
            )
            lobe = int(rng.integers(selected[1]))
            steps.append({"frame": frame, "action": "set", "path": ["lobes", lobe, key], "value": value})
        elif roll < 0.76:
            steps.append({"frame": frame, "action": "undo"})
        elif roll < 0.80:
            steps.append({"frame": frame, "action": "press", "key": "O"})
            steps.append({"frame": frame + 1, "action": "release", "key": "O"})
        elif roll < 0.84:
            steps.append(
                {"frame": frame, "action": "click", "x": float(rng.uniform(0, 1)), "y": float(rng.uniform(0, 1))}
            )
            selected = None  # the click selects whatever it hits: edits wait for the next select
        elif roll < 0.86:
            steps.append({"frame": frame, "action": "save_materials", "path": str(materials_file)})
        elif roll < 0.88:
            steps.append({"frame": frame, "action": "load_materials", "path": str(materials_file)})
        elif roll < 0.885:
            steps.append({"frame": frame, "action": "screenshot", "name": f"soak{frame:06d}"})
        if frame % stats_every == 0:
            steps.append({"frame": frame, "action": "stats"})
    steps.append({"frame": frames, "action": "stats"})
    steps.append({"frame": frames, "action": "quit"})
    return steps


XVFB_ATTEMPTS = 20  # displays tried from the preferred one on (a stale server may hold one)


def start_xvfb(display_number: int, screen: str = "1024x768x24") -> tuple[subprocess.Popen, str]:
    """A virtual X server (``screen``, no TCP) for the window tests, on ``:display_number`` or
    the next free display: one left behind by a killed run keeps its lock file and makes a new
    server on the same number exit at once."""
    proc = None
    for number in range(display_number, display_number + XVFB_ATTEMPTS):
        if Path(f"/tmp/.X{number}-lock").exists():
            continue
        display = f":{number}"
        proc = subprocess.Popen(
            ["Xvfb", display, "-screen", "0", screen, "-nolisten", "tcp"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        time.sleep(1.5)
        if proc.poll() is None:
            return proc, display
    if proc is None:
        raise RuntimeError(f"X displays :{display_number}..:{number} are all taken (lock files in /tmp)")
    return proc, display  # the caller reports the last one that did not start


def x_display(
    size: tuple[int, int] | None = None, first_number: int = 500, who: str = "the window bench"
) -> tuple[subprocess.Popen | None, str]:
    """$DISPLAY when set, else a virtual X server (returned, for the caller to terminate) whose
    screen holds a window of ``size`` (None: the default 1024x768 screen); ``who`` names the
    caller in the message when there is neither."""
    if os.environ.get("DISPLAY"):
        return None, os.environ["DISPLAY"]
    if shutil.which("Xvfb") is None:
        raise SystemExit(f"{who} needs an X display: set DISPLAY or install Xvfb")
    number = first_number + os.getpid() % 300
    if size is None:
        return start_xvfb(number)
    return start_xvfb(number, f"{size[0] + 64}x{size[1] + 64}x24")


def run_soak(
    frames: int,
    seed: int,
    size: tuple[int, int],
    work: Path,
    stats_every: int = 100,
    progress=print,
    methods=METHODS,
) -> dict:
    """Run the viewer through a random script; returns the measurements (see module doc)."""
    from lobeview.scenes.demo import build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf

    scene = load_gltf(build_demo_scene())
    objects = [(o.name, len(scene.materials[o.material].desc.get("lobes", []))) for o in scene.objects]
    work.mkdir(parents=True, exist_ok=True)
    steps = soak_script(frames, seed, objects, work, stats_every, methods)
    # Clicks: the script uses fractions of the window; the viewer wants pixels.
    for step in steps:
        if step["action"] == "click":
            step["x"], step["y"] = step["x"] * size[0], step["y"] * size[1]
    (work / "soak.json").write_text(json.dumps(steps))
    xvfb, display = x_display(first_number=400, who="the soak test")
    t0 = time.perf_counter()
    stderr_file = open(work / "viewer.stderr", "w+")  # a file, not a pipe: a full pipe would block the viewer
    try:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "lobeview",
                "view",
                "--view",
                "overview",
                "--size",
                f"{size[0]}x{size[1]}",
                "--face-size",
                "16",
                "--no-vsync",
                "--script",
                str(work / "soak.json"),
                "--screenshot-dir",
                str(work / "shots"),
            ],
            env={**os.environ, "DISPLAY": display},
            stdout=subprocess.PIPE,
            stderr=stderr_file,
            text=True,
        )
        stats = []
        for line in proc.stdout:
            match = STATS.match(line)
            if match:
                stats.append(tuple(int(g) for g in match.groups()))
                if progress:
                    frame, gl_objects, rss, cached = stats[-1]
                    elapsed = time.perf_counter() - t0
                    progress(
                        f"[soak] frame {frame}/{frames}: {gl_objects} GL objects ({cached} in bounded caches), "
                        f"{rss} MiB resident, {elapsed:.0f} s"
                    )
        code = proc.wait()
        stderr_file.seek(0)
        stderr = stderr_file.read()
    finally:
        stderr_file.close()
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(timeout=10)
    counts = {a: sum(1 for s in steps if s["action"] == a) for a in sorted({s["action"] for s in steps})}
    return {
        "frames": frames,
        "seed": seed,
        "size": list(size),
        "exit_code": code,
        "traceback": "Traceback" in stderr,
        "stderr_tail": stderr[-2000:],
        "stats": [{"frame": f, "gl_objects": g, "rss_mib": r, "cached": c} for f, g, r, c in stats],
        "actions": counts,
        "seconds": round(time.perf_counter() - t0, 1),
    }


def check(result: dict, warmup_frame: int, max_gl_growth: int, max_rss_growth_mib: float) -> list[str]:
    """The failures of a soak run: exit, traceback, and growth after ``warmup_frame``."""
    problems = []
    if result["exit_code"] != 0 or result["traceback"]:
        problems.append(f"viewer exited with {result['exit_code']}: {result['stderr_tail'][-1500:]}")
    stats = [s for s in result["stats"] if s["frame"] >= warmup_frame]
    if len(stats) < 2:
        problems.append(f"too few stats lines after warm-up: {result['stats']}")
        return problems
    base, last = stats[0], stats[-1]
    # Objects the bounded caches hold are bounded by their capacity; the rest must not grow.
    uncached = [s["gl_objects"] - s["cached"] for s in stats]
    if max(uncached) - uncached[0] > max_gl_growth:
        problems.append(
            f"GL objects outside the bounded caches grew from {uncached[0]} to {max(uncached)} (bound +{max_gl_growth})"
        )
    if last["rss_mib"] - base["rss_mib"] > max_rss_growth_mib:
        problems.append(
            f"resident memory grew from {base['rss_mib']} to {last['rss_mib']} MiB (bound +{max_rss_growth_mib})"
        )
    return problems


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.soak", description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=10000, help="frames to run (default 10000)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random script (default 1)")
    p.add_argument("--size", default="160x100", help="window size (default 160x100)")
    p.add_argument("--stats-every", type=int, default=500, help="frames between stats lines (default 500)")
    p.add_argument("--all-methods", action="store_true", help=f"also switch to {', '.join(SLOW_METHODS)} (slow)")
    p.add_argument("--report", default=None, help="JSON report (default bench/results/soak_FRAMES.json)")
    args = p.parse_args(argv)
    from lobeview.core.errors import parse_size
    from lobeview.core.paths import bench_results_dir

    size = parse_size(args.size)
    work = Path(tempfile.mkdtemp(prefix="lobeview-soak-"))
    methods = METHODS + (SLOW_METHODS if args.all_methods else ())
    result = run_soak(args.frames, args.seed, size, work, args.stats_every, methods=methods)
    warmup = min(args.stats_every, args.frames // 2)
    problems = check(result, warmup, max_gl_growth=16, max_rss_growth_mib=max(200.0, args.frames * 0.02))
    result["problems"] = problems
    result["command"] = " ".join(["python -m lobeview.bench.soak", *(argv if argv is not None else sys.argv[1:])])
    report = Path(args.report) if args.report else bench_results_dir() / f"soak_{args.frames}.json"
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text(json.dumps(result, indent=1) + "\n")
    print(f"[soak] {args.frames} frames in {result['seconds']} s; report {report}")
    for problem in problems:
        print(f"[soak] FAIL: {problem}")
    shutil.rmtree(work, ignore_errors=True)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
