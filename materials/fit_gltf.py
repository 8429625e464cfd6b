"""Fitting the glTF metallic-roughness BRDF (materials/gltf.py) to measurements:
``lobeview fit --model microfacet``. The result is a ``"model": "gltf"`` material, the model every
glTF scene already uses (GGX, height-correlated Smith, Schlick), so a measured sample can be
pasted into a user's scene as it is.

What is minimised: thesis Eq. 3.7 per channel (materials/fit.py: L1 of transfer probabilities
weighted by solid angle and |cos theta_i|, or its squared variant), summed over the channels with
Rec. 709 luminance weights.

Parameters:

- ``roughness`` (log-spaced over [0.01, 1], as alpha = roughness^2 acts as a scale),
  ``metallic`` [0, 1];
- ``anisotropy`` (KHR_materials_anisotropy strength) as a signed value in [-1, 1]: positive
  stretches the lobe along the measurement's x axis (the tangent), negative along y (written as
  strength |s| with ``anisotropy_rotation`` = 90 deg). Searched unless the data is isotropic
  (``isotropic``, always for MERL tables) or fixed;
- ``transmission`` (KHR_materials_transmission, thin-walled) [0, 1]: searched when the data has
  transmission tuples, else 0;
- ``base_color``: not searched. For fixed (roughness, metallic, anisotropy, transmission) the
  model's transfer probability is affine in each channel's base colour, p = a + b c with c >= 0
  (glTF Appendix B: the diffuse (1 - m)(1 - F_d) b / pi, the metal's Fresnel b + (1 - b)(1 - V.H)^5
  and the transmission tint are each linear in b; F_d does not depend on b). So the L1-optimal b is
  the weighted median of (p - a) / c with weights w c (L2: weighted least squares), clipped to
  [0, 1], which is the constrained optimum because the objective is convex in b.

The search is the thesis' hierarchical brute force (materials/fit.py: n values per free parameter,
shrink to the cell about the best, iterate) followed by Nelder-Mead (``polish``). ior, specular,
clearcoat and sheen keep the core model's values (not fitted).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .fit import FitError, _grid, _penalty, eq37_error, metric_weights
from .gltf import gltf_bsdf
from .lobe_fit import LUMINANCE
from .measurement import Measurement, renderer_pair

GLTF_FIT_PARAMS = ("roughness", "metallic", "anisotropy", "transmission")
GLTF_RANGES: dict[str, tuple[float, float]] = {
    "roughness": (0.01, 1.0),
    "metallic": (0.0, 1.0),
    "anisotropy": (-1.0, 1.0),
    "transmission": (0.0, 1.0),
}
LOG_GLTF_PARAMS = ("roughness",)


@dataclass
class GltfFitOptions:
    grid: int = 8  # n: values per free parameter and iteration
    iterations: int = 6
    metric: str = "l1"
    fixed: dict[str, float] = field(default_factory=dict)  # roughness, metallic, anisotropy, transmission
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    isotropic: bool = False  # anisotropy fixed at 0 (a MERL table, an isotropic sample)
    polish: bool = True
    progress: Callable[[str], None] | None = None


@dataclass
class GltfFitResult:
    params: dict[str, float]  # roughness, metallic, anisotropy (signed), transmission
    base_color: np.ndarray  # (C,)
    error: float  # Eq. 3.7 on luminance, as fit_thesis reports it
    objective: float  # what the search minimised (luminance-weighted sum of channel errors)
    metric: str
    evaluations: int
    seconds: float
    free: list[str]
    options: GltfFitOptions

    def material(self, name: str = "fitted", data: str = "") -> dict:
        """A ``gltf`` material description with the fit's provenance."""
        base = np.clip(self.base_color, 0.0, 1.0)
        base = np.repeat(base, 3) if len(base) == 1 else base
        strength = abs(self.params["anisotropy"])
        desc = {
            "model": "gltf",
            "name": name,
            "description": f"glTF metallic-roughness fitted to {data or 'a measurement'} (fit --model microfacet)",
            "base_color": [round(float(c), 6) for c in base],
            "metallic": round(self.params["metallic"], 6),
            "roughness": round(self.params["roughness"], 6),
        }
        if strength > 0:
            desc["anisotropy"] = round(strength, 6)
            desc["anisotropy_rotation"] = math.pi / 2 if self.params["anisotropy"] < 0 else 0.0
        if self.params["transmission"] > 0:
            desc["transmission"] = round(self.params["transmission"], 6)
        desc["fit"] = {
            "model": "gltf metallic-roughness (lobeview fit --model microfacet)",
            "data": data,
            "metric": "Eq. 3.7 " + ("L1" if self.metric == "l1" else "L2 (squared differences)"),
            "error": self.error,
            "free": list(self.free),
            "fixed": dict(self.options.fixed),
            "grid": self.options.grid,
            "iterations": self.options.iterations,
            "polish": self.options.polish,
            "evaluations": self.evaluations,
            "seconds": round(self.seconds, 2),
        }
        return desc


def best_scale(target: np.ndarray, offset: np.ndarray, slope: np.ndarray, weights: np.ndarray, metric: str) -> float:
    """argmin over b in [0, 1] of sum w pen(target - offset - b slope), slope >= 0: the weighted
    median of (target - offset) / slope with weights w slope (L1), or weighted least squares (L2)."""
    active = (slope > 0) & (weights > 0)
    if not active.any():
        return 0.0
    residual = target[active] - offset[active]
    s, w = slope[active], weights[active]
    if metric == "l2":
        return float(np.clip(np.sum(w * s * residual) / np.sum(w * s * s), 0.0, 1.0))
    ratio = residual / s
    order = np.argsort(ratio)
    cum = np.cumsum((w * s)[order])
    i = int(np.searchsorted(cum, 0.5 * cum[-1]))
    return float(np.clip(ratio[order][min(i, len(ratio) - 1)], 0.0, 1.0))


class GltfFitProblem:
    """The measurement in the renderer's convention and the per-candidate evaluation.

    For fixed (roughness, anisotropy) the model is multilinear in (metallic, transmission, base
    colour): material = mix(dielectric, metal, metallic) (glTF Appendix B), the transmission
    takes the fraction t of the diffuse into its own lobe, and each term is affine in the base
    colour. So the model at the 8 corners of that unit cube, from 4 evaluations of
    :func:`gltf_bsdf` (base colour 0 and 1 ride in two colour channels of one), gives every
    candidate of the (metallic, transmission) grid exactly by trilinear interpolation."""

    CACHE = 256  # (roughness, anisotropy) corner sets kept: one brute-force iteration's worth

    def __init__(self, m: Measurement, metric: str):
        self.wi, self.wo = renderer_pair(m.wi, m.wo)
        # anisotropy along y: the same directions seen from a frame turned by 90 deg (x' = y, y' = -x)
        self.wi_turned = np.stack([self.wi[:, 1], -self.wi[:, 0], self.wi[:, 2]], axis=1)
        self.wo_turned = np.stack([self.wo[:, 1], -self.wo[:, 0], self.wo[:, 2]], axis=1)
        self.cos_o = np.abs(m.wo[:, 2])
        self.has_transmission = bool(m.transmission.any())
        self.p = m.p
        self.weights = metric_weights(m)
        self.metric = metric
        self.channel_weights = np.array([1.0]) if m.channels == 1 else np.asarray(LUMINANCE, dtype=float)
        self._corners: dict[tuple[float, float], np.ndarray] = {}
        self.model_evaluations = 0

    def corners(self, roughness: float, anisotropy: float) -> np.ndarray:
        """Transfer probabilities (metallic 0|1, transmission 0|1, base 0|1, N)."""
        key = (float(roughness), float(anisotropy))
        if key in self._corners:
            return self._corners[key]
        wi, wo = (self.wi_turned, self.wo_turned) if anisotropy < 0 else (self.wi, self.wo)
        out = np.zeros((2, 2, 2, len(self.cos_o)))
        for mi, ti in itertools.product((0, 1), (0, 1) if self.has_transmission else (0,)):
            bsdf = gltf_bsdf([0.0, 1.0, 1.0], float(mi), roughness, anisotropy=abs(anisotropy), transmission=float(ti))
            f = bsdf.eval(wi, wo)
            out[mi, ti, 0], out[mi, ti, 1] = f[:, 0] * self.cos_o, f[:, 1] * self.cos_o
            self.model_evaluations += 1
        if not self.has_transmission:
            out[:, 1] = out[:, 0]
        if len(self._corners) >= self.CACHE:
            self._corners.clear()
        self._corners[key] = out
        return out

    def affine_parts(self, params: dict) -> tuple[np.ndarray, np.ndarray]:
        """(a, c) with p = a + base_color c per tuple."""
        corners = self.corners(params["roughness"], params["anisotropy"])
        m, t = params["metallic"], params["transmission"]
        at_m = (1.0 - m) * corners[0] + m * corners[1]  # (transmission, base, N)
        at_t = (1.0 - t) * at_m[0] + t * at_m[1]  # (base, N)
        return at_t[0], np.maximum(at_t[1] - at_t[0], 0.0)

    def solve(self, params: dict) -> tuple[float, np.ndarray]:
        """(objective, base colour per channel) of one candidate."""
        a, c = self.affine_parts(params)
        base = np.array([best_scale(self.p[:, k], a, c, self.weights, self.metric) for k in range(self.p.shape[1])])
        errors = [
            float(np.sum(self.weights * _penalty(self.p[:, k] - a - base[k] * c, self.metric)))
            for k in range(self.p.shape[1])
        ]
        return float(np.dot(self.channel_weights, errors)), base


def check_gltf_options(options: GltfFitOptions) -> None:
    for kind, source in (("fixed", options.fixed), ("range", options.ranges)):
        for name, value in source.items():
            if name not in GLTF_FIT_PARAMS:
                raise FitError(
                    f"{kind} parameter {name!r} is unknown to --model microfacet; use "
                    f"{', '.join(GLTF_FIT_PARAMS)} (base_color is solved exactly, not searched)"
                )
            lo, hi = GLTF_RANGES[name]
            vals = [value] if kind == "fixed" else list(value)
            if kind == "range" and not vals[0] < vals[1]:
                raise FitError(f"range {name}: expected LO < HI, got {value}")
            if not all(math.isfinite(v) and lo <= v <= hi for v in vals):
                raise FitError(f"{kind} {name} = {value}: outside [{lo}, {hi}]")
    if options.metric not in ("l1", "l2"):
        raise FitError(f"metric: expected 'l1' or 'l2', got {options.metric!r}")
    if options.grid < 3 or options.iterations < 1:
        raise FitError("grid must be >= 3 and iterations >= 1")


def fit_gltf(m: Measurement, options: GltfFitOptions | None = None) -> GltfFitResult:
    """Fit the glTF metallic-roughness model to ``m`` (see the module docstring)."""
    options = options or GltfFitOptions()
    check_gltf_options(options)
    say = options.progress or (lambda _msg: None)
    start = time.perf_counter()
    problem = GltfFitProblem(m, options.metric)
    fixed = dict(options.fixed)
    if options.isotropic:
        fixed.setdefault("anisotropy", 0.0)
    if not m.transmission.any():
        if fixed.get("transmission", 0.0) > 0:
            raise FitError(f"{m.name}: transmission fixed > 0 but the measurement has no transmission tuple")
        fixed["transmission"] = 0.0
    free = [p for p in GLTF_FIT_PARAMS if p not in fixed]
    bounds = {}
    for name in free:
        lo, hi = options.ranges.get(name, GLTF_RANGES[name])
        bounds[name] = (math.log(lo), math.log(hi)) if name in LOG_GLTF_PARAMS else (lo, hi)

    def candidate(coords: dict) -> dict:
        params = dict(fixed)
        for name, v in coords.items():
            lo, hi = bounds[name]
            v = min(max(float(v), lo), hi)
            params[name] = math.exp(v) if name in LOG_GLTF_PARAMS else v
        return params

    say(
        f"fitting glTF metallic-roughness: free {', '.join(free) or 'nothing'}; "
        f"{options.grid}^{len(free)} candidates per iteration, base colour solved per candidate"
    )
    best = (math.inf, None, None)  # objective, coords, base
    current = dict(bounds)
    evaluations = 0
    for it in range(options.iterations if free else 1):
        axes = [_grid(*current[name], options.grid) for name in free]
        for values in itertools.product(*axes):
            coords = dict(zip(free, values, strict=True))
            objective, base = problem.solve(candidate(coords))
            evaluations += 1
            if objective < best[0]:
                best = (objective, coords, base)
        for name in free:  # shrink every free interval to the cell about the minimum
            lo, hi = current[name]
            step = (hi - lo) / (options.grid - 1)
            b_lo, b_hi = bounds[name]
            current[name] = (max(b_lo, best[1][name] - step), min(b_hi, best[1][name] + step))
        shown = _shown(candidate(best[1]), best[2])
        say(f"  iteration {it + 1}: channel {options.metric.upper()} sum {best[0]:.6g}  {shown}")
    if options.polish and free:
        from scipy.optimize import minimize

        def objective_of(x):
            return problem.solve(candidate(dict(zip(free, x, strict=True))))[0]

        res = minimize(
            objective_of,
            [best[1][n] for n in free],
            method="Nelder-Mead",
            options={"xatol": 1e-5, "fatol": 1e-12, "maxfev": 150 * len(free)},
        )
        evaluations += int(res.nfev)
        if res.fun < best[0]:
            coords = dict(zip(free, res.x, strict=True))
            best = (float(res.fun), coords, problem.solve(candidate(coords))[1])
        say(f"  polished (Nelder-Mead, {res.nfev} evaluations): {best[0]:.6g}  {_shown(candidate(best[1]), best[2])}")
    params = candidate(best[1])
    a, c = problem.affine_parts(params)
    model = a[:, None] + c[:, None] * best[2][None, :]
    lum_w = problem.channel_weights
    error = eq37_error(m.luminance, model @ lum_w if m.channels == 3 else model[:, 0], problem.weights, options.metric)
    seconds = time.perf_counter() - start
    say(f"done: Eq. 3.7 {options.metric.upper()} error {error:.6g} ({evaluations} candidates, {seconds:.1f} s)")
    return GltfFitResult(
        {k: float(params[k]) for k in GLTF_FIT_PARAMS},
        best[2],
        error,
        best[0],
        options.metric,
        evaluations,
        seconds,
        free,
        options,
    )


def _shown(params: dict, base) -> str:
    shown = "  ".join(f"{k}={params[k]:.4g}" for k in GLTF_FIT_PARAMS)
    return f"{shown}  base_color={np.array2string(np.asarray(base), precision=3)}"
