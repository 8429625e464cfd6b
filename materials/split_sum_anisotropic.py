"""The split-sum line of an anisotropic lobe (issue 45), numpy twin of shaders/prefiltered.glsl's
anisotropic branch: where along its wider axis an anisotropic lobe reads the isotropic split-sum
map, and how much each read weighs.

The map is filtered with an isotropic kernel, so an anisotropic lobe reads it at its narrower
roughness alpha_min at SPLIT_SUM_LINE_NODES slopes along its wider axis (prefiltered was isotropic
before: 30 % off on GGX 0.05 x 0.3 against Mitsuba). GGX's slope density (1 + s^2 / alpha^2)^-2 has
the marginal (1 + s^2 / alpha^2)^-3/2 (Student t with 2 degrees of freedom, scaled by
alpha / sqrt 2; quantile (2u - 1) / (2 sqrt(u (1 - u)))), Beckmann's is normal with variance
alpha^2 / 2 (quantile erfinv(2u - 1)). Each node stands for an interval of probability
(SPLIT_SUM_LINE_EDGES) and weighs it: ninths, the two outer ninths split at 1/36 and 35/36 (GGX's
heavy tail: the outer ninth of GGX 0.05 x 0.3 reaches from the ground to the sky, and its one node
read the ground: a sphere's lower half 20-35 % too dark).

Where the nodes sit (:func:`anisotropic_line_slopes`): at the quantiles, along the wider axis, of
the lobe's own f cos, not of its slope marginal alone. In half-vector slopes s (h = normalize(-s, 1)),
with dwi = 4 (wo.h) dwh and D dwh = P22(s) d2s / cos theta_h,
    f cos theta_i dwi = P22(s) d2s  G2(wi, wo) (wo.h) / (cos theta_h cos theta_o)
(no Fresnel: the albedo table carries it), so along the wider axis the lobe is the marginal times
g(s) = G2 (wo.h) / cos theta_h, zero where wi falls below the surface. Seen along its wider axis the
lobe is cut by the horizon and leans (the off-specular shift); the marginal's symmetric quantiles
with the lean towards the normal that stood in for that (Lagarde & de Rousiers 2014, prefilter.py
split_sum_lean) left the sun window of GGX 0.05 x 0.3 on the Mitsuba sky 2.8 % dark and the same
lobe 14-44 % off under real captures (numpy twin, bench/split_sum_line.py). Per pixel, g is
evaluated at the marginal's own nodes (at scale alpha_max: eleven G2 evaluations), the marginal's
intervals reweighted by it, and the nodes placed at the reweighted distribution's quantiles (its
CDF linear in the marginal's probability within each interval, mapped back through the marginal's
quantile function), their offsets from its median shrunk by sqrt(1 - (alpha_min / alpha_max)^2):
the narrow kernel every read adds already spreads that much (as the deconvolved scale
sqrt(alpha_max^2 - alpha_min^2) did for the symmetric line). No lean. Eleven nodes reweighted are as
good as the exact quantiles by quadrature or 64 reweighted intervals (docs/measurements.md
"Anisotropic lobes at their own quantiles").

Lobes within SPLIT_SUM_LINE_RATIO of isotropic keep one lookup (isotropic lobes seen off the normal
take a line along the plane of incidence instead: split_sum_oblique.py).
"""

from __future__ import annotations

import numpy as np

from .microfacet import MicrofacetDistribution

SPLIT_SUM_LINE_EDGES = (0.0, 1.0 / 36.0) + tuple(k / 9.0 for k in range(1, 9)) + (35.0 / 36.0, 1.0)
SPLIT_SUM_LINE_NODES = len(SPLIT_SUM_LINE_EDGES) - 1
SPLIT_SUM_LINE_RATIO = 1.05
#: the probability each of the line's nodes sits at: the middle of its SPLIT_SUM_LINE_EDGES interval
LINE_QUANTILES = 0.5 * (np.asarray(SPLIT_SUM_LINE_EDGES)[:-1] + np.asarray(SPLIT_SUM_LINE_EDGES)[1:])
# the reweighted CDF's probabilities are kept this far inside (0, 1): the quantile functions are
# infinite at the ends (shaders/prefiltered.glsl clamps the same)
QUANTILE_MARGIN = 1e-6


def split_sum_is_line(alpha_x: float, alpha_y: float) -> bool:
    """Whether split-sum reads a lobe along the quantile line (anisotropic by more than
    SPLIT_SUM_LINE_RATIO), and, for GGX, takes its albedo from the anisotropic table."""
    return max(alpha_x, alpha_y) > SPLIT_SUM_LINE_RATIO * min(alpha_x, alpha_y)


def split_sum_line_weights() -> np.ndarray:
    """The probability each of the line's nodes stands for (sums to 1)."""
    return np.diff(np.asarray(SPLIT_SUM_LINE_EDGES))


def slope_marginal_quantile(kind: str, u) -> np.ndarray:
    """The quantile at probability ``u`` of distribution ``kind``'s slope marginal at alpha 1
    (GGX: Student t with 2 degrees of freedom / sqrt 2; Beckmann: normal / sqrt 2)."""
    from scipy.special import erfinv

    u = np.asarray(u, dtype=np.float64)
    if kind == "ggx":
        return (2.0 * u - 1.0) / (2.0 * np.sqrt(u * (1.0 - u)))
    return erfinv(2.0 * u - 1.0)


def split_sum_line_quantiles(kind: str) -> np.ndarray:
    """The slopes (in units of the scale) of the line's nodes for distribution ``kind``: the
    marginal's quantiles at the middle of each interval of SPLIT_SUM_LINE_EDGES."""
    return slope_marginal_quantile(kind, LINE_QUANTILES)


def wider_axis(alpha_x: float, alpha_y: float) -> np.ndarray:
    """The tangent-plane axis (2,) an anisotropic lobe's line runs along: x where alpha_x >= alpha_y."""
    return np.array([1.0, 0.0]) if alpha_x >= alpha_y else np.array([0.0, 1.0])


def line_half_vectors(slopes: np.ndarray, major: np.ndarray) -> np.ndarray:
    """The half vectors normalize(-s major, 1) of slopes ``slopes`` along the 2-vector ``major`` (k, 3)."""
    h = np.concatenate([-np.asarray(slopes)[:, None] * major[None], np.ones((len(slopes), 1))], axis=1)
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def mirror_directions(wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``wo`` reflected about each half vector of ``h`` (k, 3)."""
    return 2.0 * (h @ wo)[:, None] * h - wo


def anisotropic_line_slopes(wo: np.ndarray, kind: str, alpha_x: float, alpha_y: float) -> tuple[np.ndarray, np.ndarray]:
    """(slopes (SPLIT_SUM_LINE_NODES,), the wider axis (2,)) of an anisotropic lobe's line seen
    from ``wo`` (local frame): the nodes at the quantiles of the lobe's f cos along its wider axis,
    reweighting the marginal's intervals by g = G2 (wo.h) / cos theta_h at the marginal's nodes, as
    the module's docstring derives. A view whose every node reflects below the surface keeps the
    marginal's symmetric nodes (the caller then reads them all)."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    a_min, a_max = min(alpha_x, alpha_y), max(alpha_x, alpha_y)
    major = wider_axis(alpha_x, alpha_y)
    shrink = np.sqrt(max(1.0 - (a_min / a_max) ** 2, 0.0))
    marginal = split_sum_line_quantiles(kind) * a_max
    h = line_half_vectors(marginal, major)
    wi = mirror_directions(wo, h)
    distribution = MicrofacetDistribution(kind, alpha_x, alpha_y)
    g = distribution.G(wi, np.broadcast_to(wo, wi.shape)) * (h @ wo) / h[:, 2]
    mass = split_sum_line_weights() * np.where(wi[:, 2] > 0.0, g, 0.0)
    if not mass.sum() > 0.0:
        return marginal * shrink, major
    edges = np.asarray(SPLIT_SUM_LINE_EDGES)
    cdf = np.concatenate([[0.0], np.cumsum(mass)]) / mass.sum()
    # the interval each target falls in (the first whose CDF end passes it: empty intervals are
    # skipped), then linear in the marginal's probability within it
    bins = np.minimum(np.searchsorted(cdf[1:], LINE_QUANTILES, side="right"), len(mass) - 1)
    within = (LINE_QUANTILES - cdf[bins]) / np.maximum(mass[bins] / mass.sum(), 1e-30)
    u = edges[bins] + np.clip(within, 0.0, 1.0) * (edges[bins + 1] - edges[bins])
    slopes = slope_marginal_quantile(kind, np.clip(u, QUANTILE_MARGIN, 1.0 - QUANTILE_MARGIN)) * a_max
    median = slopes[SPLIT_SUM_LINE_NODES // 2]  # the middle interval's middle is 1/2
    return median + (slopes - median) * shrink, major
