"""Fitting bench (issue 19): the thesis presets as fit targets, fit time against n and P, error
against the number of lobes, and L1 against L2 under outliers.

    .venv/bin/python -m lobeview.bench.fit [--quick] [--out bench/results]

Every measurement here is virtual (:func:`lobeview.materials.measurement.virtual_measurement`):
the thesis' goniophotometer incidences (theta_i 0, 5, 20, 35, 50, 65 x phi_i 0..90 step 15, or
the white foil's 0..75), a 5 x 15 deg detector grid plus the peak scan. Times are wall clock of
one process on this machine (shared, noisy): compare rows of one run, not runs.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from lobeview.materials import measurement as meas
from lobeview.materials.fit import FitOptions, fit_thesis, material_error
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import build_bsdf, validate
from lobeview.materials.virtual import virtual_measurement

THESIS_TABLE_PRESETS = ("alanod-2000gs-1lobe", "alanod-2000gs-2lobe", "white-foil", "miro5-1lobe", "miro5-2lobe")


def _measure(name: str, quick: bool, **kw) -> meas.Measurement:
    desc = validate(PRESETS[name])
    iso = name == "white-foil"
    angles = dict(
        theta_i_deg=meas.THESIS_ISOTROPIC_THETA_I_DEG if iso else meas.THESIS_THETA_I_DEG,
        phi_i_deg=(0.0,) if iso else meas.THESIS_PHI_I_DEG,
        theta_step_deg=10.0 if quick else 5.0,
        phi_step_deg=30.0 if quick else 15.0,
    )
    return virtual_measurement(desc, **{**angles, **kw})


def _albedo(desc: dict) -> tuple[float, float]:
    r, t = build_bsdf(desc).albedo(np.array([0.0, 0.0, 1.0]), order=96)
    return float(r.mean()), float(t.mean())


def _lobe_text(desc: dict) -> str:
    parts = []
    for key, k in (("lobes", "ks"), ("transmission_lobes", "kt")):
        for lobe in desc.get(key, []):
            kv = lobe[k] if isinstance(lobe[k], float) else float(np.mean(lobe[k]))
            parts.append(
                f"{k} {kv:.3f} m ({lobe['mx']:.4f}, {lobe['my']:.4f}) r0 {lobe['r0']:.3f} a {lobe['alpha']:.2f}"
            )
    return "; ".join(parts)


def presets_section(quick: bool, say) -> list[str]:
    lines = [
        "## The thesis' fitted materials as fit targets (Tables 3.1-3.3)",
        "",
        "Virtual measurement of each table's model, fitted from scratch with the default intervals",
        "(k, r0, alpha in [0, 1], m in [0.001, 1]); kd from the histogram. `brute force` is the thesis'",
        "method alone (n = 8 and 3 alternations for two lobes; n = 6 and 2 with --quick, where the",
        "brute-force-only rows of the two-lobe presets are left out), `+ polish` adds the",
        "Nelder-Mead step (lobeview's default). Albedo: directional, normal incidence, RGB mean,",
        "reflectance (+ transmittance). Parameters: ks, (mx, my), r0, alpha per lobe.",
        "",
        "| preset | tuples | method | L1 error (Eq. 3.7) | albedo fit / table model | time | parameters |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name in THESIS_TABLE_PRESETS:
        truth = validate(PRESETS[name])
        m = _measure(name, quick)
        lobes = len(truth["lobes"])
        a_true = sum(_albedo(truth))
        lines.append(f"| {name} | {len(m)} | table | 0 | {a_true:.4f} | - | {_lobe_text(truth)} |")
        for polish in (False, True):
            if polish is False and lobes > 1 and quick:
                continue
            say(f"{name}: {'polish' if polish else 'brute force'}")
            opts = FitOptions(lobes=lobes, grid=6 if quick else 8, alternations=2 if quick else 3, polish=polish)
            t0 = time.perf_counter()
            result = fit_thesis(m, opts)
            seconds = time.perf_counter() - t0
            desc = result.material()
            a_fit = sum(_albedo(desc))
            label = "+ polish" if polish else "brute force"
            lines.append(
                f"| | | {label} | {result.error:.3g} | {a_fit:.4f} / {a_true:.4f} | {seconds:.1f} s | "
                f"{_lobe_text(desc)} |"
            )
    return lines + [""]


def time_section(quick: bool, say) -> list[str]:
    truth = validate(PRESETS["alanod-2000gs-1lobe"])
    lobe = truth["lobes"][0]
    m = _measure("alanod-2000gs-1lobe", True)
    order = ["mx", "my", "k", "r0", "alpha"]
    lines = [
        "## Fit time against n (values per parameter) and P (free parameters)",
        "",
        f"alanod-2000gs-1lobe, {len(m)} tuples (10 x 30 deg grid + peak scan), 6 iterations, no polish;",
        "the other parameters fixed at the true values. The brute force costs n^P x iterations",
        "candidate evaluations (k reuses each shape, so P counts it at the cost of a multiply-add).",
        "",
        "| n | P | free | evaluations | time | L1 error |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    ns = (4, 6, 8) if quick else (4, 6, 8, 10)
    for n in ns:
        for p in (2, 3, 4, 5):
            free = order[:p]
            fixed = {("k" if key == "ks" else key): v for key, v in lobe.items() if key not in free and key != "ks"}
            if "k" not in free:
                fixed["k"] = lobe["ks"]
            say(f"n={n} P={p}")
            opts = FitOptions(grid=n, iterations=6, polish=False, fixed={**fixed, "kd": truth["kd"]})
            t0 = time.perf_counter()
            result = fit_thesis(m, opts)
            lines.append(
                f"| {n} | {p} | {', '.join(free)} | {result.evaluations} | {time.perf_counter() - t0:.2f} s | "
                f"{result.error:.3g} |"
            )
    return lines + [""]


def lobes_section(quick: bool, say) -> list[str]:
    lines = [
        "## Error against the number of lobes",
        "",
        "Materials the thesis model holds only approximately: the Miro 5 two-lobe table model (its",
        "second, very anisotropic lobe), GGX gold (GGX's long tails and exact conductor Fresnel",
        "against Beckmann lobes with Schlick), the glTF red plastic (GGX + diffuse). n = 8 (6 quick),",
        "polish on. Relative error = Eq. 3.7 L1 / L1 of the data against zero.",
        "",
        "| material | lobes | L1 error | relative | albedo fit / truth | time |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for name in ("miro5-2lobe", "gold-ggx", "gltf-red-plastic"):
        truth = validate(PRESETS[name])
        m = _measure(name, True)
        zero = material_error({"model": "thesis", "kd": 0.0}, m)
        a_true = sum(_albedo(truth))
        for k in (1, 2, 3):
            say(f"{name}: {k} lobes")
            t0 = time.perf_counter()
            result = fit_thesis(m, FitOptions(lobes=k, grid=6 if quick else 8, alternations=2))
            a_fit = sum(_albedo(result.material()))
            lines.append(
                f"| {name} | {k} | {result.error:.3g} | {result.error / zero:.2%} | {a_fit:.4f} / "
                f"{a_true:.4f} | {time.perf_counter() - t0:.1f} s |"
            )
    return lines + [""]


def robustness_section(quick: bool, say) -> list[str]:
    truth = validate(PRESETS["alanod-2000gs-1lobe"])
    want = truth["lobes"][0]
    a_true = _albedo(truth)[0]
    lines = [
        "## L1 against L2 on data with outliers (the thesis' argument for Eq. 3.7)",
        "",
        "alanod-2000gs-1lobe with 2 % Gaussian noise and a fraction of tuples replaced by spikes",
        "(10-100 x the median value), 3 seeds each; n = 6, polish on. Columns: worst relative error of",
        "mx and my over the seeds, and of the albedo.",
        "",
        "| outliers | metric | mx, my error (worst) | albedo error (worst) |",
        "| --- | --- | --- | --- |",
    ]
    for fraction in (0.0, 0.01, 0.05):
        for metric in ("l1", "l2"):
            worst_m = worst_a = 0.0
            for seed in range(3):
                say(f"outliers {fraction} {metric} seed {seed}")
                m = _measure("alanod-2000gs-1lobe", True, noise=0.02, outliers=fraction, seed=seed)
                result = fit_thesis(m, FitOptions(grid=6, metric=metric))
                p = result.lobes[0].params
                worst_m = max(worst_m, abs(p["mx"] / want["mx"] - 1), abs(p["my"] / want["my"] - 1))
                worst_a = max(worst_a, abs(_albedo(result.material())[0] / a_true - 1))
            lines.append(f"| {fraction:.0%} | {metric.upper()} | {worst_m:.1%} | {worst_a:.1%} |")
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="coarser grids, fewer rows (~2 min)")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"), help="results folder")
    args = parser.parse_args(argv)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    t0 = time.perf_counter()

    def say(msg):
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)

    lines = [
        f"# Fitting bench {stamp}{' (quick)' if args.quick else ''}",
        "",
        f"`python -m lobeview.bench.fit{' --quick' if args.quick else ''}` on {platform.node() or 'this machine'} "
        f"({platform.processor() or platform.machine()}, numpy {np.__version__}); CPU only, one process.",
        "",
    ]
    for section in (time_section, robustness_section, lobes_section, presets_section):
        lines += section(args.quick, say)
    lines.append(f"Total {time.perf_counter() - t0:.0f} s.")
    out = Path(args.out) / f"fit-{stamp}{'-quick' if args.quick else ''}.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
