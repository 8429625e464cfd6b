"""What the data supports, for the thesis fit (materials/fit.py; issue 44 item 3).

- **The diffuse term.** Thesis 3.4.1 takes kd as pi times the most common BRDF value. A GGX
  conductor has no diffuse term, but its tail is nearly flat far from the peak (D ~ alpha^2 /
  (pi sin^4 theta_h)), so the histogram finds a "diffuse plateau" there (gold GGX alpha 0.15:
  kd 0.04 on the goniophotometer grid, 0.14 from a MERL table) and the fit renders a metal with a
  lightmap-lit diffuse glow it does not have. materials/fit.py fit_thesis fits with and without
  it (the kd = 0 fit's lobes are free to take the tail) and :class:`DiffuseChoice` keeps it only
  where it lowers Eq. 3.7 by at least :data:`KD_MIN_GAIN` of what the fitted model explains (its
  own weighted L1 mass, sum w |cos theta_i| |p_model|: the data's mass would count outlier
  spikes), or by at least :data:`KD_EXACT_SHARE` of the kd = 0 fit's error (a small diffuse term
  that makes the fit exact, as the thesis' Alanod's kd 0.003).
- **Degenerate parameters.** A lobe's k and r0 trade off where the data holds little of the
  grazing Fresnel rise: k r0 is fixed, each alone is not (without the polish step the issue
  measured ks -33 %, r0 +49 %, their product exact). :func:`lobe_valley` profiles the error
  along r0 (the best k for each r0, the other parameters kept) and reports the interval that
  fits within :data:`VALLEY_TOLERANCE` of the best, and parameters that sit on a bound of their
  range, instead of presenting one point of the valley as the answer."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: kd is kept when it lowers Eq. 3.7 by at least this fraction of the fitted model's L1 mass, or
#: by at least KD_EXACT_SHARE of the kd = 0 fit's error. Measured on one lobe, three kinds of data
#: (goniophotometer, with 5 % noise and 1 % outliers, MERL table): bench/results/fit-selection-20261127-043100.md.
KD_MIN_GAIN = 0.1
KD_EXACT_SHARE = 0.5
#: The valley: parameter values whose error stays within this fraction of the best error (plus
#: VALLEY_FLOOR of the data's L1 mass, so an exact fit's rounding does not count as a valley).
VALLEY_TOLERANCE = 0.01
VALLEY_FLOOR = 1e-4
VALLEY_R0_VALUES = 41
#: A valley this wide (in r0, of the range searched) is reported as a degenerate pair.
VALLEY_DEGENERATE_WIDTH = 0.2


class FitError(ValueError):
    """Options or data that cannot be fitted (named parameter, range, empty hemisphere...)."""


def metric_weights(m) -> np.ndarray:
    """w |cos theta_i| / sum w of Eq. 3.7, shape (N,)."""
    total = float(m.weight.sum())
    if total <= 0:
        raise FitError(f"{m.name}: all weights are zero")
    return m.weight * np.abs(m.wi[:, 2]) / total


def eq37_error(measured: np.ndarray, model: np.ndarray, weights: np.ndarray, metric: str = "l1") -> float:
    """Thesis Eq. 3.7 (or its squared variant) for one channel."""
    diff = np.asarray(measured, dtype=np.float64) - np.asarray(model, dtype=np.float64)
    return float(np.sum(weights * penalty(diff, metric)))


def penalty(diff: np.ndarray, metric: str) -> np.ndarray:
    """|d| for Eq. 3.7's L1 metric, d^2 for the squared variant (materials/fit.py)."""
    return np.abs(diff) if metric == "l1" else diff * diff


def signal_mass(target: np.ndarray, weights: np.ndarray) -> float:
    """Eq. 3.7 of a model that predicts 0: the data's own weighted L1 mass."""
    return float(np.sum(weights * np.abs(target)))


@dataclass
class DiffuseChoice:
    """The fit with the histogram's kd against the fit with kd = 0."""

    kd_histogram: np.ndarray  # (C,)
    error_with: float  # Eq. 3.7 (luminance) of the fit with kd_histogram
    error_without: float  # ... with kd = 0
    model_mass: float  # the kd fit's own weighted L1 mass

    @property
    def gain(self) -> float:
        """How much kd lowers the error, as a fraction of the fitted model's L1 mass."""
        return (self.error_without - self.error_with) / max(self.model_mass, 1e-300)

    @property
    def share(self) -> float:
        """How much kd lowers the error, as a fraction of the kd = 0 fit's error."""
        return (self.error_without - self.error_with) / max(self.error_without, 1e-300)

    @property
    def kept(self) -> bool:
        return self.gain >= KD_MIN_GAIN or self.share >= KD_EXACT_SHARE

    def message(self) -> str:
        kd = np.array2string(np.asarray(self.kd_histogram), precision=4)
        gain = (
            f"lowers the L1 error by {100 * self.gain:.1f} % of the fit's L1 mass, {100 * self.share:.0f} % of "
            "the kd = 0 fit's error"
        )
        rule = f"{100 * KD_MIN_GAIN:.0f} % of the mass or {100 * KD_EXACT_SHARE:.0f} % of the error"
        if self.kept:
            return f"diffuse term supported by the data: the histogram's kd {kd} {gain} (kept from {rule})"
        return (
            f"diffuse term not supported by the data: the histogram's kd {kd} {gain} (kept from {rule}; a "
            "conductor's flat lobe tail looks like a plateau): kd = 0. Keep it with --diffuse histogram, or set "
            "it with --fix kd=VALUE"
        )

    def as_dict(self) -> dict:
        return {
            "kd_histogram": [round(float(v), 6) for v in np.atleast_1d(self.kd_histogram)],
            "error_with_kd": self.error_with,
            "error_without_kd": self.error_without,
            "gain_of_model_l1": self.gain,
            "gain_of_error": self.share,
            "kept": self.kept,
        }


def best_scale(target: np.ndarray, unit: np.ndarray, weights: np.ndarray, metric: str, hi: float) -> float:
    """The exact minimiser over s in [0, hi] of sum w |target - s unit| (L1: a weighted median of
    target / unit with weights w unit) or of the squared variant (least squares), for unit >= 0."""
    target, unit, weights = (np.asarray(a, dtype=np.float64) for a in (target, unit, weights))
    use = unit > 0
    if not use.any():
        return 0.0
    if metric == "l2":
        s = float(np.sum(weights * target * unit) / np.sum(weights * unit * unit))
    else:
        ratio, mass = target[use] / unit[use], (weights * unit)[use]
        order = np.argsort(ratio)
        cumulative = np.cumsum(mass[order])
        s = float(ratio[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])
    return min(max(s, 0.0), hi)


@dataclass
class Valley:
    """Where one lobe's error stays within the tolerance of its best, along r0."""

    label: str
    r0: tuple[float, float]
    k: tuple[float, float]
    product: tuple[float, float]  # k r0 over the valley (k (1 - r0) for a transmission lobe)
    r0_range: tuple[float, float]  # the range searched
    at_bounds: list[str]  # "r0 = 1 (its upper bound)", ...
    fit: tuple[float, float]  # the fit's own (k, r0)
    best: tuple[float, float, float]  # the profile's best (k, r0) and its error relative to the fit's

    @property
    def off_valley(self) -> bool:
        """The fit's r0 lies outside the valley: the search stopped short of its floor."""
        return not (self.r0[0] - 1e-9 <= self.fit[1] <= self.r0[1] + 1e-9)

    @property
    def scale(self) -> str:
        return "kt" if self.label.startswith("transmission") else "ks"

    @property
    def determined(self) -> str:
        """The product the data fixes along the valley."""
        return "kt (1 - r0)" if self.scale == "kt" else "ks r0"

    @property
    def degenerate(self) -> bool:
        lo, hi = self.r0_range
        return self.r0[1] - self.r0[0] >= VALLEY_DEGENERATE_WIDTH * (hi - lo)

    def messages(self) -> list[str]:
        out = []
        if self.degenerate:
            out.append(
                f"{self.label}: {self.scale} and r0 are not determined separately by the data: any r0 in "
                f"[{self.r0[0]:.3g}, {self.r0[1]:.3g}] with {self.scale} in [{self.k[0]:.3g}, {self.k[1]:.3g}] "
                "fits within "
                f"{100 * VALLEY_TOLERANCE:.0f} % of the best error; only {self.determined} ~ {self.product[0]:.3g}-"
                f"{self.product[1]:.3g} is (measure closer to grazing angles, or fix r0 with --fix r0=VALUE)"
            )
        if self.off_valley:
            k, r0, ratio = self.best
            out.append(
                f"{self.label}: the fit's r0 = {self.fit[1]:.3g} ({self.scale} {self.fit[0]:.3g}) is off the valley's "
                f"floor: r0 = {r0:.3g} with {self.scale} = {k:.3g} fits better ({100 * (1 - ratio):.1f} % lower "
                "error; the search stopped short: keep the polish step or refine the grid)"
            )
        out += [
            f"{self.label}: {bound}: the best fit may lie beyond the range searched (--range, where the model allows)"
            for bound in self.at_bounds
        ]
        return out

    def as_dict(self) -> dict:
        return {
            "lobe": self.label,
            "r0_interval": list(self.r0),
            "ks_interval": list(self.k),
            "determined": self.determined,
            "product_interval": list(self.product),
            "degenerate": self.degenerate,
            "off_valley": self.off_valley,
            "at_bounds": list(self.at_bounds),
        }


def lobe_valley(
    geometry, target: np.ndarray, weights: np.ndarray, params: dict, metric: str, bounds: dict, label: str, fixed=()
) -> Valley:
    """Profile of one lobe's error along r0 (its range on VALLEY_R0_VALUES values, the best k
    for each, mx, my and alpha kept). ``bounds``: parameter -> (lo, hi) of the search; ``fixed``:
    parameters the user fixed (not reported on a bound)."""
    t64 = np.asarray(target, dtype=np.float64)
    k_hi = bounds["k"][1]
    r0_lo, r0_hi = bounds["r0"]
    r0_values = np.unique(np.append(np.linspace(r0_lo, r0_hi, VALLEY_R0_VALUES), params["r0"]))
    units = geometry.unit_lobe(
        np.full(len(r0_values), params["mx"]), np.full(len(r0_values), params["my"]), r0_values,
        np.full(len(r0_values), params["alpha"]),
    ).astype(np.float64)  # fmt: skip
    ks = np.array([best_scale(t64, unit, weights, metric, k_hi) for unit in units])
    errors = np.array([np.sum(weights * penalty(t64 - k * unit, metric)) for k, unit in zip(ks, units, strict=True)])
    best = float(errors.min())
    own_unit = geometry.unit_lobe([params["mx"]], [params["my"]], [params["r0"]], [params["alpha"]])[0]
    own_error = float(np.sum(weights * penalty(t64 - params["k"] * own_unit.astype(np.float64), metric)))
    within = errors <= best * (1.0 + VALLEY_TOLERANCE) + VALLEY_FLOOR * signal_mass(t64, weights)
    # the connected run of r0 values around the best one
    centre = int(np.argmin(errors))
    lo = hi = centre
    while lo > 0 and within[lo - 1]:
        lo -= 1
    while hi < len(r0_values) - 1 and within[hi + 1]:
        hi += 1
    run = slice(lo, hi + 1)
    # what the data fixes along the valley: k r0 for a reflection lobe, k (1 - r0) for a
    # transmission lobe (its Fresnel factor is 1 - F)
    products = ks[run] * ((1.0 - r0_values[run]) if geometry.transmission else r0_values[run])
    at_bounds = []
    for name, value in params.items():
        if name in fixed or name not in bounds:
            continue
        low, high = bounds[name]
        if math.isclose(value, high, rel_tol=1e-6, abs_tol=1e-9) and name in ("r0", "alpha", "k"):
            at_bounds.append(f"{name} = {value:.6g} (its upper bound)")
        elif math.isclose(value, low, rel_tol=1e-6, abs_tol=1e-9) and name in ("mx", "my"):
            at_bounds.append(f"{name} = {value:.6g} (its lower bound)")
        elif math.isclose(value, high, rel_tol=1e-6) and name in ("mx", "my"):
            at_bounds.append(f"{name} = {value:.6g} (its upper bound: a lobe as wide as the model allows)")
    return Valley(
        label,
        (float(r0_values[lo]), float(r0_values[hi])),
        (float(ks[run].min()), float(ks[run].max())),
        (float(products.min()), float(products.max())),
        (float(r0_lo), float(r0_hi)),
        at_bounds,
        (float(params["k"]), float(params["r0"])),
        (float(ks[centre]), float(r0_values[centre]), best / max(own_error, 1e-300)),
    )


#: The fit's overall verdict (issue 43 item 4: a fit that cannot be trusted says so): the share of
#: the data's Eq. 3.7 mass (the error of a black model) that the fit leaves unexplained.
VERDICT_GOOD = 0.05
VERDICT_POOR = 0.2
#: one tuple carrying more than this share of the metric's weight makes the fit that tuple's
VERDICT_HEAVY_TUPLE = 0.1


#: what to try when a model leaves too much unexplained, by the fitted description's model
VERDICT_ALTERNATIVES = {
    "thesis": "more lobes (--lobes), --model microfacet or --model rational",
    "gltf": "--model thesis with more lobes or --model rational",
    "rational": "a smaller --eps or --model thesis with more lobes",
}


def fit_verdict(m, error: float, metric: str = "l1", model: str = "thesis") -> dict:
    """{"level": good|fair|poor, "unexplained": share, "messages": [...]}: the fit's error against
    the data's own mass (Eq. 3.7 of a black model on the same tuples and weights), and the data's
    own warnings (a tuple that dominates the weights). Printed by ``lobeview fit`` and stored in
    the material's ``fit.verdict``."""
    weights = metric_weights(m)
    mass = eq37_error(m.luminance, np.zeros_like(m.luminance), weights, metric)
    unexplained = float(error / mass) if mass > 0 else 0.0
    level = "good" if unexplained <= VERDICT_GOOD else "fair" if unexplained <= VERDICT_POOR else "poor"
    messages = []
    if level == "poor":
        messages.append(
            f"the fit leaves {100 * unexplained:.0f} % of the data's Eq. 3.7 mass unexplained: this model does not "
            f"represent the material (try {VERDICT_ALTERNATIVES.get(model, 'another model')}, and look at --plot)"
        )
    elif level == "fair":
        messages.append(f"the fit leaves {100 * unexplained:.1f} % of the data's Eq. 3.7 mass unexplained")
    heaviest = float(weights.max() / weights.sum()) if weights.sum() > 0 else 0.0
    if heaviest > VERDICT_HEAVY_TUPLE:
        messages.append(
            f"one tuple carries {100 * heaviest:.0f} % of the metric's weight (its 'weight' column): the fit follows "
            "that tuple; check the weights"
        )
        level = "poor"
    return {"level": level, "unexplained": unexplained, "messages": messages}
