"""``lobeview bench [matrix|stress|mirrors|walkthrough|report]``: the command line of the benchmark package
(bench/, ``lobeview.bench``): options, then the chosen mode. The measuring lives there."""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path

from lobeview.bench import BenchError
from lobeview.bench.matrix_config import FULL_VIEWS, MATERIAL_CLASSES, SWEEP_BIASES, SWEEP_METHODS
from lobeview.core.paths import bench_results_dir

__all__ = ["BenchError", "add_arguments", "run"]
MODES = ("matrix", "stress", "mirrors", "walkthrough", "light", "report")


def add_arguments(p) -> None:
    p.usage = "lobeview bench [matrix|stress|mirrors|walkthrough|light|report JSON] [options]  (the mode first)"
    a = p.add_argument
    a(
        "mode",
        nargs="?",
        choices=MODES,
        default="matrix",
        help="matrix (default): time against error for every method; stress: the numerical stress grid;"
        " mirrors: planar mirror passes (0/1/2 reflectors x --resolutions); walkthrough: the demo and the"
        " apartment along their recorded paths, and cost against object count; light: preview spheres under"
        " the HDR captures with and without bright-source separation; report JSON: rewrite a run's"
        " Markdown and plots",
    )
    a("source", nargs="?", metavar="JSON", help="report: the run's JSON")
    a("--quick", action="store_true", help="a small subset that runs in a few minutes on a 2-core CPU")
    a("--stress", action="store_true", help=argparse.SUPPRESS)  # before the subcommands: same as 'stress'
    a("--mirrors", action="store_true", help=argparse.SUPPRESS)  # same as 'mirrors'

    a("--mirror-samples", nargs="+", type=int, help="lobe-N sample counts of --mirrors (default 3 7 11 15 19)")
    a("--methods", nargs="*", help="methods (lobe-N, lobe-N+norm, fis-N, mc-N, prefiltered[-MODE])")
    a("--materials", nargs="+", help=f"presets (default: one per class: {', '.join(MATERIAL_CLASSES.values())})")
    a(
        "--views",
        nargs="+",
        help="sphere/ENV (ENV: interior, courtyard, city, builtin:NAME or a file) and demo/CAMERA "
        f"(overview, table); default {' '.join(FULL_VIEWS)}",
    )
    a("--resolutions", nargs="+", help="WxH sizes (default 640x400 1680x1050; --quick 320x200)")
    a(
        "--error-resolutions",
        nargs="+",
        help="sizes at which errors are measured against a reference (default: all; 'none': timing only)",
    )
    a("--repeats", type=int, default=3, help="timed frames per cell after one warm-up (default 3)")
    a("--reference-spp", type=int, help="reference samples per lobe (default 1024; --quick 256)")
    a(
        "--supersample",
        type=int,
        help="light: real-time methods at this many times the size, averaged, so that they and the box-filtered "
        "reference integrate the same pixels (default 4; 1 shades pixel centres)",
    )
    a("--after-only", action="store_true", help="light: only the renders with the bright sources separated")
    a("--sweep-biases", nargs="*", type=float, help=f"LOD biases of the sweep (default {list(SWEEP_BIASES)})")
    a("--sweep-methods", nargs="*", help=f"methods of the LOD-bias sweep (default {' '.join(SWEEP_METHODS)})")
    a("--fps-size", help="fps table resolution (default 1680x1050; --quick 640x400); 'none' skips it")
    a("--face-size", type=int, default=256, help="cube-map face resolution (default 256)")
    a("--cache", help="cache folder for the demo scene and cube maps (default ~/.cache/lobeview)")
    a("--report", metavar="JSON", help=argparse.SUPPRESS)  # same as 'report JSON'

    a("--frames", type=int, help="walkthrough: frames along each path (default 24; --quick 8)")
    a("--rooms", type=int, help="walkthrough: rooms of the apartment walked (default 12; --quick 6)")
    a(
        "--count-rooms",
        nargs="+",
        type=int,
        help="walkthrough: apartment sizes of the object-count table (default 1 6 18; --quick 1 4)",
    )
    a(
        "--cube-budget",
        type=float,
        metavar="MB",
        help="walkthrough: cube-map memory budget of the budget walk over the apartment's path (default 128)",
    )
    a("--out", help="output folder (default bench/results); files are timestamped, never overwritten")


def run(args) -> int:
    mode = args.mode
    for flag, flagged in (("stress", args.stress), ("mirrors", args.mirrors), ("report", args.report)):
        if flagged:
            if mode != "matrix":
                raise BenchError(f"--{flag} and the mode {mode!r} contradict each other")
            mode = flag
    source = args.report or args.source
    if args.source is not None and mode != "report":
        raise BenchError(f"{args.source!r}: only the report mode takes a JSON file")
    out_dir = Path(args.out) if args.out else bench_results_dir()
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    if mode == "report":
        if source is None:
            raise BenchError("report: give the JSON of a run (lobeview bench report bench/results/bench-STAMP.json)")
        from lobeview.bench.matrix import run_report_command

        return run_report_command(Path(source))
    if mode == "stress":
        from lobeview.bench.stress import run_stress_command

        return run_stress_command(args, out_dir, stamp)
    if mode == "mirrors":
        from lobeview.bench.mirrors import run_mirrors_command

        return run_mirrors_command(args, out_dir, stamp)
    if mode == "light":
        from lobeview.bench.light import run_light_command

        return run_light_command(args, out_dir, stamp)
    if mode == "walkthrough":
        from lobeview.bench.walkthrough import run_walkthrough_command

        return run_walkthrough_command(args, out_dir, stamp)
    from lobeview.bench.matrix import run_matrix_command

    return run_matrix_command(args)
