"""The walkthrough window's frame rate on this machine (issue 41): the recorded paths flown in the
real window, from its frame log.

    python -m lobeview.bench.window                       # demo and apartment, 1280x800
    python -m lobeview.bench.window --scenes builtin:demo --frames 120

For each scene ``lobeview view SCENE --path builtin --size WxH --stats FILE`` runs under an X
display (Xvfb started when $DISPLAY is unset) twice in one run: with the default frame-rate
target (``--target-fps``, app/frame_pacing.py) and at fixed full resolution (``--target-fps 0``,
the window before issue 41: fewer frames, each takes seconds here). From the frame log it
reports the frame interval while the path moves the camera (median, 90th percentile), the
render scales used, the path seconds flown per wall-clock second (1 when motion follows the
clock) and the time to the first frame. Wall-clock on a shared machine: the ratio between the
two runs is what counts. The image at rest is the full-resolution frame, as ``lobeview shot``
renders it (tests/test_frames_unchanged.py).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_SCENES = ("builtin:demo", "builtin:apartment")


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def summarise(frames: list[dict]) -> dict:
    """What the frame log of one flight says (its first frame, drawn before any path moves the
    camera at a known scale, is start-up)."""
    moving = [f for f in frames[1:] if f["state"] == "moving" and f["interval_ms"] is not None]
    intervals = [f["interval_ms"] for f in moving]
    times = [f["path_time"] for f in frames if f["path_time"] is not None]
    flown = sum(b - a for a, b in zip(times, times[1:], strict=False) if b >= a)  # wraps (loops) left out
    wall = frames[-1]["t"] - frames[1]["t"] if len(frames) > 2 else 0.0
    scales = {}
    for f in moving:
        scales[str(f["render_scale"])] = scales.get(str(f["render_scale"]), 0) + 1
    return {
        "frames": len(frames),
        "moving frames": len(moving),
        "interval median ms": statistics.median(intervals) if intervals else None,
        "interval p90 ms": float(np.percentile(intervals, 90, method="nearest")) if intervals else None,
        "pass median ms": statistics.median(f["pass_ms"] for f in moving) if moving else None,
        "render scales": scales,
        "median render size": moving[len(moving) // 2]["render_size"] if moving else None,
        "path seconds per second": flown / wall if wall > 0 else None,
        "first frame ms": frames[0]["pass_ms"],
    }


def fly(scene: str, size: tuple[int, int], frames: int, target_fps: float | None, display: str, work: Path) -> dict:
    stats = work / f"frames-{scene.replace(':', '_')}-{target_fps}.jsonl"
    command = [
        sys.executable, "-m", "lobeview", "view", scene, "--path", "builtin", "--size", f"{size[0]}x{size[1]}",
        "--no-vsync", "--stats", str(stats), "--exit-after", str(frames),
    ]  # fmt: skip
    if target_fps is not None:
        command += ["--target-fps", str(target_fps)]
    _say(f"{scene}: {' '.join(command[3:])}")
    t0 = time.perf_counter()
    result = subprocess.run(command, env={**os.environ, "DISPLAY": display}, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"{scene}: the viewer failed:\n{result.stderr[-3000:]}")
    log = [json.loads(line) for line in stats.read_text().splitlines() if line.strip()]
    summary = summarise(log)
    summary["process s"] = time.perf_counter() - t0
    summary["target fps"] = 0 if target_fps == 0 else (target_fps or "default")
    return summary


def _row(scene: str, s: dict) -> str:
    def ms(v):
        return "-" if v is None else f"{v:.0f}"

    speed = s["path seconds per second"]
    return (
        f"| {scene} | {s['target fps']} | {s['moving frames']} | {ms(s['interval median ms'])} | "
        f"{ms(s['interval p90 ms'])} | {ms(s['pass median ms'])} | "
        f"{'x'.join(map(str, s['median render size'] or []))} | "
        f"{', '.join(f'{k}: {v}' for k, v in sorted(s['render scales'].items(), key=lambda kv: -float(kv[0])))} | "
        f"{'-' if speed is None else f'{speed:.2f}'} | {s['first frame ms'] / 1000:.1f} | {s['process s']:.0f} |"
    )


def main(argv: list[str] | None = None) -> int:
    from lobeview.core.errors import parse_size

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.window", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="+", default=list(DEFAULT_SCENES), help="scenes with a recorded path")
    p.add_argument("--size", default="1280x800", help="window size (default 1280x800)")
    p.add_argument("--frames", type=int, default=300, help="frames with the frame-rate target (default 300)")
    p.add_argument("--fixed-frames", type=int, default=12, help="frames at fixed full resolution (default 12)")
    p.add_argument("--out", default=None, help="Markdown report (default bench/results/window-STAMP.md, + .json)")
    args = p.parse_args(argv)
    from lobeview.bench.soak import x_display

    size = parse_size(args.size)
    server, display = x_display(size)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path(__file__).parent / "results" / f"window-{stamp}.md"
    results = {}
    t0 = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for scene in args.scenes:
                results[scene] = [
                    fly(scene, size, args.frames, None, display, Path(tmp)),
                    fly(scene, size, args.fixed_frames, 0, display, Path(tmp)),
                ]
    finally:
        if server is not None:
            server.terminate()
    from lobeview.viewer.context import create_headless_context

    ctx = create_headless_context()
    device = f"{ctx.info['GL_RENDERER']} ({ctx.info['GL_VENDOR']}), {ctx.info['GL_VERSION']}"
    ctx.release()
    lines = [
        f"# Window frame rate {stamp}",
        "",
        f"Device: {device}; {os.cpu_count()} CPU cores. `lobeview view SCENE --path builtin --size {args.size} "
        "--no-vsync --stats FILE`, the recorded path flown in the real window under Xvfb, the default method "
        f"(lobe-11+norm); {args.frames} frames with the default frame-rate target (15 fps), "
        f"{args.fixed_frames} at fixed full resolution (`--target-fps 0`, the window before issue 41). Frame "
        "interval: from one frame's start to the next's, frames that moved the camera (the first, start-up, "
        "left out); pass: the scene's real-time frame with glFinish; path speed: path seconds flown per "
        f"wall-clock second (1: motion follows the clock). Whole run {time.perf_counter() - t0:.0f} s.",
        "",
        "| scene | target fps | moving frames | interval median ms | interval p90 ms | pass median ms | "
        "median render size | render scales (frames) | path speed | first frame s | process s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene, runs in results.items():
        lines += [_row(scene, s) for s in runs]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    out.with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")
    print("\n".join(lines))
    _say(f"wrote {out} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
