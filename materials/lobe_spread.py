"""How far lobe-N's lookups reach from a lobe's centre direction (issue 18: the margin of a
scissored mirror pass, viewer/mirror_pass.py): the pattern's samples and, with the energy
normalisation, the GGX tail's lookups (materials/patterns.py step 7) over a grid of views; and
how fine a cube map those lookups read (the lobe-width face size, issue 18)."""

from __future__ import annotations

import numpy as np

from lobeview.core.methods import MAX_PATTERN

from .patterns import (
    LOBE_LOD_BIAS,
    choose_pattern,
    ggx_tail_lookups,
    ggx_tail_solid_angle,
    has_ggx_tail,
    lobe_directions,
    lobe_sample_area,
    lobe_sample_areas,
    pattern_half_vectors,
    pattern_xi,
    wide_lobe_footprint_scale,
)
from .vec import spherical_direction

SPREAD_VIEW_ANGLES = np.radians(np.linspace(0.0, 89.0, 12))
SPREAD_VIEW_AZIMUTHS = np.radians(np.linspace(0.0, 90.0, 5))  # the tail's lookups turn with the view


def lobe_spread(lobes: list, n: int, normalize: bool, planar: bool = True) -> tuple[float, float] | None:
    """How far lobe-N's lookups reach from a lobe's centre direction (issue 18: the margin of a
    scissored mirror pass): (largest angle in radians between a sample direction, GGX tail
    lookups included with ``normalize``, and its lobe's centre direction, i.e. the mirror or
    straight-through direction; largest solid angle one lookup is filtered over), over views from
    the normal to 89 deg. None when a lobe's lookups have no bound here (the Rational BRDF's
    sampled pattern)."""
    widest, largest = 0.0, 0.0
    for lobe in lobes:
        if getattr(lobe, "sampled_pattern", False) or not hasattr(lobe, "distribution"):
            return None
        dist = lobe.distribution
        kind = choose_pattern(dist.alpha_x, dist.alpha_y, planar=planar, n=n)
        xi1, xi2 = pattern_xi(n, kind)
        half_vectors = pattern_half_vectors(dist, xi1, xi2)
        tail = normalize and has_ggx_tail(lobe)
        if tail:
            largest = max(largest, ggx_tail_solid_angle(dist))
        for theta in SPREAD_VIEW_ANGLES:
            for phi in SPREAD_VIEW_AZIMUTHS:
                wo = spherical_direction(np.array(theta), np.array(phi))
                centre, _ = lobe_directions(lobe, wo, np.array([[0.0, 0.0, 1.0]]))
                wi, valid = lobe_directions(lobe, wo, half_vectors)
                wi = wi[valid]
                if tail:
                    wi = np.concatenate([wi, ggx_tail_lookups(lobe, wo)[0]])
                if len(wi):
                    cosines = np.clip(wi @ centre[0], -1.0, 1.0)
                    widest = max(widest, float(np.arccos(cosines.min())))
                largest = max(largest, lobe_sample_area(dist, wo, n))
    return widest, largest


# Cube-map face size from the lobes' width (issue 18): the finest MIP level the lobe-N lookups of
# an object read decides how many texels its cube map needs. A reflected lobe's cross-section
# shrinks towards grazing views (0.26x its area at 75 deg, 0.017x at 89 deg); views up to
# FOOTPRINT_MAX_VIEW_ANGLE count, so that the rim beyond it (under 7 % of a sphere's projected
# area) may read level 0 magnified (measured: tests/test_cube_sizes.py, bench/walkthrough.py).
FOOTPRINT_MAX_VIEW_ANGLE = np.radians(75.0)
FOOTPRINT_VIEW_STEPS = 6
MIN_CUBE_FACE = 16  # smallest face a lobe-width rule gives (6 x 16^2 texels)


def finest_sample_solid_angle(
    lobes: list, n: int = MAX_PATTERN, max_view_angle: float = FOOTPRINT_MAX_VIEW_ANGLE
) -> float | None:
    """Smallest solid angle (sr) one of ``n`` lobe-N samples covers (:func:`lobe_sample_area`,
    what the shaders' MIP level is computed from) over ``lobes`` and view directions from the
    normal to ``max_view_angle``, both tangent azimuths; more samples than MAX_PATTERN are never
    taken. None when a lobe has no pattern footprint (the Rational BRDF's sampled
    pattern filters by 1 / (N p), which has no lower bound here): such objects keep the full
    face size. Without the wide lobes' widening (wide_lobe_footprint_scale): that is lobe-N's
    filter, and the face also serves the object's other methods; sized by the widened footprint,
    the prefiltered maps of GGX and Beckmann 0.5-0.8 lost accuracy with the halved face
    (prefiltered-rsibr on the interior capture 2.3 -> 5.2 %, plain prefiltered on the sky 7.5 ->
    12.0, method table), while lobe-N reads the same filtered radiance either way."""
    finest = finest_sample_solid_angles(lobes, n, np.array([max_view_angle], dtype=np.float64))
    return None if finest is None or not np.isfinite(finest[0]) else float(finest[0])


def finest_sample_solid_angles(lobes: list, n: int, max_view_angles: np.ndarray) -> np.ndarray | None:
    """:func:`finest_sample_solid_angle` for each bound of ``max_view_angles`` (shape (A,)), in one
    numpy pass per lobe: the views of each bound are FOOTPRINT_VIEW_STEPS polar angles from 0 to it
    at both tangent azimuths. None when a lobe has no pattern footprint."""
    max_view_angles = np.asarray(max_view_angles, dtype=np.float64)
    steps = np.linspace(0.0, 1.0, FOOTPRINT_VIEW_STEPS)
    theta = max_view_angles[:, None, None] * steps[None, :, None]  # (A, steps, 1)
    phi = np.array([0.0, np.pi / 2.0])[None, None, :]  # both tangent azimuths
    wo = spherical_direction(*np.broadcast_arrays(theta, phi))  # (A, steps, 2, 3)
    finest = np.full(max_view_angles.shape, np.inf)
    for lobe in lobes:
        if getattr(lobe, "sampled_pattern", False) or not hasattr(lobe, "distribution"):
            return None
        areas = lobe_sample_areas(lobe.distribution, wo, n) / wide_lobe_footprint_scale(lobe.distribution)
        finest = np.minimum(finest, areas.min(axis=(1, 2)))
    return finest


def lobe_width_face_size(
    sample_solid_angle: float | None,
    full_size: int,
    lod_bias: float = LOBE_LOD_BIAS,
    margin_levels: float = 0.0,
    min_size: int = MIN_CUBE_FACE,
) -> int:
    """The smallest power-of-two cube face (between ``min_size`` and ``full_size``) on which no
    lookup of footprint ``sample_solid_angle`` reads below MIP level ``margin_levels``: with
    Eq. 4.17's lod = log4(Omega S^2 / 4 / max|w|^3) + bias >= log4(Omega S^2 / 4) + bias, level 0
    of a face S = full / 2^k stands in for level k of the full face, so such lookups read the
    same filtered radiance (up to how the smaller face was rasterised, see viewer/cube_bake.py).
    ``full_size`` when the footprint is unknown (None)."""
    full_size = int(full_size)
    if sample_solid_angle is None or not sample_solid_angle > 0:
        return full_size
    # lod(S) >= margin  <=>  S >= 2 / sqrt(Omega) * 2^(margin - bias)
    needed = 2.0 / np.sqrt(sample_solid_angle) * 2.0 ** (margin_levels - lod_bias)
    size = max(int(min_size), 1)
    while size < needed and size < full_size:
        size *= 2
    return min(size, full_size)
