"""Kurt (thesis), glTF (microfacet) and Rational BRDF fits on the same data (issue 19, seed 002).

    .venv/bin/python -m lobeview.bench.rational [--quick] [--out bench/results]

For each material a virtual MERL table (the material evaluated at every MERL cell) is fitted
three times: the thesis model (1 lobe, hierarchical L1 search on the table's (2, 3, 6)-strided
cells), the glTF metallic-roughness model (``fit --model microfacet``, isotropic) and the
Rational BRDF (one rational function of (theta_h, theta_d) per channel, eps as given). All are
scored on the same tuples with Eq. 3.7's L1 error, and by their directional albedo against the
true material's at three incidences.

Rendered error: the preview sphere under an HDR environment, each fitted material and the true
one rendered with ``reference`` (two independent halves, so the reference's own noise floor is
known) and with ``lobe-7`` / ``lobe-15``. Columns: the fitted material's reference against the
truth's (what the fit error looks like), lobe-N of the fitted material against its own reference
(what the real-time method adds for that model), and lobe-N against the truth (what a user sees).
Times are wall clock of one process on this shared machine: compare rows of one run.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from lobeview.materials import measurement as meas
from lobeview.materials import rational_brdf as rb
from lobeview.materials.fit import FitOptions, fit_thesis, material_error
from lobeview.materials.fit_gltf import GltfFitOptions, fit_gltf
from lobeview.materials.lobe_fit import LUMINANCE
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.materials.vec import direction_from_angles_deg

MATERIALS = ("plastic", "gold-ggx", "gltf-red-plastic")
ALBEDO_THETAS = (0.0, 45.0, 70.0)


def _albedo(desc: dict) -> list[float]:
    bsdf = build_bsdf(desc)
    return [float(bsdf.albedo(direction_from_angles_deg(t, 0.0), order=96)[0] @ LUMINANCE) for t in ALBEDO_THETAS]


def compare(name: str, quick: bool, say, lobes: int = 1) -> list[str]:
    truth = load_material(name)
    table = meas.merl_table_from_bsdf(build_bsdf(truth))
    tuples = meas.merl_measurement(table, name=name)
    scale = material_error({"model": "thesis", "kd": 0.0}, tuples)  # the error of a black model
    rows = []
    t0 = time.perf_counter()
    grid, iterations = (6, 4) if quick else (8, 6)
    kurt = fit_thesis(tuples, FitOptions(lobes=lobes, grid=grid, iterations=iterations, isotropic=True))
    kurt_desc = kurt.material(name=f"{name} kurt", data="virtual-merl")
    plural = "lobe" if lobes == 1 else "lobes"
    rows.append((f"Kurt, {lobes} {plural} (thesis 3.4.1)", kurt_desc, time.perf_counter() - t0, f"{5 * lobes} + kd"))
    say(f"{name}: Kurt fit in {rows[-1][2]:.1f} s")
    t0 = time.perf_counter()
    gltf = fit_gltf(tuples, GltfFitOptions(grid=grid, iterations=iterations, isotropic=True))
    rows.append(("glTF metallic-roughness (--model microfacet)", gltf.material(f"{name} gltf", "virtual-merl"),
                 time.perf_counter() - t0, "3 + base colour"))  # fmt: skip
    say(f"{name}: glTF fit in {rows[-1][2]:.1f} s")
    eps = 0.1 if quick else 0.05
    t0 = time.perf_counter()
    fit = rb.fit_rational_brdf(rb.project_merl(table), eps=eps, max_coefficients=40)
    sampling = rb.fit_sampling(fit.functions, fit.theta_max_deg)
    rational_desc = rb.rational_description(fit, sampling, f"{name} rational")
    counts = "+".join(str(sum(fn.counts)) for fn in fit.functions)
    rows.append((f"Rational, eps {eps}", rational_desc, time.perf_counter() - t0, counts))
    say(f"{name}: Rational fit in {rows[-1][2]:.1f} s")
    true_albedo = _albedo(truth)
    lines = [
        f"### {name}",
        "",
        f"{len(tuples)} tuples; Eq. 3.7 L1 of a black model (the scale): {scale:.4g}; true albedo "
        + ", ".join(f"{a:.4f}" for a in true_albedo)
        + f" at theta_i {ALBEDO_THETAS} deg",
        "",
        "| model | coefficients | fit time (s) | Eq. 3.7 L1 | L1 / black | albedo at theta_i 0 / 45 / 70 |",
        "|---|---|---|---|---|---|",
    ]
    for label, desc, seconds, coefficients in rows:
        error = material_error(desc, tuples)
        albedo = _albedo(desc)
        lines.append(
            f"| {label} | {coefficients} | {seconds:.1f} | {error:.4g} | {error / scale:.2%} | "
            + " / ".join(f"{a:.4f}" for a in albedo)
            + " |"
        )
    return lines + [""], [(label, desc) for label, desc, _, _ in rows]


# lobe-N with the energy normalisation: what `shot` and the viewer use by default (--lobe-normalize)
RENDER_METHODS = ("lobe-7+norm", "lobe-15+norm")


def rendered_section(fits: dict, quick: bool, env_path: str, say) -> list[str]:
    """The rendered error of every fitted material (see the module docstring)."""
    from lobeview.bench.metrics import exposure_for, make_reference, psnr_8bit, relative_rmse
    from lobeview.core.methods import Method
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.preview import PreviewRenderer
    from lobeview.viewer.tonemap import tonemap

    size, spp = (128, 1024) if quick else (256, 4096)
    ctx = create_headless_context()
    env = load_environment(env_path)
    renderer = PreviewRenderer(ctx, env, uv_sphere(), size=(size, size))
    camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
    lines = [
        "## Rendered error of the fitted materials",
        "",
        f"Preview sphere {size}x{size} under {env.name}, {renderer_description(ctx)}. `reference`: {spp} samples",
        "per lobe as two independent halves (floor: the reference's own noise, from their difference).",
        "PSNR: object pixels, 8-bit sRGB after ACES with the true material's exposure; relRMSE of linear",
        "radiance. 'fit': the fitted material's reference against the truth's; 'method': lobe-N of the",
        "fitted material against its own reference; 'seen': lobe-N against the truth.",
        "",
        "| material | model | fit relRMSE | fit PSNR | method | method relRMSE / PSNR | seen relRMSE / PSNR | ms |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def render_of(bsdf):
        return lambda method, spp=1, seed=0: renderer.render(camera, bsdf, method, spp=spp, seed=seed, background=False)

    def ldr(radiance, exposure):
        return np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0)

    for name, models in fits.items():
        truth = make_reference(render_of(build_bsdf(load_material(name))), lambda r: r.mask, spp)
        mask, exposure = truth.mask, exposure_for(truth.radiance, truth.mask)
        say(f"{name}: true reference in {truth.seconds:.1f} s, floor {truth.psnr_floor:.1f} dB")
        lines.append(
            f"| {name} | (truth: reference floor) | {truth.rel_rmse_floor:.4f} | {truth.psnr_floor:.1f} | | | | |"
        )
        truth_ldr = ldr(truth.radiance, exposure)[mask]
        for label, desc in models:
            render = render_of(build_bsdf(desc))
            own = make_reference(render, lambda r: r.mask, spp)
            fit_rel = relative_rmse(own.radiance[mask], truth.radiance[mask])
            fit_psnr = psnr_8bit(ldr(own.radiance, exposure)[mask], truth_ldr)
            for method in RENDER_METHODS:
                render(Method.parse(method))  # warm-up: shader compile, lobe tables
                t0 = time.perf_counter()
                image = render(Method.parse(method)).radiance
                ms = 1000 * (time.perf_counter() - t0)
                own_err = (relative_rmse(image[mask], own.radiance[mask]),
                           psnr_8bit(ldr(image, exposure)[mask], ldr(own.radiance, exposure)[mask]))  # fmt: skip
                seen = (
                    relative_rmse(image[mask], truth.radiance[mask]),
                    psnr_8bit(ldr(image, exposure)[mask], truth_ldr),
                )
                lines.append(
                    f"| {name} | {label.split(' (')[0]} | {fit_rel:.4f} | {fit_psnr:.1f} | {method} | "
                    f"{own_err[0]:.4f} / {own_err[1]:.1f} | {seen[0]:.4f} / {seen[1]:.1f} | {ms:.0f} |"
                )
            say(f"{name}: {label}: fit relRMSE {fit_rel:.4f}, {fit_psnr:.1f} dB")
    renderer.release()
    ctx.release()
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="eps 0.1 and a coarser Kurt grid")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"), help="results folder")
    parser.add_argument("--env", default=None, help="environment of the rendered error (default: the interior HDR)")
    parser.add_argument("--no-render", action="store_true", help="skip the rendered error (fits only)")
    args = parser.parse_args(argv)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    lines = [
        "# Kurt against Rational BRDF fits on the same virtual MERL data",
        "",
        f"Run {stamp}, {'quick' if args.quick else 'full'}; {platform.processor() or platform.machine()}, "
        f"numpy {np.__version__}; `python -m lobeview.bench.rational{' --quick' if args.quick else ''}`.",
        "Coefficients: Kurt's parameters (ks, mx, my, r0, alpha) + kd; glTF: roughness, metallic, anisotropy",
        "(fixed 0: isotropic data) + base colour; Rational: numerator + denominator per channel (R+G+B).",
        "",
    ]
    fits = {}
    for name in MATERIALS:
        section, fits[name] = compare(name, args.quick, print)
        lines += section
    if not args.no_render:
        from lobeview.bench.preview_accuracy import DEFAULT_ENV

        env = args.env or (str(DEFAULT_ENV) if DEFAULT_ENV.exists() else "builtin:studio")
        lines += rendered_section(fits, args.quick, env, print)
    from lobeview.bench.report import write_markdown_report

    write_markdown_report(Path(args.out), f"rational-{stamp}{'-quick' if args.quick else ''}.md", lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
