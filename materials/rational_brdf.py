"""The Rational BRDF (Pacanowski et al. 2012, seed 002): an isotropic BRDF as one rational function
of (theta_h, theta_d) per colour channel (section 3, Eq. 5), importance-sampled through rational
inverse CDFs (section 4, Eq. 7-9).

Fitting a BRDF (section 3.2):

- the data are projected onto (theta_h, theta_d): a MERL table is averaged over phi_d (Romeiro's
  projection), goniophotometer tuples are binned by (theta_h, theta_d) with their solid angles;
- each channel gets relative intervals [f (1 - eps), f (1 + eps)] (plus a small absolute floor,
  ``absolute`` x the channel's mean, so that zeros do not demand an exact zero), widened towards
  grazing angles (theta_h or theta_d beyond 60 deg: up to ``grazing`` x eps at 80 deg) where
  measurements are noisiest, as the paper does;
- :func:`lobeview.materials.rational.fit_rational` finds the smallest rational function inside
  them (Algorithm 1); a dense grid is then checked for poles (q <= 0 between data points), which
  are added as constraints before the same count is fitted again.

Outside the fitted domain (theta_h or theta_d > ``theta_max``, 80 deg by default as the paper's
data) the function is extended by clamping the angles, as the paper does for rendering, and
negative values (the intervals constrain the data points only) are clamped to zero.

Importance sampling (section 4): from the fitted BRDF's luminance times cos theta_l the inverse
CDFs theta_l = CDF^-1(theta_v, mu) and |phi_l - phi_v| = CDF^-1(theta_v, theta_l, tau) are
tabulated and fitted with the forms of Eq. 8 and 9, monotone in mu and tau (Eq. 4). A sample is
(theta_l, phi_v +- dphi) with the sign from the second uniform number; its density per solid
angle is 1 / (2 dtheta/dmu dphi/dtau sin theta_l) (the inverse of Eq. 7's alpha, halved for the
sign), so the weight f cos / pdf is Eq. 7's estimator. The density of an arbitrary direction (for
multiple importance sampling and the chi-square test) inverts both functions by bisection.

The whole BRDF is one lobe (the paper's point: no diffuse/specular split), lit from the
object's incident light like every lobe. lobe-N maps its deterministic lattice through these
inverse CDFs (materials/patterns.py step 6: samples distributed by the sampler's density, each
filtered over 1 / (N p)). A Beckmann *proxy* distribution fitted to the function's theta_d = 0
slice (:func:`proxy_alpha`) remains for what reads a microfacet width (the lobe's GPU row, the
split-sum prefiltered mode); an earlier lobe-N placed its ring with it and missed the broad part of p / q (plastic
fit: 8 dB, bench/results/rational-20261124-223505-quick.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .bsdf import BSDF, Component
from .lobe_fit import LUMINANCE
from .measurement import MERL_DIMS, Measurement, merl_cell_angles
from .microfacet import ALPHA_MAX, MicrofacetDistribution, fit_peak_shape, reflection_jacobian
from .rational import (
    FORMS,
    IntervalData,
    RationalFitError,
    RationalFunction,
    SolveStats,
    denominator_check_points,
    fit_rational,
    function_defects,
)
from .vec import COS_EPSILON, normalize

HALF_PI = 0.5 * math.pi
DEFAULT_THETA_MAX_DEG = 80.0  # the paper discards data beyond 80 deg (Fig. 8)
GRAZING_START_DEG = 60.0  # intervals widen beyond this angle (section 3.2)
BISECTION_STEPS = 44  # inverting a monotone inverse CDF to 2^-44 of its variable's range
# lobe-N's lattice anchored in the tangent frame up to the first view angle from the normal, to
# the view azimuth from the second, blended between (RationalLobe.tangent_anchor_weight)
TANGENT_ANCHOR_DEG = (8.0, 20.0)


@dataclass
class ProjectedBRDF:
    """BRDF values on the (theta_h, theta_d) plane: points (N, 2) in radians, values (N, C) and
    the solid-angle (or 4D) weight each point gathers."""

    points: np.ndarray
    values: np.ndarray
    weights: np.ndarray
    source: str = ""


def project_merl(table: np.ndarray, theta_max_deg: float = DEFAULT_THETA_MAX_DEG) -> ProjectedBRDF:
    """Average a MERL table (90, 90, 180, 3) over phi_d (measured cells only), keep the cells
    with theta_h and theta_d <= ``theta_max_deg``. Weights: the number of measured cells."""
    if table.shape != (*MERL_DIMS, 3):
        raise RationalFitError(f"a MERL table has shape {(*MERL_DIMS, 3)}, got {table.shape}")
    measured = np.isfinite(table).all(axis=-1)
    count = measured.sum(axis=2)
    total = np.where(measured[..., None], table, 0.0).sum(axis=2)
    theta_h, theta_d, _ = merl_cell_angles()
    th, td = np.meshgrid(theta_h, theta_d, indexing="ij")
    limit = math.radians(theta_max_deg)
    keep = (count > 0) & (th <= limit) & (td <= limit)
    values = total[keep] / count[keep][:, None]
    return ProjectedBRDF(np.stack([th[keep], td[keep]], 1), values, count[keep].astype(float), "MERL table")


def half_diff_angles(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """theta_h (from the normal) and theta_d (between wi and h), radians: the two angles the
    Rational BRDF depends on, without measurement.directions_to_half_diff's azimuths (that
    frame construction costs more than the BRDF on the shader-sized batches here)."""
    h = normalize(wi + wo)
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    theta_d = np.arccos(np.clip(np.sum(wi * h, axis=-1), -1.0, 1.0))
    return theta_h, theta_d


def project_measurement(m: Measurement, bins: int = 45, theta_max_deg: float = DEFAULT_THETA_MAX_DEG) -> ProjectedBRDF:
    """Bin a measurement's reflection tuples by (sqrt(theta_h), theta_d) into ``bins`` x ``bins``
    cells up to ``theta_max_deg``; each cell's BRDF value is the solid-angle weighted mean of
    f = p / |cos theta_o| and its point the weighted mean of its tuples' angles."""
    keep = ~m.transmission
    if not keep.any():
        raise RationalFitError(f"{m.name}: no reflection tuples; the Rational BRDF fits reflection only")
    wi, wo = m.wi[keep], m.wo[keep]
    f = m.p[keep] / np.maximum(np.abs(wo[:, 2:3]), COS_EPSILON)
    w = m.weight[keep]
    theta_h, theta_d = half_diff_angles(wi, wo)
    limit = math.radians(theta_max_deg)
    inside = (theta_h <= limit) & (theta_d <= limit) & (w > 0)
    if inside.sum() < 16:
        raise RationalFitError(
            f"{m.name}: only {int(inside.sum())} tuples within theta_h, theta_d <= {theta_max_deg} deg"
        )
    theta_h, theta_d, f, w = theta_h[inside], theta_d[inside], f[inside], w[inside]
    ih = np.minimum((np.sqrt(theta_h / limit) * bins).astype(int), bins - 1)
    idd = np.minimum((theta_d / limit * bins).astype(int), bins - 1)
    cell = ih * bins + idd
    weight = np.bincount(cell, w, bins * bins)
    used = np.flatnonzero(weight > 0)
    mean_h = np.bincount(cell, w * theta_h, bins * bins)[used] / weight[used]
    mean_d = np.bincount(cell, w * theta_d, bins * bins)[used] / weight[used]
    values = np.stack([np.bincount(cell, w * f[:, c], bins * bins)[used] for c in range(f.shape[1])], 1)
    return ProjectedBRDF(np.stack([mean_h, mean_d], 1), values / weight[used, None], weight[used], m.name)


def brdf_intervals(
    data: ProjectedBRDF,
    channel: int,
    eps: float,
    grazing: float = 3.0,
    absolute: float = 1e-4,
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG,
) -> tuple[np.ndarray, np.ndarray]:
    """Section 3.2's intervals [f (1 - eps_i), f (1 + eps_i)] (lower clipped at 0: value
    constraint), eps_i growing linearly from eps at 60 deg to grazing x eps at theta_max."""
    f = data.values[:, channel]
    angle = np.degrees(data.points.max(axis=1))
    ramp = np.clip((angle - GRAZING_START_DEG) / max(theta_max_deg - GRAZING_START_DEG, 1e-9), 0.0, 1.0)
    eps_i = eps * (1.0 + (grazing - 1.0) * ramp)
    floor = absolute * float(np.average(f, weights=data.weights)) if np.any(f > 0) else absolute
    return np.maximum(f * (1.0 - eps_i) - floor, 0.0), f * (1.0 + eps_i) + floor


def _pole_check(limit: float, steps: int = 121) -> Callable[[RationalFunction], tuple | None]:
    g = np.linspace(0.0, limit, steps)
    th, td = np.meshgrid(g, g, indexing="ij")
    dense = np.stack([th.ravel(), td.ravel()], 1)

    def verify(fn: RationalFunction):
        _, q = fn.parts(dense)
        bad = q <= 1e-9 * np.abs(q).max()
        return None if not bad.any() else (dense[bad], None, None)

    return verify


@dataclass
class RationalBRDFFit:
    functions: list  # RationalFunction per channel
    stats: list  # SolveStats per channel
    theta_max_deg: float
    max_relative_error: list  # per channel, on the projected data (|r - f| / f where f > 0)


def fit_rational_brdf(
    data: ProjectedBRDF,
    eps: float = 0.05,
    max_coefficients: int = 40,
    grazing: float = 3.0,
    absolute: float = 1e-4,
    theta_max_deg: float = DEFAULT_THETA_MAX_DEG,
    progress: Callable[[str], None] | None = None,
) -> RationalBRDFFit:
    """One rational function of (theta_h, theta_d) per channel of ``data`` (section 3.2)."""
    if not 0.0 < eps < 1.0:
        raise RationalFitError(f"eps (relative interval half-width) must be in (0, 1), got {eps}")
    limit = math.radians(theta_max_deg)
    functions, stats, errors = [], [], []
    for c in range(data.values.shape[1]):
        lower, upper = brdf_intervals(data, c, eps, grazing, absolute, theta_max_deg)
        intervals = IntervalData(data.points, lower, upper, (0.0, 0.0), (limit, limit))
        if progress:
            progress(f"rational fit, channel {c + 1}/{data.values.shape[1]}: {len(data.points)} points, eps {eps}")
        fn, st = fit_rational(intervals, max_coefficients, progress=progress, verify=_pole_check(limit))
        f = data.values[:, c]
        r = fn(data.points)
        pos = f > 0
        errors.append(float(np.max(np.abs(r[pos] - f[pos]) / f[pos])) if pos.any() else 0.0)
        if progress:
            progress(
                f"  {fn.counts} coefficients, {st.problems} problems solved in {st.seconds:.1f} s, "
                f"max relative error {errors[-1]:.3g}"
            )
        functions.append(fn)
        stats.append(st)
    return RationalBRDFFit(functions, stats, theta_max_deg, errors)


def evaluate_brdf(functions: list, theta_max_deg: float, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The Rational BRDF (..., 3) at direction pairs above the surface (0 elsewhere); angles
    beyond the fitted domain clamped, negative values clamped to 0."""
    shape = np.broadcast_shapes(wi.shape, wo.shape)[:-1]
    wi, wo = np.broadcast_to(wi, shape + (3,)).reshape(-1, 3), np.broadcast_to(wo, shape + (3,)).reshape(-1, 3)
    valid = (wi[:, 2] > COS_EPSILON) & (wo[:, 2] > COS_EPSILON)
    limit = math.radians(theta_max_deg)
    theta_h, theta_d = half_diff_angles(wi, wo)
    x = np.stack([np.minimum(theta_h, limit), np.minimum(theta_d, limit)], 1)
    values = np.stack([fn(x) for fn in functions], 1)
    if values.shape[1] == 1:
        values = np.repeat(values, 3, axis=1)
    values = np.where(valid[:, None] & np.isfinite(values), np.maximum(values, 0.0), 0.0)
    return values.reshape(shape + (3,))


# -- importance sampling (section 4) ----------------------------------------------------------------

_CDF_THETA_NODES = 513  # theta_l nodes of the tabulated marginal
_CDF_PHI_NODES = 257  # dphi nodes of the tabulated conditional


def _luminance_brdf(functions: list, theta_max_deg: float) -> Callable:
    def rho(theta_v, theta_l, dphi):
        theta_v, theta_l, dphi = np.broadcast_arrays(theta_v, theta_l, dphi)
        wo = np.stack([np.sin(theta_v), np.zeros_like(theta_v), np.cos(theta_v)], -1)
        wi = np.stack([np.sin(theta_l) * np.cos(dphi), np.sin(theta_l) * np.sin(dphi), np.cos(theta_l)], -1)
        # The sampler must cover the horizon too: evaluate with both directions lifted above it.
        wo[..., 2] = np.maximum(wo[..., 2], 2 * COS_EPSILON)
        wi[..., 2] = np.maximum(wi[..., 2], 2 * COS_EPSILON)
        return evaluate_brdf(functions, theta_max_deg, wi, wo) @ LUMINANCE

    return rho


def inverse_cdf_theta(rho: Callable, theta_v: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """theta_l = CDF_v^-1(mu) of rho cos theta_l (marginal over phi_l), for pairs (theta_v, mu)."""
    theta_l = np.linspace(0.0, HALF_PI, _CDF_THETA_NODES)
    dphi = (np.arange(64) + 0.5) / 64 * math.pi
    out = np.empty(len(theta_v))
    for tv in np.unique(theta_v):
        rows = theta_v == tv
        values = rho(tv, theta_l[:, None], dphi[None, :]).mean(axis=1) * np.sin(theta_l) * np.cos(theta_l)
        out[rows] = np.interp(mu[rows], _cumulative(values, theta_l), theta_l)
    return out


def inverse_cdf_phi(rho: Callable, theta_v: np.ndarray, theta_l: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """|phi_l - phi_v| = CDF_v^-1(tau | theta_l) over [0, pi], for triples (theta_v, theta_l, tau)."""
    dphi = np.linspace(0.0, math.pi, _CDF_PHI_NODES)
    out = np.empty(len(theta_v))
    pairs = np.unique(np.stack([theta_v, theta_l], 1), axis=0)
    for tv, tl in pairs:
        rows = (theta_v == tv) & (theta_l == tl)
        out[rows] = np.interp(tau[rows], _cumulative(rho(tv, tl, dphi), dphi), dphi)
    return out


def _cumulative(values: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Normalised trapezoid CDF, made strictly increasing by a 1e-9 uniform floor (a zero BRDF
    region would otherwise give flat, non-invertible stretches)."""
    values = np.maximum(values, 0.0)
    values = values + 1e-9 * max(float(values.max(initial=0.0)), 1e-30)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(nodes))])
    return cdf / cdf[-1]


@dataclass
class SamplingFit:
    theta: RationalFunction  # Eq. 8 form: theta_l(theta_v, mu)
    phi: RationalFunction  # Eq. 9 form: dphi(theta_v, theta_l, tau)
    stats: tuple


def _fit_inverse_cdf(
    tabulate: Callable[[np.ndarray], np.ndarray],
    points: np.ndarray,
    dense: np.ndarray,
    eps: float,
    form: str,
    max_coefficients: int,
    progress: Callable[[str], None] | None,
) -> tuple[RationalFunction, SolveStats]:
    """One inverse CDF of section 4.2 in ``form`` (Eq. 8 or 9: the last variable is the uniform
    number, every other an angle in [0, pi/2]): intervals value +- eps (1 + value) at ``points``,
    monotone in the last variable; ``dense`` is checked for monotonicity and poles where the form
    does not fix the value, and its failing points join the data with their tabulated values."""
    variable = points.shape[1] - 1
    values = tabulate(points)
    data = IntervalData(
        points,
        values - eps * (1 + values),
        values + eps * (1 + values),
        (0.0,) * points.shape[1],
        (HALF_PI,) * variable + (1.0,),
        form=form,
        monotone_in=variable,
        # the inverse CDF of dphi is symmetric in theta_v and theta_l (reciprocity, seed 002 2.2)
        symmetric=(0, 1) if form == "cdf_phi" else None,
    )
    if progress:
        progress(f"inverse CDF ({form}): {len(values)} points, eps {eps}")
    # Verified where a reader checks the material (denominator_check_points: the reader's grid
    # and the uniform variable near both ends, where the dense grid alone let poles through within
    # 1/64 of tau = 0, issue 44) and on the dense grid; the form's factor is 0 at the ends.
    checks = np.concatenate([dense, denominator_check_points(form, data.domain_lower, data.domain_upper)])
    checks = checks[FORMS[form](checks)[1] > 0]

    def verify(fn: RationalFunction):
        poles, falling = function_defects(fn, checks)
        bad = poles | falling
        if not bad.any():
            return None
        v = tabulate(checks[bad])
        return checks[bad], v - eps * (1 + v), v + eps * (1 + v)

    return fit_rational(data, max_coefficients, widen=2.0, progress=progress, verify=verify)


def fit_sampling(
    functions: list,
    theta_max_deg: float,
    eps_theta: float = 0.02,
    eps_phi: float = 0.25,
    max_coefficients: int = 30,
    grid: int = 12,
    progress: Callable[[str], None] | None = None,
) -> SamplingFit:
    """Rational inverse CDFs of a Rational BRDF (section 4.2): tabulate on a ``grid``-sized grid,
    intervals value +- eps (1 + value) as the paper's, monotone in mu / tau; a denser grid is
    verified for monotonicity and its failing points join the data."""
    rho = _luminance_brdf(functions, theta_max_deg)

    def grid_points(*axes):
        return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], 1)

    theta_v = np.linspace(0.0, HALF_PI * 0.99, grid)
    theta_fn, theta_stats = _fit_inverse_cdf(
        lambda x: inverse_cdf_theta(rho, x[:, 0], x[:, 1]),
        grid_points(theta_v, (np.arange(2 * grid) + 0.5) / (2 * grid)),
        grid_points(np.linspace(0.0, HALF_PI, 2 * grid + 1), np.linspace(0.0, 1.0, 8 * grid + 1)),
        eps_theta,
        "cdf_theta",
        max_coefficients,
        progress,
    )
    theta_l = np.linspace(0.0, HALF_PI * 0.99, grid)
    dense = np.linspace(0.0, HALF_PI, grid + 1)
    phi_fn, phi_stats = _fit_inverse_cdf(
        lambda x: inverse_cdf_phi(rho, x[:, 0], x[:, 1], x[:, 2]),
        grid_points(theta_v, theta_l, (np.arange(grid) + 0.5) / grid),
        grid_points(dense, dense, np.linspace(0.0, 1.0, 4 * grid + 1)),
        eps_phi,
        "cdf_phi",
        max_coefficients,
        progress,
    )
    return SamplingFit(theta_fn, phi_fn, (theta_stats, phi_stats))


def proxy_alpha(functions: list, theta_max_deg: float) -> float:
    """The Beckmann alpha whose D(theta_h) / D(0) best matches (least squares, sin theta_h
    weighted) the luminance slice theta_d = 0 of the function above its minimum: where lobe-N
    places its pattern. A flat function gets ALPHA_MAX."""
    limit = math.radians(theta_max_deg)
    theta_h = np.linspace(0.0, limit, 256)
    x = np.stack([theta_h, np.zeros_like(theta_h)], 1)
    lum = np.stack([fn(x) for fn in functions], 1)
    lum = (lum if lum.shape[1] == 3 else np.repeat(lum, 3, 1)) @ LUMINANCE
    lum = np.maximum(lum, 0.0)
    span = lum.max() - lum.min()
    if not np.isfinite(span) or span <= 1e-6 * max(lum.max(), 1e-30):
        return ALPHA_MAX
    shape = (lum - lum.min()) / (lum[0] - lum.min()) if lum[0] > lum.min() else (lum - lum.min()) / span
    return fit_peak_shape(theta_h, shape)[1]


class RationalLobe(Component):
    """The Rational BRDF as one reflection component: eval from the per-channel functions,
    sampling from the rational inverse CDFs; ``distribution`` is the lobe-N proxy."""

    name = "rational"
    transmission = False
    #: lobe-N places its pattern through this lobe's inverse CDFs (materials/patterns.py step 6):
    #: no microfacet distribution has the shape of a fitted p / q (a proxy missed its broad part)
    sampled_pattern = True
    #: the functions live in a per-material storage buffer (viewer/material_gpu.py pack_rational):
    #: programs without HAS_RATIONAL (the RSIBR bake) cannot evaluate this lobe
    material_buffers = True

    def __init__(self, functions: list, theta_max_deg: float, sampling: SamplingFit, alpha: float | None = None):
        self.functions = list(functions)
        self.theta_max_deg = float(theta_max_deg)
        self.sampling = sampling
        alpha = proxy_alpha(self.functions, self.theta_max_deg) if alpha is None else float(alpha)
        self.distribution = MicrofacetDistribution("beckmann", alpha, alpha)

    @property
    def cache_key(self) -> tuple:
        """Everything the lobe's value and sampling depend on (GPU caches, albedo tables)."""
        fns = [*self.functions, self.sampling.theta, self.sampling.phi]
        return (self.theta_max_deg, *(repr(fn.to_dict()) for fn in fns))

    #: BSDF.albedo's minimum Gauss-Legendre order for this lobe (order 48 was 5 % off at 70 deg)
    min_quadrature_order = 128

    @property
    def selection_weight(self) -> float:
        return 1.0

    def primary_integrand(self, u1, u2, wo):
        """f |cos theta_l| / pdf at the sample of (u1, u2): Eq. 7's alpha rho cos, the density
        read from the derivatives at (mu, tau) directly (no inversion)."""
        wi, jacobian = self._sample(u1, u2, wo)
        f = self.eval(wi, wo)
        return f * (np.abs(wi[..., 2]) * np.maximum(jacobian, 0.0))[..., None]

    def lobe_pdf(self, wi, wo):
        """The proxy's half-vector density D(h) cos theta_h / (4 wo.h) (Eq. 4.9): what lobe-N's
        pattern weights use (shaders/bsdf.glsl lobe_half_pdf), not the sampler's density."""
        wi, wo = np.broadcast_arrays(wi, wo)
        valid = (wi[..., 2] > COS_EPSILON) & (wo[..., 2] > COS_EPSILON)
        h = normalize(wi + wo)
        p = self.distribution.pdf_half_vector(h) * reflection_jacobian(wo, h)
        return np.where(valid, p, 0.0)

    def eval(self, wi, wo):
        return evaluate_brdf(self.functions, self.theta_max_deg, wi, wo)

    def sample_wi(self, u1, u2, wo):
        return self._sample(u1, u2, wo)[0]

    def tangent_anchor_weight(self, wo) -> float:
        """How much of lobe-N's estimate comes from the lattice anchored in the tangent frame
        (:meth:`_sample` with ``tangent``): 1 up to TANGENT_ANCHOR_DEG[0] from the normal, where
        the lobe is nearly symmetric about the normal and a lattice turning with the view azimuth
        drew a pinwheel (issue 44: 26 dB), 0 from TANGENT_ANCHOR_DEG[1] on (the lattice anchored
        to the view keeps its mirror-symmetric placement about the lobe, more accurate there),
        linear between (both estimates blended: continuous, twice the samples on that ring)."""
        theta_v = math.degrees(math.acos(min(max(float(np.asarray(wo).reshape(3)[2]), 0.0), 1.0)))
        low, high = TANGENT_ANCHOR_DEG
        return min(max((high - theta_v) / (high - low), 0.0), 1.0)

    def _sample(self, u1, u2, wo, tangent: bool = False):
        """(wi, 1 / pdf) for uniform numbers: theta_l = r_theta(theta_v, u1); u2 < 1/2 picks
        phi_v + dphi with tau = 2 u2, else phi_v - dphi with tau = 2 u2 - 1 (Eq. 7-9).
        ``tangent``: u2 runs once around the circle instead (tau = 2 - 2 u2 on the second side,
        both sides meeting at dphi = pi), turned by -phi_v / 2 pi (mod 1), so a deterministic
        lattice keeps its azimuths in the tangent frame instead of turning with the view azimuth;
        uniform u2 stays uniform, the density is the same."""
        u1, u2 = np.asarray(u1, np.float64), np.asarray(u2, np.float64)
        shape = np.broadcast_shapes(u1.shape, u2.shape, wo.shape[:-1])
        mu = np.broadcast_to(u1, shape).reshape(-1)
        u2 = np.broadcast_to(u2, shape).reshape(-1)
        wo = np.broadcast_to(wo, shape + (3,)).reshape(-1, 3)
        theta_v = np.arccos(np.clip(wo[:, 2], 0.0, 1.0))
        phi_v = np.arctan2(wo[:, 1], wo[:, 0])
        x_theta = np.stack([theta_v, mu], 1)
        theta_l = np.clip(self.sampling.theta(x_theta), 0.0, HALF_PI)
        if tangent:
            u2 = np.mod(u2 - phi_v / (2.0 * math.pi), 1.0)
        sign = np.where(u2 < 0.5, 1.0, -1.0)
        tau = np.where(u2 < 0.5, 2.0 * u2, (2.0 - 2.0 * u2) if tangent else (2.0 * u2 - 1.0))
        x_phi = np.stack([theta_v, theta_l, tau], 1)
        dphi = np.clip(self.sampling.phi(x_phi), 0.0, math.pi)
        phi = phi_v + sign * dphi
        s = np.sin(theta_l)
        wi = np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta_l)], 1)
        jacobian = 2.0 * self.sampling.theta.derivative(x_theta, 1) * self.sampling.phi.derivative(x_phi, 2) * s
        return wi.reshape(shape + (3,)), jacobian.reshape(shape)

    def pdf(self, wi, wo):
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        valid = (wi[:, 2] > COS_EPSILON) & (wo[:, 2] > COS_EPSILON)
        theta_v = np.arccos(np.clip(wo[:, 2], 0.0, 1.0))
        theta_l = np.arccos(np.clip(wi[:, 2], 0.0, 1.0))
        dphi = np.abs(
            (np.arctan2(wi[:, 1], wi[:, 0]) - np.arctan2(wo[:, 1], wo[:, 0]) + math.pi) % (2 * math.pi) - math.pi
        )
        mu = _invert(lambda u: self.sampling.theta(np.stack([theta_v, u], 1)), theta_l)
        tau = _invert(lambda u: self.sampling.phi(np.stack([theta_v, theta_l, u], 1)), dphi)
        d_theta = self.sampling.theta.derivative(np.stack([theta_v, mu], 1), 1)
        d_phi = self.sampling.phi.derivative(np.stack([theta_v, theta_l, tau], 1), 2)
        jacobian = 2.0 * d_theta * d_phi * np.sin(theta_l)
        ok = valid & (d_theta > 0) & (d_phi > 0) & (jacobian > 0)
        return np.where(ok, 1.0 / np.where(ok, jacobian, 1.0), 0.0).reshape(shape)


def _invert(function: Callable[[np.ndarray], np.ndarray], target: np.ndarray) -> np.ndarray:
    """u in [0, 1] with function(u) = target for a function increasing in u (bisection)."""
    lo = np.zeros_like(target)
    hi = np.ones_like(target)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        below = function(mid) < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def rational_bsdf(desc: dict, name: str = "rational") -> BSDF:
    """The BSDF of a validated ``rational`` material description (spec.validate)."""
    functions = [RationalFunction.from_dict(d, f"brdf[{i}]") for i, d in enumerate(desc["brdf"])]
    sampling = SamplingFit(
        RationalFunction.from_dict(desc["sampling"]["theta"], "sampling.theta"),
        RationalFunction.from_dict(desc["sampling"]["phi"], "sampling.phi"),
        (),
    )
    return BSDF([RationalLobe(functions, desc["theta_max"], sampling, desc.get("proxy_alpha"))], name=name)


def rational_description(fit: RationalBRDFFit, sampling: SamplingFit, name: str = "rational fit") -> dict:
    """A ``rational`` material JSON object (spec.validate) of a fit."""
    return {
        "model": "rational",
        "name": name,
        "theta_max": fit.theta_max_deg,
        "brdf": [fn.to_dict() for fn in fit.functions],
        "sampling": {"theta": sampling.theta.to_dict(), "phi": sampling.phi.to_dict()},
        "proxy_alpha": proxy_alpha(fit.functions, fit.theta_max_deg),
    }


__all__ = [
    "ProjectedBRDF",
    "RationalBRDFFit",
    "RationalLobe",
    "SamplingFit",
    "fit_rational_brdf",
    "fit_sampling",
    "project_measurement",
    "project_merl",
    "rational_bsdf",
    "rational_description",
]
