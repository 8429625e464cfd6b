"""Prefiltered environment lookups, numpy reference (issue 6).

A prefiltered map stores, per direction d, the environment convolved with a radially symmetric
kernel around d:  M(d) = integral p(angle(d, l)) L(l) dl  with  integral p dl = 1.
Every prefiltered mode of lobeview is such a map; only the kernel differs:

* split-sum GGX/Beckmann (Karis 2013): with n = v = r the importance-sampled prefilter weighted
  by n.l has the kernel  p(psi) ~ D(cos(psi/2)) / 4 * max(cos psi, 0)  (pdf of the reflected
  direction D cos(theta_h) / (4 v.h) with v.h = cos(theta_h) = cos(psi/2)); lobeview's GGX maps
  use the lobe itself at normal incidence, D(cos(psi/2)) / 4 * G1(l) (f cos with v = n, exact
  there; :func:`microfacet_kernel_values`), one map per roughness level, times the DFG table
  integral f cos = F0 A + B  (Schlick Fresnel);
* Kautz & McCool lobe maps (lobe_fit.py): the fitted radially symmetric lobe of each view
  elevation (seed 000, Eq. 1-2);
* Phong maps (Heidrich & Seidel, seed 001 section 4): p ~ cos^n psi.

This module holds the kernels (:class:`RadialProfile`), the DFG table, the brute-force prefilter
the GPU version is tested against, and the hierarchical prefilter of Kautz, Vazquez, Heidrich and
Seidel (seed 001, section 5.1).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lobeview.core.cube_layout import face_directions, face_point_directions, texel_solid_angles

from .conductor import MicrofacetReflection
from .fresnel import Fresnel
from .microfacet import ALPHA_MIN, MicrofacetDistribution
from .patterns import GOLDEN_LATTICE_STEP  # rotation of successive rings, in turns
from .split_sum_anisotropic import (  # noqa: F401  (re-exported: the line belongs to the lookups' API)
    SPLIT_SUM_LINE_EDGES,
    SPLIT_SUM_LINE_NODES,
    SPLIT_SUM_LINE_RATIO,
    anisotropic_line_slopes,
    line_half_vectors,
    mirror_directions,
    split_sum_is_line,
    split_sum_line_quantiles,
    split_sum_line_weights,
    wider_axis,
)
from .split_sum_levels import (  # noqa: F401  (re-exported: the levels belong to the maps' API)
    PEAK_MATCHED_FROM,
    SPLIT_SUM_LEVELS,
    SPLIT_SUM_LOD_GGX,
    SPLIT_SUM_LOD_NODES,
    split_sum_alpha,
    split_sum_lod,
)
from .split_sum_oblique import MIN_OBLIQUE_XY, in_plane_angles, oblique_alpha_ratio, uses_in_plane_line

# The prefilter quadrature's cells (RadialProfile.cells): the centre cap's diameter is the
# kernel's spread / CELL_CORE_DIVISIONS, rings beyond it grow by CELL_GROWTH of their angle, and
# they stop where the mass reaches CELL_MASS_END. MAX_CELLS bounds the lookups per texel.
CELL_CORE_DIVISIONS = 6
CELL_GROWTH = 0.3
CELL_MASS_END = 1.0 - 1e-5
CELL_DENSITY_DROP = 0.3
# No ring wider than this (radians): GGX's kernel (its lobe, microfacet_kernel_values) keeps mass
# out to the horizon, and one ring over 1.08-1.56 rad read at its median angle gave the tail's
# second moment 2.3 % low at alpha 0.04.
CELL_MAX_WIDTH = 0.2
MAX_CELLS = 1024


@dataclass(frozen=True)
class KernelCells:
    """Quadrature of a radial kernel: a cell's direction at angle ``psi`` from the axis and
    azimuth ``beta``, its solid angle ``omega`` (the footprint of its filtered lookup) and its
    share ``weight`` of the kernel's mass (summing to 1)."""

    psi: np.ndarray
    beta: np.ndarray
    omega: np.ndarray
    weight: np.ndarray

    def directions(self, axis: np.ndarray) -> np.ndarray:
        """The cells' directions (n, 3) around the unit vector ``axis`` (the shader's frame)."""
        axis = np.asarray(axis, dtype=np.float64)
        helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        t = np.cross(helper, axis)
        t /= np.linalg.norm(t)
        b = np.cross(axis, t)
        s, c = np.sin(self.psi)[:, None], np.cos(self.psi)[:, None]
        return c * axis + s * (np.cos(self.beta)[:, None] * t + np.sin(self.beta)[:, None] * b)


# Angles from the kernel axis: 0 plus a geometric grid (1.2 % steps) that resolves lobes down
# to alpha ~ 1e-4 and reaches pi.
PSI_GRID = np.concatenate([[0.0], np.geomspace(1e-5, np.pi, 1023)])


def cumulative_radial_mass(psi: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Integral of a radially symmetric function tabulated on ``psi`` over the caps of angle
    psi (trapezoid rule on the rings 2 pi sin(psi) dpsi); the last entry is the sphere's."""
    ring = values * 2.0 * np.pi * np.sin(psi)
    return np.concatenate([[0.0], np.cumsum(0.5 * (ring[1:] + ring[:-1]) * np.diff(psi))])


@dataclass(frozen=True)
class RadialProfile:
    """A radially symmetric kernel p(psi) per steradian, tabulated on ``psi`` and normalised so
    that its integral over the sphere is 1 (linear interpolation between nodes, 0 beyond pi)."""

    psi: np.ndarray
    density: np.ndarray
    radial_mass: np.ndarray = field(repr=False)  # integral of p over the cap of angle psi

    @classmethod
    def from_values(cls, psi, values) -> RadialProfile:
        psi = np.asarray(psi, dtype=np.float64)
        values = np.nan_to_num(np.maximum(np.asarray(values, dtype=np.float64), 0.0))
        mass = cumulative_radial_mass(psi, values)
        if not mass[-1] > 0.0:
            raise ValueError("a radial profile needs positive values somewhere")
        return cls(psi, values / mass[-1], mass / mass[-1])

    def __call__(self, psi) -> np.ndarray:
        return np.interp(psi, self.psi, self.density, right=0.0)

    def of_cosine(self, cos_angle) -> np.ndarray:
        return self(np.arccos(np.clip(cos_angle, -1.0, 1.0)))

    def quantile(self, q) -> np.ndarray:
        """The angle within which a fraction q of the kernel's mass lies."""
        keep = np.concatenate([[True], np.diff(self.radial_mass) > 0])
        return np.interp(q, self.radial_mass[keep], self.psi[keep])

    @property
    def median_angle(self) -> float:
        return float(self.quantile(0.5))

    def quadrature(self, rings: int, azimuths: int) -> tuple[np.ndarray, np.ndarray]:
        """Stratified importance quadrature: ring k at the mass quantile (k + 1/2) / rings, each
        of its ``azimuths`` samples standing for 1 / (rings azimuths) of the mass, hence for the
        solid angle 1 / (rings azimuths p(psi_k)) (the footprint a filtered lookup should cover).
        Used for Banks' thin ring kernels; centred kernels use :meth:`cells` (see there why)."""
        psi_k = self.quantile((np.arange(rings) + 0.5) / rings)
        density = np.maximum(self(psi_k), 1e-30)
        return psi_k, 1.0 / (rings * azimuths * density)

    def ring_cells(self, rings: int, azimuths: int) -> KernelCells:
        """:meth:`quadrature` as cells: ``azimuths`` per ring, each of weight 1 / (rings azimuths),
        rotated by a golden-ratio offset per ring."""
        psi_k, omega_k = self.quadrature(rings, azimuths)
        ring = np.repeat(np.arange(rings), azimuths)
        offset = (ring * GOLDEN_LATTICE_STEP) % 1.0
        beta = 2.0 * np.pi * (np.tile(np.arange(azimuths), rings) + offset) / azimuths
        weight = np.full(rings * azimuths, 1.0 / (rings * azimuths))
        return KernelCells(psi_k[ring], beta, omega_k[ring], weight)

    def cells(self, core_divisions: int = CELL_CORE_DIVISIONS, growth: float = CELL_GROWTH) -> KernelCells:
        """The prefilter quadrature of a kernel centred on its axis: cells that tile the sphere
        around the axis, each about as wide as it is long, weighted by the kernel's exact mass
        over the cell and looked up over the cell's solid angle.

        Rings of width max(w, growth psi) from a centre cap of diameter w (w = the smaller of
        the median angle and the interquartile range, / ``core_divisions``: about square cells
        where the kernel is concentrated, log-polar ones in its tail), each ring cut into
        round(2 pi sin(psi) / width) cells. :meth:`quadrature`'s rings at equal mass with a
        fixed number of azimuths made cells that were thin wedges near the axis (no lookup
        covered the axis itself: a sun at the centre of a split-sum texel lost 12-23 % of its
        weight, issue 45's dark hole) and wide arcs in the tail, where one ring's mass spread
        evenly over a range in which p falls by orders of magnitude (a bright source in the
        tail got the ring's mean weight). Rings stop where the mass reaches CELL_MASS_END;
        the weights are normalised to sum to 1."""
        spread = min(float(self.quantile(0.5)), float(self.quantile(0.75) - self.quantile(0.25)))
        width = max(spread, 1e-6) / core_divisions
        end = min(float(self.quantile(CELL_MASS_END)), np.pi)
        while True:
            edges = [0.0, min(0.5 * width, end)]
            while edges[-1] < end:
                step = min(max(width, growth * edges[-1]), max(width, CELL_MAX_WIDTH))
                # narrower rings where the kernel falls fast (its horizon cut-off)
                while step > width and self(edges[-1] + step) < CELL_DENSITY_DROP * self(edges[-1]):
                    step = max(0.5 * step, width)
                if edges[-1] + 1.5 * step >= end:  # no sliver of a ring at the end
                    step = end - edges[-1]
                edges.append(edges[-1] + step)
            edges = np.array(edges)
            inner, outer = edges[:-1], edges[1:]
            # a ring's lookups at its median angle by mass (its middle where it has none), cut
            # into cells about as long as the ring is wide there
            mass_edges = np.interp(edges, self.psi, self.radial_mass)
            median = self.quantile(0.5 * (mass_edges[:-1] + mass_edges[1:]))
            middle = np.where(mass_edges[1:] > mass_edges[:-1], median, 0.5 * (inner + outer))
            middle[0] = 0.0  # the centre cap: one lookup on the axis
            counts = np.maximum(3, np.round(2.0 * np.pi * np.sin(middle) / (outer - inner))).astype(int)
            counts[0] = 1
            if counts.sum() <= MAX_CELLS:
                break
            width, growth = 1.25 * width, 1.25 * growth  # coarser cells until they fit
        mass = np.diff(mass_edges)
        ring = np.repeat(np.arange(len(counts)), counts)
        index = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        beta = 2.0 * np.pi * (index + (ring * GOLDEN_LATTICE_STEP) % 1.0) / counts[ring]
        omega = 2.0 * np.pi * (np.cos(inner) - np.cos(outer)) / counts
        weight = mass / counts
        keep = weight[ring] > 0.0
        total = float(np.sum(weight[ring][keep]))
        return KernelCells(middle[ring][keep], beta[keep], omega[ring][keep], weight[ring][keep] / total)


def microfacet_kernel_values(kind: str, alpha: float, psi=PSI_GRID) -> np.ndarray:
    """Split-sum kernel over the angle psi from the lookup direction, unnormalised: GGX's lobe at
    normal incidence D(cos(psi/2)) G1(l) / 4 (n = v = r, height-correlated Smith with Lambda(v) =
    0), Beckmann's Karis kernel D(cos(psi/2)) / 4 max(cos psi, 0) (see the module doc).

    Why GGX differs (issue 45): Karis' n.l weight makes the kernel narrower than the lobe it
    stands for (GGX 0.5: median angle 0.61 against the lobe's 0.70 rad), so on a sky brighter
    above than below a sphere's upper half came out too bright and its lower half too dark
    (Mitsuba sky without its sun, `prefiltered` at the sun's mirror pixel 1.05 x lobeview's
    reference at GGX 0.5). The lobe itself is exact at normal incidence; over 48 pixels of the
    Mitsuba sphere (exact alpha and albedo, quadrature of the true lobe) it cut the rel-RMS error
    of GGX 0.15 / 0.3 / 0.5 / 1.0 from 6.6 / 9.8 / 12.6 / 9.1 % to 5.4 / 6.3 / 7.2 / 6.0 %.
    Beckmann keeps Karis' kernel: its lobe at alpha 0.8 is nearly flat over the hemisphere, and
    the oblique views' symmetric lookups then read the sky beyond the lobe's horizon cut on the
    sphere's lower half (Beckmann 0.5 / 0.8: 4.6 / 5.6 % -> 4.8 / 10.6 %; the n.l weight happens
    to mimic the cut); docs/measurements.md "Split-sum kernel"."""
    distribution = MicrofacetDistribution(kind, max(alpha, ALPHA_MIN), max(alpha, ALPHA_MIN))
    psi = np.asarray(psi, dtype=np.float64)
    half = 0.5 * psi
    h = np.stack([np.sin(half), np.zeros_like(half), np.cos(half)], axis=-1)
    above = np.cos(psi) > 0.0
    if kind == "ggx":
        l = np.stack([np.sin(psi), np.zeros_like(psi), np.where(above, np.cos(psi), 1.0)], axis=-1)
        return np.where(above, distribution.D(h) / 4.0 * distribution.G1(l), 0.0)
    return distribution.D(h) / 4.0 * np.maximum(np.cos(psi), 0.0)


def split_sum_profile(kind: str, alpha: float) -> RadialProfile:
    return RadialProfile.from_values(PSI_GRID, microfacet_kernel_values(kind, alpha))


def phong_profile(exponent: float) -> RadialProfile:
    return RadialProfile.from_values(PSI_GRID, np.maximum(np.cos(PSI_GRID), 0.0) ** exponent)


def split_sum_lod_table(kind: str = "ggx", nodes: int = SPLIT_SUM_LOD_NODES, steps: int = 400) -> np.ndarray:
    """The level (lower level + weight of the upper one) per roughness sqrt(alpha) = k / (nodes
    - 1) whose blend of the two levels' normalised kernels has the radial mass closest to alpha's
    own kernel (mean absolute difference over the angle, the weight on a grid of ``steps``)."""
    top = SPLIT_SUM_LEVELS - 1
    grid = np.diff(PSI_GRID, prepend=0.0)

    def mass(alpha):
        return RadialProfile.from_values(PSI_GRID, microfacet_kernel_values(kind, max(alpha, ALPHA_MIN))).radial_mass

    level_mass = [mass(split_sum_alpha(level)) for level in range(SPLIT_SUM_LEVELS)]
    weights = np.linspace(0.0, 1.0, steps + 1)
    out = np.empty(nodes)
    for k, roughness in enumerate(np.linspace(0.0, 1.0, nodes)):
        lower = min(int(np.floor(roughness * top + 1e-9)), top - 1)
        target = mass(roughness * roughness)
        blend = (1.0 - weights[:, None]) * level_mass[lower][None] + weights[:, None] * level_mass[lower + 1][None]
        distance = np.abs(blend - target[None]) @ grid
        out[k] = lower + weights[int(np.argmin(distance))]
    return out


# -- the DFG table ------------------------------------------------------------------------------
class _SchlickWeight(MicrofacetReflection):
    """The microfacet BRDF with its Fresnel term replaced by (1 - wo.h)^5 (the B integral)."""

    def fresnel_term(self, wo_h):
        return np.broadcast_to(((1.0 - np.abs(wo_h)) ** 5)[..., None], np.shape(wo_h) + (3,))


DFG_SIZE = 32
DFG_COS_MIN = 1e-4  # the grazing column's view (cos theta_o = 0 has no visible microfacets to sample)


def _dfg_rows(distribution: MicrofacetDistribution, wo: np.ndarray, order: int) -> np.ndarray:
    """(len(wo), 2): (A + B, B) of one distribution for the views ``wo`` (n, 3), integrated like
    BSDF.albedo: Gauss-Legendre in the sampler's primary space, every view at once."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    x = 0.5 * (nodes + 1.0)
    u1, u2 = np.meshgrid(x, x, indexing="ij")
    quad_w = np.outer(0.5 * weights, 0.5 * weights)
    wo_b = np.broadcast_to(wo[:, None, None, :], (len(wo), order, order, 3))
    total = MicrofacetReflection(distribution, Fresnel("none"))
    grazing = _SchlickWeight(distribution, Fresnel("none"))
    wi = total.sample_wi(u1[None], u2[None], wo_b)
    pdf = total.pdf(wi, wo_b)
    ok = pdf > 0.0
    safe_pdf = np.where(ok, pdf, 1.0)
    out = np.zeros((len(wo), 2))
    for column, comp in ((0, total), (1, grazing)):
        integrand = np.where(ok, comp.eval(wi, wo_b)[..., 0] * np.abs(wi[..., 2]) / safe_pdf, 0.0)
        out[:, column] = np.einsum("ij,mij->m", quad_w, integrand)
    return out


def dfg_table(kind: str, size: int = DFG_SIZE, order: int = 48) -> np.ndarray:
    """(size, size, 2) table of (A, B) with  integral f cos dwi = F0 A + B  for a microfacet BRDF
    with Schlick Fresnel F0 + (1 - F0)(1 - wo.h)^5, rows = perceptual roughness r, columns =
    cos(theta_o), both at the nodes k / (size - 1) (:func:`dfg_lookup`; the grazing node at
    DFG_COS_MIN, where the quadrature's view is still defined).

    Why nodes at the ends and not texel centres (k + 1/2) / size: a lookup clamped at the last
    centre read roughness 63/64, alpha 0.969, for alpha 1 (GGX 1.0's albedo 4.7 % too high at the
    Mitsuba sphere's sun pixel, issue 45: `prefiltered` 1.055 x Mitsuba there) and cos(theta_o)
    1/64 for every view more grazing (GGX 1.0 at cos 0.001: 0.935 against 0.993)."""
    nodes = np.linspace(0.0, 1.0, size)
    cosines = np.maximum(nodes, DFG_COS_MIN)
    wo = np.stack([np.sqrt(1.0 - cosines**2), np.zeros(size), cosines], axis=-1)
    table = np.zeros((size, size, 2))
    for row, r in enumerate(nodes):
        alpha = max(r * r, ALPHA_MIN)
        table[row] = _dfg_rows(MicrofacetDistribution(kind, alpha, alpha), wo, order)
    table[..., 0] -= table[..., 1]  # A = (A + B) - B
    return table


def split_sum_lean(alpha):
    """The t of the split-sum lookup direction  normalize(mix(n, r, t))  (n the normal, r the
    mirror direction) for roughness ``alpha``: Lagarde & de Rousiers 2014 ('Moving Frostbite to
    PBR', 4.9.3, listing 22), s (sqrt(s) + alpha) with s = 1 - alpha.

    Why: a rough lobe at a grazing view is cut by the horizon and leans towards the normal (the
    off-specular peak), and the split-sum map read along the mirror direction counts radiance
    from below the surface's horizon; on the Mitsuba sky (bench/mitsuba.py) the mirror direction
    left GGX 0.5 at +12 % at cos(theta_o) 0.3-0.6. Measured against two exact alternatives
    (tables over view and roughness per distribution): leaning onto the lobe's centroid (first
    moment of f cos) overshoots narrow lobes (GGX 0.15: 11.8 -> 14.5 %, gold under courtyard.exr
    22.9 -> 27.5), onto its peak undershoots wide ones (GGX 0.5: 16.9 -> 13.5); this fit:
    11.0 / 9.0 % and 22.9 (docs/measurements.md "Split-sum lookup direction")."""
    s = 1.0 - np.clip(np.asarray(alpha, dtype=np.float64), 0.0, 1.0)
    return s * (np.sqrt(s) + (1.0 - s))


def split_sum_line(
    wo: np.ndarray, kind: str, alpha_x: float, alpha_y: float, own_quantiles: bool = True
) -> tuple[np.ndarray, np.ndarray, float]:
    """The split-sum lookups of a lobe in its local frame: (mirror directions (k, 3) before the
    lean, weights (k,), the alpha whose map level they read). An anisotropic lobe: the line at
    min(alpha_x, alpha_y) along its wider axis, at the quantiles of its own f cos there
    (split_sum_anisotropic.py anisotropic_line_slopes, not leant afterwards) or, without
    ``own_quantiles``, at its slope marginal's symmetric quantiles with the scale
    sqrt(alpha_max^2 - alpha_min^2); an isotropic lobe seen off the normal: the line along the plane
    of incidence at alpha rho(alpha, cos theta_o) with the slope scale sqrt(alpha^2 - alpha'^2)
    (split_sum_oblique.py), or for Beckmann (``own_quantiles``) at the lobe's own in-plane
    quantiles (split_sum_oblique.py in_plane_angles, not leant afterwards); at normal incidence one
    lookup at sqrt(alpha_x alpha_y). Each node's slope s along the line's axis e is the half vector
    normalize(-s e, 1), reflected; nodes below the surface are left out (all of them kept if none
    is above)."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    a_min, a_max = min(alpha_x, alpha_y), max(alpha_x, alpha_y)
    along_view = float(np.hypot(wo[0], wo[1]))
    if split_sum_is_line(alpha_x, alpha_y):
        level_alpha = a_min
        if own_quantiles:
            slopes, major = anisotropic_line_slopes(wo, kind, alpha_x, alpha_y)
        else:
            major = wider_axis(alpha_x, alpha_y)
            slopes = split_sum_line_quantiles(kind) * np.sqrt(a_max * a_max - a_min * a_min)
    elif along_view > MIN_OBLIQUE_XY:
        alpha = float(np.sqrt(alpha_x * alpha_y))
        level_alpha = alpha * oblique_alpha_ratio(kind, alpha, wo[2])
        if own_quantiles and uses_in_plane_line(kind, wo):
            theta = in_plane_angles(kind, alpha, wo[2])
            plane = np.array([wo[0], wo[1], 0.0]) / along_view
            r = np.sin(theta)[:, None] * plane + np.cos(theta)[:, None] * np.array([0.0, 0.0, 1.0])
            return r, split_sum_line_weights(), float(level_alpha)
        major = wo[:2] / along_view
        slopes = split_sum_line_quantiles(kind) * np.sqrt(max(alpha * alpha - level_alpha * level_alpha, 0.0))
    else:
        return np.array([[-wo[0], -wo[1], wo[2]]]), np.ones(1), float(np.sqrt(alpha_x * alpha_y))
    r = mirror_directions(wo, line_half_vectors(slopes, major))
    weights = split_sum_line_weights()
    above = r[:, 2] > 0.0
    if above.any():
        weights = np.where(above, weights, 0.0)
    return r, weights / weights.sum(), float(level_alpha)


def uses_own_quantiles(kind: str, alpha_x: float, alpha_y: float, wo: np.ndarray) -> bool:
    """Whether split_sum_line places this lobe's nodes at its own f cos quantiles (then they are
    not leant): every anisotropic lobe, and Beckmann seen off the normal."""
    return split_sum_is_line(alpha_x, alpha_y) or uses_in_plane_line(kind, np.ravel(wo))


def split_sum_direction(normal: np.ndarray, mirror: np.ndarray, t) -> np.ndarray:
    """The lookup direction normalize(mix(normal, mirror, t)) of shaders/prefiltered.glsl (a thin
    transmission lobe passes -normal and its straight-through direction)."""
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = (1.0 - t) * normal + t * mirror
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def split_sum_lookups(
    wo: np.ndarray,
    frame: np.ndarray,
    kind: str,
    alpha_x: float,
    alpha_y: float,
    transmission: bool = False,
    own_quantiles: bool = True,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The numpy twin of shaders/prefiltered.glsl's split-sum lookups for one pixel: (world
    directions (k, 3), weights (k,), the alpha whose map level they read). :func:`split_sum_line`'s
    mirror directions (mirrored below the surface for a thin transmission lobe: straight through),
    taken to world space by ``frame`` (columns tangent, bitangent, normal) and leant towards the
    normal (the transmission lobe's -normal) by :func:`split_sum_lean` unless they sit at the
    lobe's own quantiles (:func:`uses_own_quantiles`: those hold its off-specular shift): at
    alpha_min on an anisotropic lobe's symmetric line, at the lobe's own sqrt(alpha_x alpha_y)
    otherwise (the oblique line's narrower level alpha lost the rough lobes' off-specular shift,
    split_sum_oblique.py)."""
    local, weights, level_alpha = split_sum_line(wo, kind, alpha_x, alpha_y, own_quantiles)
    lean_alpha = level_alpha if split_sum_is_line(alpha_x, alpha_y) else float(np.sqrt(alpha_x * alpha_y))
    own = own_quantiles and uses_own_quantiles(kind, alpha_x, alpha_y, wo)
    lean = 1.0 if own else split_sum_lean(lean_alpha)
    if transmission:
        local = local * np.array([1.0, 1.0, -1.0])
    normal = -frame[:, 2] if transmission else frame[:, 2]
    world = split_sum_direction(normal, local @ np.asarray(frame).T, lean)
    return world, weights, level_alpha


# Per-pixel albedo of anisotropic glTF GGX lobes (KHR_materials_anisotropy with a texture: every
# pixel has its own strength and roughness). The isotropic DFG at the geometric-mean alpha was 45 %
# too bright at strength 1, roughness 0.4 (0.78 against 0.53 by quadrature), the root-mean-square
# alpha still 49 % off at grazing views: the (A, B) are tabulated over the view (sqrt(cos theta_o)
# at texel centres, dense at grazing where B changes fastest; the azimuth from the anisotropy
# direction at nodes over [0, pi/2], the lobe being symmetric about both tangent axes), the
# roughness and the strength (nodes over [0, 1]), with alpha_x = mix(alpha, 1, strength^2),
# alpha_y = alpha = roughness^2 (materials/gltf.py).
ANISO_DFG_COS = 16
ANISO_DFG_PHI = 16
ANISO_DFG_ROUGHNESS = 12
ANISO_DFG_STRENGTH = 8


def anisotropic_dfg_table(order: int = 48) -> np.ndarray:
    """(roughness, strength, azimuth, cos, 2) table of (A, B) with integral f cos = F0 A + B for
    the anisotropic GGX of glTF, Schlick Fresnel, integrated like :func:`dfg_table`."""
    # uniform in sqrt(cos) (dense at grazing), nodes k / (ANISO_DFG_COS - 1) including both ends like
    # dfg_table's (texel centres read cos 0.94 at normal incidence: wide lobes' albedo 1-3 % off)
    cos_nodes = np.maximum(np.linspace(0.0, 1.0, ANISO_DFG_COS) ** 2, DFG_COS_MIN)
    phi_nodes = np.linspace(0.0, np.pi / 2, ANISO_DFG_PHI)
    sin_t = np.sqrt(1.0 - cos_nodes**2)
    phi, cos_t = np.meshgrid(phi_nodes, cos_nodes, indexing="ij")
    _, sin_b = np.meshgrid(phi_nodes, sin_t, indexing="ij")
    wo = np.stack([sin_b * np.cos(phi), sin_b * np.sin(phi), cos_t], axis=-1).reshape(-1, 3)
    table = np.zeros((ANISO_DFG_ROUGHNESS, ANISO_DFG_STRENGTH, len(wo), 2))
    for i, roughness in enumerate(np.linspace(0.0, 1.0, ANISO_DFG_ROUGHNESS)):
        alpha = max(roughness * roughness, ALPHA_MIN)
        for j, strength in enumerate(np.linspace(0.0, 1.0, ANISO_DFG_STRENGTH)):
            distribution = MicrofacetDistribution("ggx", alpha + (1.0 - alpha) * strength**2, alpha)
            table[i, j] = _dfg_rows(distribution, wo, order)
    table[..., 0] -= table[..., 1]  # A = (A + B) - B
    return table.reshape(ANISO_DFG_ROUGHNESS, ANISO_DFG_STRENGTH, ANISO_DFG_PHI, ANISO_DFG_COS, 2)


def anisotropic_dfg_lookup(table: np.ndarray, cos_theta_o: float, azimuth: float, roughness: float,
                           strength: float) -> np.ndarray:  # fmt: skip
    """(A, B) of :func:`anisotropic_dfg_table` as shaders/patterns.glsl reads its 3D texture:
    linear in sqrt(cos) between its nodes k / (ANISO_DFG_COS - 1) (clamped), linear between the
    azimuth, roughness and strength nodes; the azimuth folded into [0, pi/2]."""
    folded = np.arctan2(abs(np.sin(azimuth)), abs(np.cos(azimuth))) / (np.pi / 2)
    x0, fx = node_position(np.sqrt(max(cos_theta_o, 0.0)), ANISO_DFG_COS)
    out = np.zeros(2)
    r0, fr = node_position(roughness, ANISO_DFG_ROUGHNESS)
    s0, fs = node_position(strength, ANISO_DFG_STRENGTH)
    p0, fp = node_position(folded, ANISO_DFG_PHI)
    for dr, wr in ((0, 1 - fr), (1, fr)):
        for ds, ws in ((0, 1 - fs), (1, fs)):
            for dp, wp in ((0, 1 - fp), (1, fp)):
                row = table[r0 + dr, s0 + ds, p0 + dp]
                out += wr * ws * wp * (row[x0] * (1 - fx) + row[x0 + 1] * fx)
    return out


def anisotropic_ggx_dfg_lookup(table: np.ndarray, wo: np.ndarray, alpha_x: float, alpha_y: float) -> np.ndarray:
    """(A, B) of an anisotropic GGX lobe of any alphas from :func:`anisotropic_dfg_table` (the twin
    of shaders/patterns.glsl anisotropic_ggx_dfg): its wider axis is the table's x, roughness
    sqrt(alpha_min), strength^2 = (alpha_max - alpha_min) / (1 - alpha_min) clamped at 1."""
    a_min, a_max = min(alpha_x, alpha_y), max(alpha_x, alpha_y)
    strength = np.sqrt(np.clip((a_max - a_min) / max(1.0 - a_min, 1e-6), 0.0, 1.0))
    along, across = (wo[0], wo[1]) if alpha_x >= alpha_y else (wo[1], wo[0])
    return anisotropic_dfg_lookup(table, wo[2], np.arctan2(across, along), np.sqrt(a_min), strength)


def split_sum_dfg(tables: dict, kind: str, wo: np.ndarray, alpha_x: float, alpha_y: float) -> np.ndarray:
    """The (A, B) shaders/prefiltered.glsl's split-sum scales a lobe's lookups by: ``tables``
    {"ggx": dfg_table, "beckmann": dfg_table, "anisotropic": anisotropic_dfg_table}. A GGX lobe
    on the quantile line (:func:`split_sum_is_line`) from the anisotropic table: the isotropic
    one at the geometric-mean alpha was 5-9 % too bright over most views of GGX 0.05 x 0.3
    (Mitsuba sky, prefiltered 13.0 % rel-RMSE); Beckmann has no anisotropic table."""
    if kind == "ggx" and split_sum_is_line(alpha_x, alpha_y):
        return anisotropic_ggx_dfg_lookup(tables["anisotropic"], wo, alpha_x, alpha_y)
    return dfg_lookup(tables[kind], wo[2], np.sqrt(np.sqrt(alpha_x * alpha_y)))


def node_position(value, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(lower node, fraction towards the next) of ``value`` clamped to [0, 1] on a table axis of
    ``count`` nodes k / (count - 1): GL_LINEAR at shaders/bsdf.glsl node_coordinate."""
    t = np.clip(np.asarray(value, dtype=np.float64), 0.0, 1.0) * (count - 1)
    low = np.minimum(np.floor(t).astype(int), count - 2)
    return low, t - low


def dfg_lookup(table: np.ndarray, cos_theta_o, roughness) -> np.ndarray:
    """Bilinear between the table's nodes k / (size - 1) (:func:`node_position`), as
    shaders/bsdf.glsl dfg_coordinates reads the texture."""
    size = table.shape[0]
    x0, fx = node_position(cos_theta_o, size)
    y0, fy = node_position(roughness, size)
    fx, fy = fx[..., None], fy[..., None]
    top = table[y0, x0] * (1 - fx) + table[y0, x0 + 1] * fx
    bottom = table[y0 + 1, x0] * (1 - fx) + table[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def dfg_albedo(component, cos_theta_o: float, ab: np.ndarray) -> np.ndarray:
    """A microfacet lobe's directional albedo from the DFG (A, B) at its roughness: the numpy twin
    of shaders/bsdf.glsl lobe_dfg_albedo. Schlick Fresnel F = f0 (1 - Fc) + f90 Fc is linear in
    (f0, f90), so the integral of F V D cos is f0 A + f90 B: for the glTF specular
    f0 = lobe Fresnel at V.H = 1 and f90 = (1 - metallic) specular + metallic, times the
    clearcoat's attenuation; for the clearcoat (Fresnel at N.V) clearcoat F_c(N.V) (A + B); for
    the thin-walled transmission tint ((A + B) - specular (max f0 A + B)); otherwise
    scale (f0 A + B)."""
    from .gltf import GltfClearcoat, GltfSpecular, GltfTransmission

    a, b = float(ab[0]), float(ab[1])
    cos_o = np.array(cos_theta_o, dtype=np.float64)
    if isinstance(component, GltfTransmission):
        # tint (1 - specular max F) V D: max over channels of a Schlick F is the Schlick F of
        # the largest f0, so the integral is tint ((A + B) - specular (max f0 A + B)).
        kept = (a + b) - component.specular * (float(np.max(component.f0)) * a + b)
        return component.tint * kept * component.layers.attenuation(cos_o)
    if isinstance(component, GltfClearcoat):
        return component.scale * component.coat_fresnel(cos_o) * (a + b)
    f0 = component.fresnel_term(np.array(1.0))
    if isinstance(component, GltfSpecular):
        return (f0 * a + component.f90 * b) * component.layers.attenuation(cos_o)
    return component.scale * (f0 * a + b)


# -- brute-force and hierarchical prefiltering on cube maps -------------------------------------
def cube_texels(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel-centre directions (6 size^2, 3) and solid angles (6 size^2,) in face order."""
    dirs = np.concatenate([face_directions(f, size).reshape(-1, 3) for f in range(6)])
    omega = np.tile(texel_solid_angles(size).reshape(-1), 6)
    return dirs, omega


def _convolve(faces, kernel_of_cos, dirs, normalise: bool, chunk: int = 256) -> np.ndarray:
    """Sum over every texel t of k(d . l_t) L_t omega_t (optionally / sum of k omega)."""
    faces = np.asarray(faces, dtype=np.float64)
    texel_dirs, omega = cube_texels(faces.shape[1])
    radiance = faces.reshape(-1, faces.shape[-1])
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    out = np.zeros((len(dirs), radiance.shape[1]))
    for start in range(0, len(dirs), chunk):
        weights = kernel_of_cos(dirs[start : start + chunk] @ texel_dirs.T) * omega
        out[start : start + chunk] = weights @ radiance
        if normalise:
            out[start : start + chunk] /= weights.sum(axis=1, keepdims=True)
    return out


def prefilter_brute_force(faces: np.ndarray, profile: RadialProfile, dirs: np.ndarray) -> np.ndarray:
    """M(d) = sum over every texel t of p(angle(d, l_t)) L_t omega_t: the exact integral of the
    kernel against the piecewise-constant cube map (up to the kernel's variation inside a texel)."""
    return _convolve(faces, profile.of_cosine, dirs, normalise=False)


@dataclass
class HierarchicalResult:
    values: np.ndarray  # (n, channels)
    kernel_evaluations: int
    seconds: float


def _cube_pyramid(faces: np.ndarray):
    """Per level (finest first): texel-centre directions (6, s, s, 3), integrated radiance
    sum(L omega), solid angle, and angular radius (centre to farthest corner) per texel; the
    environment levels are 2x2 box sums (seed 001, Fig. 2)."""
    size = faces.shape[1]
    if size & (size - 1):
        raise ValueError("hierarchical prefiltering needs a power-of-two face size")
    omega = np.broadcast_to(texel_solid_angles(size), (6, size, size))
    integral = np.asarray(faces, dtype=np.float64) * omega[..., None]
    levels = []
    while True:
        s = integral.shape[1]
        dirs = np.stack([face_directions(f, s) for f in range(6)])
        edges = np.linspace(-1.0, 1.0, s + 1)
        corners = face_point_directions(0, *np.meshgrid(edges, edges, indexing="xy"))  # rows = t
        centre = dirs[0]
        radius = np.zeros((s, s))
        for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1)):
            c = np.einsum("ijc,ijc->ij", centre, corners[dy : dy + s, dx : dx + s])
            radius = np.maximum(radius, np.arccos(np.clip(c, -1.0, 1.0)))
        levels.append((dirs, integral, omega, radius))  # radius is the same on every face
        if s == 1:
            return levels
        integral = integral.reshape(6, s // 2, 2, s // 2, 2, -1).sum(axis=(2, 4))
        omega = omega.reshape(6, s // 2, 2, s // 2, 2).sum(axis=(2, 4))


def prefilter_hierarchical(faces, kernel, dirs, threshold: float = 1e-3) -> HierarchicalResult:
    """Hierarchical prefiltering (seed 001, section 5.1) of cube faces with a radially
    decreasing ``kernel(cos)``, normalised by the kernel's own integral (a constant map stays
    constant).

    Starting from one texel per face, a texel of the environment pyramid is multiplied by the
    kernel at its centre when the kernel varies by less than ``threshold`` x (kernel integral)
    over the texel's solid angle, i.e. (k(psi - r) - k(psi + r)) omega < threshold K, with psi
    the angle to the texel centre and r the texel's angular radius; otherwise its four children
    are visited. The paper compares the filter's mip-map values with the four values of the
    next level; point values at the children's centres miss kernels narrower than a texel (Phong
    n = 500 lost 89 % of the result here), hence this bound on the variation. All target
    directions advance level by level together (a vectorised frontier)."""
    t0 = time.perf_counter()
    levels = _cube_pyramid(np.asarray(faces, dtype=np.float64))
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    finest_dirs, _, finest_omega, _ = levels[0]
    kernel_integral = float(
        np.sum(kernel(finest_dirs.reshape(-1, 3) @ np.array([0.0, 0.0, 1.0])) * finest_omega.reshape(-1))
    )
    channels = faces.shape[-1]
    acc = np.zeros((len(dirs), channels))
    acc_weight = np.zeros(len(dirs))
    target = np.repeat(np.arange(len(dirs)), 6)
    face = np.tile(np.arange(6), len(dirs))
    row = np.zeros_like(target)
    col = np.zeros_like(target)
    evaluations = 0
    for level in range(len(levels) - 1, -1, -1):
        centres, integral, omega, radius = levels[level]
        cos_centre = np.clip(np.einsum("nc,nc->n", dirs[target], centres[face, row, col]), -1.0, 1.0)
        k_node = kernel(cos_centre)
        evaluations += len(target)
        if level == 0:
            accept = np.ones(len(target), dtype=bool)
        else:
            psi = np.arccos(cos_centre)
            r = radius[row, col]
            variation = kernel(np.cos(np.maximum(psi - r, 0.0))) - kernel(np.cos(np.minimum(psi + r, np.pi)))
            evaluations += 2 * len(target)
            accept = variation * omega[face, row, col] < threshold * kernel_integral
        np.add.at(acc, target[accept], k_node[accept, None] * integral[face[accept], row[accept], col[accept]])
        np.add.at(acc_weight, target[accept], k_node[accept] * omega[face[accept], row[accept], col[accept]])
        refine = ~accept
        target = np.repeat(target[refine], 4)
        face = np.repeat(face[refine], 4)
        row = (2 * row[refine, None] + np.array([0, 0, 1, 1])).reshape(-1)
        col = (2 * col[refine, None] + np.array([0, 1, 0, 1])).reshape(-1)
    values = acc / np.maximum(acc_weight, 1e-300)[:, None]
    return HierarchicalResult(values, evaluations, time.perf_counter() - t0)


def prefilter_kernel_brute_force(faces, kernel, dirs) -> HierarchicalResult:
    """The brute-force counterpart of :func:`prefilter_hierarchical`: every texel, same kernel,
    same normalisation."""
    t0 = time.perf_counter()
    values = _convolve(faces, kernel, dirs, normalise=True)
    evaluations = len(values) * 6 * np.shape(faces)[1] ** 2
    return HierarchicalResult(values, evaluations, time.perf_counter() - t0)


def phong_kernel(exponent: float):
    return lambda cos_angle: np.maximum(cos_angle, 0.0) ** exponent
