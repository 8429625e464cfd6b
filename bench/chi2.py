"""Chi-square goodness-of-fit of a direction sampler against its pdf (after Mitsuba 3's
``chi2.py`` and pbrt-v4's ``bsdfs_test.cpp``).

Samples are histogrammed over a binned domain; the expected count of each cell is N times the
integral of the pdf over the cell, computed with a tensor Gauss-Legendre rule inside the cell;
cells expecting fewer than 5 samples are pooled; the statistic is compared with the chi-square
distribution at a Sidak-corrected significance level. On failure the observed and expected
tables are written to a file whose path the assertion message names.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

# Number of chi-square tests in the suite; the per-test level keeps the family-wise false
# alarm rate at 1 %.
SUITE_TESTS = 60
SIGNIFICANCE = 1.0 - (1.0 - 0.01) ** (1.0 / SUITE_TESTS)
MIN_EXPECTED = 5.0


def _frame_from_z(z: np.ndarray) -> np.ndarray:
    """Orthonormal 3x3 frame (columns x, y, z) with the given z axis."""
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


@dataclass
class SphereDomain:
    """Bins over (cos theta, phi) on the whole sphere, or over a spherical cap of angular radius
    ``cap_angle`` around ``centre`` with bins in (sqrt(1 - cos theta'), phi') so that a narrow
    lobe is resolved. Solid angle d omega = d(cos) d(phi) = 2 s ds dphi."""

    res_a: int = 31
    res_b: int = 61
    centre: np.ndarray | None = None
    cap_angle: float = np.pi

    def __post_init__(self):
        self.frame = _frame_from_z(np.asarray(self.centre, float)) if self.centre is not None else np.eye(3)
        self.a_max = np.sqrt(1.0 - np.cos(self.cap_angle)) if self.centre is not None else 1.0

    def to_params(self, w: np.ndarray):
        local = w @ self.frame
        phi = np.arctan2(local[..., 1], local[..., 0])
        if self.centre is None:
            return local[..., 2], phi
        return np.sqrt(np.clip(1.0 - local[..., 2], 0.0, None)), phi

    def a_range(self):
        return (-1.0, 1.0) if self.centre is None else (0.0, self.a_max)

    def to_dirs(self, a: np.ndarray, phi: np.ndarray):
        """Directions and the solid-angle Jacobian for parameters (a, phi)."""
        if self.centre is None:
            cos_t = a
            jac = np.ones_like(a)
        else:
            cos_t = 1.0 - a * a
            jac = 2.0 * a
        sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
        local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
        return local @ self.frame.T, jac


def expected_histogram(pdf_fn, domain: SphereDomain, order: int = 6) -> np.ndarray:
    a0, a1 = domain.a_range()
    a_edges = np.linspace(a0, a1, domain.res_a + 1)
    p_edges = np.linspace(-np.pi, np.pi, domain.res_b + 1)
    nodes, weights = np.polynomial.legendre.leggauss(order)
    da = np.diff(a_edges)[:, None] * 0.5
    dp = np.diff(p_edges)[:, None] * 0.5
    a_pts = (0.5 * (a_edges[:-1] + a_edges[1:]))[:, None] + da * nodes[None, :]  # (ra, order)
    p_pts = (0.5 * (p_edges[:-1] + p_edges[1:]))[:, None] + dp * nodes[None, :]  # (rb, order)
    A = a_pts[:, None, :, None]
    P = p_pts[None, :, None, :]
    A, P = np.broadcast_arrays(A, P)
    dirs, jac = domain.to_dirs(A, P)
    pdf = pdf_fn(dirs.reshape(-1, 3)).reshape(A.shape) * jac
    w = (da * weights[None, :])[:, None, :, None] * (dp * weights[None, :])[None, :, None, :]
    return np.sum(pdf * w, axis=(2, 3))


def observed_histogram(samples: np.ndarray, domain: SphereDomain) -> np.ndarray:
    a, phi = domain.to_params(samples)
    a0, a1 = domain.a_range()
    hist, _, _ = np.histogram2d(a, phi, bins=[domain.res_a, domain.res_b], range=[[a0, a1], [-np.pi, np.pi]])
    return hist


@dataclass
class Chi2Result:
    passed: bool
    p_value: float
    dof: int
    mass_pdf: float
    mass_observed: float
    message: str


def chi2_test(
    sample_fn,
    pdf_fn,
    n: int,
    domain: SphereDomain,
    dump_dir: Path | None = None,
    name: str = "sampler",
) -> Chi2Result:
    """``sample_fn(n) -> (dirs (n,3), valid (n,))``; ``pdf_fn(dirs) -> pdf`` per solid angle."""
    dirs, valid = sample_fn(n)
    dirs = dirs[valid]
    expected_density = expected_histogram(pdf_fn, domain)
    observed = observed_histogram(dirs, domain)
    if domain.centre is None:
        expected = expected_density * n
        mass_pdf = float(expected_density.sum())
        mass_obs = float(valid.mean())
    else:
        # Condition on the cap: shape test inside it; the mass inside is checked separately.
        in_cap = observed.sum()
        expected = expected_density / expected_density.sum() * in_cap
        mass_pdf = float(expected_density.sum())
        mass_obs = float(in_cap / n)
    flat_e = expected.ravel()
    flat_o = observed.ravel()
    small = flat_e < MIN_EXPECTED
    e_cells = np.append(flat_e[~small], flat_e[small].sum())
    o_cells = np.append(flat_o[~small], flat_o[small].sum())
    if e_cells[-1] < MIN_EXPECTED:  # pooled cell still tiny: fold it into the largest cell
        biggest = np.argmax(e_cells[:-1])
        e_cells[biggest] += e_cells[-1]
        o_cells[biggest] += o_cells[-1]
        e_cells, o_cells = e_cells[:-1], o_cells[:-1]
    # Degrees of freedom: one constraint (the total), as the expected counts are scaled to it.
    stat = float(np.sum((o_cells - e_cells) ** 2 / e_cells))
    dof = len(e_cells) - 1
    p_value = float(stats.chi2.sf(stat, dof)) if dof > 0 else 1.0
    passed = p_value > SIGNIFICANCE
    message = f"{name}: chi2 = {stat:.1f}, dof = {dof}, p = {p_value:.3g} (level {SIGNIFICANCE:.2g})"
    if not passed and dump_dir is not None:
        dump_dir.mkdir(parents=True, exist_ok=True)
        path = dump_dir / f"chi2_{name.replace(' ', '_')}.txt"
        with open(path, "w") as fh:
            fh.write(message + "\nobserved:\n")
            np.savetxt(fh, observed, fmt="%8.0f")
            fh.write("expected:\n")
            np.savetxt(fh, expected, fmt="%10.2f")
        message += f"; tables written to {path}"
    return Chi2Result(passed, p_value, dof, mass_pdf, mass_obs, message)


def bsdf_chi2_test(bsdf, wo: np.ndarray, n: int, domain: SphereDomain, dump_dir: Path | None, name: str, seed: int):
    """:func:`chi2_test` of ``bsdf.sample`` against ``bsdf.pdf`` for the view ``wo`` (a failed
    sample, pdf 0, counts as lost mass)."""
    rng = np.random.default_rng(seed)

    def sample_fn(count):
        u = rng.random((2, count))
        s = bsdf.sample(u[0], u[1], wo)
        return s.wi, s.pdf > 0

    def pdf_fn(dirs):
        return bsdf.pdf(dirs, np.broadcast_to(wo, dirs.shape))

    return chi2_test(sample_fn, pdf_fn, n, domain, dump_dir, name)
