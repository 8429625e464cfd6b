"""Fitting the thesis material model to measurements (thesis 3.4.1).

What is minimised (thesis Eq. 3.7), over the measurement's tuples t:

    error = sum_t w_t |cos theta_i,t| |p_measured,t - p_model,t|  /  sum_t w_t

with p = f_s |cos theta_o| the transfer probability and w_t the solid angle the tuple stands for
(sin theta_o on a uniform goniophotometer grid). ``metric="l2"`` squares the difference instead
(Ngan et al.'s metric, for the thesis' robustness comparison).

How (thesis 3.4.1):

- kd is not searched: it is pi times the most common BRDF value, the mode of a histogram of the
  reflection tuples' f = p / |cos theta_o| (most directions see only the diffuse term), each
  value counted by its solid angle w (a dense scan of the peak must not outvote the hemisphere);
  the bin width follows the Freedman-Diaconis rule on the lower 90 %, and the modal bin's
  median is taken. ``fixed={"kd": v}`` overrides it.
- each lobe's five parameters (k, mx, my, r0, alpha) are found by hierarchical brute force: n
  equidistant values per free parameter over the user's interval, all n^P combinations
  evaluated, the interval shrunk to the cell +-(upper - lower) / (n - 1) about the best one,
  repeated ``iterations`` times; then (``polish``, not in the thesis) scipy's Nelder-Mead walks
  from that minimum, which matters where the model's parameters trade off against each other
  (ks against r0 and alpha: only ks r0 and the grazing rise are well determined). mx and my are
  spaced equidistantly in log(m) (roughness acts as a scale; linear spacing over [0.001, 1]
  would put one value below 0.14), the others linearly.
  k enters the model linearly, so each (mx, my, r0, alpha) candidate's lobe shape is computed
  once and the n values of k reuse it.
- several lobes: fit one to the specular part (measurement minus diffuse), subtract it, clamp at
  zero, fit the next to the rest; then refit each lobe against the measurement minus all others
  (clamped), ``alternations`` rounds. Transmission lobes are fitted the same way to the
  transmission tuples.
- RGB measurements: the shapes are fitted to luminance; kd per channel comes from the channel's
  own histogram, and each channel's specular (transmission) lobes are scaled by a 1-D search of
  the same metric, so ks (kt) becomes an RGB triple.

Everything is vectorised numpy in float32 over chunks of candidates (the memory of one chunk is
bounded by :data:`CHUNK_ELEMENTS`).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .fit_selection import DiffuseChoice, FitError, Valley, eq37_error, lobe_valley, metric_weights
from .fit_selection import penalty as _penalty
from .lobe_fit import LUMINANCE
from .measurement import Measurement, angles_deg, renderer_pair, sample_frame_eval
from .microfacet import ALPHA_MAX, ALPHA_MIN
from .vec import mirror_z

LOBE_PARAMS = ("k", "mx", "my", "r0", "alpha")
SHAPE_PARAMS = ("mx", "my", "r0", "alpha")
#: Default search intervals and the spacing of the grid in each.
DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    "k": (0.0, 1.0),
    "mx": (0.001, 1.0),
    "my": (0.001, 1.0),
    "r0": (0.0, 1.0),
    "alpha": (0.0, 1.0),
}
LOG_PARAMS = ("mx", "my")
# float32 elements of one chunk of candidate x tuple values: 1 MB stays in cache; measured 2-3x
# faster than 64 MB chunks (bench/results/fit.md)
CHUNK_ELEMENTS = 1 << 18


# -- the model's value for many candidates -----------------------------------------------------------


class LobeGeometry:
    """Per-tuple quantities of thesis Eq. 3.3/3.4 that do not depend on the lobe's parameters,
    so a candidate costs a few fused array operations. For transmission lobes (Eq. 3.5) the
    incident direction is mirrored through the surface first, exactly as :class:`KurtLobe`."""

    def __init__(self, wi: np.ndarray, wo: np.ndarray, transmission: bool):
        wi, wo = renderer_pair(wi, wo)
        wr = mirror_z(wi) if transmission else wi
        h = wr + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        hz2 = np.maximum(h[:, 2] ** 2, 1e-12)
        c_oh = np.maximum(np.sum(wo * h, axis=1), 1e-12)
        cos_i = np.maximum(wr[:, 2], 1e-12)
        cos_o = np.maximum(wo[:, 2], 1e-12)
        self.transmission = transmission
        self.tan2x = (h[:, 0] ** 2 / hz2).astype(np.float32)
        self.tan2y = (h[:, 1] ** 2 / hz2).astype(np.float32)
        # cos_o from p = f |cos theta_o|, 1 / (4 wo.h) of Eq. 3.4, 1 / cos^4 theta_h of Eq. 3.3
        self.scale = (cos_o / (4.0 * c_oh) / hz2**2 / math.pi).astype(np.float32)
        self.schlick5 = ((1.0 - np.clip(c_oh, 0, 1)) ** 5).astype(np.float32)
        self.log_cos = np.log(cos_i * cos_o).astype(np.float32)
        self.valid = (h[:, 2] > 0).astype(np.float32)

    def __len__(self) -> int:
        return len(self.tan2x)

    def unit_lobe(self, mx, my, r0, alpha) -> np.ndarray:
        """Transfer probability per unit k, shape (B, N), for B candidates (arrays of shape (B,))."""
        mx, my, r0, alpha = (np.asarray(a, dtype=np.float32)[:, None] for a in (mx, my, r0, alpha))
        exponent = -(self.tan2x / (mx * mx) + self.tan2y / (my * my)) - alpha * self.log_cos
        fresnel = r0 + (1.0 - r0) * self.schlick5
        if self.transmission:
            fresnel = 1.0 - fresnel
        return np.exp(exponent) * fresnel * (self.scale * self.valid / (mx * my))


# -- options and results ---------------------------------------------------------------------------


@dataclass
class FitOptions:
    lobes: int = 1
    transmission_lobes: int | None = None  # None: 1 if the measurement has transmission tuples
    grid: int = 8  # n: values per parameter and iteration
    iterations: int = 6
    alternations: int = 3
    metric: str = "l1"
    fixed: dict[str, float] = field(default_factory=dict)  # "kd", "mx", "lobe2.r0", "tlobe1.k"...
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)  # same keys, (lo, hi)
    isotropic: bool = False  # tie my = mx (an isotropic sample, a MERL table)
    polish: bool = True  # Nelder-Mead from each lobe's brute-force minimum (not in the thesis)
    # "auto": the histogram's kd only where the data supports it (materials/fit_selection.py);
    # "histogram": always (thesis 3.4.1 exactly)
    diffuse: str = "auto"
    progress: Callable[[str], None] | None = None


@dataclass
class LobeFit:
    params: dict[str, float]  # k, mx, my, r0, alpha
    transmission: bool
    error: float  # the metric of this lobe against its target (its own subset)
    evaluations: int


@dataclass
class FitResult:
    kd: np.ndarray  # (C,)
    lobes: list[LobeFit]
    transmission_lobes: list[LobeFit]
    lobe_colour: np.ndarray  # (C,) scale of the reflection lobes per channel (1 for scalar data)
    transmission_colour: np.ndarray
    error: float  # Eq. 3.7 over all tuples (luminance for RGB data)
    error_reflection: float
    error_transmission: float
    channel_errors: list[float]
    metric: str
    evaluations: int
    seconds: float
    options: FitOptions
    model_mass: float = 0.0  # Eq. 3.7 of the fitted model against 0 (luminance): what it explains
    diffuse: DiffuseChoice | None = None  # kd kept or dropped by the data (None: fixed or not tested)
    valleys: list[Valley] = field(default_factory=list)  # per reflection/transmission lobe

    @property
    def warnings(self) -> list[str]:
        """What the data does not determine (degenerate pairs, parameters on a bound)."""
        return [line for valley in self.valleys for line in valley.messages()]

    def material(self, name: str = "fitted", description: str = "", data: str = "") -> dict:
        """The fit as a lobeview material description (docs/guide.md "Material JSON") with provenance."""

        def value(arr):
            arr = np.clip(np.asarray(arr, dtype=float), 0.0, 1.0)
            return float(arr[0]) if len(arr) == 1 or np.allclose(arr, arr[0]) else [float(v) for v in arr]

        def lobe(fit: LobeFit, colour, key):
            p = fit.params
            out = {key: value(p["k"] * colour), "mx": p["mx"], "my": p["my"], "r0": p["r0"], "alpha": p["alpha"]}
            return {k: (round(v, 6) if isinstance(v, float) else [round(c, 6) for c in v]) for k, v in out.items()}

        kd = value(self.kd)
        return {
            "model": "thesis",
            "name": name,
            "description": description or f"fitted to {data or 'a measurement'} (thesis 3.4.1)",
            "kd": round(kd, 6) if isinstance(kd, float) else [round(c, 6) for c in kd],
            "lobes": [lobe(f, self.lobe_colour, "ks") for f in self.lobes],
            "transmission_lobes": [lobe(f, self.transmission_colour, "kt") for f in self.transmission_lobes],
            "fit": {
                "data": data,
                "metric": "Eq. 3.7 " + ("L1" if self.metric == "l1" else "L2 (squared differences)"),
                "error": self.error,
                "error_reflection": self.error_reflection,
                "error_transmission": self.error_transmission,
                "grid": self.options.grid,
                "iterations": self.options.iterations,
                "polish": self.options.polish,
                "alternations": self.options.alternations,
                "evaluations": self.evaluations,
                "seconds": round(self.seconds, 2),
                "fixed": dict(self.options.fixed),
                "diffuse": self.diffuse.as_dict() if self.diffuse is not None else None,
                "lobes": [valley.as_dict() for valley in self.valleys],
                "warnings": self.warnings,
            },
        }


# -- the metric ------------------------------------------------------------------------------------


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q) -> np.ndarray:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return np.interp(np.asarray(q) * cum[-1], cum, values[order])


def estimate_kd(f_values: np.ndarray, weights: np.ndarray | None = None) -> float:
    """pi times the mode of the BRDF values (thesis 3.4.1: the diffuse value is the most common
    one). The histogram counts each value by the solid angle it stands for (``weights``), so a
    goniophotometer that scans the specular peak densely does not make the peak "most common".
    Freedman-Diaconis bins over the lower 90 % (by weight); the modal bin's weighted median."""
    f = np.asarray(f_values, dtype=np.float64)
    w = np.ones_like(f) if weights is None else np.asarray(weights, dtype=np.float64)
    ok = np.isfinite(f) & (w > 0)
    f, w = f[ok], w[ok]
    if not len(f):
        return 0.0
    upper = float(_weighted_quantile(f, w, 0.9))
    keep = f <= upper
    low, low_w = f[keep], w[keep]
    if upper <= 0 or len(low) < 8:
        return float(math.pi * _weighted_quantile(low, low_w, 0.5)) if len(low) else 0.0
    q25, q75 = _weighted_quantile(low, low_w, [0.25, 0.75])
    width = 2.0 * (q75 - q25) / len(low) ** (1 / 3)
    if width <= 0:  # more than half the solid angle has one value: that value is the mode
        return float(math.pi * _weighted_quantile(low, low_w, 0.5))
    bins = int(min(max(math.ceil(upper / width), 8), 4096))
    counts, edges = np.histogram(low, bins=bins, range=(0.0, upper), weights=low_w)
    i = int(np.argmax(counts))
    in_bin = (low >= edges[i]) & (low <= edges[i + 1])
    return float(math.pi * _weighted_quantile(low[in_bin], low_w[in_bin], 0.5))


# -- hierarchical brute force ----------------------------------------------------------------------


def _grid(lo: float, hi: float, n: int) -> np.ndarray:
    """n equidistant values over [lo, hi] (in the search's coordinates: log m for mx, my)."""
    return np.array([lo]) if hi <= lo else np.linspace(lo, hi, n)


def search_lobe(
    geometry: LobeGeometry,
    target: np.ndarray,
    weights: np.ndarray,
    ranges: dict,
    fixed: dict,
    grid: int,
    iterations: int,
    metric: str,
    isotropic: bool = False,
    progress: Callable[[str], None] | None = None,
    label: str = "lobe",
    polish: bool = True,
) -> LobeFit:
    """Hierarchical brute-force search (thesis 3.4.1, steps 1-3) of one lobe's parameters
    against ``target`` (the transfer probabilities it must explain, (N,))."""
    if grid < 3:
        raise FitError(f"grid: at least 3 values per parameter are needed, got {grid}")
    target32 = target.astype(np.float32)[None, :]
    w32 = weights.astype(np.float32)[None, :]
    bounds = {}
    for name in LOBE_PARAMS:
        lo, hi = ranges.get(name, DEFAULT_RANGES[name])
        bounds[name] = (math.log(lo), math.log(hi)) if name in LOG_PARAMS else (lo, hi)
    current = dict(bounds)
    free = [p for p in LOBE_PARAMS if p not in fixed and not (isotropic and p == "my")]
    best_params: dict[str, float] = {}
    best_error = math.inf
    evaluations = 0
    for it in range(iterations):
        values = {}
        for name in LOBE_PARAMS:
            if name in fixed:
                values[name] = np.array([fixed[name]])
            elif isotropic and name == "my":
                continue
            else:
                values[name] = _grid(*current[name], grid)
                if name in LOG_PARAMS:
                    values[name] = np.exp(values[name])
        shapes = np.array(list(itertools.product(*(values[p] for p in SHAPE_PARAMS if p in values))))
        names = [p for p in SHAPE_PARAMS if p in values]
        cols = {p: shapes[:, i] for i, p in enumerate(names)}
        if isotropic and "my" not in fixed:
            cols["my"] = cols["mx"]
        ks = values["k"].astype(np.float32)
        chunk = max(1, CHUNK_ELEMENTS // max(len(geometry), 1))
        for start in range(0, len(shapes), chunk):
            sl = slice(start, start + chunk)
            unit = geometry.unit_lobe(cols["mx"][sl], cols["my"][sl], cols["r0"][sl], cols["alpha"][sl])
            for k in ks:
                diff = target32 - k * unit
                err = np.sum(w32 * _penalty(diff, metric), axis=1)
                i = int(np.argmin(err))
                evaluations += len(err)
                if err[i] < best_error:
                    best_error = float(err[i])
                    best_params = {"k": float(k), **{p: float(cols[p][sl][i]) for p in SHAPE_PARAMS}}
        # Step 3: shrink every free interval to the cell around the minimum.
        for name in free:
            lo, hi = current[name]
            step = (hi - lo) / (grid - 1)
            centre = math.log(best_params[name]) if name in LOG_PARAMS else best_params[name]
            b_lo, b_hi = bounds[name]
            current[name] = (max(b_lo, centre - step), min(b_hi, centre + step))
        if progress:
            shown = "  ".join(f"{p}={best_params[p]:.4g}" for p in LOBE_PARAMS)
            progress(f"  {label} iteration {it + 1}/{iterations}: {metric.upper()} {best_error:.6g}  {shown}")
    if polish and free:
        best_params, best_error, n = _polish(
            geometry, target, weights, best_params, best_error, free, bounds, metric, isotropic
        )
        evaluations += n
        if progress:
            shown = "  ".join(f"{p}={best_params[p]:.4g}" for p in LOBE_PARAMS)
            progress(f"  {label} polished (Nelder-Mead, {n} evaluations): {metric.upper()} {best_error:.6g}  {shown}")
    return LobeFit(best_params, geometry.transmission, best_error, evaluations)


def _polish(
    geometry, target, weights, start: dict, start_error: float, free: list, bounds: dict, metric: str, isotropic: bool
):
    """Nelder-Mead (scipy) from the brute-force minimum over the free parameters, in the search's
    own coordinates (log m), clamped to the user's intervals: the grid's last cell still leaves
    (upper - lower) x (2 / (n - 1))^iterations of slack, and the model's (ks, r0, alpha) valley
    is long and narrow, which a grid follows poorly."""
    from scipy.optimize import minimize

    t64 = target.astype(np.float64)

    def unpack(x):
        params = dict(start)
        for name, v in zip(free, x, strict=True):
            lo, hi = bounds[name]
            v = min(max(float(v), lo), hi)
            params[name] = math.exp(v) if name in LOG_PARAMS else v
        if isotropic:
            params["my"] = params["mx"]
        return params

    def error(x):
        p = unpack(x)
        model = p["k"] * geometry.unit_lobe([p["mx"]], [p["my"]], [p["r0"]], [p["alpha"]])[0].astype(np.float64)
        return eq37_error(t64, model, weights, metric)

    x0 = [math.log(start[n]) if n in LOG_PARAMS else start[n] for n in free]
    res = minimize(error, x0, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-12, "maxfev": 400 * len(free)})
    if res.fun < start_error:
        return unpack(res.x), float(res.fun), int(res.nfev)
    return start, start_error, int(res.nfev)


def _param_name(name: str) -> tuple[str, str]:
    """("lobe2", "k") for "lobe2.ks", ("", "mx") for "mx": ks and kt are aliases of k."""
    lobe, _, param = name.rpartition(".")
    return lobe, {"ks": "k", "kt": "k"}.get(param, param)


def _lobe_options(options: FitOptions, key: str) -> tuple[dict, dict]:
    """Ranges and fixed values of one lobe ("lobe2", "tlobe1") from the options' keys: "mx"
    applies to every lobe of both kinds, "lobe2.mx" to that lobe; "ks"/"kt" are aliases of k."""
    ranges, fixed = {}, {}
    for source, out in ((options.ranges, ranges), (options.fixed, fixed)):
        for name, value in source.items():
            lobe, param = _param_name(name)
            if lobe in ("", key) and param in LOBE_PARAMS:
                out[param] = value
    return ranges, fixed


def check_options(options: FitOptions, reflection_lobes: int, transmission_lobes: int) -> None:
    """Refuse unknown parameter names, empty or inverted intervals and values outside the model's
    ranges, before any work."""
    keys = {"kd", "ks", "kt", *LOBE_PARAMS}
    keys |= {f"lobe{i + 1}.{p}" for i in range(reflection_lobes) for p in (*LOBE_PARAMS, "ks")}
    keys |= {f"tlobe{i + 1}.{p}" for i in range(transmission_lobes) for p in (*LOBE_PARAMS, "kt")}
    limits = dict(DEFAULT_RANGES, kd=(0.0, 1.0), mx=(ALPHA_MIN, ALPHA_MAX), my=(ALPHA_MIN, ALPHA_MAX))
    for kind, source in (("fixed", options.fixed), ("range", options.ranges)):
        for name, value in source.items():
            if name not in keys:
                raise FitError(
                    f"{kind} parameter {name!r} is unknown; use kd, k (ks/kt), mx, my, r0, alpha, "
                    f"or lobeN./tlobeN. with N up to the number of lobes"
                )
            lo, hi = limits[_param_name(name)[1]]
            vals = [value] if kind == "fixed" else list(value)
            if kind == "range" and (name == "kd" or not vals[0] < vals[1]):
                raise FitError(
                    f"range {name}: expected LO < HI (and kd is estimated or fixed, not searched), got {value}"
                )
            if not all(math.isfinite(v) and lo <= v <= hi for v in vals):
                raise FitError(f"{kind} {name} = {value}: outside the model's range [{lo}, {hi}]")
    if options.metric not in ("l1", "l2"):
        raise FitError(f"metric: expected 'l1' or 'l2', got {options.metric!r}")
    if options.diffuse not in ("auto", "histogram"):
        raise FitError(f"diffuse: expected 'auto' or 'histogram', got {options.diffuse!r}")
    if options.iterations < 1 or options.alternations < 0:
        raise FitError("iterations must be >= 1 and alternations >= 0")


def _fit_lobe_set(
    geometry: LobeGeometry,
    target: np.ndarray,
    weights: np.ndarray,
    count: int,
    options: FitOptions,
    prefix: str,
    say: Callable[[str], None],
) -> tuple[list[LobeFit], np.ndarray, int, list[Valley]]:
    """Fit ``count`` lobes to ``target`` by the thesis' alternating scheme; returns the lobes,
    their per-lobe transfer probabilities (count, N), the evaluations and each lobe's (k, r0)
    valley (materials/fit_selection.py; none where k or r0 is fixed)."""
    fits: list[LobeFit | None] = [None] * count
    values = np.zeros((count, len(target)))
    evaluations = 0
    rounds = [list(range(count))] + ([list(range(count))] * options.alternations if count > 1 else [])
    for r, order in enumerate(rounds):
        for i in order:
            rest = target - (values.sum(axis=0) - values[i])
            lobe_target = np.maximum(rest, 0.0)  # clamped so the next lobe is not fitted to negatives
            ranges, fixed = _lobe_options(options, f"{prefix}{i + 1}")
            label = f"{prefix}{i + 1}" + (f" (round {r + 1}/{len(rounds)})" if count > 1 else "")
            say(f"fitting {label}: {len(target)} tuples, {options.grid}^{5 - len(fixed)} candidates per iteration")
            fit = search_lobe(
                geometry,
                lobe_target,
                weights,
                ranges,
                fixed,
                options.grid,
                options.iterations,
                options.metric,
                options.isotropic,
                options.progress,
                label,
                options.polish,
            )
            evaluations += fit.evaluations
            fits[i] = fit
            p = fit.params
            values[i] = p["k"] * geometry.unit_lobe([p["mx"]], [p["my"]], [p["r0"]], [p["alpha"]])[0]
    valleys = []
    for i, fit in enumerate(fits):
        rest = np.maximum(target - (values.sum(axis=0) - values[i]), 0.0)
        ranges, fixed = _lobe_options(options, f"{prefix}{i + 1}")
        bounds = {name: ranges.get(name, DEFAULT_RANGES[name]) for name in LOBE_PARAMS}
        if "r0" not in fixed and "k" not in fixed:
            label = f"{'transmission lobe' if prefix == 'tlobe' else 'lobe'} {i + 1}"
            valleys.append(lobe_valley(geometry, rest, weights, fit.params, options.metric, bounds, label, fixed))
    return [f for f in fits if f is not None], values, evaluations, valleys


def _scale_search(target, unit, weights, metric, hi: float, grid: int = 16, iterations: int = 8) -> float:
    """1-D hierarchical search of s minimising the metric of target - s unit."""
    lo_b, hi_b = 0.0, hi
    lo, top = lo_b, hi_b
    best = 0.0
    for _ in range(iterations):
        s = np.linspace(lo, top, grid)
        diff = target[None, :] - s[:, None] * unit[None, :]
        err = np.sum(weights * _penalty(diff, metric), axis=1)
        best = float(s[int(np.argmin(err))])
        step = (top - lo) / (grid - 1)
        lo, top = max(lo_b, best - step), min(hi_b, best + step)
    return best


def fit_thesis(m: Measurement, options: FitOptions | None = None) -> FitResult:
    """Fit thesis Eq. 3.6 (kd, reflection lobes, transmission lobes) to ``m`` (see module doc)."""
    options = options or FitOptions()
    say = options.progress or (lambda _msg: None)
    start = time.perf_counter()
    trans_mask = m.transmission
    refl_mask = ~trans_mask
    t_lobes = options.transmission_lobes
    if t_lobes is None:
        t_lobes = 1 if trans_mask.any() else 0
    if options.lobes < 0 or t_lobes < 0 or options.lobes + t_lobes == 0:
        raise FitError("nothing to fit: give at least one reflection or transmission lobe")
    if t_lobes and not trans_mask.any():
        raise FitError(f"{m.name}: transmission lobes requested but the measurement has no tuple below the surface")
    if options.lobes and not refl_mask.any():
        raise FitError(f"{m.name}: reflection lobes requested but the measurement has no reflection tuple")
    check_options(options, options.lobes, t_lobes)

    weights = metric_weights(m)
    cos_o = np.abs(m.wo[:, 2])
    channels = m.channels
    # kd per channel from the histogram of the reflection tuples' BRDF values (thesis 3.4.1).
    if "kd" in options.fixed:
        kd = np.full(channels, float(options.fixed["kd"]))
    elif refl_mask.any():
        f_values = m.p[refl_mask] / np.maximum(cos_o[refl_mask, None], 1e-6)
        kd = np.array([estimate_kd(f_values[:, c], m.weight[refl_mask]) for c in range(channels)])
        if (kd > 1.0).any():
            say(
                f"warning: the histogram's kd {np.array2string(kd, precision=3)} exceeds 1 (no diffuse plateau in the "
                "data?); clamped to 1 - fix it with --fix kd=VALUE"
            )
        kd = np.clip(kd, 0.0, 1.0)
    else:
        kd = np.zeros(channels)
    say(
        f"kd = {np.array2string(kd, precision=4)} (histogram mode of the BRDF values)"
        if "kd" not in options.fixed
        else f"kd = {kd[0]:.4g} (fixed)"
    )
    result = _fit_given_kd(m, options, t_lobes, kd, weights, say)
    if options.diffuse == "auto" and "kd" not in options.fixed and options.lobes and kd.any():
        say("fitting again with kd = 0: does the data support a diffuse term? (materials/fit_selection.py)")
        without = _fit_given_kd(m, options, t_lobes, np.zeros(channels), weights, say)
        choice = DiffuseChoice(kd, result.error, without.error, result.model_mass)
        evaluations = result.evaluations + without.evaluations
        result = result if choice.kept else without
        result.diffuse, result.evaluations = choice, evaluations
        say(choice.message())
    result.seconds = time.perf_counter() - start
    for line in result.warnings:
        say(f"warning: {line}")
    say(
        f"done: Eq. 3.7 {options.metric.upper()} error {result.error:.6g} "
        f"({result.evaluations} candidate evaluations, {result.seconds:.1f} s)"
    )
    return result


def _fit_given_kd(m: Measurement, options: FitOptions, t_lobes: int, kd: np.ndarray, weights, say) -> FitResult:
    """The lobes and colours of thesis Eq. 3.6 for a given kd (fit_thesis's work after kd)."""
    trans_mask = m.transmission
    refl_mask = ~trans_mask
    lum = m.luminance
    cos_o = np.abs(m.wo[:, 2])
    channels = m.channels
    kd_lum = float(kd[0]) if channels == 1 else float(kd @ LUMINANCE)
    diffuse = kd_lum / math.pi * cos_o

    evaluations = 0
    lobes, t_fits, valleys, t_valleys = [], [], [], []
    refl_values = trans_values = None
    if options.lobes:
        geo = LobeGeometry(m.wi[refl_mask], m.wo[refl_mask], transmission=False)
        target = lum[refl_mask] - diffuse[refl_mask]
        lobes, refl_values, n, valleys = _fit_lobe_set(
            geo, target, weights[refl_mask], options.lobes, options, "lobe", say
        )
        evaluations += n
    if t_lobes:
        geo_t = LobeGeometry(m.wi[trans_mask], m.wo[trans_mask], transmission=True)
        t_fits, trans_values, n, t_valleys = _fit_lobe_set(
            geo_t, lum[trans_mask], weights[trans_mask], t_lobes, options, "tlobe", say
        )
        evaluations += n

    # Colour: each channel's lobes scaled by a 1-D search (ks, kt <= 1 stays within the model).
    lobe_colour = np.ones(channels)
    trans_colour = np.ones(channels)
    channel_errors = []
    if channels == 3:
        for c in range(3):
            if refl_values is not None:
                spec = refl_values.sum(axis=0)
                k_max = max(f.params["k"] for f in lobes)
                target = m.p[refl_mask, c] - kd[c] / math.pi * cos_o[refl_mask]
                lobe_colour[c] = _scale_search(target, spec, weights[refl_mask], options.metric, 1.0 / max(k_max, 1e-6))
            if trans_values is not None:
                k_max = max(f.params["k"] for f in t_fits)
                trans_colour[c] = _scale_search(
                    m.p[trans_mask, c],
                    trans_values.sum(axis=0),
                    weights[trans_mask],
                    options.metric,
                    1.0 / max(k_max, 1e-6),
                )
    model_rgb = np.zeros((len(m), channels))
    for c in range(channels):
        model_rgb[refl_mask, c] = kd[c] / math.pi * cos_o[refl_mask]
        if refl_values is not None:
            model_rgb[refl_mask, c] += lobe_colour[c] * refl_values.sum(axis=0)
        if trans_values is not None:
            model_rgb[trans_mask, c] = trans_colour[c] * trans_values.sum(axis=0)
        channel_errors.append(eq37_error(m.p[:, c], model_rgb[:, c], weights, options.metric))
    model_final_lum = model_rgb[:, 0] if channels == 1 else model_rgb @ LUMINANCE
    error = eq37_error(lum, model_final_lum, weights, options.metric)
    err_r = eq37_error(lum[refl_mask], model_final_lum[refl_mask], weights[refl_mask], options.metric)
    err_t = eq37_error(lum[trans_mask], model_final_lum[trans_mask], weights[trans_mask], options.metric)
    return FitResult(
        kd,
        lobes,
        t_fits,
        lobe_colour,
        trans_colour,
        error,
        err_r,
        err_t,
        channel_errors,
        options.metric,
        evaluations,
        0.0,  # fit_thesis times the whole fit
        options,
        model_mass=eq37_error(np.zeros_like(model_final_lum), model_final_lum, weights, "l1"),
        valleys=valleys + t_valleys,
    )


def model_transfer(desc: dict, m: Measurement) -> np.ndarray:
    """Transfer probabilities (N, 3) of a lobeview material at the measurement's tuples."""
    from .spec import build_bsdf

    wi, wo = renderer_pair(m.wi, m.wo)
    return sample_frame_eval(build_bsdf(desc), wi, wo) * np.abs(m.wo[:, 2:3])


def material_error(desc: dict, m: Measurement, metric: str = "l1") -> float:
    """Eq. 3.7 of a material description against a measurement (luminance for RGB data)."""
    model = model_transfer(desc, m)
    model_scalar = model @ LUMINANCE if m.channels == 3 else model.mean(axis=1)
    return eq37_error(m.luminance, model_scalar, metric_weights(m), metric)


def measured_albedo(m: Measurement) -> list[dict]:
    """Per incidence, the measurement's own estimate of thesis Eq. 2.6 (reflectance and
    transmittance: the sum of p w over each hemisphere, scaled by 2 pi / sum w so a grid with
    unnormalised weights such as sin(theta_o) still integrates to the hemisphere)."""
    out = []
    theta, phi = (np.round(a, 2) for a in angles_deg(m.wi))
    for t, ph in m.incidences():
        sel = (theta == t) & (phi == ph)
        row = {"theta_i": float(t), "phi_i": float(ph)}
        for label, mask in (("reflectance", sel & ~m.transmission), ("transmittance", sel & m.transmission)):
            w = m.weight[mask]
            row[label] = float(2 * math.pi * (m.luminance[mask] @ w) / w.sum()) if w.sum() > 0 else 0.0
        out.append(row)
    return out
