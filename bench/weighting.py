"""The thesis' two lobe-N quadratures side by side (Fig. 4.24): Eq. 4.24 (derived) against Eq. 4.25
(empirical, lobeview's default) and its energy-normalised form, on the preview sphere.

Fig. 4.24 shows a glossy metal (n = 15), an anisotropic metal (n = 15), frosted glass (5 + 5) and
varnish (n = 7) against the converged QMC reference: Eq. 4.25 is closer on all four (PSNR 41.27 /
41.35 / 50.99 / 50.33 dB against 38.41 / 37.25 / 50.86 / 49.88 dB). Here the same four material
classes (lobeview's presets alanod-2000gs-1lobe, miro5-1lobe, frosted-glass, lacquer; the thesis
does not name its glossy and anisotropic metals) plus gold-ggx, each with lobe-N+eq4.24,
lobe-N (Eq. 4.25) and lobe-N+norm at the thesis' N per lobe, against `reference` at the pixel
centres (pixel_filter='point': lobe-N shades the centres too, so the comparison is of shading
only). PSNR of 8-bit sRGB after ACES over the object's pixels, exposure mapping the reference's
median luminance to 0.18; relRMSE of linear radiance. The figure has one row per material:
Eq. 4.24 | Eq. 4.25 | reference | |error| x 15 of each (the thesis' scale).

    .venv/bin/python -m lobeview.bench.weighting [--size 160] [--spp 2048] [--env FILE|builtin:NAME]
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

import numpy as np

from lobeview.bench.metrics import exposure_for, psnr_8bit, relative_rmse
from lobeview.bench.report import write_image_rows
from lobeview.core.methods import Method
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.builtin_env import load_environment
from lobeview.scenes.meshes import uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import create_headless_context, renderer_description
from lobeview.viewer.preview import PreviewRenderer
from lobeview.viewer.tonemap import tonemap

# (preset, N per lobe, the thesis' material, thesis PSNR Eq. 4.24, Eq. 4.25) from Fig. 4.24
CASES = (
    ("alanod-2000gs-1lobe", 15, "glossy metal", 38.41, 41.27),
    ("miro5-1lobe", 15, "anisotropic", 37.25, 41.35),
    ("frosted-glass", 5, "frosted glass (5 + 5)", 50.86, 50.99),
    ("lacquer", 7, "varnish", 49.88, 50.33),
    ("gold-ggx", 15, "(not in the thesis)", None, None),
)
ERROR_SCALE = 15.0  # the thesis' difference-image scale
DEFAULT_ENV = Path(__file__).resolve().parents[1] / ".." / "shared" / "assets" / "env" / "blender_studiolights_1k"
DEFAULT_ENV = DEFAULT_ENV / "interior.exr"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=str(DEFAULT_ENV) if DEFAULT_ENV.exists() else "builtin:studio")
    parser.add_argument("--size", type=int, default=160, help="image size in pixels (square; default 160)")
    parser.add_argument("--spp", type=int, default=2048, help="reference samples per lobe (default 2048)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)

    ctx = create_headless_context()
    env = load_environment(args.env)
    renderer = PreviewRenderer(ctx, env, uv_sphere(), size=(args.size, args.size))
    camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
    device = renderer_description(ctx)
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    rows, figure_rows = [], []
    for preset, n, thesis_name, thesis_424, thesis_425 in CASES:
        bsdf = build_bsdf(load_material(preset))
        t0 = time.perf_counter()
        halves = [
            renderer.render(camera, bsdf, "reference", spp=args.spp // 2, seed=seed, background=False,
                            pixel_filter="point")
            for seed in (0, 1)
        ]  # fmt: skip
        mask = halves[0].mask
        reference = 0.5 * (halves[0].radiance + halves[1].radiance)
        exposure = exposure_for(reference, mask)

        def ldr(radiance, exposure=exposure):
            return np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0)

        floor = psnr_8bit(ldr(halves[0].radiance)[mask], ldr(halves[1].radiance)[mask]) + 6.02
        print(f"{preset}: reference {args.spp} spp in {time.perf_counter() - t0:.1f} s, floor {floor:.1f} dB",
              flush=True)  # fmt: skip
        images = {}
        for method in (Method("lobe", n, weighting="eq4.24"), Method("lobe", n), Method("lobe", n, normalize=True)):
            result = renderer.render(camera, bsdf, method, background=False)
            images[str(method)] = result.radiance
            value = psnr_8bit(ldr(result.radiance)[mask], ldr(reference)[mask])
            rel = relative_rmse(result.radiance[mask], reference[mask])
            thesis = thesis_424 if method.weighting == "eq4.24" else thesis_425 if not method.normalize else None
            rows.append((preset, thesis_name, str(method), value, rel, thesis, floor))
            print(f"  {method}: PSNR {value:.2f} dB, relRMSE {rel:.4f}", flush=True)
        eq424, eq425 = images[f"lobe-{n}+eq4.24"], images[f"lobe-{n}"]
        figure_rows.append(
            np.concatenate(
                [
                    ldr(eq424),
                    ldr(eq425),
                    ldr(reference),
                    np.clip(np.abs(ldr(eq424) - ldr(reference)) * ERROR_SCALE, 0, 1),
                    np.clip(np.abs(ldr(eq425) - ldr(reference)) * ERROR_SCALE, 0, 1),
                ],
                axis=1,
            )  # fmt: skip
        )
    renderer.release()
    ctx.release()

    out = Path(args.out)
    figure = write_image_rows(out, f"weighting-{stamp}.png", figure_rows)
    lines = [
        "# lobe-N: Eq. 4.24 against Eq. 4.25 (thesis Fig. 4.24)",
        "",
        f"Run {stamp}: `python -m lobeview.bench.weighting --size {args.size} --spp {args.spp}`; {device}.",
        f"Preview sphere {args.size}x{args.size} under {env.name}, cube faces {renderer.cubes.face_size} px;",
        f"reference: {args.spp} samples per lobe at the pixel centres (two halves: 'floor' is its own noise).",
        "PSNR: object pixels, 8-bit sRGB after ACES (exposure: reference median -> 0.18); relRMSE: linear.",
        "The thesis' PSNR is of its own scene, environment and tonemapping: compare the ranking, not the values.",
        f"Figure {figure.name}: rows as below; columns Eq. 4.24 | Eq. 4.25 | reference | |error| x "
        f"{ERROR_SCALE:g} of Eq. 4.24 | of Eq. 4.25.",
        "",
        "| preset | thesis material | method | PSNR (dB) | relRMSE | thesis PSNR (dB) | ref. floor (dB) |",
        "|---|---|---|---|---|---|---|",
    ]
    for preset, thesis_name, method, value, rel, thesis, floor in rows:
        thesis_text = f"{thesis:.2f}" if thesis is not None else ""
        lines.append(f"| {preset} | {thesis_name} | {method} | {value:.2f} | {rel:.4f} | {thesis_text} | {floor:.1f} |")
    path = out / f"weighting-{stamp}.md"
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path} and {figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
