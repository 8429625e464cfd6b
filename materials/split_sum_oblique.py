"""Split-sum lookups of isotropic lobes at oblique views (issue 45; numpy reference of
shaders/prefiltered.glsl's oblique line).

The split-sum map is filtered with the lobe's kernel at normal incidence, n = v = r (Karis 2013),
round about the mirror direction. At a view theta_o off the normal the reflected lobe is not
round: a half vector tilted by d across the plane of incidence moves the reflected direction by
2 d cos(theta_o), one tilted within it by 2 d, so the lobe narrows across the plane by about
cos(theta_o) (less for wide lobes, whose shadowing and horizon reshape them). One round lookup is
then too blurred across the plane: a vertical edge of a courtyard seen at a sphere's side smeared
over twice its width, and `prefiltered` was 24-43 % from Mitsuba on GGX 0.15 / Beckmann 0.3 under
courtyard.exr (bench/mitsuba.py --env courtyard).

So an isotropic lobe reads the map at the narrower alpha' = alpha rho(alpha, cos theta_o), whose
kernel has the lobe's spread across the plane, at the quantile line of the anisotropic lobes
(prefilter.py split_sum_line) along the plane of incidence with the slope scale
sqrt(alpha^2 - alpha'^2), the part of the lobe's width within the plane the narrow kernel does not
cover; the lookups lean towards the normal by split_sum_lean at the lobe's own alpha (the
off-specular shift of the whole lobe; at alpha' the rough lobes lost it: GGX 0.5 under courtyard.exr
28.4 % against 18.7 %).

rho is tabulated (OBLIQUE_RATIO): the interquartile range of the lobe's f cos over the angle
across the plane of incidence (:func:`perpendicular_spread`, a Fibonacci quadrature of the
hemisphere), matched by the alpha' whose lobe at normal incidence has the same range
(:func:`oblique_ratio_table`). At narrow lobes rho is cos(theta_o), at wide ones closer to 1 (GGX
0.5 at cos 0.3: 0.64).
"""

from __future__ import annotations

import numpy as np

from .microfacet import MicrofacetDistribution

OBLIQUE_ALPHAS = (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0)
OBLIQUE_COSINES = tuple(round(0.1 * k, 1) for k in range(1, 11))  # cos(theta_o) 0.1 .. 1.0
# rho(alpha, cos theta_o): rows OBLIQUE_ALPHAS, columns OBLIQUE_COSINES (oblique_ratio_table with
# OBLIQUE_TABLE_POINTS; shaders/prefiltered.glsl OBLIQUE_RATIO holds the same numbers, GGX first).
OBLIQUE_RATIO = {
    "ggx": (
        (0.205, 0.249, 0.323, 0.408, 0.499, 0.596, 0.694, 0.794, 0.897, 1.000),
        (0.288, 0.307, 0.359, 0.429, 0.508, 0.598, 0.691, 0.789, 0.892, 1.000),
        (0.362, 0.367, 0.403, 0.458, 0.526, 0.604, 0.691, 0.786, 0.889, 1.000),
        (0.476, 0.470, 0.488, 0.522, 0.571, 0.631, 0.703, 0.787, 0.886, 1.000),
        (0.556, 0.547, 0.557, 0.582, 0.618, 0.667, 0.726, 0.799, 0.889, 1.000),
        (0.625, 0.611, 0.617, 0.636, 0.665, 0.705, 0.755, 0.818, 0.898, 1.000),
        (0.802, 0.763, 0.753, 0.760, 0.775, 0.800, 0.835, 0.876, 0.932, 1.000),
        (1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000),
    ),
    "beckmann": (
        (0.140, 0.217, 0.307, 0.402, 0.500, 0.598, 0.698, 0.799, 0.901, 1.000),
        (0.170, 0.243, 0.322, 0.408, 0.500, 0.597, 0.696, 0.796, 0.898, 1.000),
        (0.202, 0.270, 0.344, 0.423, 0.509, 0.598, 0.695, 0.794, 0.896, 1.000),
        (0.259, 0.323, 0.390, 0.460, 0.535, 0.614, 0.699, 0.792, 0.892, 1.000),
        (0.306, 0.368, 0.431, 0.496, 0.564, 0.635, 0.712, 0.795, 0.889, 1.000),
        (0.344, 0.404, 0.464, 0.526, 0.589, 0.655, 0.725, 0.803, 0.892, 1.000),
        (0.397, 0.455, 0.513, 0.571, 0.633, 0.699, 0.771, 0.850, 0.930, 1.000),
        (0.447, 0.516, 0.597, 0.693, 0.813, 0.973, 1.000, 1.000, 1.000, 1.000),
    ),
}
OBLIQUE_TABLE_POINTS = 400_000
MIN_OBLIQUE_XY = 1e-4  # |wo.xy| below this: normal incidence, one lookup (no plane of incidence)


def oblique_alpha_ratio(kind: str, alpha: float, cos_theta_o: float) -> float:
    """rho: bilinear in OBLIQUE_RATIO, alpha clamped to [0.1, 1] (below 0.1 the 0.1 row, about
    cos theta_o), cos theta_o to [0.1, 1] (shaders/prefiltered.glsl oblique_ratio)."""
    table = np.asarray(OBLIQUE_RATIO[kind])
    alphas = np.asarray(OBLIQUE_ALPHAS)
    a = float(np.clip(alpha, alphas[0], alphas[-1]))
    i = min(int(np.searchsorted(alphas, a, side="right")) - 1, len(alphas) - 2)
    ta = (a - alphas[i]) / (alphas[i + 1] - alphas[i])
    c = float(np.clip(cos_theta_o, 0.1, 1.0)) * 10.0 - 1.0
    j = min(int(np.floor(c)), len(OBLIQUE_COSINES) - 2)
    tc = c - j
    low = (1.0 - tc) * table[i, j] + tc * table[i, j + 1]
    high = (1.0 - tc) * table[i + 1, j] + tc * table[i + 1, j + 1]
    return float((1.0 - ta) * low + ta * high)


def _hemisphere(points: int) -> np.ndarray:
    """A Fibonacci lattice of the upper hemisphere, equal solid angle per point."""
    k = np.arange(points) + 0.5
    z = k / points
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def perpendicular_spread(kind: str, alpha: float, cos_theta_o: float, points: int = OBLIQUE_TABLE_POINTS) -> float:
    """Interquartile range (radians) of the angle across the plane of incidence of light
    reflected by an isotropic lobe (f cos, no Fresnel) toward wo = (sin theta_o, 0, cos theta_o)."""
    from .conductor import MicrofacetReflection
    from .fresnel import Fresnel

    wi = _hemisphere(points)
    lobe = MicrofacetReflection(MicrofacetDistribution(kind, alpha, alpha), Fresnel("none"))
    wo = np.array([np.sqrt(max(1.0 - cos_theta_o**2, 0.0)), 0.0, cos_theta_o])
    weight = lobe.eval(wi, np.broadcast_to(wo, wi.shape))[:, 0] * wi[:, 2]
    across = np.arcsin(np.clip(wi[:, 1], -1.0, 1.0))
    order = np.argsort(across)
    cumulative = np.cumsum(weight[order])
    cumulative /= cumulative[-1]
    return float(np.interp(0.75, cumulative, across[order]) - np.interp(0.25, cumulative, across[order]))


def oblique_ratio_table(kind: str, points: int = OBLIQUE_TABLE_POINTS, alphas=OBLIQUE_ALPHAS, cosines=OBLIQUE_COSINES):
    """rho for every (alpha, cos theta_o): the alpha' whose lobe at normal incidence spreads as
    far across the plane (log-interpolated over 60 alphas from 0.003 to 1) over alpha, at most 1."""
    fine = np.geomspace(0.003, 1.0, 60)
    normal = np.array([perpendicular_spread(kind, a, 1.0, points) for a in fine])
    table = np.empty((len(alphas), len(cosines)))
    for i, alpha in enumerate(alphas):
        for j, cosine in enumerate(cosines):
            spread = perpendicular_spread(kind, alpha, cosine, points)
            matched = np.exp(np.interp(np.log(spread), np.log(normal), np.log(fine)))
            table[i, j] = min(matched / alpha, 1.0)
    return table
