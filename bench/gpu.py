"""The thesis' tables on whatever GPU runs it (issue 42 item 3), prepared for the moment one is lent.

    python -m lobeview.bench.gpu --out DIR            # full sizes: 1680x1050 (a GPU: minutes)
    python -m lobeview.bench.gpu --small --out DIR    # llvmpipe sizes (what tests/test_bench_gpu.py runs)
    bash bench/gpu_device.sh                          # on a lent GPU machine (see bench/README.md)

One Markdown (``gpu-STAMP.md``) with, on the device it names:
- Table 4.1: lobe-N (N = 3, 7, 11, 19) frame times with a glossy plane covering the whole frame
  and half of it (bench/matrix.py run_fps_table, the preview renderer), GPU timer where the
  driver's is meaningful;
- Table 4.2: planar mirror passes (bench/mirrors.py: 0 / 1 / 2 reflectors, the mirror passes alone
  and the whole frame), its own Markdown beside this one;
- the CPU's cost of a frame against the scene's size, per-object draws against the multi-draws
  (bench/draw_cost.py), its own Markdown beside this one;
- the apartment along its recorded path and the cost against object count (bench/walkthrough.py),
  its own Markdown beside this one.
Each part is timed and a failing part is reported in the summary without stopping the others; the
summary is rewritten after every part, so a lease that ends early keeps what was measured. The
parts run in order of what a lease must not miss: the timings first, the mirrors' ray-traced
refinement (a CPU measurement, bench/mirrors.py) only in the small plan.

The first lease (bench/results/gpu-20261126-210515.md, an H200) timed out at 540 s: the mirrors'
refinement against the CPU ray tracer took 290 s of it, and the bakes (CPU) another 130 s.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
import traceback
from pathlib import Path

# The real-time methods' cost on the preview sphere (issue 45: what lobe-N+norm+fit's fitted reads
# cost beside the thesis pattern and the other methods, where llvmpipe's numbers say little).
METHODS = ("lobe-7", "lobe-7+norm", "lobe-7+norm+fit", "lobe-15+norm", "lobe-15+norm+fit", "fis-16", "prefiltered",
           "prefiltered-rsibr")  # fmt: skip
FULL = {"size": (1680, 1050), "fps_samples": (3, 7, 11, 19), "mirror_sizes": ((1680, 1050),),
        "mirror_samples": (3, 7, 11, 19), "walk_size": (1680, 1050), "frames": 24, "rooms": 12,
        "count_rooms": (1, 18), "draw_sizes": ((64, 40), (160, 100), (1680, 1050)), "draw_frames": 16,
        "face_size": 256, "repeats": 9, "spp": 256, "refinement": False,
        "method_materials": ("ggx:0.3", "beckmann:0.15"), "methods": METHODS}  # fmt: skip
SMALL = {"size": (160, 100), "fps_samples": (3, 7), "mirror_sizes": ((160, 100),), "mirror_samples": (3,),
         "walk_size": (160, 100), "frames": 3, "rooms": 1, "count_rooms": (1,), "draw_sizes": ((64, 40),),
         "draw_frames": 3, "face_size": 32, "repeats": 1, "spp": 16, "refinement": True,
         "method_materials": ("ggx:0.3",), "methods": ("lobe-7+norm", "lobe-7+norm+fit")}  # fmt: skip
PARTS = ("fps", "methods", "draw-cost", "walkthrough", "mirrors")  # in order of what a short lease must not miss


def _say(text: str) -> None:
    print(f"[gpu bench] {text}", file=sys.stderr, flush=True)


def fps_rows(ctx, plan: dict, timer: str) -> list[str]:
    from .matrix import run_fps_table
    from .matrix_config import THESIS_FPS  # the thesis' GTS 450, Table 4.1, full / half

    settings = {"fps_size": plan["size"], "fps_samples": list(plan["fps_samples"]), "face_size": plan["face_size"],
                "repeats": plan["repeats"], "timer": timer}  # fmt: skip
    lines = [
        f"## Table 4.1: lobe-N, {plan['size'][0]}x{plan['size'][1]}, glossy plane over the whole / half frame",
        "",
        "| N | full ms | full fps | half ms | half fps | thesis GTS 450 fps full / half | wall ms full / half |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in run_fps_table(ctx, settings):
        full, half = row["full"]["ms"], row["half"]["ms"]
        thesis = THESIS_FPS.get(row["samples"])
        lines.append(
            f"| {row['samples']} | {full:.2f} | {1000 / full:.1f} | {half:.2f} | {1000 / half:.1f} | "
            f"{'-' if thesis is None else f'{thesis[0]} / {thesis[1]}'} "
            f"| {row['full']['wall_ms']:.2f} / {row['half']['wall_ms']:.2f} |"
        )
    return lines


def method_rows(ctx, plan: dict, timer: str) -> list[str]:
    """Frame time of each method in ``plan['methods']`` on a sphere that fills the frame's height
    (camera 2.2 units from a unit sphere, fov 60) under the interior capture, its bright sources
    separated as the viewer does, per material (``bench.mitsuba`` case names)."""
    import warnings

    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.preview import PreviewRenderer

    from .light import build_material
    from .targets import resolve_environment, time_frames

    size = plan["size"]
    camera = Camera(position=(0.0, 0.0, 2.2), target=(0.0, 0.0, 0.0), fov_y=60.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = resolve_environment("interior")
        renderer = PreviewRenderer(ctx, env, uv_sphere(1.0), size=size, face_size=plan["face_size"],
                                   bright_sources=True)  # fmt: skip
    lines = [
        f"## The methods on a sphere, {size[0]}x{size[1]}, interior capture with its lights separated",
        "",
        "| material | method | ms | fps | wall ms | sphere share of the frame |",
        "|---|---|---|---|---|---|",
    ]
    try:
        for case in plan["method_materials"]:
            bsdf = build_material(case)
            for method in plan["methods"]:
                result, ms, _, wall_ms, _ = time_frames(
                    functools.partial(renderer.render, camera, bsdf, method, background=False),
                    plan["repeats"],
                    timer,
                )
                lines.append(f"| {case} | {method} | {ms:.2f} | {1000 / ms:.1f} | {wall_ms:.2f} "
                             f"| {float(result.mask.mean()):.2f} |")  # fmt: skip
                _say(f"methods: {case} {method}: {ms:.2f} ms")
    finally:
        renderer.release()
    return lines


def main(argv: list[str] | None = None) -> int:
    from lobeview.core.paths import cache_dir
    from lobeview.viewer.context import create_headless_context, gpu_timer_meaningful, renderer_description

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.gpu", description=__doc__.split("\n\n")[0])
    p.add_argument("--small", action="store_true", help="llvmpipe sizes (seconds to minutes on a CPU)")
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS), help="which tables (default all)")
    results = str(Path(__file__).parent / "results")
    p.add_argument("--out", default=results, help="output folder (default bench/results)")
    p.add_argument("--cache", help="cache folder for scenes and cube maps (default ~/.cache/lobeview)")
    args = p.parse_args(argv)
    plan = SMALL if args.small else FULL
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    ctx = create_headless_context()
    device = renderer_description(ctx)
    timer = "gpu" if gpu_timer_meaningful(device) else "wall"
    _say(f"{device}; {'small' if args.small else 'full'} sizes; timing by the {timer} clock")
    summary = [
        f"# GPU bench {stamp}",
        "",
        f"Device: {device}. Sizes: {'small (llvmpipe check)' if args.small else 'full (the thesis tables)'}; "
        f"timing: {timer} clock; cube faces {plan['face_size']}^2; `python -m lobeview.bench.gpu"
        f"{' --small' if args.small else ''}`.",
        "",
    ]
    parts = {
        "fps": lambda: fps_rows(ctx, plan, timer),
        "methods": lambda: method_rows(ctx, plan, timer),
        "mirrors": lambda: _mirrors(ctx, device, out, stamp, plan),
        "draw-cost": lambda: _draw_cost(ctx, device, out, stamp, plan, cache_dir(args.cache)),
        "walkthrough": lambda: _walkthrough(ctx, device, out, stamp, plan, cache_dir(args.cache), args.small),
    }
    failed = 0
    path = out / f"gpu-{stamp}.md"
    for name in sorted(args.parts, key=PARTS.index):
        t0 = time.perf_counter()
        _say(f"{name} ...")
        try:
            summary += parts[name]()
            summary.append(f"\n({name}: {time.perf_counter() - t0:.0f} s)\n")
        except Exception:  # one failing part must not cost the others on a short lease
            failed += 1
            summary += [f"## {name}: FAILED after {time.perf_counter() - t0:.0f} s", "", "```",
                        traceback.format_exc()[-3000:], "```", ""]  # fmt: skip
            _say(f"{name} failed:\n{traceback.format_exc()}")
        path.write_text("\n".join(summary) + "\n")  # after every part: a lease may end before the next
    ctx.release()
    print("\n".join(summary))
    _say(f"wrote {path}")
    return 1 if failed else 0


def _mirrors(ctx, device: str, out: Path, stamp: str, plan: dict) -> list[str]:
    from .mirrors import run_mirror_bench

    path = run_mirror_bench(ctx, device, out, stamp, list(plan["mirror_sizes"]), list(plan["mirror_samples"]),
                            plan["repeats"], plan["spp"], refinement=plan["refinement"])  # fmt: skip
    return ["## Table 4.2: planar mirror passes", "", f"[{path.name}]({path.name})", ""]


def _draw_cost(ctx, device: str, out: Path, stamp: str, plan: dict, cache: Path) -> list[str]:
    from .draw_cost import markdown, measure

    t0 = time.perf_counter()
    runs = []
    for rooms in plan["count_rooms"]:
        runs += measure(ctx, rooms, list(plan["draw_sizes"]), plan["draw_frames"], cache, "lobe-7")
    path = out / f"draw-cost-{stamp}.md"
    path.write_text(markdown(runs, device, "lobe-7", plan["draw_frames"], time.perf_counter() - t0))
    return ["## The CPU's cost of a frame against the scene's size", "", f"[{path.name}]({path.name})", ""]


def _walkthrough(ctx, device: str, out: Path, stamp: str, plan: dict, cache: Path, small: bool) -> list[str]:
    from .walkthrough import run_walkthrough_bench

    path = run_walkthrough_bench(
        ctx, device, out, stamp, size=plan["walk_size"], frames=plan["frames"], method="lobe-7",
        face_size=plan["face_size"], rooms=plan["rooms"], count_rooms=plan["count_rooms"],
        count_frames=plan["frames"], cache=cache, quick=small,
    )  # fmt: skip
    return ["## The apartment's path and the cost against object count", "", f"[{path.name}]({path.name})", ""]


if __name__ == "__main__":
    raise SystemExit(main())
