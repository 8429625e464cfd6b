"""Cold start of the viewer (issue 42 item 2), as a new user meets it: ``lobeview view SCENE``
from an empty cache folder, under an X display (Xvfb started when $DISPLAY is unset), timed from
the launch of the process by its frame log (``--stats``, one JSON line per frame): the first frame
drawn (the scene unbaked, on preview cube maps), the baked scene swapped in (the background bake,
app/background_bake.py) and the finished state (no bake running, every cube map exact). The
window is closed once it is finished (or at ``--timeout``).

    python -m lobeview.bench.cold_start                              # builtin:apartment, 1280x800
    python -m lobeview.bench.cold_start --scenes builtin:demo builtin:apartment --timeout 900

Wall-clock on a shared machine: the bake and the cube maps run on the CPU beside the window.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEFAULT_SCENES = ("builtin:apartment",)
POLL_SECONDS = 0.1


def _say(text: str) -> None:
    print(f"[cold start] {text}", file=sys.stderr, flush=True)


def events(log: list[tuple[float, dict]]) -> dict:
    """The start-up's milestones from the frame log, each line with the seconds since launch at
    which it was seen: the first frame (its own state, bake and cube-map build), the first frame
    with no bake running after one ran (None: no bake ran, or it did not end), and the first frame
    with no bake, cube-map build or horizon-map worker running (None: not reached); ``swap_pause_s``: the
    seconds between the last frame drawn during the bake and the first after it (None: no swap)."""
    if not log:
        return {"first_frame_s": None, "baked_s": None, "swap_pause_s": None, "finished_s": None, "frames": 0}
    first_seen, first = log[0]
    baking = False
    baked = finished = swap_pause = None
    previous_seen = first_seen
    for seen, record in log:
        bake, cubes, horizons = record.get("background_bake"), record.get("cube_build"), record.get("horizon_maps")
        if bake is not None:
            baking = True
        elif baking and baked is None:
            baked, swap_pause = seen, seen - previous_seen
        idle = bake is None and cubes is None and horizons is None
        if idle and finished is None and (baked is not None or not baking):
            finished = seen
        previous_seen = seen
    return {
        "first_frame_s": first_seen,
        "first_frame_window_s": first.get("t"),
        "first_frame_bake": first.get("background_bake"),
        "first_frame_cube_build": first.get("cube_build"),
        "first_frame_state": first.get("state"),
        "baked_s": baked,
        "swap_pause_s": swap_pause,
        "finished_s": finished,
        "frames": len(log),
    }


def cold_start(scene: str, size: tuple[int, int], timeout: float, display: str, work: Path) -> dict:
    """Launch the viewer on ``scene`` with an empty cache and watch its frame log until the finished
    state or ``timeout`` seconds; the process and its bake worker are then stopped (SIGTERM to
    its process group, SIGKILL after 30 s)."""
    cache = work / f"cache-{scene.replace(':', '_')}"
    cache.mkdir()
    stats = work / f"frames-{scene.replace(':', '_')}.jsonl"
    command = [sys.executable, "-m", "lobeview", "view", scene, "--size", f"{size[0]}x{size[1]}", "--no-vsync",
               "--cache", str(cache), "--stats", str(stats)]  # fmt: skip
    _say(f"{scene}: {' '.join(command[3:])}")
    log: list[tuple[float, dict]] = []
    err = (work / "stderr.txt").open("w")
    t0 = time.perf_counter()
    # its own process group: the bake worker it spawns goes with it at the end
    process = subprocess.Popen(command, env={**os.environ, "DISPLAY": display}, stdout=subprocess.DEVNULL,
                               stderr=err, start_new_session=True)  # fmt: skip
    offset = 0
    try:
        while time.perf_counter() - t0 < timeout:
            if stats.exists():
                with stats.open() as handle:
                    handle.seek(offset)
                    chunk = handle.read()
                complete = chunk[: chunk.rfind("\n") + 1]
                offset += len(complete)
                seen = time.perf_counter() - t0
                log += [(seen, json.loads(line)) for line in complete.splitlines() if line.strip()]
                found = events(log)
                if found["finished_s"] is not None:
                    break
            if process.poll() is not None:
                break
            time.sleep(POLL_SECONDS)
    finally:
        for sent in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(process.pid, sent)
            except ProcessLookupError:
                break
            try:
                process.wait(timeout=30)
                break
            except subprocess.TimeoutExpired:
                continue
        err.close()
    result = events(log)
    result.update(scene=scene, size=list(size), timeout_s=timeout, exit_code=process.returncode,
                  stderr_tail=(work / "stderr.txt").read_text()[-2000:])  # fmt: skip
    return result


def _progress(value) -> str:
    """The frame log's cube-map progress ([done, total]) or bake status as the table says it."""
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return f"cube map {value[0]} of {value[1]}"
    return str(value)


def _seconds(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def markdown(results: list[dict], device: str, stamp: str, command: str) -> str:
    lines = [
        f"# Cold start of the viewer {stamp}",
        "",
        f"`{command}`; {device}; {os.cpu_count()} CPU cores. `lobeview view SCENE` from an empty cache folder, "
        "seconds since the process was launched at which the window's frame log showed: its first frame (what "
        "it drew it with), the baked scene swapped in, the pause of the view at that swap (from the last frame "
        "drawn during the bake), the finished state (no bake, every cube map exact).",
        "",
        "| scene | size | first frame s | first frame: bake / cube maps | baked scene in s | pause at the swap s "
        "| finished s | frames |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        bake, cubes = r.get("first_frame_bake"), r.get("first_frame_cube_build")
        how = f"{'baked' if bake is None else _progress(bake)} / {'exact' if cubes is None else _progress(cubes)}"
        finished = _seconds(r["finished_s"]) if r["finished_s"] is not None else f"not within {r['timeout_s']:.0f}"
        lines.append(
            f"| {r['scene']} | {r['size'][0]}x{r['size'][1]} | {_seconds(r['first_frame_s'])} | {how} "
            f"| {_seconds(r['baked_s'])} | {_seconds(r.get('swap_pause_s'))} | {finished} | {r['frames']} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from lobeview.bench.soak import x_display
    from lobeview.core.errors import parse_size

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.cold_start", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="+", default=list(DEFAULT_SCENES), help="scenes (default builtin:apartment)")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds to wait for the finished state (900)")
    p.add_argument("--size", type=parse_size, default=(1280, 800), help="window size WxH (default 1280x800)")
    p.add_argument("--out", help="Markdown report or a folder for cold-start-STAMP.md (default bench/results; + .json)")
    args = p.parse_args(argv)
    size = args.size
    server, display = x_display(size)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path(__file__).parent / "results"
    if out.is_dir() or not out.suffix:  # a folder: the stamped name in it
        out = out / f"cold-start-{stamp}.md"
    results = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for scene in args.scenes:
                work = Path(tmp) / scene.replace(":", "_")
                work.mkdir()
                results.append(cold_start(scene, size, args.timeout, display, work))
                r = results[-1]
                _say(f"{scene}: first frame {_seconds(r['first_frame_s'])} s, baked {_seconds(r['baked_s'])} s "
                     f"(paused {_seconds(r['swap_pause_s'])} s), finished {_seconds(r['finished_s'])} s")  # fmt: skip
    finally:
        if server is not None:
            server.terminate()
    from lobeview.viewer.context import create_headless_context, renderer_description

    ctx = create_headless_context()
    device = renderer_description(ctx)
    ctx.release()
    command = "python -m lobeview.bench.cold_start " + " ".join(argv if argv is not None else sys.argv[1:])
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(markdown(results, device, stamp, command.strip()))
    out.with_suffix(".json").write_text(json.dumps(results, indent=1))
    print(out.read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
