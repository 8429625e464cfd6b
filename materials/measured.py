"""A measured material rendered from its table (issue 44 item 1): a MERL ``.binary`` BRDF read
as it is, evaluated at the nearest cell as MERL's own reading code does, and importance-sampled
from a CDF tabulated from the table itself.

The sampler (:class:`TabulatedSampler`): for ``THETA_O_BINS`` view elevations theta_o (bin
centres, wo at azimuth 0) the luminance of f(wi, wo) cos theta_i is integrated over the cells of
a half-vector grid: t in [0, 1) with theta_h = t^2 pi / 2 (MERL's own square-root spacing, fine
at the specular peak) by the azimuth of h relative to the view, phi in [0, 2 pi). A cell's mass
is the midpoint rule over SUBSAMPLES^2 points of

    f cos theta_i |d omega_i / d(t, phi)|,   d omega_i = 4 (wo.h) d omega_h,
    d omega_h = sin theta_h (dtheta_h / dt) dt dphi = sin theta_h (pi t) dt dphi.

Sampling: a view between two bin centres samples the linear mixture of both bins' tables (its
marginal and conditional CDFs are the same mixtures of theirs, so a sample stays continuous in
wo and its density is exactly w0 p0 + w1 p1); u1 inverts the row CDF over t, u2 - phi_v / 2 pi
(mod 1: anchored in the tangent frame, no pinwheel near the normal) the cumulative row over
phi, each uniform inside its cell; h then reflects wo. A DEFENSIVE_COSINE share of
cosine-weighted samples keeps the density positive wherever f cos may be (cells whose midpoints
all missed the measured region, views beyond the outer bins), so every estimate stays unbiased.

Density per solid angle of wi:  p(wi) = (1 - e) p_cells(t, phi) / (dt dphi pi t sin theta_h 4 wo.h)
+ e cos theta_i / pi. The GLSL twin is shaders/measured.glsl; the chi-square test of this sampler
against this density is tests/test_measured.py.

Real-time methods read the same table through a fitted proxy: ``distribution``, the GGX or
Beckmann distribution fitted to the table's specular peak (:func:`peak_distribution`), places
lobe-N's pattern (weighted by the table's values, normalised to the table's albedo), the
prefiltered lookups and the bright-source lights' points; fis-N, mc-N and the reference sample
the tabulated CDFs.
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import numpy as np

from .bsdf import BSDF, Component, Lambert
from .lobe_fit import LUMINANCE
from .measurement import MERL_DIMS, merl_cell_angles, merl_lookup, read_merl
from .microfacet import ALPHA_MAX, MicrofacetDistribution, fit_peak_shape, reflection_jacobian
from .vec import COS_EPSILON, cosine_hemisphere, normalize, reflect

THETA_O_BINS = 32  # view elevations tabulated (bin centres over [0, pi/2))
T_CELLS = 64  # half-vector cells in t (theta_h = t^2 pi / 2)
PHI_CELLS = 64  # half-vector cells in azimuth relative to the view, over [0, 2 pi)
SUBSAMPLES = 3  # midpoint rule per cell and axis when the masses are tabulated
DEFENSIVE_COSINE = 0.05  # share of cosine-weighted samples (positive density wherever f cos may be)
FLOOR_DOMAIN_DEG = 80.0  # split_diffuse: the table's floor is taken where MERL's data are reliable
FLOOR_MIN_RATIO = 1e-6  # split_diffuse: a smaller floor (against the channel's peak) is no diffuse term
HALF_PI = 0.5 * math.pi


class MeasuredError(ValueError):
    """A measured material that cannot be rendered (unreadable file, nothing measured)."""


def _theta_o_position(cos_o: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first bin, weight of the next) of the linear mixture between bin centres for views of
    elevation cos_o; clamped to the outer bins."""
    theta_o = np.arccos(np.clip(cos_o, 0.0, 1.0))
    x = np.clip(theta_o / HALF_PI * THETA_O_BINS - 0.5, 0.0, THETA_O_BINS - 1.0)
    k0 = np.minimum(np.floor(x).astype(int), THETA_O_BINS - 2)
    return k0, x - k0


class TabulatedSampler:
    """Per view-elevation bin: ``row_cdf`` (K, T + 1), the CDF over t, and ``cell_cdf``
    (K, T, P + 1), each row's cumulative mass over phi (unnormalised: its last entry is the row's
    mass); both normalised so that each bin's total is 1 (a bin with no mass is uniform)."""

    def __init__(self, luminance_eval):
        k = THETA_O_BINS
        theta_o = (np.arange(k) + 0.5) / k * HALF_PI
        masses = np.stack([_cell_masses(luminance_eval, float(t)) for t in theta_o])[..., 0]
        totals = masses.sum(axis=(1, 2))
        empty = ~(totals > 0)
        masses[empty] = 1.0
        totals[empty] = masses[empty].sum(axis=(1, 2))
        cells = masses / totals[:, None, None]
        self.cell_probability = cells  # (K, T, P), each bin sums to 1
        self.cell_cdf = np.concatenate([np.zeros((k, T_CELLS, 1)), np.cumsum(cells, axis=2)], axis=2)
        rows = self.cell_cdf[:, :, -1]
        self.row_cdf = np.concatenate([np.zeros((k, 1)), np.cumsum(rows, axis=1)], axis=1)
        self.row_cdf[:, -1] = 1.0

    def sample(self, u1: np.ndarray, u2: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Directions wi (n, 3) from the cell tables for views wo (n, 3); u in [0, 1)."""
        k0, w = _theta_o_position(wo[:, 2])
        rows = (1.0 - w)[:, None] * self.row_cdf[k0] + w[:, None] * self.row_cdf[k0 + 1]
        i, t = _invert(rows, u1 * rows[:, -1])
        t = t / T_CELLS
        cum = (1.0 - w)[:, None] * self.cell_cdf[k0, i] + w[:, None] * self.cell_cdf[k0 + 1, i]
        # u2 turned by -phi_v / 2 pi (mod 1): still uniform, but a deterministic point set (fis-N's)
        # keeps its azimuths in the tangent frame where the rows are nearly uniform (near the
        # normal), instead of turning with the view azimuth there (a pinwheel).
        phi_v = np.arctan2(wo[:, 1], wo[:, 0])
        _, phi = _invert(cum, np.mod(u2 - phi_v / (2.0 * math.pi), 1.0) * cum[:, -1])
        phi = phi * (2.0 * math.pi / PHI_CELLS)
        h = _half_vector(t, phi + phi_v)
        return reflect(wo, h)

    def density(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Density per solid angle of :meth:`sample` at (wi, wo) (n, 3) each."""
        k0, w = _theta_o_position(wo[:, 2])
        h = normalize(wi + wo)
        theta_h = np.arccos(np.clip(h[:, 2], -1.0, 1.0))
        t = np.sqrt(np.clip(theta_h / HALF_PI, 0.0, 1.0))
        phi = np.mod(np.arctan2(h[:, 1], h[:, 0]) - np.arctan2(wo[:, 1], wo[:, 0]), 2.0 * math.pi)
        i = np.clip((t * T_CELLS).astype(int), 0, T_CELLS - 1)
        j = np.clip((phi / (2.0 * math.pi) * PHI_CELLS).astype(int), 0, PHI_CELLS - 1)
        p = (1.0 - w) * self.cell_probability[k0, i, j] + w * self.cell_probability[k0 + 1, i, j]
        jacobian = _cell_jacobian(t, theta_h, np.sum(wo * h, axis=-1)) * (1.0 / T_CELLS) * (2.0 * math.pi / PHI_CELLS)
        ok = (wi[:, 2] > COS_EPSILON) & (wo[:, 2] > COS_EPSILON) & (jacobian > 0) & (h[:, 2] > 0)
        return np.where(ok, p / np.where(ok, jacobian, 1.0), 0.0)

    def pack(self) -> np.ndarray:
        """float32 of the GLSL buffer (shaders/measured.glsl): every bin's row CDF (T + 1), then
        every bin's cell CDFs (T x (P + 1))."""
        return np.concatenate([self.row_cdf.reshape(-1), self.cell_cdf.reshape(-1)]).astype(np.float32)


def _search(cdf: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per row of ``cdf`` (n, m + 1), the cell i with cdf[i] <= target < cdf[i + 1] (the last
    non-empty cell where target reaches the end), as the GLSL binary search finds it."""
    lo = np.zeros(len(cdf), dtype=int)
    hi = np.full(len(cdf), cdf.shape[1] - 1, dtype=int)
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2
        below = np.take_along_axis(cdf, mid[:, None], 1)[:, 0] <= target
        active = hi - lo > 1
        lo = np.where(active & below, mid, lo)
        hi = np.where(active & ~below, mid, hi)
    return lo


def _invert(cdf: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cell, continuous position in cells) of ``target`` in each row's piecewise-linear ``cdf``:
    the cell of :func:`_search`, then uniform inside it."""
    cell = _search(cdf, target)
    low = np.take_along_axis(cdf, cell[:, None], 1)[:, 0]
    high = np.take_along_axis(cdf, cell[:, None] + 1, 1)[:, 0]
    return cell, cell + np.clip((target - low) / np.maximum(high - low, 1e-300), 0.0, 1.0)


def _cell_jacobian(t: np.ndarray, theta_h: np.ndarray, wo_h: np.ndarray) -> np.ndarray:
    """|d omega_i / d(t, phi)| = 4 (wo.h) sin theta_h (pi t) (module docstring)."""
    return 4.0 * wo_h * np.sin(theta_h) * math.pi * t


def _half_vector(t: np.ndarray, phi: np.ndarray) -> np.ndarray:
    theta_h = t * t * HALF_PI
    s = np.sin(theta_h)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta_h)], -1)


def _cell_masses(evaluate, theta_o: float) -> np.ndarray:
    """(T, P, C) masses of f cos theta_i over the half-vector cells for the view at theta_o
    (azimuth 0), by the midpoint rule (module docstring); ``evaluate(wi, wo)`` gives f as (n,)
    or (n, C)."""
    offsets = (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES
    t = (np.arange(T_CELLS)[:, None] + offsets[None, :]).reshape(-1) / T_CELLS
    phi = (np.arange(PHI_CELLS)[:, None] + offsets[None, :]).reshape(-1) * (2.0 * math.pi / PHI_CELLS)
    tt, pp = np.meshgrid(t, phi, indexing="ij")
    h = _half_vector(tt.reshape(-1), pp.reshape(-1))
    wo = np.broadcast_to(np.array([math.sin(theta_o), 0.0, math.cos(theta_o)]), h.shape)
    wi = reflect(wo, h)
    wo_h = np.sum(wo * h, axis=-1)
    ok = (wi[:, 2] > COS_EPSILON) & (wo_h > 0)
    f = np.asarray(evaluate(wi[ok], wo[ok]))
    f = f.reshape(len(f), -1)
    value = np.zeros((len(h), f.shape[1]))
    value[ok] = f * wi[ok, 2:3]
    theta_h = tt.reshape(-1) * tt.reshape(-1) * HALF_PI
    jacobian = _cell_jacobian(tt.reshape(-1), theta_h, np.maximum(wo_h, 0.0))
    cell_area = (1.0 / T_CELLS) * (2.0 * math.pi / PHI_CELLS) / SUBSAMPLES**2
    mass = (value * (jacobian * cell_area)[:, None]).reshape(T_CELLS, SUBSAMPLES, PHI_CELLS, SUBSAMPLES, -1)
    return mass.sum(axis=(1, 3))


def peak_distribution(table: np.ndarray) -> MicrofacetDistribution:
    """The isotropic GGX or Beckmann distribution whose D(theta_h) / D(0) best matches (least
    squares, sin theta_h weighted) the table's luminance at theta_d's first cell, averaged over
    phi_d, above its minimum: where lobe-N places its pattern and prefiltered and the
    bright-source lights their lookups (the Rational BRDF's proxy rule, materials/rational_brdf.py
    proxy_alpha, with GGX as a candidate: a measured peak often has its long tail)."""
    theta_h, _, _ = merl_cell_angles()
    lum = np.nanmean(table[:, 0, :, :], axis=1) @ LUMINANCE
    keep = np.isfinite(lum)
    flat = MicrofacetDistribution("beckmann", ALPHA_MAX, ALPHA_MAX)
    if keep.sum() < 3:
        return flat
    theta_h, lum = theta_h[keep], np.maximum(lum[keep], 0.0)
    span = lum.max() - lum.min()
    if not np.isfinite(span) or span <= 1e-6 * max(lum.max(), 1e-30) or lum[0] <= lum.min():
        return flat
    kind, alpha = fit_peak_shape(theta_h, (lum - lum.min()) / (lum[0] - lum.min()), ("beckmann", "ggx"))
    return MicrofacetDistribution(kind, alpha, alpha)


class MeasuredLobe(Component):
    """A measured isotropic BRDF as one reflection component: ``eval`` is the table's nearest
    cell (unmeasured cells 0), ``sample_wi`` / ``pdf`` the tabulated sampler with its cosine
    share, ``distribution`` the proxy of :func:`peak_distribution` (or a Beckmann lobe of the
    given ``alpha``)."""

    name = "measured"
    transmission = False
    #: lobe-N places its pattern by the proxy ``distribution`` and weighs it with the table's
    #: values (materials/patterns.py): the lattice through the tabulated sampler was blotchy
    #: (gold table, studio: 17.7 % against 11.1 % with the proxy's ring and GGX tail)
    sampled_pattern = False
    #: the table and CDFs live in per-material GPU buffers (viewer/material_gpu.py): programs
    #: without HAS_MEASURED (the RSIBR bake) cannot evaluate this lobe
    material_buffers = True

    def __init__(self, table: np.ndarray, source: str = "", alpha: float | None = None):
        if table.shape != (*MERL_DIMS, 3):
            raise MeasuredError(f"a measured table has shape {(*MERL_DIMS, 3)}, got {table.shape}")
        finite = np.isfinite(table)
        if not finite.any():
            raise MeasuredError(f"{source or 'measured table'}: no measured cell")
        if (table[finite] < 0).any():
            raise MeasuredError(f"{source or 'measured table'}: negative BRDF values")
        self.table = np.where(finite, table, 0.0).astype(np.float32)
        self.distribution = (
            peak_distribution(table) if alpha is None else MicrofacetDistribution("beckmann", alpha, alpha)
        )
        self.sampler = TabulatedSampler(self._luminance)
        self._selection_weight = max(float(self.albedo_many(np.array([[0.0, 0.0, 1.0]]))[0] @ LUMINANCE), 1e-6)
        self._key = (source, self.distribution.kind, self.distribution.alpha_x, _table_digest(self.table))

    @property
    def cache_key(self) -> tuple:
        """Everything the lobe's value and sampling depend on (GPU caches, albedo tables)."""
        return self._key

    @property
    def selection_weight(self) -> float:
        """The lobe's albedo at normal incidence (luminance), beside a Lambert term's mean kd."""
        return self._selection_weight

    def _luminance(self, wi, wo):
        return merl_lookup(self.table, wi, wo) @ LUMINANCE

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        valid = (wi[:, 2] > COS_EPSILON) & (wo[:, 2] > COS_EPSILON)
        out = np.zeros((len(wi), 3))
        if valid.any():
            out[valid] = merl_lookup(self.table, wi[valid], wo[valid])
        return out.reshape(shape + (3,))

    def lobe_pdf(self, wi, wo):
        """The proxy's half-vector density (Eq. 4.9): what lobe-N's pattern weights use."""
        wi, wo = np.broadcast_arrays(wi, wo)
        valid = (wi[..., 2] > COS_EPSILON) & (wo[..., 2] > COS_EPSILON)
        h = normalize(wi + wo)
        p = self.distribution.pdf_half_vector(h) * reflection_jacobian(wo, h)
        return np.where(valid, p, 0.0)

    def sample_wi(self, u1, u2, wo):
        return self._sample(u1, u2, wo)

    def albedo_many(self, wos: np.ndarray) -> np.ndarray:
        """Directional albedo (k, 3) for views (k, 3): the midpoint rule over the sampler's
        half-vector cells (BSDF.albedo_many uses it: a Gauss-Legendre rule in primary-sample
        space straddles the piecewise-constant sampler's cell edges, 0.8 % high at normal
        incidence on a gold table). The BRDF is isotropic: only theta_o matters."""
        cos_o = np.clip(np.asarray(wos, np.float64).reshape(-1, 3)[:, 2], 0.0, 1.0)
        out = np.zeros((len(cos_o), 3))
        for index, c in enumerate(cos_o):
            if c > COS_EPSILON:
                out[index] = _cell_masses(self.eval, math.acos(c)).sum(axis=(0, 1))
        return out

    def _sample(self, u1, u2, wo):
        u1, u2 = np.asarray(u1, np.float64), np.asarray(u2, np.float64)
        shape = np.broadcast_shapes(u1.shape, u2.shape, np.shape(wo)[:-1])
        u1 = np.broadcast_to(u1, shape).reshape(-1)
        u2 = np.broadcast_to(u2, shape).reshape(-1)
        wo = np.broadcast_to(wo, shape + (3,)).reshape(-1, 3)
        cosine = u1 < DEFENSIVE_COSINE
        wi = np.empty_like(wo)
        if cosine.any():
            wi[cosine] = cosine_hemisphere(u1[cosine] / DEFENSIVE_COSINE, u2[cosine])
        rest = ~cosine
        if rest.any():
            u_rest = np.minimum((u1[rest] - DEFENSIVE_COSINE) / (1.0 - DEFENSIVE_COSINE), 1.0 - 1e-12)
            wi[rest] = self.sampler.sample(u_rest, u2[rest], wo[rest])
        return wi.reshape(shape + (3,))

    def pdf(self, wi, wo):
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        valid = (wi[:, 2] > COS_EPSILON) & (wo[:, 2] > COS_EPSILON)
        p = (1.0 - DEFENSIVE_COSINE) * self.sampler.density(wi, wo) + DEFENSIVE_COSINE * wi[:, 2] / math.pi
        return np.where(valid, p, 0.0).reshape(shape)


def _table_digest(table: np.ndarray) -> str:
    import hashlib

    return hashlib.sha1(np.ascontiguousarray(table).tobytes()).hexdigest()[:16]


def split_diffuse(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(kd, residual table): kd / pi is each channel's smallest measured value over the cells
    with theta_h and theta_d <= FLOOR_DOMAIN_DEG (the table's floor, which every direction pair
    there reaches: a diffuse term or a microfacet tail's floor), the residual max(f - kd / pi, 0).
    kd / pi + residual = max(f, kd / pi) is the table exactly inside that domain; outside, a cell
    below the floor (grazing noise) is raised to it. The real-time methods light kd by the
    irradiance like any diffuse term and integrate only the residual's peak with the proxy."""
    theta_h, theta_d, _ = merl_cell_angles()
    limit = math.radians(FLOOR_DOMAIN_DEG)
    inside = (theta_h[:, None] <= limit) & (theta_d[None, :] <= limit)
    values = table[inside]  # (cells, phi_d, 3)
    floor = np.nanmin(np.where(np.isfinite(values), values, np.inf), axis=(0, 1))
    floor = np.where(np.isfinite(floor), np.maximum(floor, 0.0), 0.0)
    # A floor below FLOOR_MIN_RATIO of the channel's peak is no diffuse term: a Beckmann tail's
    # minimum (1e-45 on a Beckmann 0.5 table) made a Lambert term that drew nothing but cost an
    # irradiance lookup and a share of the samples.
    peak = np.nanmax(np.where(np.isfinite(table), table, 0.0), axis=(0, 1, 2))
    floor = np.where(floor > FLOOR_MIN_RATIO * peak, floor, 0.0)
    kd = np.minimum(floor * math.pi, 1.0)
    return kd, np.where(np.isfinite(table), np.maximum(table - kd / math.pi, 0.0), np.nan)


@functools.lru_cache(maxsize=4)
def _cached_parts(path: str, size: int, mtime_ns: int, alpha: float | None) -> tuple[np.ndarray, MeasuredLobe]:
    kd, residual = split_diffuse(read_merl(path))
    return kd, MeasuredLobe(residual, source=path, alpha=alpha)


def _parts(path, alpha: float | None) -> tuple[np.ndarray, MeasuredLobe]:
    """(kd, residual lobe) of a MERL file, read and tabulated once per (path, size, modification
    time): the preview rebuilds its BSDF on every panel edit."""
    path = Path(path)
    try:
        info = os.stat(path)
    except OSError as exc:
        raise FileNotFoundError(f"measured material {path}: {exc.strerror or 'cannot stat'}") from None
    return _cached_parts(str(path.resolve()), info.st_size, info.st_mtime_ns, alpha)


def measured_lobe(path, alpha: float | None = None) -> MeasuredLobe:
    """The residual lobe of a MERL file (:func:`split_diffuse`)."""
    return _parts(path, alpha)[1]


def measured_bsdf(desc: dict, name: str = "measured") -> BSDF:
    """The BSDF of a validated ``measured`` material description (spec.validate): the table's
    floor as a Lambert term plus the residual lobe (:func:`split_diffuse`)."""
    kd, lobe = _parts(desc["file"], desc.get("proxy_alpha"))
    components = [Lambert(kd)] if np.any(kd > 0) else []
    return BSDF([*components, lobe], name=name)


__all__ = [
    "MeasuredError", "MeasuredLobe", "TabulatedSampler", "measured_bsdf", "measured_lobe", "peak_distribution",
    "split_diffuse",
]  # fmt: skip
