"""lobe-N's pattern against N: the thesis' ring against lobeview's default (issue 20 item 1, issue 45).

The thesis' ring puts every sample but the centre at 40 % of the lobe radius and filters each over
lobe area / N (Eq. 4.14-4.17): as N grows the footprints shrink while the lobe's rim stays
unsampled, so PSNR fell with N on glossy lobes. lobe-N takes a double ring (centre, inner ring at
35 %, outer ring at 70 % of the lobe radius) from N = 11 on (materials/patterns.py step 3; it
replaced a Fibonacci spiral that made lobe-15 worse than lobe-7 against Mitsuba). This bench
renders lobe-N+norm (the viewer's default) with the default pattern and with ``+ring`` (the
thesis' ring at every N) for N = 3..19 on the preview sphere under each environment, against
the box-filtered `reference` (two halves: 'floor' is its own noise), and lists every step where
PSNR falls as N grows. The figure has, per preset, at the
largest N: ring | default | reference | |error| x 8 of each.

    .venv/bin/python -m lobeview.bench.patterns [--envs interior courtyard] [--size 200] [--spp 1024]
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.bench.metrics import exposure_for, psnr_8bit, relative_rmse
from lobeview.bench.report import write_image_rows
from lobeview.bench.targets import resolve_environment
from lobeview.core.methods import DEFAULT_LOBE_LOD_BIAS, Method
from lobeview.materials.patterns import DOUBLE_RING_MIN_SAMPLES
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.meshes import uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import create_headless_context, renderer_description
from lobeview.viewer.mip_chain import DEFAULT_MIP_FILTER
from lobeview.viewer.preview import PreviewRenderer
from lobeview.viewer.tonemap import tonemap

PRESETS = ("chrome", "lacquer", "plastic", "gltf-red-plastic", "gold-ggx", "frosted-glass", "alanod-2000gs-1lobe")
SAMPLES = (3, 5, 7, 11, 15, 19)
PATTERNS = ("auto", "ring")
ERROR_SCALE = 8.0
FALL_TOLERANCE_DB = 0.1  # steps that lose less than this are within the reference's noise here


def falls(values: list[float], samples: tuple[int, ...]) -> str:
    """'7->11 -1.05, ...' for every step where PSNR drops by more than FALL_TOLERANCE_DB."""
    drops = [
        f"{samples[i]}->{samples[i + 1]} {values[i + 1] - values[i]:+.2f}"
        for i in range(len(values) - 1)
        if values[i + 1] < values[i] - FALL_TOLERANCE_DB
    ]
    return ", ".join(drops) if drops else "none"


def sphere_bench_parser(description: str) -> argparse.ArgumentParser:
    """The command line the preview-sphere benches share (this one and mip_chain.py): environments,
    presets, image size, reference samples, output folder."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--envs", nargs="+", default=["interior", "courtyard"],
                        help="sphere environments: interior, courtyard, city, builtin:NAME or a file")  # fmt: skip
    parser.add_argument("--presets", nargs="+", default=list(PRESETS))
    parser.add_argument("--size", type=int, default=200, help="image size in pixels (square; default 200)")
    parser.add_argument("--spp", type=int, default=1024, help="reference samples per lobe (default 1024)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    return parser


def main(argv=None) -> int:
    parser = sphere_bench_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--samples", nargs="+", type=int, default=list(SAMPLES), help="the N of lobe-N")
    args = parser.parse_args(argv)
    samples = tuple(sorted(set(args.samples)))

    ctx = create_headless_context()
    camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
    device = renderer_description(ctx)
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    table, figure_rows, env_names = [], [], []
    started = time.perf_counter()
    for env_name in args.envs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # capture clamps (a few negative texels) are not news here
            env = resolve_environment(env_name)
        env_names.append(Path(env.name).name)
        renderer = PreviewRenderer(ctx, env, uv_sphere(), size=(args.size, args.size))
        for preset in args.presets:
            bsdf = build_bsdf(load_material(preset))
            t0 = time.perf_counter()
            halves = [
                renderer.render(camera, bsdf, "reference", spp=args.spp // 2, seed=seed, background=False)
                for seed in (0, 1)
            ]
            mask = halves[0].mask
            reference = 0.5 * (halves[0].radiance + halves[1].radiance)
            exposure = exposure_for(reference, mask)

            def ldr(radiance, exposure=exposure):
                return np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0)

            floor = psnr_8bit(ldr(halves[0].radiance)[mask], ldr(halves[1].radiance)[mask]) + 6.02
            print(f"{env_names[-1]} {preset}: reference {args.spp} spp in {time.perf_counter() - t0:.1f} s, "
                  f"floor {floor:.1f} dB", flush=True)  # fmt: skip
            last = {}
            for pattern in PATTERNS:
                values, rels = [], []
                for n in samples:
                    method = Method("lobe", n, normalize=True, pattern=pattern)
                    result = renderer.render(camera, bsdf, method, background=False)
                    values.append(psnr_8bit(ldr(result.radiance)[mask], ldr(reference)[mask]))
                    rels.append(relative_rmse(result.radiance[mask], reference[mask]))
                    last[pattern] = ldr(result.radiance)
                table.append((env_names[-1], preset, pattern, values, rels, floor))
                print(f"  {pattern:5s} " + " ".join(f"{v:6.2f}" for v in values) + f"  falls: {falls(values, samples)}",
                      flush=True)  # fmt: skip
            ref_ldr = ldr(reference)
            figure_rows.append(
                np.concatenate(
                    [last["ring"], last["auto"], ref_ldr]
                    + [np.clip(np.abs(last[p] - ref_ldr) * ERROR_SCALE, 0.0, 1.0) for p in ("ring", "auto")],
                    axis=1,
                )
            )
        renderer.release()
    ctx.release()

    out = Path(args.out)
    figure = write_image_rows(out, f"patterns-{stamp}.png", figure_rows)
    n_text = " | ".join(f"N={n}" for n in samples)
    lines = [
        "# lobe-N against N: the thesis' ring and lobeview's default pattern",
        "",
        f"Run {stamp}: `python -m lobeview.bench.patterns --envs {' '.join(args.envs)} --size {args.size} "
        f"--spp {args.spp}`; {device}; {time.perf_counter() - started:.0f} s.",
        f"Preview sphere {args.size}x{args.size}, cube faces 256 px, environments {', '.join(env_names)}.",
        "Methods: lobe-N+norm (the viewer's default: Eq. 4.25, energy-normalised, "
        f"LOD bias {DEFAULT_LOBE_LOD_BIAS:+g}, {DEFAULT_MIP_FILTER} MIP chain) with the default pattern ('auto': "
        f"the ring below N = {DOUBLE_RING_MIN_SAMPLES}, the double ring from N = {DOUBLE_RING_MIN_SAMPLES})",
        "and with +ring (the thesis' ring at every N); anisotropic lobes (max/min roughness >= 3) take the",
        "line pattern either way.",
        f"Reference: `reference`, {args.spp} samples per lobe, box-filtered pixel integral, two halves ('floor':",
        "PSNR the reference's own noise allows). PSNR: object pixels, 8-bit sRGB after ACES (exposure: reference",
        f"median -> 0.18). 'falls': steps where PSNR drops by more than {FALL_TOLERANCE_DB} dB as N grows.",
        f"Figure {figure.name}: one row per environment and preset (in table order), at N = {samples[-1]}:",
        f"ring | default | reference | |error| x {ERROR_SCALE:g} of the ring | of the default.",
        "",
        f"| environment | preset | pattern | {n_text} | falls | relRMSE at N={samples[-1]} | floor (dB) |",
        "|---|---|---|" + "---|" * len(samples) + "---|---|---|",
    ]
    for env_label, preset, pattern, values, rels, floor in table:
        cells = " | ".join(f"{v:.2f}" for v in values)
        fell = falls(values, samples)
        lines.append(f"| {env_label} | {preset} | {pattern} | {cells} | {fell} | {rels[-1]:.4f} | {floor:.1f} |")
    path = out / f"patterns-{stamp}.md"
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path} and {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
