"""``lobeview bench``: run time against error for every method, proven in one run.

A matrix of methods x materials x views x resolutions. Per cell: time per frame (GPU timer
query around the shading pass where the driver has one, wall clock around glFinish otherwise;
median of repeated frames after a warm-up), error against the converged ``reference`` (relative
RMSE of linear radiance, PSNR of the tonemapped 8-bit image, mean FLIP of the tonemapped image)
on the view-dependent pixels, and the GPU memory the method reads. Then a sweep of the MIP-level
bias of fis-N and lobe-N, a thesis-style fps table (tables 4.1/4.2), Markdown + JSON + PNG plots
with the Pareto front marked. ``--stress`` runs the numerical stress suite instead.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.core.methods import DEFAULT_FIS_LOD_BIAS, DEFAULT_LOBE_LOD_BIAS, Method
from lobeview.core.paths import bench_results_dir, shared_assets_dir
from lobeview.viewer.context import gpu_timer_meaningful

#: material classes of the issue -> presets
MATERIAL_CLASSES = {
    "near-mirror": "chrome",
    "very glossy": "lacquer",
    "glossy": "alanod-2000gs-1lobe",
    "glossy GGX": "gold-ggx",
    "anisotropic": "miro5-2lobe",
    "transmissive": "frosted-glass",
}
QUICK_MATERIALS = ("chrome", "alanod-2000gs-1lobe", "frosted-glass")
FULL_METHODS = (
    "lobe-3",
    "lobe-5",
    "lobe-7",
    "lobe-11",
    "lobe-15",
    "lobe-19",
    "lobe-7+norm",
    "lobe-15+norm",
    "fis-8",
    "fis-16",
    "fis-32",
    "fis-64",
    "mc-16",
    "mc-64",
    "prefiltered",
    "prefiltered-lobe2d",
    "prefiltered-phong",
)
QUICK_METHODS = ("lobe-3", "lobe-7", "lobe-15", "fis-8", "fis-32", "mc-16", "prefiltered")
FULL_VIEWS = ("sphere/interior", "sphere/courtyard", "demo/table", "demo/overview")
QUICK_VIEWS = ("sphere/interior",)
SWEEP_BIASES = (-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
SWEEP_METHODS = ("fis-16", "fis-64", "lobe-7", "lobe-15")
QUICK_SWEEP_BIASES = (-1.0, 0.0, 1.0)
QUICK_SWEEP_METHODS = ("fis-16", "lobe-7")
FPS_SAMPLES = (3, 5, 7, 9, 11, 13, 15, 17, 19)
QUICK_FPS_SAMPLES = (3, 7, 11, 19)
#: thesis table 4.1 (cube-map method, GTS 450, 1680x1050): samples -> (full, half) fps
THESIS_FPS = {3: (70, 95), 5: (52, 75), 7: (41, 60), 9: (35, 52), 11: (30, 43), 13: (26, 40), 15: (24, 35)}
THESIS_FPS.update({17: (22, 31), 19: (20, 28)})
SHARED_ASSETS = shared_assets_dir()  # None outside a checkout: sphere views fall back to built-in skies
SHARED_ENV_DIR = SHARED_ASSETS / "env" if SHARED_ASSETS is not None else None
SPHERE_ENVS = {
    "interior": ("blender_studiolights_1k/interior.exr", "builtin:studio"),
    "courtyard": ("blender_studiolights_1k/courtyard.exr", "builtin:sky"),
    "city": ("blender_studiolights_1k/city.exr", "builtin:overcast"),
}
PSNR_TARGETS = (40.0, 50.0)


class BenchError(ValueError):
    pass


def add_arguments(p) -> None:
    a = p.add_argument
    a("--quick", action="store_true", help="a small subset that runs in a few minutes on a 2-core CPU")
    a("--stress", action="store_true", help="run the numerical stress suite instead of the timing matrix")
    a(
        "--mirrors",
        action="store_true",
        help="time planar mirror passes (0/1/2 reflectors x --resolutions) instead of the matrix",
    )
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
    a("--sweep-biases", nargs="*", type=float, help=f"LOD biases of the sweep (default {list(SWEEP_BIASES)})")
    a("--sweep-methods", nargs="*", help=f"methods of the LOD-bias sweep (default {' '.join(SWEEP_METHODS)})")
    a("--fps-size", help="fps table resolution (default 1680x1050; --quick 640x400); 'none' skips it")
    a("--face-size", type=int, default=256, help="cube-map face resolution (default 256)")
    a("--cache", help="cache folder for the demo scene and cube maps (default ~/.cache/lobeview)")
    a("--report", metavar="JSON", help="rewrite the Markdown and plots of an earlier run from its JSON (no rendering)")
    a("--out", help="output folder (default bench/results); files are timestamped, never overwritten")


# -- metrics -------------------------------------------------------------------------------------------
def exposure_for(reference: np.ndarray, mask: np.ndarray) -> float:
    """Stops that map the reference's median luminance over the mask to 0.18."""
    luminance = reference[mask] @ np.array([0.2126, 0.7152, 0.0722])
    return float(np.log2(0.18 / max(float(np.median(luminance)), 1e-6)))


def psnr_8bit(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.round(a * 255) / 255 - np.round(b * 255) / 255) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((image - reference) ** 2)) / max(np.sqrt(np.mean(reference**2)), 1e-30))


def flip_error(test_ldr: np.ndarray, reference_ldr: np.ndarray, mask: np.ndarray) -> float:
    """Mean LDR-FLIP (NVIDIA's flip-evaluator, 67 pixels per degree) over the mask; the images
    are tonemapped sRGB in [0, 1]."""
    import flip_evaluator

    test = np.where(mask[..., None], test_ldr, reference_ldr).astype(np.float32)
    error_map, _, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference_ldr, np.float32), np.ascontiguousarray(test), "LDR", applyMagma=False
    )
    error_map = np.asarray(error_map)
    if error_map.ndim == 3:
        error_map = error_map[..., 0]
    return float(error_map[mask].mean())


@dataclasses.dataclass
class Reference:
    radiance: np.ndarray
    mask: np.ndarray
    exposure: float
    ldr: np.ndarray  # tonemapped sRGB in [0, 1]
    psnr_floor: float  # PSNR the reference's own noise allows (estimated from two halves)
    rel_rmse_floor: float
    seconds: float
    spp: int

    def errors(self, radiance: np.ndarray) -> dict:
        from lobeview.viewer.tonemap import tonemap

        ldr = np.clip(tonemap(radiance, "aces", self.exposure), 0.0, 1.0)
        return {
            "rel_rmse": relative_rmse(radiance[self.mask], self.radiance[self.mask]),
            "psnr": psnr_8bit(ldr[self.mask], self.ldr[self.mask]),
            "flip": flip_error(ldr, self.ldr, self.mask),
        }


def make_reference(render, mask_of, spp: int) -> Reference:
    """Mean of two independent half-sample references (seeds 0 and 1). Their difference
    estimates the reference's noise: with per-pixel variance s^2 of the full reference, the
    halves differ by variance 4 s^2, so the full reference lies ~6 dB closer to the truth than
    the two halves to each other (PSNR floor = PSNR(A, B) + 6.02 dB, relRMSE floor = relRMSE(A, B)/2)."""
    from lobeview.viewer.tonemap import tonemap

    t0 = time.perf_counter()
    half = max(spp // 2, 1)
    a = render(Method.parse("reference"), spp=half, seed=0)
    b = render(Method.parse("reference"), spp=half, seed=1)
    seconds = time.perf_counter() - t0
    mask = mask_of(a)
    radiance = 0.5 * (a.radiance + b.radiance)
    exposure = exposure_for(radiance, mask)
    ldr_a = np.clip(tonemap(a.radiance, "aces", exposure), 0, 1)
    ldr_b = np.clip(tonemap(b.radiance, "aces", exposure), 0, 1)
    return Reference(
        radiance=radiance,
        mask=mask,
        exposure=exposure,
        ldr=np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0),
        psnr_floor=psnr_8bit(ldr_a[mask], ldr_b[mask]) + 6.02,
        rel_rmse_floor=relative_rmse(a.radiance[mask], b.radiance[mask]) / 2.0,
        seconds=seconds,
        spp=2 * half,
    )


def pareto_front(times, errors) -> list[bool]:
    """True for the points no other point beats in both time and error (lower is better)."""
    times, errors = np.asarray(times, float), np.asarray(errors, float)
    front = []
    for i in range(len(times)):
        dominated = np.any((times <= times[i]) & (errors <= errors[i]) & ((times < times[i]) | (errors < errors[i])))
        front.append(not bool(dominated) and np.isfinite(errors[i]))
    return front


def interpolate_log(x_query: float, xs, ys) -> float:
    """y at x_query by linear interpolation in log x over the points sorted by x; NaN outside."""
    order = np.argsort(xs)
    xs, ys = np.log(np.asarray(xs, float)[order]), np.asarray(ys, float)[order]
    x = np.log(x_query)
    if len(xs) < 2 or x < xs[0] or x > xs[-1]:
        return float("nan")
    return float(np.interp(x, xs, ys))


def first_crossing(target: float, xs, ys) -> float:
    """Smallest x (log-linear between points sorted by x) at which y reaches ``target``; NaN if
    it never does. Used for 'time (or samples) fis-N needs for lobe-N's PSNR'."""
    order = np.argsort(xs)
    xs, ys = np.asarray(xs, float)[order], np.asarray(ys, float)[order]
    if len(xs) == 0:
        return float("nan")
    if ys[0] >= target:
        return float(xs[0])  # reached at the smallest measured x already (an upper bound)
    for i in range(1, len(xs)):
        if ys[i] >= target:
            f = (target - ys[i - 1]) / (ys[i] - ys[i - 1])
            return float(np.exp(np.log(xs[i - 1]) + f * (np.log(xs[i]) - np.log(xs[i - 1]))))
    return float("nan")


# -- what is rendered ----------------------------------------------------------------------------------
def parse_method(text: str) -> Method:
    try:
        return Method.parse(text)
    except ValueError as exc:
        raise BenchError(f"--methods: {exc}") from None


def resolve_environment(name: str):
    """sphere/ENV: a named shared capture (falls back to a built-in sky when the shared assets
    are absent), builtin:NAME, or a file."""
    from lobeview.scenes.builtin_env import load_environment

    if name in SPHERE_ENVS:
        relative, fallback = SPHERE_ENVS[name]
        path = SHARED_ENV_DIR / relative if SHARED_ENV_DIR is not None else None
        if path is not None and path.exists():
            return load_environment(str(path))
        missing = path if path is not None else f"the shared assets ($LOBEVIEW_ASSETS) for sphere/{name}"
        warnings.warn(f"{missing} not found: sphere/{name} uses {fallback} instead", stacklevel=2)
        return load_environment(fallback)
    return load_environment(name)


class SphereTarget:
    """The preview sphere under a distant environment (no lightmaps)."""

    def __init__(self, ctx, env_name: str, size, face_size: int):
        from lobeview.app.shot import PREVIEW_CAMERA  # the camera of `lobeview shot --object`
        from lobeview.scenes.meshes import uv_sphere
        from lobeview.viewer.camera import Camera
        from lobeview.viewer.preview import PreviewRenderer

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # capture clamps (a few negative texels) are not news here
            env = resolve_environment(env_name)
        self.env_label = Path(env.name).name
        self.renderer = PreviewRenderer(ctx, env, uv_sphere(), size=size, face_size=face_size)
        position, target, up, fov = PREVIEW_CAMERA  # the camera of `lobeview shot --object`
        self.camera = Camera(position=position, target=target, up=up, fov_y=fov)
        self.bsdf = None
        self.packed = None

    def set_material(self, preset: str) -> None:
        from lobeview.materials.spec import build_bsdf, load_material
        from lobeview.viewer.material_gpu import pack_material

        self.bsdf = build_bsdf(load_material(preset))
        self.packed = pack_material(self.bsdf)

    def render(self, method: Method, spp: int = 1, lod_bias=None, seed: int = 0):
        return self.renderer.render(
            self.camera, self.bsdf, method, spp=spp, lod_bias=lod_bias, background=False, seed=seed
        )

    @staticmethod
    def mask_of(result) -> np.ndarray:
        return result.mask

    def memory(self, method: Method) -> int:
        return sum(self.renderer.method_memory(self.renderer.cubes, self.packed, method).values())

    def release(self):
        self.renderer.release()


class DemoTarget:
    """The built-in demo scene from one of its cameras; its materials are the scene's."""

    def __init__(self, ctx, view: str, size, face_size: int, cache):
        from lobeview.app.options import load_scene_and_environment, scene_view
        from lobeview.viewer.camera import Camera
        from lobeview.viewer.scene_renderer import SceneRenderer

        _, scene, env, cache = load_scene_and_environment(None, None, cache)
        self.env_label = Path(env.name).name
        position, target, up, fov = scene_view(scene, view)
        self.camera = Camera(position=position, target=target, up=up, fov_y=fov)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.renderer = SceneRenderer(
                ctx, scene, env, size=size, cube_face_size=face_size, cache_dir=cache / "cubes", progress=False
            )

    def set_material(self, preset: str) -> None:  # the scene's own materials
        pass

    def render(self, method: Method, spp: int = 1, lod_bias=None, seed: int = 0):
        return self.renderer.render(self.camera, method, spp=spp, lod_bias=lod_bias, seed=seed)

    def mask_of(self, result) -> np.ndarray:
        """The view-dependent pixels: objects with a cube map."""
        return np.isin(result.object_id, self.renderer.analysis.cube_mapped)

    def memory(self, method: Method) -> int:
        total = 0
        for obj in self.renderer.objects:
            if obj.cube is not None:
                total += sum(self.renderer.method_memory(obj.cube, obj.material, method).values())
        return total

    def release(self):
        self.renderer.release()


def time_frames(render, repeats: int, timer: str):
    """Call ``render()`` once as a warm-up (compiles the variant, builds maps), then ``repeats``
    times: (last result, ms by the ``timer`` in use ('gpu' or 'wall'), median GPU-timer ms or
    None, median wall ms, wall seconds of the warm-up frame)."""
    start = time.perf_counter()
    render()
    first_s = time.perf_counter() - start
    gpu, wall = [], []
    result = None
    for _ in range(max(repeats, 1)):
        result = render()
        wall.append(result.timings["shade"] * 1e3)
        if "gpu shade" in result.timings:
            gpu.append(result.timings["gpu shade"] * 1e3)
    gpu_ms = statistics.median(gpu) if gpu else None
    wall_ms = statistics.median(wall)
    return result, (gpu_ms if timer == "gpu" and gpu_ms is not None else wall_ms), gpu_ms, wall_ms, first_s


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
    from lobeview.app.options import parse_size

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


def run(args) -> int:
    from lobeview.viewer.context import create_headless_context, renderer_description

    out_dir = Path(args.out) if args.out else bench_results_dir()
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    if args.stress:
        return run_stress(args, out_dir, stamp)
    if args.mirrors:
        from lobeview.app.options import parse_size

        from .bench_mirror import MIRROR_SAMPLES, run_mirror_bench

        default_sizes = ["320x200"] if args.quick else ["640x400", "1680x1050"]
        sizes = [parse_size(text) for text in (args.resolutions or default_sizes)]
        ctx = create_headless_context()
        samples = args.mirror_samples or ([3, 7] if args.quick else list(MIRROR_SAMPLES))
        spp = args.reference_spp or (128 if args.quick else 512)
        run_mirror_bench(ctx, renderer_description(ctx), out_dir, stamp, sizes, samples, args.repeats, spp)
        ctx.release()
        return 0
    if args.report:
        source = Path(args.report)
        try:
            data = json.loads(source.read_text())
            data["meta"]["settings"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise BenchError(f"--report: {source} is not a lobeview bench JSON ({exc})") from None
        base = source.with_suffix("")
        plots = write_plots(base, data["cells"], data["sweep"], data["references"])
        write_markdown(base.with_suffix(".md"), data, plots)
        print(f"wrote {base.with_suffix('.md')} and {len(plots)} plots")
        return 0
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


# -- stress --------------------------------------------------------------------------------------------
def run_stress(args, out_dir: Path, stamp: str) -> int:
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.stress import FULL_METHODS as STRESS_METHODS
    from lobeview.viewer.stress import run_stress as stress_suite

    methods = args.methods or list(STRESS_METHODS)
    for m in methods:
        parse_method(m)
    ctx = create_headless_context()
    device = renderer_description(ctx)
    rows = stress_suite(ctx, methods, progress=True, quick=args.quick)
    ctx.release()
    failures = [r for r in rows if not r.clean or r.furnace == "FAIL"]
    known = [r for r in rows if r.furnace == "known defect"]
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"stress-{stamp}.md"
    lines = [
        "# lobeview stress suite",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- device: {device}",
        f"- methods: {', '.join(methods)}",
        f"- {len(rows)} checks: {len(failures)} failures, {len(known)} known defects"
        " (plain lobe-N, Eq. 4.25 as printed, overshoots the white furnace for roughness > 0.2 and"
        " for horizon-cut lobes whose albedo climbs steeply toward grazing: a weighted mean over the"
        " pattern cannot see the lobe mass it misses; counted as known where normalised lobe-N,"
        " the viewer's default, passes the same material)",
        "- white furnace: value / directional albedo at 20 random pixels of a 40x40 sphere; tolerances"
        " in lobeview/viewer/stress.py (furnace_tolerance)",
        "",
        "| case | method | finite, >= 0 | white furnace | worst value / albedo |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = "" if not np.isfinite(r.worst_ratio) else f"{r.worst_ratio:.3f}"
        lines.append(f"| {r.case} | {r.method} | {'yes' if r.clean else 'NO'} | {r.furnace} | {ratio} |")
    path.write_text("\n".join(lines) + "\n")
    print(f"{len(rows)} checks, {len(failures)} failures, {len(known)} known defects; wrote {path}")
    for r in failures[:20]:
        print(f"  FAILED: {r.case} {r.method} (finite: {r.clean}, furnace: {r.furnace}, ratio {r.worst_ratio:.3f})")
    return 1 if failures else 0


# -- reports -------------------------------------------------------------------------------------------
def _time(cell) -> float:
    return cell["ms"]


def _family(method: str) -> str:
    return Method.parse(method).family


def _groups(cells):
    """(view, material, resolution) -> cells with errors."""
    groups: dict = {}
    for c in cells:
        if "psnr" in c:
            groups.setdefault((c["view"], c["material"], c["resolution"]), []).append(c)
    return groups


def write_plots(base: Path, cells, sweep, references) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    groups = _groups(cells)
    floors = {(r["view"], r["material"], r["resolution"]): r["psnr_floor"] for r in references}
    colours = {"lobe": "tab:blue", "lobe+norm": "tab:cyan", "fis": "tab:orange", "mc": "tab:grey"}
    colours["prefiltered"] = "tab:green"
    for resolution in sorted({k[2] for k in groups}):
        keys = [k for k in groups if k[2] == resolution]
        columns = min(len(keys), 4)
        rows = -(-len(keys) // columns)
        fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False)
        for ax, key in zip(axes.ravel(), keys, strict=False):
            group = groups[key]
            times = [_time(c) for c in group]
            psnrs = [c["psnr"] for c in group]
            front = pareto_front(times, [-p for p in psnrs])
            for family in ("lobe", "lobe+norm", "fis", "mc", "prefiltered"):
                members = sorted((c for c in group if _family(c["method"]) == family), key=_time)
                if not members:
                    continue
                style = "o-" if family in ("lobe", "fis") else "s"
                ax.plot(
                    [_time(c) for c in members],
                    [c["psnr"] for c in members],
                    style,
                    color=colours[family],
                    label=family,
                    ms=4,
                )
                for c in members:
                    if family in ("lobe", "fis", "mc"):
                        ax.annotate(
                            c["method"].split("-")[1].replace("+norm", ""),
                            (_time(c), c["psnr"]),
                            fontsize=6,
                            xytext=(2, 2),
                            textcoords="offset points",
                        )
            ax.plot(
                [t for t, f in zip(times, front, strict=True) if f],
                [p for p, f in zip(psnrs, front, strict=True) if f],
                "o",
                mfc="none",
                mec="red",
                ms=9,
                label="Pareto front",
            )
            if key in floors:
                ax.axhline(floors[key], color="k", ls=":", lw=0.8, label="reference floor")
            ax.set_xscale("log")
            ax.set_title(f"{key[0]} - {key[1]}", fontsize=8)
            ax.set_xlabel("ms / frame", fontsize=7)
            ax.set_ylabel("PSNR (dB)", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(alpha=0.3, which="both")
        for ax in axes.ravel()[len(keys) :]:
            ax.axis("off")
        axes.ravel()[0].legend(fontsize=6)
        fig.suptitle(f"PSNR against time per frame, {resolution} (numbers: samples per lobe)", fontsize=10)
        fig.tight_layout()
        path = Path(f"{base}-pareto-{resolution}.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    if sweep:
        fig, ax = plt.subplots(figsize=(5.5, 3.6))
        for method in sorted({r["method"] for r in sweep}):
            biases = sorted({r["bias"] for r in sweep if r["method"] == method})
            score = [
                _geomean([r["rel_rmse"] for r in sweep if r["method"] == method and r["bias"] == b]) for b in biases
            ]
            ax.plot(biases, score, "o-", label=method)
        ax.set_xlabel("MIP level bias b")
        ax.set_ylabel("geometric mean relRMSE")
        ax.set_title("LOD bias sweep (sphere views, all materials)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = Path(f"{base}-lod-bias.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _geomean(values) -> float:
    values = np.maximum(np.asarray(values, float), 1e-12)
    return float(np.exp(np.mean(np.log(values))))


def sweep_winners(sweep) -> dict:
    """method -> (best bias by mean PSNR, {bias: mean PSNR}, {bias: geometric-mean relRMSE}).
    PSNR of the tonemapped image decides (what a viewer sees, and what the targets of the
    report are stated in); relRMSE weighs the brightest texels and is listed beside it."""
    winners = {}
    for method in sorted({r["method"] for r in sweep}):
        biases = sorted({r["bias"] for r in sweep if r["method"] == method})
        rows = {b: [r for r in sweep if r["method"] == method and r["bias"] == b] for b in biases}
        psnr = {b: float(np.mean([r["psnr"] for r in rows[b]])) for b in biases}
        rel = {b: _geomean([r["rel_rmse"] for r in rows[b]]) for b in biases}
        winners[method] = (max(psnr, key=psnr.get), psnr, rel)
    return winners


def write_markdown(path: Path, data: dict, plots: list[Path]) -> None:
    meta, cells, sweep, references, fps = data["meta"], data["cells"], data["sweep"], data["references"], data["fps"]
    s = meta["settings"]
    timer = (
        "GPU timer query (GL_TIME_ELAPSED) around the shading pass"
        if s.get("timer") == "gpu"
        else "wall clock around the shading pass + glFinish (a software renderer: its timer queries do not "
        "cover rasterisation)"
    )
    lines = [
        f"# lobeview bench{' (--quick)' if meta['quick'] else ''}",
        "",
        f"- date: {meta['date']}",
        f"- device: {meta['device']}",
        *([f"- command: `{meta['command']}`"] if meta.get("command") else []),
        f"- time: median of {s['repeats']} frames after a warm-up; {timer}; both clocks are in the JSON",
        f"- reference: `reference` (MIS), {s['reference_spp']} samples per lobe as two independent halves; "
        "'floor' is the PSNR its own noise allows (PSNR of the halves + 6 dB)"
        if references
        else "- errors: none measured (a timing-only run, --error-resolutions none)",
        "- errors on the view-dependent pixels (sphere: the object; demo: objects with cube maps): relRMSE of "
        "linear radiance, PSNR of the 8-bit sRGB image after ACES with the reference's median luminance at "
        "0.18, mean LDR-FLIP (flip-evaluator, 67 ppd) of the same tonemapped image",
        "- memory: GPU textures the method reads per cube (radiance cube + MIP chain, importance tables, albedo "
        "table or prefiltered maps), summed over the scene's cube maps",
        "- first frame s: the warm-up frame (shader compilation; for prefiltered methods also the fits and "
        "maps not yet built: methods run in the order listed per view, so maps an earlier mode built, or "
        "that the --cache folder holds, cost ~0 here)",
        f"- LOD bias: fis-N {DEFAULT_FIS_LOD_BIAS:+g}, lobe-N {DEFAULT_LOBE_LOD_BIAS:+g} (defaults, see the sweep)",
        f"- cube faces {s['face_size']}^2; views: " + ", ".join(s["views"]),
        "",
    ]
    for p in plots:
        lines.append(f"![{p.stem}]({p.name})")
    lines.append("")
    groups = _groups(cells)
    floors = {(r["view"], r["material"], r["resolution"]): r for r in references}

    lines += ["## Fastest method reaching a PSNR target", ""]
    lines.append(
        "| view | material | resolution | floor (dB) | " + " | ".join(f"{t:g} dB" for t in PSNR_TARGETS) + " |"
    )
    lines.append("|---|---|---|---|" + "---|" * len(PSNR_TARGETS))
    for key, group in groups.items():
        floor = floors.get(key, {}).get("psnr_floor", float("nan"))
        entries = []
        for target_db in PSNR_TARGETS:
            reaching = [c for c in group if c["psnr"] >= target_db]
            if reaching:
                best = min(reaching, key=_time)
                entries.append(f"{best['method']} ({_time(best):.1f} ms)")
            else:
                best = max(group, key=lambda c: c["psnr"])
                if best["psnr"] < floor - 3.0:  # the reference resolves that no method gets there
                    entries.append(f"none (best {best['method']} {best['psnr']:.1f})")
                else:
                    entries.append(f"not measurable (best {best['method']} {best['psnr']:.1f}, floor {floor:.1f})")
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {floor:.1f} | " + " | ".join(entries) + " |")
    lines.append("")

    lines += [
        "## lobe-N against fis-N",
        "",
        "At equal time: fis-N's PSNR interpolated (log time) at lobe-N's time. At equal error: the time and "
        "the samples fis-N needs to reach lobe-N's PSNR (first crossing, log-linear); '-' where fis-N's "
        "measured range does not reach.",
        "",
        "| view | material | resolution | lobe-N | ms | PSNR | fis PSNR at equal time | fis ms at equal PSNR "
        "| fis N at equal PSNR |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key, group in groups.items():
        fis = [c for c in group if _family(c["method"]) == "fis"]
        if len(fis) < 2:
            continue
        fis_t = [_time(c) for c in fis]
        fis_p = [c["psnr"] for c in fis]
        fis_n = [int(c["method"].split("-")[1]) for c in fis]
        for c in sorted((c for c in group if _family(c["method"]) == "lobe"), key=_time):
            at_time = interpolate_log(_time(c), fis_t, fis_p)
            t_needed = first_crossing(c["psnr"], fis_t, fis_p)
            n_needed = first_crossing(c["psnr"], fis_n, fis_p)
            lines.append(
                f"| {key[0]} | {key[1]} | {key[2]} | {c['method']} | {_time(c):.1f} | {c['psnr']:.2f} | "
                f"{_fmt(at_time, '.2f')} | {_fmt(t_needed, '.1f')} | {_fmt(n_needed, '.0f')} |"
            )
    lines.append("")

    if sweep:
        winners = sweep_winners(sweep)
        lines += [
            "## MIP level bias (lod = 0.5 log2(Omega_s / Omega_p) + b)",
            "",
            "Mean PSNR (dB) / geometric-mean relRMSE over the sphere views and materials at the error resolution;"
            " the best bias by PSNR is marked.",
            "",
            "| method | " + " | ".join(f"b = {b:+g}" for b in sorted({r["bias"] for r in sweep})) + " | best b |",
            "|---|" + "---|" * (len({r["bias"] for r in sweep}) + 1),
        ]
        for method, (best, psnr, rel) in winners.items():
            values = " | ".join(
                (f"**{psnr[b]:.2f}** / {rel[b]:.4f}" if b == best else f"{psnr[b]:.2f} / {rel[b]:.4f}")
                for b in sorted(psnr)
            )
            lines.append(f"| {method} | {values} | {best:+g} |")
        lines.append("")

    lines += ["## All cells", ""]
    lines.append(
        "| view | material | resolution | method | ms / frame | GPU timer ms | first frame s | PSNR dB | relRMSE"
        " | FLIP | memory MiB |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cells:
        gpu = _fmt(c.get("gpu_ms"), ".1f")
        lines.append(
            f"| {c['view']} | {c['material']} | {c['resolution']} | {c['method']} | {c['ms']:.1f} | {gpu} | "
            f"{_fmt(c.get('first_frame_s'), '.2f')} | {_fmt(c.get('psnr'), '.2f')} | "
            f"{_fmt(c.get('rel_rmse'), '.4f')} | {_fmt(c.get('flip'), '.4f')} | "
            f"{c['memory_mb']:.1f} |"
        )
    lines.append("")
    lines += ["## References", "", "| view | material | resolution | environment | spp | seconds | floor (dB) |"]
    lines.append("|---|---|---|---|---|---|---|")
    for r in references:
        lines.append(
            f"| {r['view']} | {r['material']} | {r['resolution']} | {r['environment']} | {r['spp']} | "
            f"{r['seconds']:.1f} | {r['psnr_floor']:.1f} |"
        )
    lines.append("")
    if fps:
        size = s["fps_size"]
        lines += [
            f"## Frame rate by samples (thesis tables 4.1/4.2 layout), {size[0]}x{size[1]}, lobe-N",
            "",
            "Full: a glossy plane covers the frame; half: it covers the left half (background elsewhere). "
            "Thesis: table 4.1 (cube maps, GeForce GTS 450, 2012).",
            "",
            "| samples | full ms | full fps | half ms | half fps | fraction full / half | thesis fps full / half |",
            "|---|---|---|---|---|---|---|",
        ]
        for row in fps:
            full, half = row["full"], row["half"]
            thesis = THESIS_FPS.get(row["samples"])
            lines.append(
                f"| {row['samples']} | {full['ms']:.1f} | {1000 / full['ms']:.1f} | {half['ms']:.1f} | "
                f"{1000 / half['ms']:.1f} | {full['fraction']:.2f} / {half['fraction']:.2f} | "
                f"{'' if thesis is None else f'{thesis[0]} / {thesis[1]}'} |"
            )
        lines.append("")
    path.write_text("\n".join(lines) + "\n")


def _fmt(value, spec: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return format(value, spec)
