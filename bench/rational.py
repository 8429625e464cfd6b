"""Kurt (thesis) against Rational BRDF fits on the same data (issue 19, seed 002).

    .venv/bin/python -m lobeview.bench.rational [--quick] [--out bench/results]

For each material a virtual MERL table (the material evaluated at every MERL cell) is fitted
twice: the thesis model (1 lobe, hierarchical L1 search on the table's (2, 3, 6)-strided cells)
and the Rational BRDF (one rational function of (theta_h, theta_d) per channel, eps as given).
Both are scored on the same tuples with Eq. 3.7's L1 error, and by their directional albedo
against the true material's at three incidences. Times are wall clock of one process on this
shared machine: compare rows of one run.
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
from lobeview.materials.lobe_fit import LUMINANCE
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.materials.vec import direction_from_angles_deg

MATERIALS = ("plastic", "gold-ggx", "gltf-red-plastic")
ALBEDO_THETAS = (0.0, 45.0, 70.0)


def _albedo(desc: dict) -> list[float]:
    bsdf = build_bsdf(desc)
    return [float(bsdf.albedo(direction_from_angles_deg(t, 0.0), order=96)[0] @ LUMINANCE) for t in ALBEDO_THETAS]


def compare(name: str, quick: bool, say) -> list[str]:
    truth = load_material(name)
    table = meas.merl_table_from_bsdf(build_bsdf(truth))
    tuples = meas.merl_measurement(table, name=name)
    scale = material_error({"model": "thesis", "kd": 0.0}, tuples)  # the error of a black model
    rows = []
    t0 = time.perf_counter()
    grid, iterations = (6, 4) if quick else (8, 6)
    kurt = fit_thesis(tuples, FitOptions(lobes=1, grid=grid, iterations=iterations, isotropic=True))
    kurt_desc = kurt.material(name=f"{name} kurt", data="virtual-merl")
    rows.append(("Kurt, 1 lobe (thesis 3.4.1)", kurt_desc, time.perf_counter() - t0, "5 + kd"))
    say(f"{name}: Kurt fit in {rows[-1][2]:.1f} s")
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
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="eps 0.1 and a coarser Kurt grid")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"), help="results folder")
    args = parser.parse_args(argv)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    lines = [
        "# Kurt against Rational BRDF fits on the same virtual MERL data",
        "",
        f"Run {stamp}, {'quick' if args.quick else 'full'}; {platform.processor() or platform.machine()}, "
        f"numpy {np.__version__}; `python -m lobeview.bench.rational{' --quick' if args.quick else ''}`.",
        "Coefficients: Kurt's parameters (ks, mx, my, r0, alpha) + kd; Rational: numerator + denominator",
        "per channel (R+G+B). Not measured here: the rendered error (lobe-N against reference) of the fitted",
        "materials.",
        "",
    ]
    for name in MATERIALS:
        lines += compare(name, args.quick, print)
    out = Path(args.out) / f"rational-{stamp}{'-quick' if args.quick else ''}.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
