"""Model selection of the thesis fit (issue 44 item 3; materials/fit_selection.py): does the data
support a diffuse term, and which lobe parameters does it leave undetermined?

For conductors without a diffuse term (GGX gold, anisotropic Beckmann steel, chrome) and for
materials with one (the thesis' Alanod, plastic, lacquer, porcelain, glTF red plastic), measured
three ways (the thesis' virtual goniophotometer; the same with 5 % noise and 1 % outlier spikes;
a MERL table, isotropic materials only), one reflection lobe is fitted with the histogram's kd
(thesis 3.4.1) and with kd = 0. The table gives the true kd, the histogram's, Eq. 3.7 of both
fits relative to the data's L1 mass, the gain of kd as a fraction of that mass and of the kd = 0
fit's error, and what ``--diffuse auto`` decides. A second table: the (ks, r0) valley of each
fit with and without the polish step.

    .venv/bin/python -m lobeview.bench.fit_selection [--out bench/results/fit-selection-STAMP.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from lobeview.materials import measurement as meas
from lobeview.materials.fit import FitOptions, fit_thesis
from lobeview.materials.fit_selection import signal_mass
from lobeview.materials.lobe_fit import LUMINANCE
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import build_bsdf, validate
from lobeview.materials.virtual import virtual_measurement

CONDUCTORS = ("gold-ggx", "brushed-steel-beckmann", "chrome")
DIFFUSE = ("alanod-2000gs-1lobe", "plastic", "lacquer", "porcelain", "gltf-red-plastic")
VARIANTS = ("goniophotometer", "noise 5 % + outliers 1 %", "MERL table")


def _true_kd(desc: dict) -> float:
    if desc.get("model") == "gltf":
        colour = np.asarray(desc.get("base_color", [1.0, 1.0, 1.0]), dtype=float)[:3]
        return float(colour @ LUMINANCE) * (1.0 - float(desc.get("metallic", 0.0)))
    kd = np.broadcast_to(np.asarray(desc.get("kd", 0.0), dtype=float), (3,))
    return float(kd @ LUMINANCE)


def _measure(name: str, variant: str) -> meas.Measurement | None:
    desc = validate(PRESETS[name])
    if variant == "MERL table":
        if name == "brushed-steel-beckmann":
            return None  # anisotropic: a MERL table cannot hold it
        return meas.merl_measurement(meas.merl_table_from_bsdf(build_bsdf(desc)), name=name)
    noisy = variant != "goniophotometer"
    return virtual_measurement(desc, name=name, noise=0.05 if noisy else 0.0, outliers=0.01 if noisy else 0.0)


def run() -> tuple[list[dict], list[dict]]:
    rows, valleys = [], []
    for name in CONDUCTORS + DIFFUSE:
        for variant in VARIANTS:
            m = _measure(name, variant)
            if m is None:
                continue
            isotropic = variant == "MERL table"
            t0 = time.perf_counter()
            auto = fit_thesis(m, FitOptions(isotropic=isotropic))
            seconds = time.perf_counter() - t0
            with_kd = fit_thesis(m, FitOptions(isotropic=isotropic, diffuse="histogram"))
            without = fit_thesis(m, FitOptions(isotropic=isotropic, fixed={"kd": 0.0}))
            signal = with_kd.model_mass
            kd_hist = float(with_kd.kd @ LUMINANCE) if len(with_kd.kd) == 3 else float(with_kd.kd[0])
            rows.append(
                {
                    "material": name,
                    "data": variant,
                    "true_kd": _true_kd(PRESETS[name]),
                    "kd_histogram": kd_hist,
                    "error_with": with_kd.error / signal,
                    "error_without": without.error / signal,
                    "gain_of_mass": (without.error - with_kd.error) / signal,
                    "gain_of_error": (without.error - with_kd.error) / max(without.error, 1e-300),
                    "data_mass": signal_mass(m.luminance, _weights(m)) / signal,
                    "kept": bool(auto.diffuse.kept) if auto.diffuse is not None else None,
                    "seconds": seconds,
                }
            )
            print(f"{name} / {variant}: {rows[-1]}", file=sys.stderr, flush=True)
            if variant == "goniophotometer":
                no_polish = fit_thesis(m, FitOptions(isotropic=isotropic, polish=False))
                for label, fit in (("polished", auto), ("no polish", no_polish)):
                    for valley in fit.valleys:
                        p = fit.lobes[0].params if fit.lobes else {}
                        valleys.append({"material": name, "fit": label, "ks": p.get("k"), "r0": p.get("r0"),
                                        **valley.as_dict()})  # fmt: skip
    return rows, valleys


def _weights(m):
    from lobeview.materials.fit import metric_weights

    return metric_weights(m)


def markdown(rows: list[dict], valleys: list[dict], elapsed: float) -> str:
    lines = [
        "# Thesis fit: model selection by the data (issue 44 item 3)",
        "",
        f"`python -m lobeview.bench.fit_selection` ({time.strftime('%Y-%m-%d')}, {elapsed / 60:.1f} min). One "
        "reflection lobe, default grid; errors are Eq. 3.7 (L1, luminance) relative to the L1 mass of the fit with the "
        "histogram's kd (its Eq. 3.7 against 0: what it explains; *data / fit mass*: the data's own, which outlier "
        "spikes inflate). *gain*: how much the histogram's kd lowers the error, as a fraction of that mass and of "
        "the kd = 0 fit's error. *auto*: what `--diffuse auto` keeps (materials/fit_selection.py: from 10 % of the "
        "mass or 50 % of the error).",
        "",
        "| material | data | true kd (lum.) | histogram kd | data / fit mass | error with kd | error kd = 0 "
        "| gain / mass | gain / error | auto keeps kd | auto fit s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['material']} | {r['data']} | {r['true_kd']:.3f} | {r['kd_histogram']:.4f} | {r['data_mass']:.2f} "
            f"| {r['error_with']:.4f} "
            f"| {r['error_without']:.4f} | {r['gain_of_mass']:.4f} | {r['gain_of_error']:.3f} "
            f"| {'-' if r['kept'] is None else ('yes' if r['kept'] else 'no')} | {r['seconds']:.1f} |"
        )
    lines += [
        "",
        "The (ks, r0) valley of each lobe (goniophotometer data): r0 values whose best ks fits within 1 % of the best "
        "error (materials/fit_selection.py lobe_valley), with and without the Nelder-Mead polish.",
        "",
        "| material | fit | ks | r0 | r0 interval | ks interval | ks r0 | degenerate | on a bound |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for v in valleys:
        lines.append(
            f"| {v['material']} | {v['fit']} | {v['ks']:.4g} | {v['r0']:.4g} | {v['r0_interval'][0]:.3g}-"
            f"{v['r0_interval'][1]:.3g} | {v['ks_interval'][0]:.3g}-{v['ks_interval'][1]:.3g} "
            f"| {v['product_interval'][0]:.3g}-{v['product_interval'][1]:.3g} | {'yes' if v['degenerate'] else 'no'} "
            f"| {'; '.join(v['at_bounds']) or '-'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.fit_selection", description=__doc__.split("\n\n")[0])
    stamp = time.strftime("%Y%m%d-%H%M%S")
    p.add_argument("--out", default=str(Path(__file__).parent / "results" / f"fit-selection-{stamp}.md"))
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    rows, valleys = run()
    text = markdown(rows, valleys, time.perf_counter() - t0)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
