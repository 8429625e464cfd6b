"""How far lobe-N's lookups reach from a lobe's centre direction (issue 18: the margin of a
scissored mirror pass, viewer/mirror_pass.py): the pattern's samples and, with the energy
normalisation, the GGX tail's lookups (materials/patterns.py step 7) over a grid of views."""

from __future__ import annotations

import numpy as np

from .patterns import (
    choose_pattern,
    ggx_tail_lookups,
    ggx_tail_solid_angle,
    has_ggx_tail,
    lobe_directions,
    lobe_sample_area,
    pattern_half_vectors,
    pattern_xi,
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
