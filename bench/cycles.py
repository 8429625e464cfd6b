"""lobeview against Blender Cycles on glTF models (issue 40: an independent reference for the glTF
shading, with its differences found and fixed).

Each case is a glTF file, an environment and a camera. Cycles renders it through Blender's own glTF
importer (``bpy`` from PyPI, in its own process: :mod:`lobeview.bench.cycles_worker`, whose
docstring states the conventions), lobeview through ``lobeview shot`` (``reference`` and the
chosen real-time methods). Errors are over the object's pixels (Cycles' alpha = 1, one pixel in
from the silhouette): the ratio of mean brightness, relative RMSE, and the ratio at the darkest
5 % of pixels. Figures: Cycles | lobeview reference | each method | |error| x4 per case.

Cases: a generated unit sphere of a white roughness-1 glTF dielectric (Cycles renders it at 1.00
everywhere under a white sky: the grazing test), a chrome sphere (verifies the environment's
orientation: a turned or mirrored map shows as tens of percent), every model in
../shared/assets/gltf and Khronos' ClearCoatTest (committed in bench/models; SOURCES.md there);
environments: a white sky (constant radiance 1) and the HDR captures named
by ``--envs``. Cycles' images are cached in the lobeview cache folder (keyed by the glTF and
environment files' bytes, the camera, size, samples and Blender's version).

    python3.11 -m venv ~/bpy-env && ~/bpy-env/bin/pip install bpy==4.3.0 numpy==1.26.4
    .venv/bin/python -m lobeview.bench.cycles --bpy-python ~/bpy-env/bin/python [--size 240x180] [--spp 512]
        [--cases sphere-white ... | a glTF file] [--envs white garden studio] [--lobeview "COMMAND"]
        [--passes [--trace]]

bpy is not a lobeview dependency and cannot be an optional one: bpy 4.3 (the last for Python
3.11) is built against numpy 1.x and its Cycles add-on fails to register under lobeview's numpy
2.4, so it lives in an environment of its own and the bench calls that interpreter.

Where Cycles and the glTF specification disagree, the specification wins and the table says so:
Cycles' Principled BSDF adds multiple scattering to GGX (about +5 % on rough metals) and maps
KHR_materials_anisotropy differently.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import shlex
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lobeview.core.errors import parse_size
from lobeview.core.images import box_downsample
from lobeview.core.paths import cache_dir, lobeview_program

ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "assets"
WORKER = Path(__file__).resolve().parent / "cycles_worker.py"
BLENDER_VERSION_PIN = "4.3.0"
ENVIRONMENTS = {
    "white": None,  # constant radiance 1, written by the bench
    "garden": "env/polyhaven_1k/chinese_garden_1k.hdr",
    "studio": "env/blender_studiolights_1k/studio.exr",
}
DEFAULT_ENVS = ("white", "garden", "studio")
# Written out: `shot --method lobe-7` is lobe-7+norm+fit since the twenty-ninth session (the
# command line's default lobe-N), and a table's column should say which pattern it measured.
DEFAULT_METHODS = ("lobe-7+norm+fit", "prefiltered")
SPHERE_MATERIALS = {
    "sphere-white": {"model": "gltf", "base_color": [1.0, 1.0, 1.0], "metallic": 0.0, "roughness": 1.0},
    "sphere-chrome": {"model": "gltf", "base_color": [1.0, 1.0, 1.0], "metallic": 1.0, "roughness": 0.0},
    "sphere-gold": {"model": "gltf", "base_color": [1.0, 0.78, 0.34], "metallic": 1.0, "roughness": 0.4},
}
MODELS = {
    "WaterBottle": ASSETS / "gltf/WaterBottle/WaterBottle.glb",
    "Suzanne": ASSETS / "gltf/Suzanne/Suzanne.gltf",
    "CornellBox": ASSETS / "gltf/CornellBox/CornellBox.glb",
    # committed with the bench (bench/models/SOURCES.md): Khronos' KHR_materials_clearcoat test
    "ClearCoatTest": Path(__file__).resolve().parent / "models/ClearCoatTest/ClearCoatTest.gltf",
}
# A model's mesh with one untextured material: prefiltered-rsibr bakes maps only for lobes no
# texture changes, so on the textured models it falls back to the split-sum lookup.
PLAIN_MODELS = {
    "suzanne-metal": ("Suzanne", {"model": "gltf", "base_color": [0.8, 0.8, 0.8], "metallic": 1.0, "roughness": 0.35}),
}
DEFAULT_CASES = (*SPHERE_MATERIALS, *MODELS, *PLAIN_MODELS)
FOV_Y = 40.0
# Where the camera sits relative to a model's bounding sphere: up and to the side a little, so
# that the silhouette shows grazing angles and the top shows the sky's reflection.
VIEW_DIRECTION = np.array([0.35, 0.3, 1.0]) / np.linalg.norm([0.35, 0.3, 1.0])
DARKEST_SHARE = 0.05


@dataclass
class Case:
    name: str
    gltf: Path
    environment: str  # a key of ENVIRONMENTS
    camera: tuple
    target: tuple


def white_environment(path: Path) -> Path:
    """A constant radiance-1 equirectangular EXR (64 x 32), the white sky of both renderers."""
    from lobeview.scenes.hdrio import write_hdr_image

    if not path.exists():
        write_hdr_image(path, np.ones((32, 64, 3), np.float32))
    return path


def environment_file(name: str, work: Path) -> Path:
    if ENVIRONMENTS[name] is None:
        return white_environment(work / "white.exr")
    return ASSETS / ENVIRONMENTS[name]


def sphere_gltf(name: str, work: Path, material: dict | None = None) -> Path:
    """A unit sphere at the origin with the named glTF material (or ``material``), written as .glb
    (core metallic-roughness values, which Blender's importer reads too)."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject

    path = work / f"{name}.glb"
    # written every run (the work folder persists: an older file could hold another material)
    scene = Scene([SceneObject("sphere", uv_sphere(rings=96, segments=192), 0)],
                  [SceneMaterial(name, validate(material or SPHERE_MATERIALS[name]))])  # fmt: skip
    scene.objects[0].planar_reflector = False
    write_glb(scene, path)
    return path


def plain_model_gltf(name: str, work: Path) -> Path:
    """PLAIN_MODELS[name]: the model's objects with every material replaced by the one given,
    written as .glb (every run, as sphere_gltf)."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.scene import SceneMaterial

    model, material = PLAIN_MODELS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(MODELS[model])
    scene.materials = [SceneMaterial(name, validate(material))]
    for obj in scene.objects:
        obj.material = 0
    path = work / f"{name}.glb"
    write_glb(scene, path)
    return path


def framing(gltf: Path) -> tuple[tuple, tuple]:
    """(camera, target) that fit the model's bounding sphere in a vertical field of view of
    FOV_Y, seen along VIEW_DIRECTION."""
    from lobeview.scenes.gltf_loader import load_gltf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the loader's notes about the model are not the bench's business
        scene = load_gltf(gltf)
    low, high = scene.bounds
    centre = (np.asarray(low) + np.asarray(high)) / 2
    radius = float(np.linalg.norm(np.asarray(high) - np.asarray(low)) / 2)
    distance = radius / np.sin(np.radians(FOV_Y / 2)) * 1.05
    camera = centre + VIEW_DIRECTION * distance
    return tuple(float(v) for v in camera), tuple(float(v) for v in centre)


def make_cases(names, envs, work: Path) -> list[Case]:
    cases = []
    for name in names:
        if name in SPHERE_MATERIALS:
            gltf = sphere_gltf(name, work)
            camera, target = (0.0, 0.35, 3.2), (0.0, 0.0, 0.0)
        elif name in MODELS:
            gltf = MODELS[name]
            camera, target = framing(gltf)
        elif name in PLAIN_MODELS:
            gltf = plain_model_gltf(name, work)
            camera, target = framing(gltf)
        else:
            path = Path(name)
            if not path.is_file():
                raise SystemExit(f"unknown case {name!r}: one of {', '.join(DEFAULT_CASES)} or a glTF file")
            gltf, (camera, target) = path, framing(path)
            name = path.stem
        cases.extend(Case(name, gltf, env, camera, target) for env in envs)
    return cases


SWEEP_ROUGHNESS = (0.0, 0.002, 0.005, 0.008, 0.012, 0.02, 0.05)
SWEEP_CAMERA = ((0.0, 0.35, 3.2), (0.0, 0.0, 0.0))


def roughness_sweep(python: str, work: Path, cache: Path | None, version: str, size=(64, 48), spp: int = 64) -> list:
    """Cycles' mean brightness of a metal sphere (base colour 0.4, glTF roughness per
    SWEEP_ROUGHNESS) under the white sky, without the worker's roughness floor and with it: the
    check behind the floor (bench/cycles_worker.py). Under a white sky every roughness gives the
    same mean but for single scattering's small loss at the rough end."""
    from lobeview.bench.cycles_worker import ROUGHNESS_FLOOR

    env = white_environment(work / "white.exr")
    rows = []
    for roughness in SWEEP_ROUGHNESS:
        name = f"sweep-metal-{roughness:g}"
        material = {"model": "gltf", "base_color": [0.4, 0.4, 0.4], "metallic": 1.0, "roughness": roughness}
        case = Case(name, sphere_gltf(name, work, material), "white", *SWEEP_CAMERA)
        row = {"roughness": roughness}
        for floor in (0.0, ROUGHNESS_FLOOR):
            job = cycles_job(case, env, size, spp, work / f"{name}-floor-{floor:g}-cycles.exr")
            job["roughness_floor"] = floor
            image, _, _ = render_cycles(job, python, cache, version, work)
            mask = object_mask(image[..., 3])
            row[f"floor {floor:g}"] = float(image[..., :3].mean(-1)[mask].mean())
        means = ", ".join(f"{k} {v:.4f}" for k, v in row.items() if k != "roughness")
        print(f"[cycles] roughness {roughness:g}: {means}", file=sys.stderr, flush=True)
        rows.append(row)
    return rows


def roughness_sweep_markdown(rows: list, stamp: str, version: str) -> str:
    floors = [k for k in rows[0] if k != "roughness"]
    lines = [f"# Cycles {version} against near-zero roughness ({stamp})", "",
             "`python -m lobeview.bench.cycles --roughness-sweep`: a metal unit sphere (glTF base colour 0.4, "
             "metallic 1) under the white sky (radiance 1), 64x48, 64 spp; the mean over the sphere's pixels "
             "without the worker's roughness floor and with it. Every row should read about 0.40.", "",
             "| glTF roughness | " + " | ".join(f"Cycles mean, {k}" for k in floors) + " |",
             "|---|" + "---|" * len(floors)]  # fmt: skip
    lines += [f"| {r['roughness']:g} | " + " | ".join(f"{r[k]:.4f}" for k in floors) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _vec(v) -> str:
    return ",".join(f"{x:.6g}" for x in v)


def shot_arguments(case: Case, env_path: Path, size, method: str, out: Path, spp: int) -> list[str]:
    """``lobeview shot`` arguments that render the case's view (vertical fov, linear .npy)."""
    args = [str(case.gltf), f"--env={env_path}", f"--camera={_vec(case.camera)}", f"--target={_vec(case.target)}",
            f"--fov={FOV_Y}", f"--size={size[0]}x{size[1]}", f"--method={method}", f"--out={out}"]  # fmt: skip
    if method == "reference":
        args.append(f"--spp={spp}")
    return args


def render_lobeview(case: Case, env_path: Path, size, method: str, work: Path, spp: int,
                    lobeview=None, supersample: int = 1) -> tuple[np.ndarray, str]:  # fmt: skip
    """lobeview's linear image of the case through ``lobeview shot`` in a process of its own (as
    a user runs it), and the command, pasteable. ``lobeview``: the command that runs lobeview
    (a list; default this interpreter's ``-m lobeview``), e.g. another checkout's for a
    before/after table. ``supersample`` K: rendered at K times ``size`` and box-filtered here (what
    ``shot --supersample K`` writes; done here so an older checkout's shot runs it too)."""
    out = work / f"{case.name}-{case.environment}-{method}.npy"
    rendered = (size[0] * supersample, size[1] * supersample)
    args = shot_arguments(case, env_path, rendered, method, out, spp)
    command = [*(lobeview or lobeview_program()), "shot", *args]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"lobeview shot failed ({done.returncode}): {done.stderr[-2000:]}")
    return box_downsample(np.load(out).astype(np.float64), supersample), shlex.join(command)


def cycles_job(case: Case, env_path: Path, size, spp: int, out: Path) -> dict:
    return {"gltf": str(case.gltf), "environment": str(env_path), "camera": list(case.camera),
            "target": list(case.target), "up": [0.0, 1.0, 0.0], "fov_y": FOV_Y, "size": list(size), "spp": spp,
            "out": str(out), "env_rotation_deg": -90.0}  # fmt: skip


def cycles_key(job: dict, version: str) -> str:
    """What a Cycles render depends on: the job (without its output path), the glTF and
    environment files' bytes (and a .gltf's folder: its buffers and images), the worker's
    conventions and Blender's version."""
    # paths by name only: the generated spheres and the white sky are written to a new temporary
    # folder every run, and their bytes are hashed below anyway
    named = {k: Path(v).name if k in ("gltf", "environment") else v for k, v in job.items() if k != "out"}
    digest = hashlib.sha1(repr((named, version)).encode())
    gltf = Path(job["gltf"])
    files = sorted(p for p in gltf.parent.iterdir() if p.is_file()) if gltf.suffix == ".gltf" else [gltf]
    for path in [*files, Path(job["environment"]), WORKER]:
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _bpy_probe(python: str) -> subprocess.CompletedProcess:
    # isolated (-I), as the worker runs: this folder's cycles.py must not shadow Blender's add-on
    return subprocess.run([python, "-I", "-c", "import bpy; print(bpy.app.version_string)"],
                          capture_output=True, text=True)  # fmt: skip


def bpy_importable(python: str) -> bool:
    """Whether ``python`` can import Blender's module."""
    return _bpy_probe(python).returncode == 0


def bpy_version(python: str) -> str:
    """Blender's version as ``python`` imports it, or SystemExit saying how to install it."""
    done = _bpy_probe(python)
    if done.returncode != 0:
        raise SystemExit(
            f"Blender's Python module is not importable by {python}: pip install bpy=={BLENDER_VERSION_PIN} "
            "numpy==1.26.4 in a separate environment (bpy 4.3 is built against numpy 1.x; lobeview pins 2.x) "
            "and give its interpreter as --bpy-python PATH"
        )
    return done.stdout.strip().splitlines()[-1]


def render_cycles(job: dict, python: str, cache: Path | None, version: str, work: Path) -> tuple:
    """Cycles' RGBA image (linear), the seconds it took (0: from the cache) and the command. The
    worker runs isolated (``-I``: neither its own folder nor the working folder on sys.path),
    since this module's name would otherwise shadow Blender's ``cycles`` add-on."""
    from lobeview.core.cache import read_cache_file, write_cache_file

    size = tuple(job["size"])
    path = cache / f"cycles-{cycles_key(job, version)}.npz" if cache else None

    def read(file: Path):
        with np.load(file) as data:
            image, seconds = data["image"], float(data["seconds"])
        if image.shape != (size[1], size[0], 4) or not np.all(np.isfinite(image)):
            raise ValueError(f"image of shape {image.shape}, expected {(size[1], size[0], 4)}")
        return image, seconds

    command = worker_command(job, python)
    found = read_cache_file(path, read, "Cycles render")
    if found is not None:
        return found[0], 0.0, shlex.join(command)
    seconds = run_worker(command, job, "Cycles")
    image = read_rgba_exr(Path(job["out"]))
    if path is not None:
        write_cache_file(path, lambda handle: np.savez(handle, image=image, seconds=seconds))
    return image, seconds, shlex.join(command)


def worker_command(job: dict, python: str) -> list[str]:
    """The worker's command line for ``job``, whose file it writes beside the job's output."""
    job_file = Path(job["out"]).with_suffix(".json")
    job_file.write_text(json.dumps(job, indent=1))
    return [python, "-I", str(WORKER), str(job_file)]


def run_worker(command: list[str], job: dict, what: str) -> float:
    """Run the worker's ``command``; the seconds it took, or RuntimeError saying ``what`` failed
    where it fails or writes no output."""
    t0 = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0 or not Path(job["out"]).exists():
        raise RuntimeError(f"{what} failed ({done.returncode}): {(done.stderr or done.stdout)[-2000:]}")
    return time.perf_counter() - t0


def read_rgba_exr(path: Path) -> np.ndarray:
    """Cycles' output (our own worker's file): RGBA float32, top row first."""
    import OpenEXR

    with OpenEXR.File(str(path)) as exr:
        channels = exr.channels()
        if "RGBA" in channels:
            return np.asarray(channels["RGBA"].pixels, dtype=np.float32)
        return np.stack([np.asarray(channels[c].pixels, np.float32) for c in "RGBA"], axis=-1)


def object_mask(alpha: np.ndarray) -> np.ndarray:
    """The object's pixels: fully covered in Cycles (alpha = 1), one pixel in from the silhouette
    (the box filter mixes the silhouette's pixels with the background in both renderers)."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(alpha > 0.999, iterations=1)


def compare(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict:
    """Mean-brightness ratio, relative RMSE, the median of the per-pixel ratio image / truth of
    the grey value, and that ratio at the darkest 5 % of pixels (the mean of its lowest 5 %) over
    ``mask``. The median is the bulk of the surface: on a near-mirror under a sun a few glint
    pixels carry half the image's sum (DamagedHelmet's visor under chinese_garden) and decide the
    mean and the RMSE."""
    a, b = image[mask], truth[mask]
    grey_a, grey_b = a.mean(axis=-1), b.mean(axis=-1)
    ratio = grey_a / np.maximum(grey_b, 1e-6)
    lowest = np.sort(ratio)[: max(1, int(DARKEST_SHARE * ratio.size))]
    return {
        "mean_ratio": float(grey_a.mean() / max(grey_b.mean(), 1e-12)),
        "rel_rmse": float(np.sqrt(np.mean((a - b) ** 2)) / max(float(np.mean(b)), 1e-12)),
        "median_ratio": float(np.median(ratio)),
        "darkest_ratio": float(lowest.mean()),
    }


def _display(image: np.ndarray, exposure: float) -> np.ndarray:
    """Linear -> [0, 1] sRGB after scaling by ``exposure`` (clipped), for the figures."""
    x = np.clip(image[..., :3] * exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def figure_row(truth: np.ndarray, images: list[np.ndarray], mask: np.ndarray) -> np.ndarray:
    """Cycles | lobeview images... | |last - Cycles| x4, one exposure per row (the object's 95th
    percentile of Cycles maps to 0.9)."""
    scale = 0.9 / max(float(np.percentile(truth[..., :3][mask], 95)), 1e-6) if mask.any() else 1.0
    panels = [_display(truth, scale)] + [_display(image, scale) for image in images]
    error = np.abs(images[-1][..., :3] - truth[..., :3]) * 4.0 * mask[..., None]
    panels.append(_display(error, scale))
    return np.concatenate(panels, axis=1)


def run(cases: list[Case], methods, size, spp: int, ref_spp: int, work: Path, python: str, cache: Path | None,
        progress=print, lobeview=None, supersample: int = 1, passes: bool = False,
        trace: bool = False) -> dict:  # fmt: skip
    """``passes``: under the white sky, also Cycles' light passes and where each method's error lies
    against them (bench/cycles_passes.py); ``trace`` (with ``passes``): the mirror direction's
    visibility at the hidden and open pixels by vertex and per-point horizons (bench/cycles_trace.py)."""
    version = bpy_version(python)
    rows, figures, commands, passes_figures = [], [], [], []
    for i, case in enumerate(cases):
        env_path = environment_file(case.environment, work)
        job = cycles_job(case, env_path, size, spp, work / f"{case.name}-{case.environment}-cycles.exr")
        progress(f"[cycles] {i + 1}/{len(cases)} {case.name} under {case.environment}: Cycles ...")
        truth, seconds, cycles_command = render_cycles(job, python, cache, version, work)
        mask = object_mask(truth[..., 3])
        if not mask.any():
            raise RuntimeError(f"Cycles rendered no object pixels for {case.name} (see {cycles_command})")
        row = {"case": case.name, "env": case.environment, "cycles_seconds": seconds, "pixels": int(mask.sum())}
        images = []
        for method in ("reference", *methods):
            progress(f"[cycles] {i + 1}/{len(cases)} {case.name} under {case.environment}: lobeview {method} ...")
            # the reference integrates each pixel itself (box pixel filter); the real-time methods
            # shade K x K points a pixel, as `shot --supersample K`
            factor = 1 if method == "reference" else supersample
            image, command = render_lobeview(case, env_path, size, method, work, ref_spp, lobeview, factor)
            images.append(image)
            row[method] = compare(image, truth[..., :3], mask)
            if method == "reference":
                commands.append((f"{case.name} / {case.environment}", cycles_command, command))
        if passes and case.environment == "white":
            from lobeview.bench.cycles_passes import (
                passes_job,
                render_passes,
                self_occlusion_split,
                visibility_figure_row,
            )

            progress(f"[cycles] {i + 1}/{len(cases)} {case.name} under {case.environment}: Cycles' passes ...")
            light_job = passes_job(job)
            key = f"cycles-passes-{cycles_key(light_job, version)}.npz"

            def run_passes(passes: dict) -> float:
                return run_worker(worker_command(passes, python), passes, "Cycles' passes")

            layers = render_passes(light_job, cache / key if cache else None, run_passes)
            labelled = zip(("reference", *methods), images, strict=True)
            row["self_occlusion"] = {
                m: self_occlusion_split(image, truth[..., :3], layers, mask) for m, image in labelled
            }
            passes_figures.append(visibility_figure_row(images[0], layers, mask))
            if trace:
                from lobeview.bench.cycles_trace import trace_case
                from lobeview.scenes.gltf_loader import load_gltf

                progress(f"[cycles] {i + 1}/{len(cases)} {case.name}: tracing the hidden and open pixels ...")
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    scene = load_gltf(case.gltf)
                row["trace"] = trace_case(scene, case.camera, case.target, FOV_Y, size, layers)
        rows.append(row)
        figures.append(figure_row(truth[..., :3], images, mask))
    return {"rows": rows, "figures": figures, "passes_figures": passes_figures, "commands": commands,
            "blender": version, "methods": list(methods),
            "size": list(size), "spp": spp, "ref_spp": ref_spp, "supersample": supersample}  # fmt: skip


def markdown(results: dict, stamp: str, command: str, figure: str) -> str:
    methods = ["reference", *results["methods"]]
    lines = [
        f"# lobeview against Blender Cycles {results['blender']} ({stamp})",
        "",
        f"`{command}`",
        "",
        f"lobeview: {results.get('lobeview', 'this checkout')}",
        "",
        f"{results['size'][0]}x{results['size'][1]} px, box filter; Cycles path tracer at {results['spp']} spp "
        f"(CPU, no denoiser, view transform Standard), lobeview's reference at {results['ref_spp']} spp; glTF "
        "files through Blender's own importer. Over the object's pixels (Cycles' alpha = 1, one pixel in): mean "
        "brightness ratio lobeview / Cycles, relative RMSE (%), the median per-pixel ratio (the bulk of the "
        "surface, where a few glints decide mean and RMSE) and the ratio at the darkest 5 % of pixels. "
        + _supersample_note(results.get("supersample", 1)),
        "",
        "| case | env | " + " | ".join(f"{m} mean / rmse % / median / darkest" for m in methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for row in results["rows"]:
        cells = [f"{row[m]['mean_ratio']:.3f} / {100 * row[m]['rel_rmse']:.1f} / {row[m]['median_ratio']:.3f} / "
                 f"{row[m]['darkest_ratio']:.3f}" for m in methods]  # fmt: skip
        lines.append(f"| {row['case']} | {row['env']} | " + " | ".join(cells) + " |")
    from lobeview.bench.cycles_passes import markdown_lines

    lines += markdown_lines(results["rows"], methods, results.get("passes_figure"))
    from lobeview.bench.cycles_trace import markdown_lines as trace_lines

    lines += trace_lines(results["rows"])
    lines += ["", f"Figure: `{figure}` (rows in the table's order; Cycles | reference | "
              + " | ".join(results["methods"]) + f" | |{results['methods'][-1]} - Cycles| x4).", "",
              "Commands (Cycles worker, lobeview reference):", ""]  # fmt: skip
    for label, cycles_command, lobeview_command in results["commands"]:
        lines += [f"- {label}: `{cycles_command}`; `{lobeview_command}`"]
    return "\n".join(lines) + "\n"


def _supersample_note(factor: int) -> str:
    if factor == 1:
        return ("The real-time methods shade one point a pixel (no anti-aliasing): their error holds the "
                "aliasing of edges, creases and glints.")  # fmt: skip
    return (f"The real-time methods shade {factor}x{factor} points a pixel, box-filtered (`shot --supersample "
            f"{factor}`), as Cycles and the reference integrate the pixel: their error is the shading's, not "
            "aliasing.")  # fmt: skip


def _shown(path: Path) -> str:
    """``path`` relative to the repository when it lies inside it (the committed figures)."""
    try:
        return str(path.resolve().relative_to(Path(__file__).resolve().parents[1]))
    except ValueError:
        return str(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m lobeview.bench.cycles", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES),
                        help=f"cases: {', '.join(DEFAULT_CASES)} or glTF files (default: all named)")  # fmt: skip
    parser.add_argument("--envs", nargs="+", default=list(DEFAULT_ENVS), choices=sorted(ENVIRONMENTS))
    parser.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS))
    parser.add_argument("--size", type=parse_size, default=(240, 180), help="WxH (default 240x180)")
    parser.add_argument("--spp", type=int, default=512, help="Cycles samples per pixel (default 512)")
    parser.add_argument("--ref-spp", type=int, default=256, help="lobeview reference spp (default 256)")
    parser.add_argument("--supersample", type=int, default=4, choices=range(1, 9), metavar="K",
                        help="the real-time methods shade K x K points a pixel (default 4: their error is the "
                             "shading's; 1 adds the aliasing of one point a pixel)")  # fmt: skip
    parser.add_argument("--bpy-python", default=sys.executable,
                        help="the Python that imports bpy (default: this one)")  # fmt: skip
    parser.add_argument("--no-cache", action="store_true", help="render Cycles' images again")
    parser.add_argument("--lobeview", default=None,
                        help="the command that runs lobeview, e.g. another checkout's for a before/after table "
                             "(default: this interpreter's -m lobeview)")  # fmt: skip
    parser.add_argument(
        "--out",
        default=str(Path(__file__).resolve().parent / "results"),
        help="folder of the table and JSON (default bench/results; made if its parent exists)",
    )
    parser.add_argument(
        "--figures",
        default=str(Path(__file__).resolve().parent / "figures"),
        help="folder of the figure (default bench/figures; made if its parent exists)",
    )
    parser.add_argument("--passes", action="store_true",
                        help="under the white sky also render Cycles' light passes and report where each method's "
                             "error lies: on the pixels whose glossy lobe the object hides from itself, or "
                             "elsewhere (bench/cycles_passes.py)")  # fmt: skip
    parser.add_argument("--trace", action="store_true",
                        help="with --passes: the mirror direction's visibility at the hidden and open pixels by "
                             "lobeview's vertex horizons and by horizons traced per pixel "
                             "(bench/cycles_trace.py)")  # fmt: skip
    parser.add_argument("--roughness-sweep", action="store_true",
                        help="only check Cycles against near-zero roughness (a metal sphere, with and without the "
                             "worker's roughness floor) and write that table")  # fmt: skip
    args = parser.parse_args(argv)

    from lobeview.bench.report import write_image_rows

    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    # Not a temporary folder: the generated spheres, the white sky, the job files and the images
    # stay there, so the commands the table prints run when pasted.
    work = cache_dir() / "cycles-work"
    work.mkdir(parents=True, exist_ok=True)
    cache = None if args.no_cache else cache_dir() / "cycles"
    if args.roughness_sweep:
        version = bpy_version(args.bpy_python)
        text = roughness_sweep_markdown(roughness_sweep(args.bpy_python, work, cache, version), stamp, version)
        out = Path(args.out)
        out.mkdir(exist_ok=True)
        (out / f"cycles-roughness-{stamp}.md").write_text(text)
        print(text)
        return 0
    cases = make_cases(args.cases, args.envs, work)
    lobeview = shlex.split(args.lobeview) if args.lobeview else None
    results = run(cases, args.methods, args.size, args.spp, args.ref_spp, work, args.bpy_python, cache,
                  lobeview=lobeview, supersample=args.supersample, passes=args.passes or args.trace,
                  trace=args.trace)  # fmt: skip
    results["lobeview"] = args.lobeview or "this checkout"
    out, figures = Path(args.out), Path(args.figures)
    out.mkdir(exist_ok=True)
    figures.mkdir(exist_ok=True)
    figure = write_image_rows(figures, f"cycles-{stamp}.png", results.pop("figures"))
    passes_rows = results.pop("passes_figures")
    if passes_rows:
        results["passes_figure"] = _shown(write_image_rows(figures, f"cycles-passes-{stamp}.png", passes_rows))
    command = "python -m lobeview.bench.cycles " + shlex.join(argv if argv is not None else sys.argv[1:])
    (out / f"cycles-{stamp}.json").write_text(json.dumps(results, indent=1))
    path = out / f"cycles-{stamp}.md"
    path.write_text(markdown(results, stamp, command.strip(), _shown(figure)))
    print(path.read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
