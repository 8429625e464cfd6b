"""Deterministic in-lobe sample patterns and their quadrature (thesis section 4.4.3, 4.5.3).

The method ``lobe-N`` (docs/methods.md) shades each specular lobe with N samples placed regularly in
the lobe, each looked up with a MIP level that makes the samples cover the lobe, and combines
them with the weighting of Eq. 4.25. Everything here is the numpy reference the GLSL version is
tested against.

Steps, with the thesis equations:
  1. Lobe extent: theta_thresh(phi) = arctan(sqrt(T(xi_border) / A(phi))) (Eq. 4.10) with
     xi_border = 0.01, T(xi) = -ln(xi) for Beckmann and for GGX too (its core, see theta_thresh) and
     A(phi) = cos^2(phi)/mx^2 + sin^2(phi)/my^2.
  2. Uniformity-preserving map of pattern coordinates (xi1, xi2) to half vectors:
     phi_h = arctan(my/mx tan(2 pi xi2)) (Eq. 4.12), theta_h = (1 - xi1) theta_thresh (Eq. 4.13),
     h by Eq. 4.7 and wi = 2 (wo.h) h - wo (Eq. 4.8).
  3. Patterns in (xi1, xi2) (section 4.4.3): ``ring`` = centre + a ring at xi1 = 0.6;
     ``line_x`` / ``line_y`` = equally spaced samples along the major axis for strongly
     anisotropic lobes; ``multi_ring`` = centre + concentric rings of about three samples
     (section 4.5.3, for planar mirror buffers); ``spiral`` (lobeview's, not the thesis') =
     centre + a Fibonacci (Vogel) spiral, radius fraction 1 - xi1 = sqrt((k + 1/2) / N) at
     azimuth parameter xi2 = frac(k (3 - sqrt 5) / 2); ``double_ring`` (lobeview's) = centre +
     an inner ring of min(6, (N - 1) // 2) samples at 35 % of the lobe radius + the rest on an
     outer ring at 70 %, rotated by half its step. The ring puts all of its samples at 40 % of
     the lobe radius: with more samples each one's footprint (lobe area / N) shrinks while the
     outer 60 % of the lobe stays unsampled, and accuracy fell as N grew. The spiral (the
     default from N = 15 until 2026-11-26) fixed that on gold under interior.exr but made lobe-15
     worse than lobe-7 on 5 of 6 isotropic lobes of the Mitsuba comparison (bench/mitsuba.py:
     GGX 0.5 18.2 against 13.9 %, Beckmann 0.5 15.4 against 11.8) and on frosted glass (interior:
     15.1 against 4.4 %; why the spiral loses is not established: the lookups' shape is not it,
     a smoother MIP chain changed nothing). :func:`choose_pattern` takes the double ring from
     DOUBLE_RING_MIN_SAMPLES = 11 on: lobe-11 / 15 / 19 are then better than lobe-7 on every case
     of the Mitsuba table and never worse by more than 0.2 points on 8 materials x 2 captures
     but frosted glass at N = 11 under interior.exr (5.8 against 4.4 %; docs/measurements.md
     "lobe-N against N").
     :func:`choose_pattern` picks the line pattern from the anisotropy ratio max(mx, my) /
     min(mx, my): >= 3 gives a line along the longer axis.
  4. MIP level per sample (Eq. 4.14-4.17): the lobe cross-section is an ellipse with semi-axes
     2 sin(angle(w_C, w_U) / 2), 2 sin(angle(w_C, w_V) / 2) (the thesis: tan(angle), which
     overstates wide lobes, see lobe_sample_area); its area divided by N is one sample's solid
     angle, projected to the cube (x d^2 / cos(beta) = 1 / max|w|^3 for a unit cube of
     half-size 1) and converted to texels (face area 4 holds face_size^2 texels);
     lod = log4(texels). Lobes wider than alpha 0.3 read up to 1.5 levels coarser
     (:func:`wide_lobe_footprint_scale`, measured against Mitsuba: GGX 1.0 lobe-7+norm 29.8 ->
     12.8 %).
  5. Quadrature (Eq. 4.25):  L = sum L_i cos_i^2 f_i^2 / p_i  /  sum f_i cos_i , with f the lobe
     BSDF, p its importance pdf (Eq. 4.9), samples below the horizon discarded. Eq. 4.24
     (sum L_i cos_i^2 f_i / sum p_i cos_i) is available for comparison.
  6. Lobes with their own inverse-CDF sampler and no half-vector distribution of their shape (the
     Rational BRDF, seed 002: ``sampled_pattern = True``): the pattern is the golden-ratio lattice
     of :func:`lattice_xi` mapped through the lobe's sampler, so the samples are distributed by
     its density p; each sample covers the solid angle 1 / (N p) (its MIP level) and the
     quadrature is the importance-sampling one, (1/N) sum L f cos / p, or with the energy
     normalisation the self-normalised sum L f cos / p / sum f cos / p times the albedo. Eq.
     4.25 assumes samples spread evenly over the lobe's core, weighted by f cos / p towards the
     lobe's shape; with p-distributed samples it would weight by the squared lobe.
  7. GGX tails (lobeview's, with the energy normalisation only): the pattern covers GGX's core
     (step 1), and the normalisation used to pour the tail's 18 % of the energy into the core,
     which made highlights too sharp and lost the glow around them. lobe-N+norm adds
     GGX_TAIL_SAMPLES = 4 lookups, one per quarter of the tail (half vectors beyond the core's
     edge), each weighted by its quarter's share of the albedo found by quadrature over
     GGX_TAIL_POINTS microfacet normals (lobe evaluations, no lookups: f cos vanishes at the
     horizon, so the share follows the part of the tail above it), read at the share-weighted
     mean direction over its part of the annulus between the core's edge and the tail's third
     quartile (:func:`ggx_tail_solid_angle`, at sqrt(ax ay); anisotropic lobes place the points
     along their own ellipse); the core's radiance takes the rest of the albedo (:func:`ggx_tail_integral`).
     Exact under uniform light like the normalisation itself. Against Mitsuba (issue 45's sky,
     lobe-7+norm, 2x supersampled, relative RMSE): GGX 0.05 / 0.15 / 0.3 / 0.5 3.4 / 8.7 / 10.1 /
     13.8 -> 3.2 / 7.3 / 8.0 / 12.2 %. Before (2026-11-26) the tail had a fixed GGX_TAIL_FRACTION
     of the albedo, the mean of 4 lookups on the tail's median cone faded in over their last 0.1
     of z: at normal incidence a wide lobe's tail lies below the horizon, at grazing it holds up
     to half of the albedo, and at GGX 0.5 one lookup just above the horizon carried a quarter
     of the tail (a sharp-edged diamond on a sphere). Measured for that version (200 px sphere,
     lobe-7+norm / lobe-19+norm, bench/patterns.py): gold-ggx 23.5 -> 26.3 / 25.4 -> 28.2 dB on
     interior.exr, 20.9 -> 21.5 / 22.8 -> 21.7 on courtyard.exr, gltf-red-plastic 29.2 -> 29.9 /
     29.8 -> 30.8 and 31.2 -> 31.6 / 31.4 -> 31.9 against the tail poured into the core. One
     lookup at the lobe's centre over the whole tail cone was tried first: 2-3 dB worse on
     courtyard.exr (the coarse box-filtered MIP level put the sun's glow around the texel, not
     around the sun).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lobeview.core.methods import DEFAULT_LOBE_LOD_BIAS, LOBE_PATTERNS

from . import fitted_pattern
from .bsdf import BSDF, HalfVectorLobe
from .conductor import MicrofacetReflection
from .microfacet import MicrofacetDistribution
from .vec import dot, mirror_z, reflect, spherical_direction

XI_BORDER = 0.01  # Eq. 4.10: empirical lobe border of the thesis
# MIP level bias of each sample's lookup (lod = 0.5 log2(area / texel) + bias): -0.5, measured by
# `lobeview bench` (the thesis uses 0; core/methods.py says how it was chosen).
LOBE_LOD_BIAS = DEFAULT_LOBE_LOD_BIAS
RING_XI1 = 0.6  # single ring at 40 % of the lobe radius (thesis 4.4.3)
ANISOTROPY_LINE_RATIO = 3.0  # max/min roughness at which the line pattern replaces the ring
# A line-pattern sample stands for the lobe's width as well as for its piece of the line: its
# footprint is at least a disc of half the lobe's short semi-axis (area pi (v / 2)^2, v = the
# short axis' equal-area radius). Without it the footprints of N samples on a line shrink with N
# below the lobe's width, and lobe-N grew worse with N on lobes anisotropic by 3: GGX 0.2 x 0.6
# on the method table's sky, lobe-7 / 11 / 19 14.3 / 16.7 / 21.0 % -> 14.0 / 14.1 / 14.0; Beckmann
# 12.8 / 12.7 / 12.6 (was 13.5 / 17.6 / 23.2); ratio 8 unchanged within 0.1 point but for GGX and
# Beckmann 0.1 x 0.8 at N = 19 (11.6 -> 10.9, 14.5 -> 13.2). 0.15 left Beckmann 0.2 x 0.6 growing
# (16.6 -> 17.3), 0.35 and 0.5 cost ratio 3 up to 1.5 points, a whole disc (1) up to 8.
LINE_MIN_FOOTPRINT_FRACTION = 0.25
MULTI_RING_SAMPLES_PER_RING = 3  # thesis 4.5.3 / Fig. 4.34: rings of three samples
# Widest lobe extent the footprint follows (lobe_sample_area): the thesis' tan form blows up at
# 90 deg; the solid-angle form does not, and keeps the clamp so footprints stay below a hemisphere.
MAX_ELLIPSE_ANGLE = np.radians(80.0)
# Step 4's footprint grows for wide lobes (wide_lobe_footprint_scale): a few samples of a lobe
# wider than alpha 0.3 read levels up to WIDE_LOBE_MAX_LEVELS coarser (measured, issue 45).
WIDE_LOBE_ALPHA = 0.3
WIDE_LOBE_LEVELS_PER_ALPHA = 2.5
WIDE_LOBE_MAX_LEVELS = 1.5
PATTERN_KINDS = ("ring", "multi_ring", "line_x", "line_y", "spiral", "double_ring")
# lobe-N takes the double ring instead of the ring from this N on (step 3; the ring at N = 8-10
# is within a few tenths of lobe-7, a double ring with an outer ring of 1-4 samples was worse).
DOUBLE_RING_MIN_SAMPLES = 11
# The double ring: the centre, min(DOUBLE_RING_INNER_SAMPLES, (N - 1) // 2) samples on an inner
# ring and the rest on an outer one, at these fractions of the lobe radius (1 - xi1). Chosen on
# the Mitsuba sky at the default LOD bias from radii (0.4, 0.8), (0.35, 0.7), (0.45, 0.85) and
# inner counts 5 / 6 / (N - 1) // 2, checked on interior / courtyard / studio / chinese_garden:
# (0.35, 0.7) with at most 6 inside is the one where N = 11 < 15 < 19 on every Mitsuba case.
DOUBLE_RING_INNER_SAMPLES = 6
DOUBLE_RING_RADII = (0.35, 0.7)
# The golden angle in turns, 1 - 1 / golden ratio: successive spiral samples 137.5 deg apart.
GOLDEN_ANGLE_TURNS = (3.0 - np.sqrt(5.0)) / 2.0
# Step 7, the GGX tail of lobe-N+norm: the pattern covers tan(theta_h) <= sqrt(T) alpha with
# T = -ln(XI_BORDER) (theta_thresh), which holds T / (1 + T) = 82 % of GGX's projected normal
# mass (its CDF in tan^2 theta_h is tan^2 / (alpha^2 + tan^2)); the other 18 % is the tail.
GGX_TAIL_FRACTION = 1.0 / (1.0 - np.log(XI_BORDER))
# The tail's third quartile tan(theta_h) / alpha (CDF 1 - GGX_TAIL_FRACTION / 4): the outer edge of the footprints.
GGX_TAIL_OUTER_TAN = float(np.sqrt((1.0 - GGX_TAIL_FRACTION / 4.0) / (GGX_TAIL_FRACTION / 4.0)))
GGX_TAIL_SAMPLES = 4  # tail lookups, one per quarter of the tail (one centre lookup: see step 7)
# Quadrature points per quarter of the tail (ggx_tail_quadrature): lobe evaluations, no lookups.
GGX_TAIL_RADIAL = 2
GGX_TAIL_AZIMUTHAL = 2
GGX_TAIL_POINTS = GGX_TAIL_RADIAL * GGX_TAIL_AZIMUTHAL
# 1 / golden ratio: the rank-1 lattice of lattice_xi (a Fibonacci lattice for any n)
GOLDEN_LATTICE_STEP = (np.sqrt(5.0) - 1.0) / 2.0
# Second coordinate of the lattice's first point: 0.25 is the middle of the first half of [0, 1),
# for the Rational sampler the median azimuth on one side (u2 < 1/2 picks one side, Eq. 9).
LATTICE_U2_START = 0.25


def uses_line_pattern(alpha_x: float, alpha_y: float) -> bool:
    """Whether a lobe is anisotropic enough for the line pattern: max / min roughness of at least
    ANISOTROPY_LINE_RATIO, written as the shaders test it (patterns.glsl uses_line_pattern)."""
    return max(alpha_x, alpha_y) >= ANISOTROPY_LINE_RATIO * min(alpha_x, alpha_y)


def choose_pattern(
    alpha_x: float, alpha_y: float, planar: bool = False, n: int | None = None, pattern: str = "auto"
) -> str:
    """The thesis' rule: line pattern along the longer axis for strongly anisotropic lobes,
    otherwise the ring (cube maps) or the multi-ring (planar mirror buffers); with the sample
    count ``n`` and ``pattern`` 'auto' the double ring replaces the ring on cube maps from
    DOUBLE_RING_MIN_SAMPLES on ('ring', the method suffix +ring: the thesis' ring at any N)."""
    if pattern not in LOBE_PATTERNS:
        raise ValueError(f"unknown lobe-N pattern choice {pattern!r}; use one of {LOBE_PATTERNS}")
    if uses_line_pattern(alpha_x, alpha_y):
        return "line_y" if alpha_y > alpha_x else "line_x"
    if planar:
        return "multi_ring"
    if pattern == "ring" or n is None:
        return "ring"
    # "fitted" (fitted_pattern.py) reads a table instead of a pattern where a lobe has one; the
    # lobes without one take the automatic choice
    return "double_ring" if n >= DOUBLE_RING_MIN_SAMPLES else "ring"


def pattern_xi(n: int, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Pattern coordinates (xi1, xi2) of ``n`` samples; xi1 = 1 is the lobe centre, 0 the
    border; xi2 in [0, 1) is the azimuth parameter of Eq. 4.12."""
    if n < 1:
        raise ValueError(f"a lobe pattern needs at least one sample, got n = {n}")
    if kind not in PATTERN_KINDS:
        raise ValueError(f"unknown pattern {kind!r}; use one of {PATTERN_KINDS}")
    if kind in ("line_x", "line_y"):
        # Equally spaced along the major axis: signed positions s_k = (2k+1)/n - 1 in (-1, 1),
        # xi1 = 1 - |s_k|; the two half-lines are xi2 = 0.25 / 0.75 (phi = 90 / 270 deg) for
        # line_y and xi2 = 0 / 0.5 for line_x (thesis 4.4.3; also valid for even n).
        s = (2.0 * np.arange(n) + 1.0) / n - 1.0
        xi1 = 1.0 - np.abs(s)
        first, second = (0.25, 0.75) if kind == "line_y" else (0.0, 0.5)
        xi2 = np.where(s < 0.0, first, second)
        return xi1, xi2
    if kind == "spiral":
        # Vogel's spiral with its first point moved to the centre: sample k >= 1 at the radius
        # fraction sqrt((k + 1/2) / N), the middle of an annulus of area 1 / N of the unit disc.
        k = np.arange(n, dtype=np.float64)
        radius = np.sqrt((k + 0.5) / n)
        radius[0] = 0.0
        return 1.0 - radius, (k * GOLDEN_ANGLE_TURNS) % 1.0
    xi1 = [1.0]
    xi2 = [0.0]
    ring_samples = n - 1
    if ring_samples == 0:
        return np.array(xi1), np.array(xi2)
    if kind == "double_ring":
        # The centre, then up to DOUBLE_RING_INNER_SAMPLES on the inner ring and the rest on the
        # outer one, rotated by half its step so that the two rings interleave.
        inner = min(DOUBLE_RING_INNER_SAMPLES, ring_samples // 2)
        outer = ring_samples - inner
        xi1 += [1.0 - DOUBLE_RING_RADII[0]] * inner + [1.0 - DOUBLE_RING_RADII[1]] * outer
        xi2 += list(np.arange(inner) / inner) + list((np.arange(outer) + 0.5) / max(outer, 1))
        return np.array(xi1), np.array(xi2)
    if kind == "ring":
        xi1 += [RING_XI1] * ring_samples
        xi2 += list(np.arange(ring_samples) / ring_samples)
        return np.array(xi1), np.array(xi2)
    # multi_ring: R rings of about three samples, radii (j + 0.5) / R * 0.8 of the lobe
    # radius (R = 1 reproduces the single ring at 0.4), inner rings get the remainder last,
    # alternate rings rotated by half a step so the samples interleave.
    rings = max(1, round(ring_samples / MULTI_RING_SAMPLES_PER_RING))
    counts = [ring_samples // rings] * rings
    for j in range(ring_samples - sum(counts)):
        counts[rings - 1 - j] += 1
    for j, count in enumerate(counts):
        radius = 0.8 * (j + 0.5) / rings
        xi1 += [1.0 - radius] * count
        xi2 += list((np.arange(count) + 0.5 * (j % 2)) / count)
    return np.array(xi1), np.array(xi2)


def lattice_xi(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n points of the golden-ratio rank-1 lattice in [0, 1)^2, u1 = (i + 1/2) / n stratified and
    u2 = frac(1/4 + i / golden ratio): the deterministic pattern of lobes sampled through their
    own inverse CDFs (step 6 above). Any n; at Fibonacci numbers it is the Fibonacci lattice."""
    if n < 1:
        raise ValueError(f"a lobe pattern needs at least one sample, got n = {n}")
    i = np.arange(n, dtype=np.float64)
    return (i + 0.5) / n, (LATTICE_U2_START + i * GOLDEN_LATTICE_STEP) % 1.0


def theta_thresh(distribution: MicrofacetDistribution, phi: np.ndarray, xi_border: float = XI_BORDER):
    """Eq. 4.10: the half-vector angle that bounds the sampled part of the lobe at azimuth phi,
    tan^2 theta = -ln(xi_border) / A(phi) for both distributions. For Beckmann this is the 99 %
    border of the thesis; GGX's heavy tail would put its 99 % border at tan theta = 9.95 alpha
    (4.6x wider: a gold alpha = 0.15 lobe spread its 3 samples 45 deg off the mirror direction at
    the coarsest MIP levels, 9.7 dB), so GGX lobes use the same core width (tan theta = 2.15
    alpha, 82 % of their half-vector mass); Eq. 4.25 weights the samples by the BRDF either way."""
    border = -np.log(np.asarray(xi_border, float))
    return np.arctan(np.sqrt(border / distribution.inv_alpha2(phi)))


def pattern_half_vectors(
    distribution: MicrofacetDistribution,
    xi1: np.ndarray,
    xi2: np.ndarray,
    xi_border: float = XI_BORDER,
) -> np.ndarray:
    """Eq. 4.12, 4.13 and 4.7: pattern coordinates -> half vectors in the local frame."""
    phi = distribution.phi_from_xi(xi2)
    theta = (1.0 - np.asarray(xi1, dtype=np.float64)) * theta_thresh(distribution, phi, xi_border)
    return spherical_direction(theta, phi)


def lobe_sample_area(
    distribution: MicrofacetDistribution, wo: np.ndarray, n: int, xi_border: float = XI_BORDER
) -> float:
    """Eq. 4.14-4.15 divided by n: solid angle of one of n samples covering the elliptical lobe
    cross-section around the mirror direction of ``wo`` (a single direction).

    The thesis measures the ellipse in the plane at unit distance, semi-axes tan(angle): for
    wide lobes that overstates their solid angle (2.5x for a 56 deg cone, frosted glass), so
    every sample was filtered about 0.66 MIP levels too coarse. Here the semi-axes are the
    radii 2 sin(angle / 2) of Lambert's equal-area azimuthal projection, whose ellipse area is
    exactly the solid angle 2 pi (1 - cos angle) of a circular cone and close to it for
    elliptical ones (identical to the thesis' for narrow lobes). Measured (bench/patterns.py,
    lobe-7+norm, 200 px): frosted glass 28.4 -> 31.1 dB (interior.exr), 21.0 -> 26.1
    (courtyard.exr); GGX gold loses 0.4-1.2 dB, which the overstated footprint had made up for
    the GGX tail beyond the pattern's core (theta_thresh). On the line pattern of a strongly
    anisotropic lobe, at least a disc of LINE_MIN_FOOTPRINT_FRACTION of the short axis' radius
    squared (the lobe's width). Times :func:`wide_lobe_footprint_scale` (1 up to alpha 0.3): the
    footprint a lookup filters over, not the lobe's share alone (finest_sample_solid_angle, which
    sizes cube faces by the lobe's width, divides it out again)."""
    return float(lobe_sample_areas(distribution, np.asarray(wo, dtype=np.float64), n, xi_border))


def lobe_sample_areas(
    distribution: MicrofacetDistribution, wo: np.ndarray, n: int, xi_border: float = XI_BORDER
) -> np.ndarray:
    """:func:`lobe_sample_area` of every direction of ``wo`` (shape (..., 3)), shape (...): one
    numpy pass instead of one call per view (the mirror passes' per-reflector tables)."""
    wo = np.asarray(wo, dtype=np.float64)[..., None, :]  # (..., 1, 3) against the two border azimuths
    phis = np.array([0.0, np.pi / 2.0])
    h_border = spherical_direction(theta_thresh(distribution, phis, xi_border), phis)  # (2, 3)
    w_centre = reflect(wo, np.array([0.0, 0.0, 1.0]))
    w_border = reflect(np.broadcast_to(wo, wo.shape[:-2] + h_border.shape), h_border)
    angles = np.arccos(np.clip(dot(w_border, w_centre), -1.0, 1.0))  # (..., 2)
    radii = 2.0 * np.sin(0.5 * np.minimum(angles, MAX_ELLIPSE_ANGLE))
    u, v = radii[..., 0], radii[..., 1]
    area = np.pi * u * v / n
    if uses_line_pattern(distribution.alpha_x, distribution.alpha_y):  # not narrower than the lobe's width
        area = np.maximum(area, np.pi * LINE_MIN_FOOTPRINT_FRACTION * np.minimum(u, v) ** 2)
    return area * wide_lobe_footprint_scale(distribution)


def wide_lobe_footprint_scale(distribution: MicrofacetDistribution) -> float:
    """How much wider than its share of the lobe one lookup of a wide lobe filters: 4^levels,
    levels = WIDE_LOBE_LEVELS_PER_ALPHA (alpha - WIDE_LOBE_ALPHA) clamped to [0,
    WIDE_LOBE_MAX_LEVELS], alpha = sqrt(alpha_x alpha_y); the GGX tail's lookups too. The best LOD
    bias against Mitsuba (issue 45's sky, lobe-7+norm and lobe-15+norm) is -1 up to alpha 0.3 and
    grows beyond: -0.5 at 0.5, about +0.25 at 0.8, +0.5 at 1 (a few samples alias a wide lobe's sources
    unless each reads a coarser level; docs/measurements.md "Wide lobes")."""
    alpha = np.sqrt(distribution.alpha_x * distribution.alpha_y)
    levels = np.clip((alpha - WIDE_LOBE_ALPHA) * WIDE_LOBE_LEVELS_PER_ALPHA, 0.0, WIDE_LOBE_MAX_LEVELS)
    return float(4.0**levels)


def cube_map_lod(world_dirs: np.ndarray, sample_area: float | np.ndarray, face_size: int) -> np.ndarray:
    """Eq. 4.16-4.17: MIP level of a cube-map lookup covering ``sample_area`` (at unit distance)
    in direction ``world_dirs``. May be negative (the texture unit clamps at level 0)."""
    max_component = np.max(np.abs(world_dirs), axis=-1)
    area_on_cube = sample_area / np.maximum(max_component, 1e-6) ** 3
    texels = area_on_cube * face_size * face_size / 4.0
    return 0.5 * np.log2(np.maximum(texels, 1e-30))


@dataclass(frozen=True)
class LobeSamples:
    """The n deterministic directions of one lobe for one viewer direction."""

    wi: np.ndarray  # (n, 3) local-frame incident directions (below the surface for transmission)
    valid: np.ndarray  # (n,) False for samples on the wrong side of the surface (discarded)
    lod: np.ndarray  # (n,) cube-map MIP level per sample (Eq. 4.14-4.17)
    kind: str


def lobe_samples(
    lobe: HalfVectorLobe | MicrofacetReflection,
    wo: np.ndarray,
    n: int,
    face_size: int = 256,
    frame: np.ndarray | None = None,
    kind: str | None = None,
    xi_border: float = XI_BORDER,
    lod_bias: float = LOBE_LOD_BIAS,
    pattern: str = "auto",
) -> LobeSamples:
    """``kind`` forces a pattern; otherwise :func:`choose_pattern` picks one, with ``pattern``
    'auto' (the double ring from DOUBLE_RING_MIN_SAMPLES on) or 'ring' (the thesis' ring at every N)."""
    dist = lobe.distribution
    kind = kind or choose_pattern(dist.alpha_x, dist.alpha_y, n=n, pattern=pattern)
    xi1, xi2 = pattern_xi(n, kind)
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    wi, valid = lobe_directions(lobe, wo, pattern_half_vectors(dist, xi1, xi2, xi_border))
    area = lobe_sample_area(dist, wo, n, xi_border)
    lod = cube_map_lod(to_world(wi, frame), area, face_size) + lod_bias
    return LobeSamples(wi=wi, valid=valid, lod=lod, kind=kind)


def lobe_directions(lobe, wo: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.8 for the half vectors ``h`` (n, 3): the incident directions of ``lobe`` (mirrored
    below the surface for a transmission lobe, shaders/bsdf.glsl reflected_wi) and whether the
    reflection is above the horizon (False: discarded)."""
    wr = reflect(np.broadcast_to(wo, h.shape), h)
    valid = wr[:, 2] > 0.0
    return (mirror_z(wr) if getattr(lobe, "transmission", False) else wr), valid


def to_world(dirs: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
    """Local-frame directions (n, 3) in world space; ``frame`` columns are tangent, bitangent,
    normal (None: the identity)."""
    return dirs if frame is None else dirs @ np.asarray(frame, dtype=np.float64).T


RadianceFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def integrate_lobe(
    lobe: HalfVectorLobe | MicrofacetReflection,
    wo: np.ndarray,
    radiance: RadianceFn,
    n: int,
    face_size: int = 256,
    frame: np.ndarray | None = None,
    kind: str | None = None,
    weighting: str = "eq4.25",
    albedo_table: AlbedoTable | None = None,
    pattern: str = "auto",
    stack=None,
) -> np.ndarray:
    """Outgoing radiance of one lobe by the deterministic pattern quadrature.

    ``radiance(world_dirs (n, 3), lod (n,)) -> (n, 3)`` gives incident radiance, typically a
    MIP-filtered environment lookup; ``frame`` (3x3, columns = tangent, bitangent, normal in
    world space) maps local directions to world space (identity if None).

    With ``albedo_table`` (lobeview's energy normalisation, not in the thesis) the Eq. 4.25
    result is rescaled by albedo(wo) / Eq. 4.25(L = 1): exact under a uniform environment, so
    lobes wider than their pattern or cut by the horizon keep their true energy.

    ``pattern`` ('auto' or 'ring', the method suffix +ring) is the pattern choice of
    :func:`lobe_samples` when ``kind`` is None; 'fitted' (+fit) reads the fitted pattern
    (materials/fitted_pattern.py), its coarse reads from ``stack`` where one is given.

    A lobe with ``sampled_pattern`` (the Rational BRDF) uses step 6 of the module docstring:
    ``kind``, ``pattern`` and ``weighting`` do not apply to it.
    """
    if getattr(lobe, "sampled_pattern", False):
        return integrate_sampled_lobe(lobe, wo, radiance, n, face_size, frame, albedo_table)
    if pattern == "fitted" and albedo_table is not None and fitted_pattern.has_fitted_pattern(lobe):
        table = fitted_pattern.load_table(lobe.distribution.kind, fitted_pattern.read_count(lobe.distribution.kind, n))
        return fitted_pattern.integrate_fitted(lobe, wo, radiance, table, face_size, frame, albedo_table, stack)
    samples = lobe_samples(lobe, wo, n, face_size, frame, kind, pattern=pattern)
    valid = samples.valid
    if not np.any(valid):
        return np.zeros(3)
    wi = samples.wi[valid]
    wo_b = np.broadcast_to(np.asarray(wo, dtype=np.float64).reshape(3), wi.shape)
    world = to_world(wi, frame)
    li = np.asarray(radiance(world, samples.lod[valid]), dtype=np.float64)
    f = lobe.eval(wi, wo_b)
    p = lobe.lobe_pdf(wi, wo_b)
    cos_i = np.abs(wi[:, 2])
    if weighting == "eq4.25":
        ok = p > 0.0
        num = np.sum(
            np.where(ok[:, None], li * (cos_i**2)[:, None] * f * f / np.where(ok, p, 1.0)[:, None], 0.0),
            axis=0,
        )
        den = np.sum(f * cos_i[:, None], axis=0)
        if albedo_table is not None:
            # Eq. 4.25 with L = 1 uses the same samples: num / num_1 * albedo(wo).
            num_1 = np.sum(
                np.where(ok[:, None], (cos_i**2)[:, None] * f * f / np.where(ok, p, 1.0)[:, None], 0.0), axis=0
            )
            target = albedo_table.lookup(np.asarray(wo, dtype=np.float64).reshape(3))
            core = np.where(num_1 > 0.0, num / np.where(num_1 > 0.0, num_1, 1.0), 0.0)
            if not has_ggx_tail(lobe):
                return core * target
            return ggx_tail_integral(lobe, wo, radiance, face_size, frame, core, target)
    elif weighting == "eq4.24":
        num = np.sum(li * (cos_i**2)[:, None] * f, axis=0)
        den = np.full(3, np.sum(p * cos_i))
    else:
        raise ValueError(f"unknown weighting {weighting!r}; use 'eq4.25' or 'eq4.24'")
    return np.where(den > 0.0, num / np.where(den > 0.0, den, 1.0), 0.0)


def has_ggx_tail(lobe) -> bool:
    """Whether lobe-N+norm adds the tail term of step 7 (GGX lobes with a half-vector pattern)."""
    distribution = getattr(lobe, "distribution", None)
    return getattr(distribution, "kind", None) == "ggx" and not getattr(lobe, "sampled_pattern", False)


def ggx_tail_solid_angle(distribution: MicrofacetDistribution) -> float:
    """Step 7: the footprint of one tail lookup, 1 / GGX_TAIL_SAMPLES of the annulus between the
    reflected cones of the core's edge and of GGX_TAIL_OUTER_TAN (at normal incidence the
    reflection of a half vector at theta_h is 2 theta_h away), alpha = sqrt(alpha_x alpha_y).
    The cones are not clamped: for alpha > 0.3 they open past 80 deg (to 156 deg at alpha 1), and
    clamping both at the core's 80 deg (MAX_ELLIPSE_ANGLE) collapsed the footprint to 0 from
    alpha 0.35 on, so the tail read the cube's finest level: sharp copies of the sun (issue 45)."""
    alpha = np.sqrt(distribution.alpha_x * distribution.alpha_y)
    inner = 2.0 * np.arctan(np.sqrt(-np.log(XI_BORDER)) * alpha)
    outer = 2.0 * np.arctan(GGX_TAIL_OUTER_TAN * alpha)
    annulus = 2.0 * np.pi * (np.cos(inner) - np.cos(outer))
    return float(annulus / GGX_TAIL_SAMPLES * wide_lobe_footprint_scale(distribution))


def ggx_tail_quadrature(distribution: MicrofacetDistribution) -> tuple[np.ndarray, np.ndarray]:
    """Step 7: the tail's quadrature, (GGX_TAIL_SAMPLES, GGX_TAIL_POINTS, 3) half vectors and
    each point's share of the projected microfacet mass (GGX_TAIL_POINTS,). Per quarter of the
    tail (azimuths 2 pi [k, k + 1) / GGX_TAIL_SAMPLES), GGX_TAIL_RADIAL bands x
    GGX_TAIL_AZIMUTHAL azimuths; GGX's CDF in x = tan^2 theta_h / alpha^2 is q = x / (1 + x) and
    the tail holds q from 1 - GGX_TAIL_FRACTION to 1; band r ends where the mass left beyond it
    is GGX_TAIL_FRACTION (1 - (r + 1) / GGX_TAIL_RADIAL)^2 (bands narrowing outwards, where the
    horizon cuts the tail), its points at its middle q. Against quadrature of the tail's f cos
    above the horizon (GGX 0.05-0.5, views 0-80 deg): within 2.4 % of the lobe's albedo with 2 x 2
    points per quarter, 1.2 % with 3 x 2 or 4 x 2 (lobe-7+norm 1.5x / 1.75x / 1.9x the frame
    time of the 4 fixed lookups before on llvmpipe, its image against Mitsuba the same to 0.2
    points); equal-mass bands were worse at equal cost, equal-angle bands worse still. An
    anisotropic lobe's points are its own: slopes rho (alpha_x cos phi, alpha_y sin phi) with
    rho^2 = x above (the mass of each cell is the same in the stretched space); placed with the
    isotropic sqrt(alpha_x alpha_y) they spread the tail of GGX 0.05 x 0.3 around the lobe instead of
    along it (lobe-7+norm / lobe-15+norm against Mitsuba 7.8 / 7.7 -> 6.7 / 5.2 %)."""
    s = np.arange(GGX_TAIL_RADIAL + 1) / GGX_TAIL_RADIAL
    q = 1.0 - GGX_TAIL_FRACTION * (1.0 - s) ** 2
    middle = 0.5 * (q[1:] + q[:-1])
    rho = np.sqrt(middle / (1.0 - middle))  # the slope's radius in the lobe's stretched space
    sub = (np.arange(GGX_TAIL_AZIMUTHAL) + 0.5) / GGX_TAIL_AZIMUTHAL
    phi = 2.0 * np.pi * (np.arange(GGX_TAIL_SAMPLES)[:, None] + sub[None, :]) / GGX_TAIL_SAMPLES
    rho_grid = np.broadcast_to(rho[None, :, None], (GGX_TAIL_SAMPLES, GGX_TAIL_RADIAL, GGX_TAIL_AZIMUTHAL))
    phi_grid = np.broadcast_to(phi[:, None, :], rho_grid.shape)
    slope_x = distribution.alpha_x * rho_grid * np.cos(phi_grid)
    slope_y = distribution.alpha_y * rho_grid * np.sin(phi_grid)
    slopes = np.stack([slope_x, slope_y, np.ones(rho_grid.shape)], axis=-1)
    points = (slopes / np.linalg.norm(slopes, axis=-1, keepdims=True)).reshape(GGX_TAIL_SAMPLES, -1, 3)
    masses = np.repeat(np.diff(q), GGX_TAIL_AZIMUTHAL) / (GGX_TAIL_SAMPLES * GGX_TAIL_AZIMUTHAL)
    return points, masses


def ggx_tail_lookups(lobe, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 7: the tail's lookups at view ``wo`` (local): directions (m, 3), their quarters'
    shares of the albedo C_k (m, 3) and footprints (m,) sr, m <= GGX_TAIL_SAMPLES. C_k is a
    quadrature over the quarter's points (ggx_tail_quadrature): each adds its share of the
    projected microfacet mass times f cos / p, p the density of its reflected direction under
    the GGX of the lobe's alphas that placed it (Eq. 4.9: D cos theta_h / 4 wo.h); f cos vanishes at the
    horizon and below it, so the shares follow the part of the tail above the horizon
    continuously. The lookup is at the f cos-weighted mean direction of the quarter's points
    above the horizon, filtered over their share of the quarter's reflected annulus."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    dist = lobe.distribution
    placed = MicrofacetDistribution("ggx", dist.alpha_x, dist.alpha_y)
    points, masses = ggx_tail_quadrature(dist)
    directions, shares, footprints = [], [], []
    for quarter in points:
        wi, valid = lobe_directions(lobe, wo, quarter)
        if not np.any(valid):
            continue
        h, wi, mass = quarter[valid], wi[valid], masses[valid]
        wo_b = np.broadcast_to(wo, wi.shape)
        p = placed.D(h) * h[:, 2] / (4.0 * np.maximum(np.sum(wo_b * h, axis=-1), 1e-12))
        share = (mass * np.abs(wi[:, 2]) / p)[:, None] * lobe.eval(wi, wo_b)
        weight = share.sum(axis=1)
        if not np.any(weight > 0.0):
            continue
        direction = np.sum(weight[:, None] * wi, axis=0)
        directions.append(direction / np.linalg.norm(direction))
        shares.append(share.sum(axis=0))
        footprints.append(ggx_tail_solid_angle(dist) * mass.sum() / masses.sum())  # the visible points' share
    if not directions:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.array(directions), np.array(shares), np.array(footprints)


def ggx_tail_terms(lobe, wo: np.ndarray, radiance: RadianceFn, face_size: int, frame) -> tuple[np.ndarray, np.ndarray]:
    """Step 7: the tail's part of the lobe's integral, (sum_k C_k L_k, W = sum_k C_k), RGB, with
    the lookups of ggx_tail_lookups."""
    directions, shares, footprints = ggx_tail_lookups(lobe, wo)
    if not len(directions):
        return np.zeros(3), np.zeros(3)
    world = to_world(directions, frame)
    lod = cube_map_lod(world, footprints, face_size) + LOBE_LOD_BIAS
    total = np.sum(shares * np.asarray(radiance(world, lod), dtype=np.float64), axis=0)
    return total, shares.sum(axis=0)


def ggx_tail_integral(lobe, wo, radiance: RadianceFn, face_size: int, frame, core, target) -> np.ndarray:
    """Step 7: lobe-N+norm of a GGX lobe, core and tail: the tail's terms (ggx_tail_terms) plus
    the core's radiance over the rest of the albedo ``target``, max(target - W, 0) core, all
    scaled by target / W where the tail's estimate exceeds the albedo: exact under uniform light.
    (The tail had a fixed GGX_TAIL_FRACTION of the albedo, the mean of its lookups above the
    horizon, each faded in over its last 0.1 of z: at GGX alpha 0.5 one lookup just above the
    horizon carried a quarter of the tail, a sharp-edged diamond on a sphere, issue 45; at normal
    incidence the tail of a wide lobe lies below the horizon and at grazing it holds up to half
    of the albedo.)"""
    total, carried = ggx_tail_terms(lobe, wo, radiance, face_size, frame)
    target = np.asarray(target, dtype=np.float64)
    value = np.maximum(target - carried, 0.0) * np.asarray(core, dtype=np.float64) + total
    return np.where(carried > target, value * target / np.where(carried > 0.0, carried, 1.0), value)


def integrate_sampled_lobe(
    lobe,
    wo: np.ndarray,
    radiance: RadianceFn,
    n: int,
    face_size: int = 256,
    frame: np.ndarray | None = None,
    albedo_table: AlbedoTable | None = None,
    lod_bias: float = LOBE_LOD_BIAS,
) -> np.ndarray:
    """lobe-N of a lobe with its own sampler (step 6 of the module docstring): the lattice of
    :func:`lattice_xi` through ``lobe._sample(u1, u2, wo) -> (wi, 1 / p)``, one MIP level per
    sample from its solid angle 1 / (N p) (Eq. 4.16-4.17 with that area)."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    # Near the normal the lattice is anchored in the tangent frame (RationalLobe
    # tangent_anchor_weight), blended into the view-anchored one between two view angles.
    tangent = float(lobe.tangent_anchor_weight(wo)) if hasattr(lobe, "tangent_anchor_weight") else 0.0
    out = np.zeros(3)
    for anchored, share in ((True, tangent), (False, 1.0 - tangent)):
        if share > 0.0:
            out += share * _sampled_estimate(lobe, wo, radiance, n, face_size, frame, albedo_table, lod_bias, anchored)
    return out


def _sampled_estimate(lobe, wo, radiance, n, face_size, frame, albedo_table, lod_bias, tangent: bool) -> np.ndarray:
    u1, u2 = lattice_xi(n)
    wi, inverse_pdf = lobe._sample(u1, u2, wo, tangent=True) if tangent else lobe._sample(u1, u2, wo)
    ok = (inverse_pdf > 0.0) & (wi[:, 2] > 0.0)
    if not np.any(ok):
        return np.zeros(3)
    wi, inverse_pdf = wi[ok], inverse_pdf[ok]
    world = to_world(wi, frame)
    lod = cube_map_lod(world, inverse_pdf / n, face_size) + lod_bias
    li = np.asarray(radiance(world, lod), dtype=np.float64)
    weight = lobe.eval(wi, np.broadcast_to(wo, wi.shape)) * (wi[:, 2] * inverse_pdf)[:, None]  # f cos / p
    if albedo_table is None:
        return np.sum(li * weight, axis=0) / n
    total = np.sum(weight, axis=0)
    target = albedo_table.lookup(wo)
    return np.where(total > 0.0, np.sum(li * weight, axis=0) * target / np.where(total > 0.0, total, 1.0), 0.0)


ALBEDO_MU = 32  # cos(theta_o) samples of the normalisation table
ALBEDO_PHI = 16  # azimuth samples for anisotropic lobes (isotropic lobes repeat one row)


@dataclass(frozen=True)
class AlbedoTable:
    """Directional albedo of one lobe over (cos theta_o, phi_o): values (ALBEDO_PHI + 1, ALBEDO_MU,
    3), row ALBEDO_PHI repeating row 0 so bilinear interpolation wraps in phi. Sample points are
    texel centres in sqrt(cos theta_o), sqrt(mu_i) = (i + 0.5) / ALBEDO_MU, and phi_j = 2 pi j /
    ALBEDO_PHI, i.e. exactly what a linearly filtered texture with clamp returns at
    (sqrt(wo.z), phi) (shaders/integrate.glsl). The square root puts samples where the albedo
    changes fastest, near grazing: the stress suite's worst furnace excess of a rough isotropic
    lobe (m = 1, alpha = 1) fell from 33 % (linear in mu) to 5 %."""

    values: np.ndarray

    @classmethod
    def build(cls, lobe, order: int = 48) -> AlbedoTable:
        single = BSDF([lobe])
        d = lobe.distribution
        isotropic = d.alpha_x == d.alpha_y
        mus = ((np.arange(ALBEDO_MU) + 0.5) / ALBEDO_MU) ** 2
        phis = np.arange(ALBEDO_PHI) / ALBEDO_PHI * 2 * np.pi
        values = np.zeros((ALBEDO_PHI + 1, ALBEDO_MU, 3))
        rows = phis[:1] if isotropic else phis
        sin_o = np.sqrt(np.maximum(1.0 - mus * mus, 0.0))
        wos = np.stack(
            [
                np.outer(np.cos(rows), sin_o),
                np.outer(np.sin(rows), sin_o),
                np.broadcast_to(mus, (len(rows), ALBEDO_MU)),
            ],
            axis=-1,
        ).reshape(-1, 3)
        r, t = single.albedo_many(wos, order)  # one vectorised quadrature for the whole table
        values[: len(rows)] = (r + t).reshape(len(rows), ALBEDO_MU, 3)
        if isotropic:
            values[:] = values[0]
        values[ALBEDO_PHI] = values[0]
        return cls(values)

    def lookup(self, wo: np.ndarray) -> np.ndarray:
        x = np.clip(np.sqrt(max(wo[2], 0.0)) * ALBEDO_MU - 0.5, 0.0, ALBEDO_MU - 1.0)
        y = (np.arctan2(wo[1], wo[0]) / (2 * np.pi)) % 1.0 * ALBEDO_PHI
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        x1, y1 = min(x0 + 1, ALBEDO_MU - 1), min(y0 + 1, ALBEDO_PHI)
        fx, fy = x - x0, y - y0
        v = self.values
        return (v[y0, x0] * (1 - fx) + v[y0, x1] * fx) * (1 - fy) + (v[y1, x0] * (1 - fx) + v[y1, x1] * fx) * fy


def specular_lobes(bsdf: BSDF) -> list:
    """The view-dependent lobes of a BSDF (everything but the diffuse term, which the
    lightmap provides)."""
    # Every lobe with a pattern density (lobe_pdf): the half-vector lobes, the microfacet ones and
    # the Rational BRDF (through its proxy distribution).
    return [c for c in bsdf.components if callable(getattr(c, "lobe_pdf", None))]


def integrate_specular(
    bsdf: BSDF,
    wo: np.ndarray,
    radiance: RadianceFn,
    n: int,
    face_size: int = 256,
    frame: np.ndarray | None = None,
    weighting: str = "eq4.25",
    pattern: str = "auto",
) -> np.ndarray:
    """``lobe-N`` for a whole BSDF: the sum over its specular and transmission lobes, each with
    its own N-sample pattern (the thesis' "n = 5 + 5" for frosted glass)."""
    total = np.zeros(3)
    for lobe in specular_lobes(bsdf):
        total += integrate_lobe(lobe, wo, radiance, n, face_size, frame, None, weighting, pattern=pattern)
    return total
