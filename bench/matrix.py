"""``lobeview bench``: run time against error for every method, proven in one run.

A matrix of methods x materials x views x resolutions. Per cell: time per frame (GPU timer
query around the shading pass where the driver has one, wall clock around glFinish otherwise;
median of repeated frames after a warm-up), error against the converged ``reference`` (relative
RMSE of linear radiance, PSNR of the tonemapped 8-bit image, mean FLIP of the tonemapped image)
on the view-dependent pixels, and the GPU memory the method reads. Then a sweep of the MIP-level
bias of fis-N and lobe-N, a thesis-style fps table (tables 4.1/4.2), Markdown + JSON + PNG plots
with the Pareto front marked. ``lobeview bench stress`` runs the numerical stress suite instead.
"""

from __future__ import annotations

import datetime
import functools
import json
import sys
import time
import warnings
from pathlib import Path

from lobeview.core.methods import Method
from lobeview.core.paths import bench_results_dir
from lobeview.viewer.context import gpu_timer_meaningful

from . import BenchError
from .matrix_config import (
    FPS_SAMPLES,
    FULL_METHODS,
    FULL_VIEWS,
    MATERIAL_CLASSES,
    QUICK_FPS_SAMPLES,
    QUICK_MATERIALS,
    QUICK_METHODS,
    QUICK_SWEEP_BIASES,
    QUICK_SWEEP_METHODS,
    QUICK_VIEWS,
    SWEEP_BIASES,
    SWEEP_METHODS,
)
from .metrics import make_reference
from .report import write_markdown, write_plots
from .targets import DemoTarget, SphereTarget, parse_method, resolve_environment, time_frames


# -- the run -------------------------------------------------------------------------------------------
class Progress:
    def __init__(self, total: int):
        self.total = max(total, 1)
        self.done = 0
        self.t0 = time.perf_counter()

    def step(self, text: str) -> None:
        self.done += 1
        elapsed = time.perf_counter() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        print(
            f"[bench {self.done}/{self.total}, {elapsed:.0f} s, ~{eta:.0f} s left] {text}", file=sys.stderr, flush=True
        )


def _settings(args) -> dict:
    from lobeview.core.errors import parse_size

    quick = args.quick
    methods = list(QUICK_METHODS if quick else FULL_METHODS) if args.methods is None else args.methods
    for m in methods:
        parse_method(m)
    materials = args.materials or list(QUICK_MATERIALS if quick else MATERIAL_CLASSES.values())
    from lobeview.materials.spec import load_material

    for m in materials:
        load_material(m)  # MaterialError for unknown presets before anything renders
    views = args.views or list(QUICK_VIEWS if quick else FULL_VIEWS)
    for v in views:
        kind, _, name = v.partition("/")
        if kind not in ("sphere", "demo") or not name:
            raise BenchError(f"--views: expected sphere/ENV or demo/CAMERA, got {v!r}")
    resolutions = [parse_size(r) for r in (args.resolutions or (["320x200"] if quick else ["640x400", "1680x1050"]))]
    if args.error_resolutions == ["none"]:
        error_resolutions = []
    elif args.error_resolutions:
        error_resolutions = [parse_size(r) for r in args.error_resolutions]
    else:
        error_resolutions = resolutions
    fps_size = args.fps_size or ("640x400" if quick else "1680x1050")
    if args.repeats < 1:
        raise BenchError("--repeats must be at least 1")
    spp = args.reference_spp or (256 if quick else 1024)
    if spp < 2:
        raise BenchError("--reference-spp must be at least 2")
    sweep_biases = (
        list(QUICK_SWEEP_BIASES if quick else SWEEP_BIASES) if args.sweep_biases is None else args.sweep_biases
    )
    sweep_methods = (
        args.sweep_methods if args.sweep_methods is not None else list(QUICK_SWEEP_METHODS if quick else SWEEP_METHODS)
    )
    for m in sweep_methods:
        if parse_method(m).kind not in ("lobe", "fis"):
            raise BenchError(f"--sweep-methods: only lobe-N and fis-N have a LOD bias, got {m!r}")
    return {
        "methods": methods,
        "materials": materials,
        "views": views,
        "resolutions": resolutions,
        "error_resolutions": error_resolutions,
        "fps_size": None if fps_size == "none" else parse_size(fps_size),
        "fps_samples": list(QUICK_FPS_SAMPLES if quick else FPS_SAMPLES),
        "reference_spp": spp,
        "sweep_biases": sweep_biases,
        "sweep_methods": sweep_methods,
        "repeats": args.repeats,
        "face_size": args.face_size,
    }


def run_matrix_command(args) -> int:
    """``lobeview bench [matrix]``: the matrix, the LOD-bias sweep and the fps table."""
    from lobeview.viewer.context import create_headless_context, renderer_description

    out_dir = Path(args.out) if args.out else bench_results_dir()
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    settings = _settings(args)
    ctx = create_headless_context()
    device = renderer_description(ctx)
    settings["timer"] = "gpu" if gpu_timer_meaningful(device) else "wall"
    print(f"lobeview bench on {device} (timing: {settings['timer']} clock)", file=sys.stderr, flush=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    checkpoint = out_dir / f"bench-{stamp}.partial.json"
    cells, sweep, references = run_matrix(ctx, settings, args.cache, checkpoint)
    fps_rows = run_fps_table(ctx, settings) if settings["fps_size"] else []
    ctx.release()
    base = out_dir / f"bench-{stamp}"
    meta = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "device": device,
        "quick": bool(args.quick),
        "command": "lobeview " + " ".join(sys.argv[1:])
        if sys.argv and sys.argv[0].endswith(("lobeview", "__main__.py"))
        else "",
        "settings": dict(settings),
    }
    data = {"meta": meta, "cells": cells, "sweep": sweep, "references": references, "fps": fps_rows}
    base.with_suffix(".json").write_text(json.dumps(data, indent=1, default=float))
    plots = write_plots(base, cells, sweep, references)
    write_markdown(base.with_suffix(".md"), data, plots)
    checkpoint.unlink(missing_ok=True)
    print(f"wrote {base.with_suffix('.md')}, {base.with_suffix('.json')} and {len(plots)} plots", flush=True)
    return 0


def run_report_command(source: Path) -> int:
    """``lobeview bench report JSON``: rewrite the Markdown and plots of an earlier run (no rendering)."""
    try:
        data = json.loads(Path(source).read_text())
        data["meta"]["settings"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise BenchError(f"--report: {source} is not a lobeview bench JSON ({exc})") from None
    base = Path(source).with_suffix("")
    plots = write_plots(base, data["cells"], data["sweep"], data["references"])
    write_markdown(base.with_suffix(".md"), data, plots)
    print(f"wrote {base.with_suffix('.md')} and {len(plots)} plots")
    return 0


def _targets(ctx, view: str, size, settings, cache):
    kind, _, name = view.partition("/")
    if kind == "sphere":
        return SphereTarget(ctx, name, size, settings["face_size"]), settings["materials"]
    return DemoTarget(ctx, name, size, settings["face_size"], cache), ["scene"]


def run_matrix(ctx, settings, cache, checkpoint: Path | None = None):
    n_views_materials = sum(len(settings["materials"]) if v.startswith("sphere") else 1 for v in settings["views"])
    per_cell = len(settings["methods"]) + 1
    sweep_cells = len(settings["sweep_methods"]) * len(settings["sweep_biases"])
    total = (
        n_views_materials * len(settings["resolutions"]) * per_cell
        + sum(len(settings["materials"]) for v in settings["views"] if v.startswith("sphere")) * sweep_cells
    )
    progress = Progress(total)
    cells, sweep, references = [], [], []
    sweep_resolution = settings["error_resolutions"][0] if settings["error_resolutions"] else None
    for view in settings["views"]:
        target = None
        for size in settings["resolutions"]:
            if target is None:
                target, materials = _targets(ctx, view, size, settings, cache)
            else:
                target.renderer.resize(size)
            label = f"{size[0]}x{size[1]}"
            for material in materials:
                target.set_material(material)
                reference = None
                if size in settings["error_resolutions"]:
                    reference = make_reference(target.render, target.mask_of, settings["reference_spp"])
                    references.append(
                        {
                            "view": view,
                            "material": material,
                            "resolution": label,
                            "seconds": reference.seconds,
                            "spp": reference.spp,
                            "psnr_floor": reference.psnr_floor,
                            "rel_rmse_floor": reference.rel_rmse_floor,
                            "view_dependent_fraction": float(reference.mask.mean()),
                            "environment": target.env_label,
                        }
                    )
                    progress.step(
                        f"{view} {material} {label}: reference {reference.spp} spp in {reference.seconds:.1f} s,"
                        f" floor {reference.psnr_floor:.1f} dB"
                    )
                else:
                    progress.step(f"{view} {material} {label}: timing only")
                for text in settings["methods"]:
                    method = parse_method(text)
                    result, ms, gpu_ms, wall_ms, first_s = time_frames(
                        functools.partial(target.render, method), settings["repeats"], settings["timer"]
                    )
                    cell = {
                        "view": view,
                        "material": material,
                        "resolution": label,
                        "method": text,
                        "ms": ms,
                        "gpu_ms": gpu_ms,
                        "wall_ms": wall_ms,
                        "memory_mb": target.memory(method) / 2**20,
                        # first use: shader compilation, and for prefiltered the fits and maps
                        # (built, or read from the --cache folder when an earlier run made them)
                        "first_frame_s": first_s,
                        "lod_bias": method.default_lod_bias() if method.kind in ("lobe", "fis") else None,
                    }
                    if reference is not None:
                        cell.update(reference.errors(result.radiance))
                        cell["invalid_pixels"] = int(result.invalid.sum())
                    cells.append(cell)
                    _checkpoint(checkpoint, cells, sweep, references)
                    err = f" PSNR {cell['psnr']:.2f} dB relRMSE {cell['rel_rmse']:.4f}" if reference else ""
                    progress.step(f"{view} {material} {label} {text}: {cell['ms']:.1f} ms{err}")
                if reference is not None and size == sweep_resolution and view.startswith("sphere"):
                    for text in settings["sweep_methods"]:
                        method = parse_method(text)
                        for bias in settings["sweep_biases"]:
                            result = target.render(method, lod_bias=bias)
                            row = {"view": view, "material": material, "method": text, "bias": bias}
                            row.update(reference.errors(result.radiance))
                            sweep.append(row)
                            _checkpoint(checkpoint, cells, sweep, references)
                            progress.step(f"sweep {view} {material} {text} bias {bias:+.1f}: PSNR {row['psnr']:.2f} dB")
        if target is not None:
            target.release()
    return cells, sweep, references


def _checkpoint(path: Path | None, cells, sweep, references) -> None:
    """Everything measured so far, rewritten after every cell: a long run that fails late (a
    driver crash, a killed job) keeps its numbers."""
    if path is not None:
        path.write_text(json.dumps({"cells": cells, "sweep": sweep, "references": references}, default=float))


def run_fps_table(ctx, settings) -> list[dict]:
    """Thesis tables 4.1/4.2: lobe-N frame times with the whole frame, and about half of it,
    covered by view-dependent pixels (a glossy plane facing the camera; the other half is
    background, which costs about what the thesis' purely diffuse half costs)."""
    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.scenes.meshes import quad
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.preview import PreviewRenderer

    size = settings["fps_size"]
    camera = Camera(position=(0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), fov_y=60.0)
    bsdf = build_bsdf(load_material("alanod-2000gs-1lobe"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = resolve_environment("interior")
    planes = {
        "full": quad([-20.0, -20.0, 0.0], [40.0, 0.0, 0.0], [0.0, 40.0, 0.0]),
        "half": quad([-20.0, -20.0, 0.0], [20.0, 0.0, 0.0], [0.0, 40.0, 0.0]),  # x < 0: the left half
    }
    rows = {n: {"samples": n} for n in settings["fps_samples"]}
    print(f"[fps] {size[0]}x{size[1]}, lobe-N for N in {settings['fps_samples']}", file=sys.stderr, flush=True)
    for coverage, mesh in planes.items():
        renderer = PreviewRenderer(ctx, env, mesh, size=size, face_size=settings["face_size"])
        for n in settings["fps_samples"]:
            method = Method("lobe", n)
            result, ms, _, wall_ms, _ = time_frames(
                functools.partial(renderer.render, camera, bsdf, method, background=False),
                settings["repeats"],
                settings["timer"],
            )
            rows[n][coverage] = {"ms": ms, "wall_ms": wall_ms, "fraction": float(result.mask.mean())}
            print(f"[fps] {coverage} lobe-{n}: {ms:.1f} ms ({1000 / ms:.1f} fps)", file=sys.stderr, flush=True)
        renderer.release()
    return list(rows.values())
