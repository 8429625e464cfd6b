"""Fitted lobe patterns: N blurred reads whose sum is the lobe (issue 45; numpy reference, no shader yet).

lobe-N+norm is one kernel, sum_j w_j G_j, each G_j the blur that one MIP read returns
(bench/lobe_kernel.py). The thesis' pattern places the reads by a map from half vectors and weights
them by Eq. 4.25; the kernel it makes is 6-18 % (relative L2) from the lobe's f cos near the normal
and 24-60 % at 70-80 degrees, and with ideal reads that alone leaves lobe-7 at 4-8 % on issue 45's
sky. Here the reads are *fitted*: for a lobe (distribution, alpha) seen at cos theta_o, N reads
(a_j, b_j, w_j, sigma_j) minimise the L2 distance between

    K(x) = sum_j w_j G(x; d_j, sigma_j)   and   T(x) = f(x, wo) cos theta_x / albedo(wo)

over the sphere of directions, with G the normalised spherical Gaussian exp((x.d - 1) / sigma^2)
(what a read of the tent MIP chain returns: bench/lobe_kernel.py measured sigma on llvmpipe) and
the weights a softmax (they sum to 1, so the estimate albedo(wo) sum_j w_j L_j is exact under
uniform light like lobe-N+norm). d_j is the point (a_j, b_j) of the tangent plane at the mirror
direction r mapped to the sphere (the exponential map): a along the plane of incidence, positive
towards the normal, b across it. The topology is fixed (:data:`TOPOLOGIES`): m reads on the plane of
incidence (b = 0) and p mirrored pairs (a, +-b), so the kernel keeps the lobe's symmetry and the
fit moves continuously with the view (pairs fold onto the plane at grazing, where the lobe is
1 / cos theta_o longer in the plane than across it and cut by the horizon).

Positions and widths are in units of the lobe's own spread (its standard deviations along a and
b), so that one set of parameters serves a range of alpha. The T grid is the tangent plane at r,
96 x 96 points over +-min(pi, 6 sd) about the lobe's mean along each axis, weighted by the
exponential map's area element sin(rho) / rho; below the horizon T = 0 and a read's mass there
is error (a cube read there sees the ground).

The table (:func:`build_table`, written by bench/fitted_patterns.py to fitted_patterns.npz) holds
the fit at 12 alphas x 24 views, each node started from its neighbour's solution so that the
parameters move continuously; :func:`table_reads` interpolates it bilinearly in (log alpha,
theta_o), :func:`integrate_fitted` is the estimator, reading each sample at the MIP level whose
blur is its sigma (:func:`lod_for_sigma`). The GPU reads the same tables (viewer/fitted_gpu.py,
shaders/fitted.glsl); anisotropic and transmission lobes keep the thesis pattern (patterns.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from .microfacet import MicrofacetDistribution

# reads -> (reads on the plane of incidence, mirrored pairs); reads = line + 2 pairs. lobe-N reads N
# for a Beckmann lobe and N + 4 for a GGX lobe (the budget of lobe-N+norm's tail term, patterns.py step 7).
TOPOLOGIES = {3: (1, 1), 5: (3, 1), 7: (3, 2), 9: (3, 3), 11: (5, 3), 15: (5, 5), 19: (7, 6), 23: (7, 8)}
# The table's nodes: roughness alpha (log-spaced) and view angle theta_o (uniform, degrees).
TABLE_ALPHAS = (0.02, 0.035, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.65, 0.8, 1.0)
TABLE_VIEWS_DEG = tuple(float(x) for x in np.linspace(0.0, 89.0, 24))
GRID_POINTS = 96  # per axis of the tangent-plane grid the fit measures the distance on
GRID_SPREADS = 6.0  # its half-width in the lobe's largest standard deviation (at most pi)
FIT_ITERATIONS = 500
# The pull of a table node's fit towards its already-fitted neighbours (fit_target). Chosen on GGX
# 0.15-0.4 (11 reads), the worst relative L2 distance at the nodes / between them (views 2-78 deg):
# no pull 0.04 / 0.13 (neighbours in different minima), 1e-4 0.039 / 0.121, 1e-3 0.047 / 0.058,
# 1e-2 0.14 / 0.13 (held too close to the first view's shape).
ANCHOR_STIFFNESS = 1e-3
# The pull grows with the parameters it sums over: at 1e-3 the GGX tables of 15 and more reads
# ended farther from the lobe than the 11-read one (GGX 0.3 from 35 deg; lobe-15 behind lobe-7).
# Refitted at 3e-4 (anchor_stiffness), mean distance at the nodes / between them (99 midpoints,
# alpha <= 0.65, views <= 80 deg): 15 reads 0.039 / 0.056 -> 0.031 / 0.052, 19 reads 0.035 / 0.050
# -> 0.029 / 0.046, 23 reads 0.030 / 0.045 -> 0.024 / 0.045 (11 reads: 0.042 / 0.054).
LARGE_TABLE_STIFFNESS = 3e-4
# The fitted tables, written by bench/fitted_patterns.py (one array per distribution and read count).
TABLE_PATH = Path(__file__).with_name("fitted_patterns.npz")


def mirror_frame(cos_theta_o: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(wo, r, e_a, e_b) in the lobe's local frame for a view at azimuth 0: the mirror direction r,
    e_a in the plane of incidence towards the normal, e_b across it."""
    cos_o = float(np.clip(cos_theta_o, 1e-4, 1.0))
    sin_o = np.sqrt(max(1.0 - cos_o * cos_o, 0.0))
    wo = np.array([sin_o, 0.0, cos_o])
    r = np.array([-sin_o, 0.0, cos_o])
    e_b = np.array([0.0, 1.0, 0.0])
    e_a = np.cross(e_b, r)
    return wo, r, e_a, e_b


def exp_map(r: np.ndarray, e_a: np.ndarray, e_b: np.ndarray, a, b) -> np.ndarray:
    """Directions (..., 3) at tangent-plane offsets (a, b) (radians) from r along e_a, e_b."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    rho = np.hypot(a, b)
    sinc = np.sinc(rho / np.pi)  # sin(rho) / rho
    return np.cos(rho)[..., None] * r + (a * sinc)[..., None] * e_a + (b * sinc)[..., None] * e_b


def gaussian_norm(sigma):
    """The integral of exp((cos - 1) / sigma^2) over the sphere: 2 pi sigma^2 (1 - exp(-2 / sigma^2))."""
    sigma = np.asarray(sigma, dtype=np.float64)
    return 2.0 * np.pi * sigma * sigma * -np.expm1(-2.0 / (sigma * sigma))


@dataclass(frozen=True)
class LobeTarget:
    """The normalised lobe f cos / albedo of one view on the tangent-plane grid, and its spread."""

    wo: np.ndarray
    r: np.ndarray
    e_a: np.ndarray
    e_b: np.ndarray
    directions: np.ndarray  # (G, 3) grid directions
    area: np.ndarray  # (G,) solid angle of each grid point
    values: np.ndarray  # (G,) f cos / albedo (0 below the horizon)
    albedo: float
    mean_a: float
    spread: np.ndarray  # (2,) standard deviations along e_a and e_b (radians)


def lobe_target(distribution: MicrofacetDistribution, cos_theta_o: float, points: int = GRID_POINTS) -> LobeTarget:
    """The fit's target for an isotropic microfacet reflection lobe without Fresnel (D G / 4 cos_o)."""
    from .conductor import MicrofacetReflection
    from .fresnel import Fresnel

    lobe = MicrofacetReflection(distribution, Fresnel("none"))
    wo, r, e_a, e_b = mirror_frame(cos_theta_o)

    def sample(centre_a: float, half_a: float, half_b: float):
        step_a, step_b = 2.0 * half_a / points, 2.0 * half_b / points
        axis_a = centre_a + (np.arange(points) + 0.5) * step_a - half_a
        axis_b = (np.arange(points) + 0.5) * step_b - half_b
        a, b = np.meshgrid(axis_a, axis_b, indexing="ij")
        a, b = a.reshape(-1), b.reshape(-1)
        rho = np.hypot(a, b)
        keep = rho < np.pi
        a, b, rho = a[keep], b[keep], rho[keep]
        dirs = exp_map(r, e_a, e_b, a, b)
        area = np.sinc(rho / np.pi) * step_a * step_b  # the exponential map's area element
        values = np.zeros(len(dirs))
        above = dirs[:, 2] > 0.0
        values[above] = lobe.eval(dirs[above], np.broadcast_to(wo, (int(above.sum()), 3)))[:, 0] * dirs[above, 2]
        return a, b, dirs, area, values

    def moments(a, b, area, values):
        albedo = float(np.sum(values * area))
        if not albedo > 0.0:
            raise ValueError(f"the lobe has no energy above the horizon at cos theta_o = {cos_theta_o}")
        weights = values * area / albedo
        mean_a = float(np.sum(weights * a))
        spread = np.sqrt(np.array([np.sum(weights * (a - mean_a) ** 2), np.sum(weights * b * b)]))
        return albedo, mean_a, spread

    # A first look at the whole sphere, then twice on grids fitted to the lobe's spread along each
    # axis (at grazing it is 1 / cos theta_o narrower across the plane than along it).
    a, b, dirs, area, values = sample(0.0, np.pi, np.pi)
    albedo, mean_a, spread = moments(a, b, area, values)
    for _ in range(2):
        half_a, half_b = (min(np.pi, GRID_SPREADS * float(s)) for s in spread)
        a, b, dirs, area, values = sample(mean_a, half_a, half_b)
        albedo, mean_a, spread = moments(a, b, area, values)
    return LobeTarget(wo, r, e_a, e_b, dirs, area, values / albedo, albedo, mean_a, spread)


@dataclass(frozen=True)
class FittedPattern:
    """N reads: tangent-plane offsets (a, b) and widths sigma in radians, weights summing to 1."""

    a: np.ndarray
    b: np.ndarray
    weight: np.ndarray
    sigma: np.ndarray
    distance: float  # relative L2 distance of the kernel to the target

    def directions(self, target: LobeTarget) -> np.ndarray:
        return exp_map(target.r, target.e_a, target.e_b, self.a, self.b)


def _unpack(params: np.ndarray, n: int, target: LobeTarget):
    """Parameters -> (a, b, logits, log sigma) per read; positions in units of the lobe's spread."""
    line, pairs = TOPOLOGIES[n]
    k = line + pairs
    pa, pb, logits, log_sigma = (
        params[:k],
        params[k : k + pairs],
        params[k + pairs : 2 * k + pairs],
        params[2 * k + pairs :],
    )
    sa, sb = target.spread
    a = np.concatenate([pa[:line], pa[line:], pa[line:]]) * sa + target.mean_a
    b = np.concatenate([np.zeros(line), pb, -pb]) * sb
    logit = np.concatenate([logits[:line], logits[line:], logits[line:]])
    sigma = np.exp(np.concatenate([log_sigma[:line], log_sigma[line:], log_sigma[line:]])) * min(sa, sb)
    return a, b, logit, sigma


def _kernel_and_gradient(params: np.ndarray, n: int, target: LobeTarget):
    """The relative squared L2 distance and its gradient in the parameters."""
    line, pairs = TOPOLOGIES[n]
    a, b, logit, sigma = _unpack(params, n, target)
    weight = np.exp(logit - logit.max())
    weight /= weight.sum()
    dirs = exp_map(target.r, target.e_a, target.e_b, a, b)  # (N, 3)
    cosines = target.directions @ dirs.T  # (G, N)
    shapes = np.exp(np.minimum((cosines - 1.0) / (sigma * sigma), 0.0)) / gaussian_norm(sigma)
    kernel = shapes @ weight
    residual = kernel - target.values
    norm = np.sum(target.values**2 * target.area)
    loss = np.sum(residual**2 * target.area) / norm
    back = 2.0 * residual * target.area / norm  # dloss / dkernel per grid point
    # per read: dloss/dw_j, dloss/dd_j (through the cosines), dloss/dsigma_j
    d_weight = back @ shapes
    d_shape = back[:, None] * shapes * weight[None, :]  # dloss / d(shape_j) times shape_j, weighted
    d_dir = (d_shape.T @ target.directions) / (sigma * sigma)[:, None]  # (N, 3)
    exp_term = np.exp(-2.0 / (sigma * sigma))
    dlog_norm = 2.0 / sigma - 4.0 * exp_term / (sigma**3 * -np.expm1(-2.0 / (sigma * sigma)))
    d_sigma = np.sum(d_shape * (-2.0 * (cosines - 1.0) / sigma**3), axis=0) - d_weight * weight * dlog_norm
    # softmax: dloss/dlogit_j = w_j (dloss/dw_j - sum_k w_k dloss/dw_k)
    d_logit = weight * (d_weight - np.sum(weight * d_weight))
    # positions: the exponential map's derivatives by central differences (cheap: no grid)
    step = 1e-6
    da = (
        exp_map(target.r, target.e_a, target.e_b, a + step, b) - exp_map(target.r, target.e_a, target.e_b, a - step, b)
    ) / (2 * step)
    db = (
        exp_map(target.r, target.e_a, target.e_b, a, b + step) - exp_map(target.r, target.e_a, target.e_b, a, b - step)
    ) / (2 * step)
    d_a = np.sum(d_dir * da, axis=1)
    d_b = np.sum(d_dir * db, axis=1)
    sa, sb = target.spread
    # fold the mirrored pairs back onto their shared parameters
    k = line + pairs

    def fold(per_read):
        return np.concatenate([per_read[:line], per_read[line:k] + per_read[k:]])

    grad = np.concatenate(
        [
            fold(d_a) * sa,
            (d_b[line:k] - d_b[k:]) * sb,
            fold(d_logit),
            fold(d_sigma * sigma),
        ]
    )
    return loss, grad


def initial_parameters(n: int) -> np.ndarray:
    """A start in spread units: the line's reads over +-1.2 sd, the pairs at +-0.8 sd across, widths
    half the smaller spread, equal weights."""
    line, pairs = TOPOLOGIES[n]
    line_a = np.linspace(-1.2, 1.2, line) if line > 1 else np.zeros(1)
    pair_a = np.linspace(-0.6, 0.6, pairs) if pairs > 1 else np.zeros(1)
    return np.concatenate(
        [line_a, pair_a, np.full(pairs, 0.9), np.zeros(line + pairs), np.full(line + pairs, np.log(0.5))]
    )


def fit_pattern(
    distribution: MicrofacetDistribution,
    cos_theta_o: float,
    n: int = 7,
    start: np.ndarray | None = None,
    anchor: np.ndarray | None = None,
) -> tuple[FittedPattern, np.ndarray, LobeTarget]:
    """The fitted n reads of one view, the parameters (to warm-start a neighbouring view) and the
    target. ``start`` and ``anchor`` (parameters of nearby nodes) keep neighbouring fits on one branch."""
    target = lobe_target(distribution, cos_theta_o)
    pattern, params = fit_target(target, n, start, anchor, anchor_stiffness(distribution.kind, n))
    return pattern, params, target


def anchor_stiffness(kind: str, reads: int) -> float:
    """The anchor's pull for a table: ANCHOR_STIFFNESS, LARGE_TABLE_STIFFNESS for GGX tables of 15
    or more reads (lobe-11 and up)."""
    return LARGE_TABLE_STIFFNESS if kind == "ggx" and reads >= 15 else ANCHOR_STIFFNESS


def fit_target(
    target: LobeTarget,
    n: int,
    start: np.ndarray | None = None,
    anchor: np.ndarray | None = None,
    stiffness: float = ANCHOR_STIFFNESS,
) -> tuple[FittedPattern, np.ndarray]:
    """L-BFGS on :func:`_kernel_and_gradient` (an analytic gradient) from ``start`` or
    :func:`initial_parameters`. With ``anchor`` (parameters), ``stiffness`` |p - anchor|^2 is
    added: the distance has many near-equal minima (reads trade places, a pair folds onto the
    line), and a table whose neighbouring nodes sit in different ones cannot be interpolated."""
    if n not in TOPOLOGIES:
        raise ValueError(f"no fitted topology for {n} reads; use one of {sorted(TOPOLOGIES)}")
    params = initial_parameters(n) if start is None else np.asarray(start, dtype=np.float64)

    def objective(p):
        loss, grad = _kernel_and_gradient(p, n, target)
        if anchor is None:
            return loss, grad
        pull = p - anchor
        return loss + stiffness * float(pull @ pull), grad + 2.0 * stiffness * pull

    result = minimize(objective, params, jac=True, method="L-BFGS-B", options={"maxiter": FIT_ITERATIONS})
    params = result.x.copy()
    line, pairs = TOPOLOGIES[n]
    params[line + pairs : line + 2 * pairs] = np.abs(params[line + pairs : line + 2 * pairs])  # b >= 0
    return pattern_of(params, n, target), params


def pattern_of(params: np.ndarray, n: int, target: LobeTarget) -> FittedPattern:
    """The reads (radians, weights summing to 1) of parameters, with their distance to ``target``."""
    a, b, logit, sigma = _unpack(np.asarray(params, dtype=np.float64), n, target)
    weight = np.exp(logit - logit.max())
    weight /= weight.sum()
    pattern = FittedPattern(a, b, weight, sigma, 0.0)
    return FittedPattern(a, b, weight, sigma, kernel_distance(pattern, target))


def kernel_distance(pattern: FittedPattern, target: LobeTarget) -> float:
    """Relative L2 distance of a pattern's kernel to its target, recomputed from the reads."""
    dirs = pattern.directions(target)
    cosines = target.directions @ dirs.T
    sigma = pattern.sigma
    shapes = np.exp(np.minimum((cosines - 1.0) / (sigma * sigma), 0.0)) / gaussian_norm(sigma)
    residual = shapes @ pattern.weight - target.values
    return float(np.sqrt(np.sum(residual**2 * target.area) / np.sum(target.values**2 * target.area)))


def _microfacet_reflection(lobe) -> bool:
    """A GGX or Beckmann microfacet reflection, isotropic or not (the fitted table's lobe family)."""
    from .conductor import MicrofacetReflection

    dist = getattr(lobe, "distribution", None)
    return (
        isinstance(lobe, MicrofacetReflection)
        and not getattr(lobe, "transmission", False)
        and dist is not None
        and dist.kind in ("ggx", "beckmann")
    )


def has_fitted_pattern(lobe) -> bool:
    """Whether lobe-N+norm+fit reads a lobe through the fitted table: an isotropic GGX or Beckmann
    microfacet reflection (conductor.py MicrofacetReflection and its glTF specular and clearcoat
    lobes, whose f is D G times factors of the view alone; shaders: LOBE_MICROFACET,
    LOBE_GLTF_SPECULAR, LOBE_GLTF_CLEARCOAT). Anisotropic and transmission lobes keep the thesis
    pattern for now."""
    return _microfacet_reflection(lobe) and lobe.distribution.alpha_x == lobe.distribution.alpha_y


def may_read_fitted(lobes, per_pixel_lobes: bool = False) -> bool:
    """Whether lobe-N+norm+fit may read any of ``lobes`` through the fitted table, i.e. needs the
    cube's blur stack (materials/blur_stack.py). With ``per_pixel_lobes`` (glTF textures) the
    shader decides per pixel (an anisotropy texture may be zero there): every GGX or Beckmann
    microfacet reflection counts, isotropic or not."""
    test = _microfacet_reflection if per_pixel_lobes else has_fitted_pattern
    return any(test(lobe) for lobe in lobes)


def read_count(kind: str, n: int) -> int:
    """The reads of lobe-N's fitted pattern: N for Beckmann, N + 4 for GGX (its tail's budget)."""
    return n + 4 if kind == "ggx" else n


@dataclass(frozen=True)
class PatternTable:
    """Fitted reads over TABLE_ALPHAS x TABLE_VIEWS_DEG for one distribution and read count:
    ``reads`` (alphas, views, reads, 4) = (a / spread_a, b / spread_b, weight, sigma / min spread)
    and ``lobe`` (alphas, views, 3) = (mean_a, spread_a, spread_b) in radians, so that positions
    and widths interpolate between nodes in the lobe's own units; ``distance`` (alphas, views)
    the kernel's relative L2 distance at each node."""

    kind: str
    reads: np.ndarray
    lobe: np.ndarray
    distance: np.ndarray


def build_table(kind: str, reads: int, progress=None) -> PatternTable:
    """Fit every node from, and anchored to (fit_target), the mean of its fitted neighbours at the
    previous alpha and the previous view, so that the parameters move continuously across the table
    in both directions (positions and widths are in the lobe's own units, which change slowly)."""
    alphas, views = TABLE_ALPHAS, TABLE_VIEWS_DEG
    out = np.zeros((len(alphas), len(views), reads, 4))
    lobe = np.zeros((len(alphas), len(views), 3))
    distance = np.zeros((len(alphas), len(views)))
    fitted: dict[tuple[int, int], np.ndarray] = {}
    for i, alpha in enumerate(alphas):
        distribution = MicrofacetDistribution(kind, alpha, alpha)
        for j, view in enumerate(views):
            neighbours = [fitted[node] for node in ((i - 1, j), (i, j - 1)) if node in fitted]
            anchor = np.mean(neighbours, axis=0) if neighbours else None
            cos_o = float(np.cos(np.radians(view)))
            pattern, params, target = fit_pattern(distribution, cos_o, reads, anchor, anchor)
            fitted[(i, j)] = params
            sa, sb = target.spread
            out[i, j, :, 0] = (pattern.a - target.mean_a) / sa
            out[i, j, :, 1] = pattern.b / sb
            out[i, j, :, 2] = pattern.weight
            out[i, j, :, 3] = pattern.sigma / min(sa, sb)
            lobe[i, j] = (target.mean_a, sa, sb)
            distance[i, j] = pattern.distance
        if progress:
            progress(f"[fitted patterns] {kind} {reads} reads, alpha {alpha:g}: distance "
                     f"{distance[i].min():.3f}-{distance[i].max():.3f}")  # fmt: skip
    return PatternTable(kind, out, lobe, distance)


def table_reads(table: PatternTable, alpha: float, cos_theta_o: float) -> tuple[np.ndarray, ...]:
    """(a, b, weight, sigma) of the reads at (alpha, view), bilinear between the table's nodes
    (log alpha, theta_o) in the lobe's units, clamped at the table's edges; weights renormalised."""
    alpha_x = np.interp(np.log(alpha), np.log(TABLE_ALPHAS), np.arange(len(TABLE_ALPHAS)))
    theta = np.degrees(np.arccos(np.clip(cos_theta_o, 0.0, 1.0)))
    view_x = np.interp(theta, TABLE_VIEWS_DEG, np.arange(len(TABLE_VIEWS_DEG)))
    i, j = min(int(alpha_x), len(TABLE_ALPHAS) - 2), min(int(view_x), len(TABLE_VIEWS_DEG) - 2)
    fa, fv = alpha_x - i, view_x - j

    def blend(grid):
        return ((grid[i, j] * (1 - fv) + grid[i, j + 1] * fv) * (1 - fa)
                + (grid[i + 1, j] * (1 - fv) + grid[i + 1, j + 1] * fv) * fa)  # fmt: skip

    reads, (mean_a, sa, sb) = blend(table.reads), blend(table.lobe)
    weight = reads[:, 2] / np.sum(reads[:, 2])
    return mean_a + reads[:, 0] * sa, reads[:, 1] * sb, weight, reads[:, 3] * min(sa, sb)


# -- reading the cube: the blur of one MIP read, and the level that gives a wanted blur -----------
def level_variance(level) -> np.ndarray:
    """The variance, in base texels^2, of a read of integer ``level`` of the tent MIP chain around a
    point source (viewer/mip_chain.py): each level's [1 3 3 1] / 8 adds 3/4 of its source texel^2,
    L levels sum to 1/4 (4^L - 1), the bilinear read a tent of one level-L texel (4^L / 6):
    4^L 5/12 - 1/4."""
    return 4.0 ** np.asarray(level, dtype=np.float64) * 5.0 / 12.0 - 0.25


def read_sigma_texels(level) -> np.ndarray:
    """The standard deviation, in base texels, of what a trilinear read at ``level`` returns: the
    blend of its two levels' kernels, whose variance is the blend of theirs (both centred on the
    read). Measured on llvmpipe by bench/lobe_kernel.py (tests/test_lobe_kernel.py): at levels 2 /
    2.25 / 2.5 / 2.75 / 3 sigma is 0.634 / 0.710 / 0.716 / 0.688 / 0.643 level texels, this model
    0.633 / 0.710 / 0.716 / 0.688 / 0.643 (one smooth 4^L law instead: 0.637-0.641, up to 12 %
    low between levels)."""
    level = np.maximum(np.asarray(level, dtype=np.float64), 0.0)
    low = np.floor(level)
    t = level - low
    return np.sqrt((1.0 - t) * level_variance(low) + t * level_variance(low + 1.0))


def texel_angle(directions: np.ndarray, face_size: int) -> np.ndarray:
    """The angular width (rad) of a base texel of a cube face seen in ``directions``: its solid
    angle is (2 / face_size)^2 max|d|^3 (patterns.cube_map_lod)."""
    return 2.0 / face_size * np.max(np.abs(directions), axis=-1) ** 1.5


def lod_for_sigma(directions: np.ndarray, sigma: np.ndarray, face_size: int) -> np.ndarray:
    """The inverse of :func:`read_sigma_texels`: the MIP level whose read blurs by ``sigma`` (rad)
    in ``directions``: the integer level L below (level_variance(L) <= s^2) and the blend t of L + 1
    that makes up the rest of the variance, s = sigma in base texels; a sigma below level 0's
    (sqrt(1/6) texel) gives level 0 (a read cannot be sharper)."""
    texels = np.asarray(sigma, dtype=np.float64) / texel_angle(directions, face_size)
    variance = np.maximum(texels * texels, level_variance(0.0))
    low = np.floor(np.log2((variance + 0.25) * 12.0 / 5.0) / 2.0 + 1e-12)
    t = (variance - level_variance(low)) / (level_variance(low + 1.0) - level_variance(low))
    return low + np.clip(t, 0.0, 1.0)


# -- the estimator --------------------------------------------------------------------------------
def fitted_reads(table: PatternTable, alpha: float, wo: np.ndarray):
    """Local directions (N, 3), weights (N,) and widths (N,) rad of the fitted reads for a view
    ``wo`` (local frame, any azimuth): the table's pattern at azimuth 0 turned to wo's azimuth."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    a, b, weight, sigma = table_reads(table, alpha, float(wo[2]))
    _, r, e_a, e_b = mirror_frame(float(wo[2]))
    local = exp_map(r, e_a, e_b, a, b)
    phi = np.arctan2(wo[1], wo[0])
    c, s = np.cos(phi), np.sin(phi)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return local @ turn.T, weight, sigma


def integrate_fitted(
    lobe, wo, radiance, table: PatternTable, face_size: int, frame, albedo_table, stack=None
) -> np.ndarray:
    """lobe-N with the fitted pattern: albedo(wo) sum_j w_j L(d_j, lod_j), each read at the level
    that blurs by its sigma (:func:`lod_for_sigma`); exact under uniform light. ``radiance`` as
    patterns.integrate_lobe takes it; the lobe must be an isotropic GGX or Beckmann reflection.
    ``stack`` (materials/blur_stack.py StackReads, or None): reads of sigma >= its ``sigma0`` read
    it (``stack(world, sigma)``) instead of the MIP chain, as the preview renderer does."""
    dist = lobe.distribution
    dirs, weight, sigma = fitted_reads(table, float(dist.alpha_x), wo)
    world = dirs if frame is None else dirs @ np.asarray(frame, dtype=np.float64).T  # patterns.to_world
    lod = lod_for_sigma(world, sigma, face_size)
    values = np.asarray(radiance(world, lod), dtype=np.float64)
    if stack is not None:
        coarse = sigma >= stack.sigma0
        if np.any(coarse):
            values[coarse] = stack(world[coarse] / np.linalg.norm(world[coarse], axis=1, keepdims=True), sigma[coarse])
    return albedo_table.lookup(np.asarray(wo, dtype=np.float64).reshape(3)) * (weight @ values)


@lru_cache(maxsize=2)
def fitted_sample_counts(path: Path = TABLE_PATH) -> tuple[int, ...]:
    """The lobe-N sample counts with a fitted table for both distributions (lobe-N+norm+fit); read
    once (the panel asks every frame), cleared with load_table's cache when tables are written."""
    try:
        with np.load(path, allow_pickle=False) as data:
            keys = set(data.files)
    except OSError:
        return ()
    kinds = ("beckmann", "ggx")
    counts = range(1, max(TOPOLOGIES) + 1)
    return tuple(n for n in counts if all(f"{kind}_{read_count(kind, n)}_reads" in keys for kind in kinds))


def save_tables(tables: list[PatternTable], path: Path = TABLE_PATH) -> None:
    arrays = {}
    for table in tables:
        key = f"{table.kind}_{table.reads.shape[2]}"
        arrays[key + "_reads"] = table.reads.astype(np.float32)
        arrays[key + "_lobe"] = table.lobe.astype(np.float32)
        arrays[key + "_distance"] = table.distance.astype(np.float32)
    arrays["alphas"] = np.asarray(TABLE_ALPHAS, dtype=np.float32)
    arrays["views_deg"] = np.asarray(TABLE_VIEWS_DEG, dtype=np.float32)
    np.savez(path, **arrays)


@lru_cache(maxsize=8)
def load_table(kind: str, reads: int, path: Path = TABLE_PATH) -> PatternTable:
    """One fitted table from the committed file; a missing table or one made on other nodes raises
    (bench/fitted_patterns.py writes them)."""
    key = f"{kind}_{reads}"
    with np.load(path, allow_pickle=False) as data:
        if key + "_reads" not in data:
            raise KeyError(f"{path.name} has no fitted pattern of {reads} reads for {kind}")
        nodes_ok = np.allclose(data["alphas"], TABLE_ALPHAS) and np.allclose(data["views_deg"], TABLE_VIEWS_DEG)
        table = PatternTable(kind, data[key + "_reads"].astype(np.float64), data[key + "_lobe"].astype(np.float64),
                             data[key + "_distance"].astype(np.float64))  # fmt: skip
    shape = (len(TABLE_ALPHAS), len(TABLE_VIEWS_DEG), reads, 4)
    if not nodes_ok or table.reads.shape != shape:
        raise ValueError(f"{path.name}: the {key} table was fitted on other nodes; run bench/fitted_patterns.py")
    return table
