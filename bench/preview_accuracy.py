"""Accuracy and cost of lobe-N and fis-40 against the converged reference on the preview sphere.

For each preset: render the sphere with `reference` (--reference-spp samples per lobe), then
lobe-N for N in 3, 5, 7, 11, 15, 19 and fis-40; report PSNR of the tonemapped image (object
pixels only, 8-bit sRGB after ACES with an exposure that maps the reference's median luminance to
0.18) and relative RMSE of linear radiance, with the time per frame of each method measured in
this run (median of --repeats renders after one warm-up, wall clock around a glFinish). The
thesis' PSNR values (figures 4.39-4.41) are listed beside ours where the thesis has them; note
the thesis counts samples per material (split over reflection + transmission), lobeview per lobe.

    python bench/preview_accuracy.py [--env FILE|builtin:NAME] [--size 320] [--out bench/results]
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.builtin_env import load_environment
from lobeview.scenes.meshes import uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import create_headless_context, renderer_description
from lobeview.viewer.preview import PreviewRenderer
from lobeview.viewer.tonemap import tonemap

LOBE_N = (3, 5, 7, 11, 15, 19)
FIS = "fis-40"
PRESETS = (
    "alanod-2000gs-1lobe",
    "miro5-2lobe",
    "chrome",
    "lacquer",
    "plastic",
    "porcelain",
    "white-foil",
    "frosted-glass",
    "clear-glass",
)
# Thesis figures 4.39-4.41: preset -> {samples per material: PSNR}. Transmissive materials
# split the samples over two lobes, so thesis n=8 corresponds to lobe-4 here.
THESIS_PSNR = {
    "alanod-2000gs-1lobe": {7: 41.08, 15: 43.49},
    "miro5-2lobe": {7: 47.22, 15: 48.84},
    "chrome": {7: 38.04, 15: 40.87},
    "lacquer": {3: 55.05, 7: 57.48},
    "plastic": {3: 56.30, 7: 59.03},
    "porcelain": {3: 68.95, 7: 71.70},
    "white-foil": {8: 39.44, 16: 45.41},
    "frosted-glass": {8: 47.20, 16: 48.22},
    "clear-glass": {4: 62.60, 8: 65.65},
}
TWO_LOBE_SPLIT = {"white-foil", "frosted-glass", "clear-glass"}
DEFAULT_ENV = (
    Path(__file__).resolve().parents[1]
    / ".."
    / "shared"
    / "assets"
    / "env"
    / "blender_studiolights_1k"
    / "interior.exr"
)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.round(a * 255) / 255 - np.round(b * 255) / 255) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def timed(renderer, repeats, *args, **kwargs):
    renderer.render(*args, **kwargs)  # warm-up (shader compile, caches)
    times = []
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = renderer.render(*args, **kwargs)
        times.append(time.perf_counter() - t0)
    return result, statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default=str(DEFAULT_ENV) if DEFAULT_ENV.exists() else "builtin:studio")
    parser.add_argument("--size", type=int, default=320)
    parser.add_argument("--reference-spp", type=int, default=8192)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--presets", nargs="*", default=list(PRESETS))
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)

    ctx = create_headless_context()
    env = load_environment(args.env)
    renderer = PreviewRenderer(ctx, env, uv_sphere(), size=(args.size, args.size))
    camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
    device = renderer_description(ctx)
    rows = []
    for preset in args.presets:
        bsdf = build_bsdf(load_material(preset))
        t0 = time.perf_counter()
        ref = renderer.render(camera, bsdf, "reference", spp=args.reference_spp, background=False)
        ref_seconds = time.perf_counter() - t0
        mask = ref.mask
        lum = ref.radiance[mask] @ np.array([0.2126, 0.7152, 0.0722])
        exposure = float(np.log2(0.18 / max(np.median(lum), 1e-6)))
        ref_tm = tonemap(ref.radiance, "aces", exposure)[mask]
        ref_lin = ref.radiance[mask]
        # Noise floor: a second, independent reference (other per-pixel scrambling seed).
        ref_b = renderer.render(camera, bsdf, "reference", spp=args.reference_spp, seed=1, background=False)
        floor = psnr(tonemap(ref_b.radiance, "aces", exposure)[mask], ref_tm)
        methods = [f"lobe-{n}" for n in LOBE_N] + [FIS]
        for method in methods:
            result, seconds = timed(renderer, args.repeats, camera, bsdf, method, background=False)
            img = result.radiance[mask]
            rel_rmse = float(np.sqrt(np.mean((img - ref_lin) ** 2)) / np.sqrt(np.mean(ref_lin**2)))
            value = psnr(tonemap(result.radiance, "aces", exposure)[mask], ref_tm)
            thesis = ""
            if method.startswith("lobe-"):
                n = int(method.split("-")[1])
                key = 2 * n if preset in TWO_LOBE_SPLIT else n
                thesis = THESIS_PSNR.get(preset, {}).get(key, "")
            rows.append((preset, method, value, rel_rmse, seconds * 1000.0, thesis, floor))
            ms = seconds * 1000
            line = f"{preset:22s} {method:8s} PSNR {value:6.2f} dB  relRMSE {rel_rmse:.4f}"
            print(f"{line}  {ms:8.1f} ms  thesis {thesis}", flush=True)
        print(
            f"{preset:22s} reference {args.reference_spp} spp per lobe: {ref_seconds:.1f} s,"
            f" noise floor {floor:.2f} dB",
            flush=True,
        )

    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    path = out_dir / f"preview_accuracy-{stamp}.md"
    lines = [
        "# lobe-N and fis-40 against the converged reference (preview sphere)",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- device: {device}",
        f"- environment: {env.name}; sphere {args.size}x{args.size} px, camera (0, 0.35, 3.2),"
        " fov 40 deg, cube faces 256 px",
        f"- reference: `reference`, {args.reference_spp} BSDF + {args.reference_spp} environment"
        " samples per lobe (MIS), unfiltered; its own noise floor is the PSNR between two"
        " references with different seeds (column 'ref. floor')",
        "- PSNR: object pixels, 8-bit sRGB after ACES, exposure mapping the reference's median luminance to 0.18",
        "- relRMSE: RMS of the linear radiance error over RMS of the reference (object pixels)",
        f"- time: median of {args.repeats} frames after a warm-up, wall clock around glFinish, shading pass only",
        "- lod bias: 0 for lobe-N (thesis), +1 for fis-N (Colbert & Krivanek)",
        "- thesis: PSNR of figures 4.39-4.41 at the same samples per lobe (other scene, environment"
        " and tonemapping; the thesis' chrome is blurry, lobeview's is sharp)",
        "",
        "| preset | method | PSNR (dB) | relRMSE | ms / frame | thesis PSNR (dB) | ref. floor (dB) |",
        "|---|---|---|---|---|---|---|",
    ]
    for preset, method, value, rel_rmse, ms, thesis, floor in rows:
        thesis_text = f"{thesis:.2f}" if thesis != "" else ""
        lines.append(f"| {preset} | {method} | {value:.2f} | {rel_rmse:.4f} | {ms:.1f} | {thesis_text} | {floor:.2f} |")
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
    renderer.release()
    ctx.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
