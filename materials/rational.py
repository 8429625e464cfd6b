"""Rational functions fitted by interval interpolation (Pacanowski et al. 2012, seed 002, section 2).

A rational function r = p / q of a vector x (Eq. 1) has numerator and denominator coefficients on
multinomial basis functions ordered by increasing total degree (1, x1, x2, x1^2, x1 x2, x2^2, ...).
Each variable is mapped affinely from its domain [lower, upper] to [-1, 1] before the monomials
are formed, so the basis stays bounded and the conditioning of the fit does not depend on units.

Fitting (section 2.1): given intervals [lo_i, hi_i] around measured values f_i at points x_i, find
the smallest n + m such that some r_{n,m} satisfies lo_i <= r(x_i) <= hi_i at every point. For a
fixed (n, m) this is the problem P(n, m):

    minimise ||c||_2  subject to  A_j c >= delta ||A_j||,

with c = (p_0..p_n, q_0..q_m) and two rows per point, p(x_i) - lo_i q(x_i) >= 0 and
hi_i q(x_i) - p(x_i) >= 0 (whose sum makes q(x_i) > 0: the fit is pole-free at the data).
delta = 1 / cond(A) as in the paper. P is a least-distance program; it is solved exactly with
Lawson & Hanson's reduction to non-negative least squares (Solving Least Squares Problems,
1974, ch. 23; scipy.optimize.nnls): NNLS on E = [G^T; h^T], f = e_{n+1} gives the solution
x = -r[:n] / r[n] of the residual r, and a zero residual proves the constraints infeasible.

Fitted functions may also have a known part, r = a(x) + b(x) p / q (the inverse-CDF forms of
Eq. 8 and 9, which meet their boundary conditions by construction), and monotonicity
constraints in one variable (Eq. 3-4, derived below for the general form), both linear in c.

Speed (section 2.3): each P(n, m) is solved on a small *training* subset; the remaining points
are verified, and the ones that deviate most are added until the function satisfies them all.
Algorithm 1 then looks for the smallest n + m that has a solution (in geometric steps, then by
bisection: a count with a solution has one at every larger count; the paper scans upwards one by
one) and keeps that count's feasible split (numerator, denominator) with the smallest condition
number; if no count up to the maximum works, every interval is widened and the search restarts.
Same counts as the linear scan on the bench's fits, 2.9x faster on a MERL gold table at eps 0.02
(61.8 -> 21.5 s for three channels, three widenings each).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls


class RationalFitError(ValueError):
    """Rational fitting that cannot proceed (bad data) or found no function."""


def graded_exponents(dimension: int, count: int) -> np.ndarray:
    """(count, dimension) exponents of the first ``count`` multinomials by increasing total
    degree; within a degree, in decreasing powers of the first variable, then the second
    (2D: 1, x, y, x^2, x y, y^2, ...). shaders/rational.glsl reads the exponents from the packed
    terms, so this order is the only convention to keep."""
    out: list[tuple[int, ...]] = []
    degree = 0
    while len(out) < count:
        out.extend(_exponents_of_degree(dimension, degree))
        degree += 1
    return np.asarray(out[:count], dtype=np.int64).reshape(count, dimension)


def _exponents_of_degree(dimension: int, degree: int) -> list[tuple[int, ...]]:
    if dimension == 1:
        return [(degree,)]
    return [(i, *rest) for i in range(degree, -1, -1) for rest in _exponents_of_degree(dimension - 1, degree - i)]


@functools.lru_cache(maxsize=64)
def symmetric_expansion(dimension: int, count: int, pair: tuple[int, int]) -> np.ndarray:
    """(K, count) matrix E from the coefficients of ``count`` symmetric basis functions to those of
    the first K graded monomials (E @ c): seed 002's symmetry by grouping (section 2.2), a basis
    function is a monomial plus its image under swapping the variables ``pair`` (itself where the
    swap maps it to itself), taken in graded order of their first monomial; K covers every
    monomial used (the ones between stay 0), so the file format and shaders are unchanged."""
    i, j = pair
    index: dict[tuple, int] = {}
    groups: list[tuple[int, ...]] = []
    degree = 0
    while len(groups) < count:
        exponents = _exponents_of_degree(dimension, degree)  # a swap keeps the degree
        for e in exponents:
            index[e] = len(index)
        for e in exponents:
            swapped = list(e)
            swapped[i], swapped[j] = e[j], e[i]
            group = tuple(sorted({index[e], index[tuple(swapped)]}))
            if group not in groups:
                groups.append(group)
        degree += 1
    groups = groups[:count]
    out = np.zeros((max(max(g) for g in groups) + 1, count))
    for column, group in enumerate(groups):
        out[list(group), column] = 1.0
    return out


def monomials(x_unit: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """(N, K) values of the monomials at points already mapped to [-1, 1] (N, D)."""
    max_degree = int(exponents.max(initial=0))
    powers = np.ones((x_unit.shape[1], max_degree + 1, len(x_unit)))
    for e in range(1, max_degree + 1):
        powers[:, e] = powers[:, e - 1] * x_unit.T
    out = np.ones((len(x_unit), len(exponents)))
    for d in range(x_unit.shape[1]):
        out *= powers[d, exponents[:, d]].T
    return out


def monomial_derivatives(x_unit: np.ndarray, exponents: np.ndarray, variable: int) -> np.ndarray:
    """(N, K) derivatives of the monomials with respect to the unit variable ``variable``."""
    lowered = exponents.copy()
    factor = lowered[:, variable].astype(np.float64)
    lowered[:, variable] = np.maximum(lowered[:, variable] - 1, 0)
    return monomials(x_unit, lowered) * factor


@dataclass(frozen=True)
class RationalFunction:
    """r(x) = a(x) + b(x) p(x) / q(x) with the known part (a, b) given by ``form``:
    'plain' (a = 0, b = 1), 'cdf_theta' (Eq. 8: a = pi/2 mu, b = mu (1 - mu), x = (theta_v, mu))
    or 'cdf_phi' (Eq. 9: a = pi tau, b = tau (1 - tau) theta_v theta_l, x = (theta_v, theta_l,
    tau)). Coefficients multiply the graded monomials of the unit variables."""

    numerator: tuple
    denominator: tuple
    lower: tuple
    upper: tuple
    form: str = "plain"

    def __post_init__(self):
        if self.form not in FORMS:
            raise RationalFitError(f"unknown rational form {self.form!r}; expected one of {sorted(FORMS)}")
        if len(self.lower) != len(self.upper) or not self.numerator or not self.denominator:
            raise RationalFitError("a rational function needs its domain and at least one coefficient each")
        if any(not (hi > lo) for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise RationalFitError(f"empty domain {self.lower} .. {self.upper}")

    @property
    def dimension(self) -> int:
        return len(self.lower)

    @property
    def counts(self) -> tuple[int, int]:
        return len(self.numerator), len(self.denominator)

    def unit(self, x: np.ndarray) -> np.ndarray:
        return unit_map(x, self.lower, self.upper)

    def parts(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """p(x), q(x) at points x (N, D) in domain units."""
        u = self.unit(x)
        p = monomials(u, graded_exponents(self.dimension, len(self.numerator))) @ np.asarray(self.numerator)
        q = monomials(u, graded_exponents(self.dimension, len(self.denominator))) @ np.asarray(self.denominator)
        return p, q

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        p, q = self.parts(x)
        a, b = FORMS[self.form](x)[:2]
        return a + b * p / q

    def derivative(self, x: np.ndarray, variable: int) -> np.ndarray:
        """dr/dx_variable in domain units (the unit map's slope included)."""
        x = np.asarray(x, dtype=np.float64)
        u = self.unit(x)
        ex_p = graded_exponents(self.dimension, len(self.numerator))
        ex_q = graded_exponents(self.dimension, len(self.denominator))
        p, q = self.parts(x)
        slope = 2.0 / (self.upper[variable] - self.lower[variable])
        dp = monomial_derivatives(u, ex_p, variable) @ np.asarray(self.numerator) * slope
        dq = monomial_derivatives(u, ex_q, variable) @ np.asarray(self.denominator) * slope
        _, b, da, db = FORMS[self.form](x, variable)
        s = p / q
        return da + db * s + b * (dp - s * dq) / q

    def to_dict(self) -> dict:
        return {
            "form": self.form,
            "lower": list(map(float, self.lower)),
            "upper": list(map(float, self.upper)),
            "numerator": list(map(float, self.numerator)),
            "denominator": list(map(float, self.denominator)),
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "rational function") -> RationalFunction:
        if not isinstance(d, dict):
            raise RationalFitError(f"{where}: expected an object, got {d!r}")
        unknown = set(d) - {"form", "lower", "upper", "numerator", "denominator"}
        if unknown:
            raise RationalFitError(f"{where}: unknown key(s) {sorted(unknown)}")
        values = {}
        for key in ("lower", "upper", "numerator", "denominator"):
            v = d.get(key)
            if (
                not isinstance(v, list)
                or not v
                or not all(isinstance(e, int | float) and not isinstance(e, bool) for e in v)
            ):
                raise RationalFitError(f"{where}.{key}: expected a non-empty list of numbers, got {v!r}")
            if not all(math.isfinite(float(e)) for e in v):
                raise RationalFitError(f"{where}.{key}: values must be finite")
            if len(v) > MAX_TERMS:
                raise RationalFitError(f"{where}.{key}: at most {MAX_TERMS} coefficients, got {len(v)}")
            values[key] = tuple(float(e) for e in v)
        return cls(values["numerator"], values["denominator"], values["lower"], values["upper"], d.get("form", "plain"))


#: The most coefficients of a numerator or denominator (shaders/rational.glsl's storage-buffer
#: block holds that many per function).
MAX_TERMS = 128


def unit_map(x, lower, upper) -> np.ndarray:
    """Domain units -> [-1, 1] per variable, where the graded monomials are well conditioned."""
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    return 2.0 * (np.asarray(x, dtype=np.float64) - lo) / (hi - lo) - 1.0


def _plain(x, variable=None):
    one, zero = np.ones(len(x)), np.zeros(len(x))
    return (zero, one) if variable is None else (zero, one, zero, zero)


def _cdf_theta(x, variable=None):
    # Eq. 8: r(theta_v, mu) = pi/2 mu + mu (1 - mu) p/q; r(., 0) = 0, r(., 1) = pi/2.
    mu = x[:, 1]
    a, b = 0.5 * math.pi * mu, mu * (1.0 - mu)
    if variable is None:
        return a, b
    if variable == 1:
        return a, b, np.full(len(x), 0.5 * math.pi), 1.0 - 2.0 * mu
    zero = np.zeros(len(x))
    return a, b, zero, zero


def _cdf_phi(x, variable=None):
    # Eq. 9: r(theta_v, theta_l, tau) = pi tau + tau (1 - tau) theta_v theta_l p/q;
    # r(., ., 0) = 0, r(., ., 1) = pi, and pi tau (uniform) where theta_v or theta_l is 0.
    tv, tl, tau = x[:, 0], x[:, 1], x[:, 2]
    a, b = math.pi * tau, tau * (1.0 - tau) * tv * tl
    if variable is None:
        return a, b
    if variable == 2:
        return a, b, np.full(len(x), math.pi), (1.0 - 2.0 * tau) * tv * tl
    if variable == 1:
        return a, b, np.zeros(len(x)), tau * (1.0 - tau) * tv
    return a, b, np.zeros(len(x)), tau * (1.0 - tau) * tl


FORMS: dict[str, Callable] = {"plain": _plain, "cdf_theta": _cdf_theta, "cdf_phi": _cdf_phi}

#: Points per axis at which a rational function's denominator is checked (2 variables: 65^2,
#: 3 variables: 21^3, edges included), when a material is read and when the fit verifies itself
DENOMINATOR_CHECK_POINTS = {2: 65, 3: 21}
#: ... and, for an inverse CDF, along every axis near both ends, where the form's factor vanishes
#: at the end itself: a fitted sampler had its pole 0.003 rad from theta_l = 0 at tau = 0.01
#: (issue 44), between the grid's points
EDGE_CHECK_OFFSETS = (1e-3, 2.5e-3, 5e-3, 1e-2, 2e-2)
MIN_DENOMINATOR_RATIO = 1e-6  # smallest |q| against the largest over the domain


def denominator_check_points(fn_form: str, lower, upper) -> np.ndarray:
    """The points at which a function of ``fn_form`` on [lower, upper] must keep its
    denominator's sign: the DENOMINATOR_CHECK_POINTS grid plus, for an inverse CDF, every axis at
    EDGE_CHECK_OFFSETS from both ends; points where the form fixes the value (its factor is 0:
    an inverse CDF's ends, theta_v or theta_l = 0) are left out."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    dimension = len(lower)
    axes = [np.linspace(lo, hi, DENOMINATOR_CHECK_POINTS[dimension]) for lo, hi in zip(lower, upper, strict=True)]
    if fn_form != "plain":  # every axis: the form's factor also vanishes at theta_v = 0, theta_l = 0
        for i, (lo, hi) in enumerate(zip(lower, upper, strict=True)):
            offsets = np.asarray(EDGE_CHECK_OFFSETS) * (hi - lo)
            axes[i] = np.unique(np.concatenate([axes[i], lo + offsets, hi - offsets]))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dimension)
    factor = np.broadcast_to(FORMS[fn_form](grid)[1], (len(grid),))
    return grid[factor != 0.0]


def pole_points(fn: RationalFunction, points: np.ndarray) -> np.ndarray:
    """Mask of ``points`` where ``fn``'s denominator is not safely away from zero with the sign it
    has over most of them (|q| < MIN_DENOMINATOR_RATIO max|q|, or the minority sign): a pole."""
    _, q = fn.parts(points)
    largest = float(np.max(np.abs(q))) if q.size else 0.0
    if not np.all(np.isfinite(q)) or largest == 0.0:
        return np.ones(len(points), dtype=bool)
    sign = 1.0 if np.sum(q > 0) >= np.sum(q < 0) else -1.0
    return sign * q < MIN_DENOMINATOR_RATIO * largest


def function_defects(fn: RationalFunction, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(poles, falling) masks of ``points``: :func:`pole_points`, and for an inverse CDF where it
    does not increase in its uniform (last) variable (its samples would fold over). What the
    reader refuses (materials/spec.py) and the fit's verification refits (rational_brdf.py)."""
    poles = pole_points(fn, points)
    if fn.form == "plain":
        return poles, np.zeros(len(points), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):  # at a pole (reported as one) q is 0
        return poles, fn.derivative(points, fn.dimension - 1) <= 0


# -- the interval problem ---------------------------------------------------------------------------


def least_distance(g: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """argmin ||x|| subject to g x >= h (Lawson & Hanson's LDP via NNLS), or None when the
    constraints are infeasible. Rows of ``g`` should be normalised by the caller."""
    rows, cols = g.shape
    e = np.vstack([g.T, h[None, :]])
    f = np.zeros(cols + 1)
    f[-1] = 1.0
    u, _ = nnls(e, f, maxiter=50 * max(rows, cols + 1))
    r = e @ u - f
    if abs(r[-1]) < 1e-12 or np.linalg.norm(r) < 1e-12:
        return None
    x = -r[:-1] / r[-1]
    # Infeasible systems leave a residual too: verify (with a tolerance for round-off).
    if np.any(g @ x < h - 1e-9 * max(1.0, float(np.abs(h).max(initial=0.0)))):
        return None
    return x


@dataclass
class IntervalData:
    """What one fit must meet: points x (N, D), intervals [lower, upper] of r at them, and
    optionally monotone_in (a variable index): dr/dx >= 0 at every point. ``check`` points
    (a denser grid, poles found between data) require only q > 0."""

    x: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    domain_lower: tuple
    domain_upper: tuple
    form: str = "plain"
    monotone_in: int | None = None
    check: np.ndarray | None = None
    # (i, j): the function is symmetric in variables i and j (seed 002 section 2.2: the inverse
    # CDF of dphi in theta_v and theta_l), fitted in the grouped basis of symmetric_expansion
    symmetric: tuple[int, int] | None = None

    def expansion(self, count: int) -> np.ndarray:
        """(K, count): coefficients of ``count`` basis functions -> of the first K monomials."""
        if self.symmetric is None:
            return np.eye(count)
        return symmetric_expansion(self.x.shape[1], count, tuple(self.symmetric))

    def __post_init__(self):
        self.x = np.asarray(self.x, dtype=np.float64)
        self.lower = np.asarray(self.lower, dtype=np.float64).reshape(-1)
        self.upper = np.asarray(self.upper, dtype=np.float64).reshape(-1)
        if self.x.ndim != 2 or len(self.x) != len(self.lower) or len(self.lower) != len(self.upper):
            raise RationalFitError("interval data: x must be (N, D) with N lower and N upper bounds")
        if not (np.isfinite(self.x).all() and np.isfinite(self.lower).all() and np.isfinite(self.upper).all()):
            raise RationalFitError("interval data: points and bounds must be finite")
        if np.any(self.upper < self.lower):
            raise RationalFitError("interval data: an upper bound lies below its lower bound")
        if self.check is None:
            self.check = np.zeros((0, self.x.shape[1]))


@dataclass
class _Rows:
    """Constraint rows of P(n, m) per point: interval rows (2 per point) and monotone rows (2)."""

    interval: np.ndarray  # (N, 2, K)
    monotone: np.ndarray  # (N, 2, K) or (N, 0, K)
    positive: np.ndarray  # (M, K): q > 0 at the check points


def _constraint_rows(data: IntervalData, n_num: int, n_den: int) -> _Rows:
    d = data.x.shape[1]
    e_p, e_q = data.expansion(n_num), data.expansion(n_den)
    ex_p, ex_q = graded_exponents(d, len(e_p)), graded_exponents(d, len(e_q))
    lo, hi = np.asarray(data.domain_lower), np.asarray(data.domain_upper)

    def rows_at(x, s_lo, s_hi):
        u = unit_map(x, lo, hi)
        bp, bq = monomials(u, ex_p) @ e_p, monomials(u, ex_q) @ e_q
        interval = np.zeros((len(x), 2, n_num + n_den))
        # s = p/q in [s_lo, s_hi]: p - s_lo q >= 0 and s_hi q - p >= 0.
        interval[:, 0] = np.hstack([bp, -s_lo[:, None] * bq])
        interval[:, 1] = np.hstack([-bp, s_hi[:, None] * bq])
        if data.monotone_in is None:
            return interval, np.zeros((len(x), 0, n_num + n_den))
        v = data.monotone_in
        slope = 2.0 / (hi[v] - lo[v])
        dbp = monomial_derivatives(u, ex_p, v) @ e_p * slope
        dbq = monomial_derivatives(u, ex_q, v) @ e_q * slope
        _, b, da, db = FORMS[data.form](x, v)
        # r = a + b s, s = p/q, q > 0: q dr/dx = a' q + b' p + b p' - b s q' (linear in s), so
        # dr/dx >= 0 for every s in [s_lo, s_hi] iff it holds at both ends (Eq. 4, generalised).
        mono = np.zeros((len(x), 2, n_num + n_den))
        for k, s in enumerate((s_lo, s_hi)):
            mono[:, k] = np.hstack([db[:, None] * bp + b[:, None] * dbp, da[:, None] * bq - (b * s)[:, None] * dbq])
        return interval, mono

    a, b = FORMS[data.form](data.x)[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s_lo = np.where(b > 0, (data.lower - a) / b, 0.0)
        s_hi = np.where(b > 0, (data.upper - a) / b, 0.0)
    interval, mono = rows_at(data.x, s_lo, s_hi)
    # Where b = 0 the form fixes r = a: no interval rows (they would read 0 >= 0).
    interval[b <= 0] = 0.0
    if len(data.check):
        # Check points carry no interval: only q > 0 there (no pole between the data).
        positive = np.hstack([np.zeros((len(data.check), n_num)), monomials(unit_map(data.check, lo, hi), ex_q) @ e_q])
    else:
        positive = np.zeros((0, n_num + n_den))
    return _Rows(interval, mono, positive)


def _normalise(rows: np.ndarray) -> np.ndarray:
    norms = np.linalg.norm(rows, axis=1)
    keep = norms > 0
    return rows[keep] / norms[keep, None]


@dataclass
class SolveStats:
    problems: int = 0  # P(n, m) solved (training subsets)
    refinements: int = 0  # training points added after verification
    seconds: float = 0.0
    widenings: int = 0
    tried: list = field(default_factory=list)  # (n + 1, m + 1, feasible)


def _violations(data: IntervalData, c: np.ndarray, rows: _Rows) -> np.ndarray:
    """Per point, the worst constraint violation (> 0: violated) of coefficients c, each row
    normalised, so interval and monotone violations are comparable."""
    per_point = np.zeros(len(data.x))
    for block in (rows.interval, rows.monotone):
        if block.shape[1] == 0:
            continue
        norms = np.linalg.norm(block, axis=2)
        values = np.einsum("nkc,c->nk", block, c) / np.where(norms > 0, norms, 1.0)
        values = np.where(norms > 0, values, np.inf)
        per_point = np.maximum(per_point, -values.min(axis=1))
    return per_point


def solve_problem(
    data: IntervalData,
    n_num: int,
    n_den: int,
    stats: SolveStats | None = None,
    add_per_round: int = 8,
) -> tuple[np.ndarray, float] | None:
    """Solve P(n, m) (``n_num`` = n + 1 numerator and ``n_den`` = m + 1 denominator coefficients)
    on all of ``data`` with the training/verification scheme of section 2.3. Returns
    (coefficients, condition number) or None when no such function meets every interval."""
    stats = stats if stats is not None else SolveStats()
    rows = _constraint_rows(data, n_num, n_den)
    k = n_num + n_den
    full = np.concatenate([rows.interval.reshape(-1, k), rows.monotone.reshape(-1, k)])
    full = _normalise(full)
    if len(full) == 0:
        raise RationalFitError("no constraints: every point lies where the form fixes the value")
    cond = float(np.linalg.cond(full)) if len(full) >= k else float("inf")
    if not math.isfinite(cond):
        return None
    delta = 1.0 / cond
    n = len(data.x)
    start = min(n, max(4 * k, 32))
    training = np.unique(np.linspace(0, n - 1, start).round().astype(int))
    extra_rows = np.zeros((0, k))
    if len(rows.positive):
        extra_rows = _normalise(rows.positive)
    while True:
        g = np.concatenate([rows.interval[training].reshape(-1, k), rows.monotone[training].reshape(-1, k)])
        g = np.concatenate([_normalise(g), extra_rows])
        stats.problems += 1
        c = least_distance(g, np.full(len(g), delta))
        if c is None:
            return None  # infeasible on a subset: infeasible on all of the data
        worst = _violations(data, c, rows)
        worst[training] = 0.0
        bad = np.flatnonzero(worst > 1e-9 * delta)
        if len(bad) == 0:
            return c, cond
        chosen = bad[np.argsort(worst[bad])[::-1][:add_per_round]]
        stats.refinements += len(chosen)
        training = np.union1d(training, chosen)


def _add_checks(data: IntervalData, points: np.ndarray, lower: np.ndarray | None, upper: np.ndarray | None) -> None:
    points = np.asarray(points, dtype=np.float64).reshape(-1, data.x.shape[1])
    if lower is None:
        data.check = np.concatenate([data.check, points])
        return
    data.x = np.concatenate([data.x, points])
    data.lower = np.concatenate([data.lower, np.asarray(lower, dtype=np.float64).reshape(-1)])
    data.upper = np.concatenate([data.upper, np.asarray(upper, dtype=np.float64).reshape(-1)])


COUNT_STEP = 1.4  # the geometric steps of the count search in fit_rational


def _best_split(data: IntervalData, total: int, stats: SolveStats, first: bool = False) -> tuple | None:
    """The best-conditioned feasible (numerator, denominator) split of ``total`` coefficients:
    (n_num, n_den, condition number, coefficients), or None where no split meets the intervals;
    ``first``: the first feasible split found (whether the count has a function at all)."""
    best = None
    for n_num in range(total - 1, 0, -1):
        n_den = total - n_num
        if n_num > MAX_TERMS or n_den > MAX_TERMS:
            continue
        found = solve_problem(data, n_num, n_den, stats)
        stats.tried.append((n_num, n_den, found is not None))
        if found is not None and (best is None or found[1] < best[2]):
            best = (n_num, n_den, found[1], found[0])
            if first:
                break
    return best


def fit_rational(
    data: IntervalData,
    max_coefficients: int = 40,
    widen: float = 1.5,
    max_widenings: int = 8,
    progress: Callable[[str], None] | None = None,
    verify: Callable[[RationalFunction], tuple | None] | None = None,
) -> tuple[RationalFunction, SolveStats]:
    """Algorithm 1: the rational function with the fewest coefficients (n + m + 2 <=
    ``max_coefficients``; counts searched in geometric steps, then by bisection) that meets every
    interval, the best-conditioned one among equal counts; when none exists, widen every interval
    about its centre by ``widen`` (up to ``max_widenings`` times). ``verify(fn)`` returns None
    when the found function is acceptable between the data too, else (points, lower, upper)
    where it misbehaves: points with bounds (lost monotonicity: the tabulated values there) join
    the data, points with ``lower`` None
    (a pole) join ``data.check`` (q > 0 only), and the same count is fitted again."""
    if max_coefficients < 2 or max_coefficients > 2 * MAX_TERMS:
        raise RationalFitError(f"max_coefficients must be in [2, {2 * MAX_TERMS}], got {max_coefficients}")
    stats = SolveStats()
    t0 = time.perf_counter()
    for widening in range(max_widenings + 1):
        # Algorithm 1 scans n + m upwards. A function with some count is one with every larger
        # count too (a zero coefficient more), so the scan steps up geometrically to the first
        # count that has one and bisects the last step. Refuting a count is cheap (the training
        # subset already fails) and solving a feasible large one slow (its verification rounds),
        # so the steps start small (a bisection from the largest count: clean plastic 9.8 -> 20 s).
        infeasible, step, best = 1, 2, None
        while best is None:
            best = _best_split(data, step, stats, first=True)
            if best is not None:
                total = step
                break
            infeasible = step
            if progress:
                progress(f"  no function with {step} coefficients ({time.perf_counter() - t0:.1f} s)")
            if step >= max_coefficients:
                break
            step = min(max_coefficients, max(step + 1, int(step * COUNT_STEP)))
        if best is not None:
            while total - infeasible > 1:
                middle = (infeasible + total) // 2
                found = _best_split(data, middle, stats, first=True)
                if found is not None:
                    total, best = middle, found
                else:
                    infeasible = middle
                    if progress:
                        progress(f"  no function with {middle} coefficients ({time.perf_counter() - t0:.1f} s)")
            best = _best_split(data, total, stats)  # the smallest count found: its best-conditioned split
        while best is not None:
            n_num, n_den, cond, c = best
            numerator, denominator = data.expansion(n_num) @ c[:n_num], data.expansion(n_den) @ c[n_num:]
            fn = RationalFunction(
                tuple(numerator), tuple(denominator), tuple(data.domain_lower), tuple(data.domain_upper), data.form
            )
            extra = verify(fn) if verify is not None else None
            if extra is None:
                stats.seconds = time.perf_counter() - t0
                return fn, stats
            if progress:
                progress(f"  ({n_num}, {n_den}) coefficients misbehave at {len(extra[0])} check point(s); refitting")
            _add_checks(data, *extra)
            best = _best_split(data, total, stats)  # the same count again, with the new points, then upwards
            while best is None and total < max_coefficients:
                total += 1
                best = _best_split(data, total, stats)
        if widening == max_widenings:
            break
        centre = 0.5 * (data.lower + data.upper)
        half = 0.5 * (data.upper - data.lower) * widen
        data.lower, data.upper = centre - half, centre + half
        stats.widenings += 1
        if progress:
            progress(f"  no function with <= {max_coefficients} coefficients: intervals widened x{widen}")
    raise RationalFitError(
        f"no rational function with at most {max_coefficients} coefficients meets the intervals, even widened "
        f"{max_widenings} times by x{widen}; raise the coefficient limit or the tolerance"
    )
