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
    return float(_grid_bilinear(np.asarray(OBLIQUE_RATIO[kind]), alpha, cos_theta_o))


def _grid_bilinear(table: np.ndarray, alpha: float, cos_theta_o: float) -> np.ndarray:
    """``table`` (OBLIQUE_ALPHAS, OBLIQUE_COSINES, ...) bilinear at (alpha, cos theta_o), both
    clamped to the grid (shaders/prefiltered.glsl oblique_cell)."""
    alphas = np.asarray(OBLIQUE_ALPHAS)
    a = float(np.clip(alpha, alphas[0], alphas[-1]))
    i = min(int(np.searchsorted(alphas, a, side="right")) - 1, len(alphas) - 2)
    ta = (a - alphas[i]) / (alphas[i + 1] - alphas[i])
    c = float(np.clip(cos_theta_o, 0.1, 1.0)) * 10.0 - 1.0
    j = min(int(np.floor(c)), len(OBLIQUE_COSINES) - 2)
    tc = c - j
    low = (1.0 - tc) * table[i, j] + tc * table[i, j + 1]
    high = (1.0 - tc) * table[i + 1, j] + tc * table[i + 1, j + 1]
    return (1.0 - ta) * low + ta * high


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


# Beckmann's oblique line at the lobe's own in-plane quantiles (issues 45 and 39). The symmetric
# line above reads Karis' kernel (narrower than Beckmann's lobe, prefilter.py
# microfacet_kernel_values) at the normal-incidence quantiles plus a fixed lean, and the lobe at an
# oblique view is neither symmetric nor centred there: cut by the horizon and shifted off the mirror
# direction. The nodes now sit where the lobe's f cos puts its mass within the plane of incidence:
# at the quantiles (SPLIT_SUM_LINE_EDGES middles) of the angle theta from the normal (positive
# towards the viewer's side, the mirror direction at -theta_o), their offsets from the median
# shrunk quantile by quantile by what the level kernel spreads on its own, sqrt(offset^2 -
# kernel quantile^2) (exact for Gaussians, where variances add), no lean. bench/split_sum_line.py
# measures it per pixel of the preview sphere against the exact lobe integral of the maps a cube
# keeps (12^2 pixels; relative RMSE, symmetric line -> in-plane quantiles, %): the sky 8.1 -> 2.6 /
# 3.1 -> 2.6 / 5.0 -> 3.6 (Beckmann 0.15 / 0.5 / 0.8), interior.exr 15.9 -> 4.1 / 16.0 -> 10.2 /
# 11.9 -> 7.8, courtyard.exr 24.9 -> 11.9 / 27.8 -> 19.9 / 19.8 -> 19.6, and the sun's mirror pixel
# of issue 45's sky 1.028 -> 0.997 (0.5), 1.076 -> 1.017 (0.8). GGX keeps the symmetric line: its
# kernel is its lobe at normal incidence and its heavy tails do not deconvolve (GGX 0.8 under
# interior.exr 5.5 -> 8.1 %, courtyard 9.5 -> 17.6 with the same rule; GGX 0.15 would gain).
# Tabulated as t_k = (theta_k + theta_o) / alpha over OBLIQUE_ALPHAS x OBLIQUE_COSINES (a narrow lobe's
# offsets grow with alpha: below alpha 0.1 the 0.1 row), bilinear like OBLIQUE_RATIO. At cos theta_o
# 1 every node is at the normal: the plane of incidence turns round a sphere's centre, and a line of
# fixed length there drew a pinwheel on Beckmann 0.8 (the symmetric line closes there too).
IN_PLANE_KINDS = ("beckmann",)
IN_PLANE_OFFSETS = {  # in_plane_offset_table(kind): rows (alpha, cos theta_o) alpha-major, 11 nodes each
    "beckmann": (
        (-0.680, -0.359, 0.009, 0.342, 0.654, 0.955, 1.277, 1.631, 2.088, 2.720, 3.621),
        (-1.519, -1.070, -0.588, -0.174, 0.185, 0.533, 0.883, 1.274, 1.758, 2.420, 3.350),
        (-2.175, -1.505, -0.913, -0.445, -0.055, 0.305, 0.673, 1.069, 1.559, 2.223, 3.151),
        (-2.496, -1.658, -1.026, -0.550, -0.161, 0.192, 0.552, 0.944, 1.420, 2.069, 2.970),
        (-2.501, -1.657, -1.042, -0.588, -0.214, 0.128, 0.470, 0.844, 1.299, 1.914, 2.774),
        (-2.368, -1.576, -1.004, -0.578, -0.236, 0.082, 0.408, 0.748, 1.176, 1.748, 2.547),
        (-2.156, -1.444, -0.931, -0.549, -0.233, 0.053, 0.343, 0.652, 1.036, 1.546, 2.262),
        (-1.861, -1.248, -0.810, -0.482, -0.216, 0.028, 0.271, 0.532, 0.862, 1.304, 1.911),
        (-1.413, -0.952, -0.630, -0.374, -0.178, 0.010, 0.195, 0.394, 0.641, 0.972, 1.430),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (-0.333, -0.057, 0.271, 0.578, 0.859, 1.139, 1.436, 1.771, 2.198, 2.795, 3.636),
        (-0.893, -0.580, -0.207, 0.140, 0.456, 0.764, 1.087, 1.445, 1.898, 2.517, 3.387),
        (-1.405, -1.018, -0.571, -0.178, 0.168, 0.498, 0.835, 1.210, 1.673, 2.302, 3.178),
        (-1.842, -1.327, -0.808, -0.383, -0.022, 0.319, 0.659, 1.036, 1.500, 2.123, 2.985),
        (-2.134, -1.485, -0.923, -0.491, -0.131, 0.202, 0.539, 0.903, 1.355, 1.952, 2.781),
        (-2.216, -1.498, -0.947, -0.528, -0.190, 0.130, 0.445, 0.791, 1.213, 1.776, 2.546),
        (-2.101, -1.414, -0.905, -0.524, -0.212, 0.079, 0.368, 0.679, 1.067, 1.579, 2.279),
        (-1.861, -1.258, -0.819, -0.482, -0.210, 0.040, 0.291, 0.566, 0.899, 1.344, 1.948),
        (-1.488, -1.012, -0.667, -0.401, -0.185, 0.013, 0.212, 0.430, 0.698, 1.051, 1.524),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (-0.130, 0.116, 0.417, 0.702, 0.968, 1.232, 1.511, 1.830, 2.234, 2.792, 3.577),
        (-0.528, -0.286, 0.034, 0.342, 0.629, 0.913, 1.211, 1.548, 1.972, 2.552, 3.356),
        (-0.901, -0.643, -0.290, 0.047, 0.355, 0.656, 0.968, 1.318, 1.751, 2.343, 3.153),
        (-1.244, -0.949, -0.549, -0.183, 0.141, 0.451, 0.774, 1.126, 1.565, 2.154, 2.958),
        (-1.553, -1.181, -0.734, -0.348, -0.016, 0.299, 0.619, 0.970, 1.400, 1.976, 2.755),
        (-1.794, -1.319, -0.841, -0.449, -0.122, 0.187, 0.499, 0.837, 1.250, 1.801, 2.539),
        (-1.899, -1.343, -0.864, -0.490, -0.180, 0.110, 0.399, 0.715, 1.097, 1.605, 2.284),
        (-1.822, -1.262, -0.821, -0.485, -0.202, 0.056, 0.315, 0.595, 0.936, 1.387, 1.985),
        (-1.569, -1.086, -0.716, -0.433, -0.200, 0.019, 0.234, 0.472, 0.753, 1.127, 1.617),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (0.134, 0.318, 0.577, 0.829, 1.067, 1.305, 1.557, 1.843, 2.204, 2.691, 3.350),
        (-0.076, 0.065, 0.316, 0.573, 0.820, 1.067, 1.331, 1.628, 2.001, 2.503, 3.173),
        (-0.266, -0.170, 0.078, 0.341, 0.596, 0.854, 1.125, 1.432, 1.814, 2.324, 3.000),
        (-0.450, -0.390, -0.141, 0.132, 0.396, 0.660, 0.940, 1.253, 1.642, 2.154, 2.825),
        (-0.629, -0.597, -0.337, -0.053, 0.219, 0.490, 0.774, 1.088, 1.477, 1.986, 2.644),
        (-0.825, -0.791, -0.511, -0.213, 0.066, 0.340, 0.625, 0.940, 1.322, 1.823, 2.457),
        (-1.045, -0.962, -0.651, -0.343, -0.059, 0.214, 0.495, 0.802, 1.174, 1.656, 2.260),
        (-1.273, -1.092, -0.748, -0.432, -0.154, 0.112, 0.383, 0.676, 1.030, 1.481, 2.041),
        (-1.477, -1.154, -0.787, -0.476, -0.209, 0.039, 0.290, 0.563, 0.886, 1.299, 1.807),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (0.329, 0.444, 0.662, 0.885, 1.098, 1.313, 1.541, 1.797, 2.114, 2.532, 3.063),
        (0.228, 0.277, 0.473, 0.691, 0.908, 1.128, 1.363, 1.627, 1.954, 2.380, 2.914),
        (0.148, 0.117, 0.294, 0.510, 0.728, 0.954, 1.195, 1.466, 1.800, 2.234, 2.767),
        (0.078, -0.038, 0.120, 0.337, 0.559, 0.790, 1.037, 1.314, 1.655, 2.091, 2.621),
        (0.010, -0.195, -0.050, 0.168, 0.396, 0.633, 0.887, 1.169, 1.515, 1.952, 2.475),
        (-0.095, -0.364, -0.219, 0.006, 0.241, 0.485, 0.744, 1.034, 1.381, 1.819, 2.335),
        (-0.277, -0.548, -0.391, -0.153, 0.094, 0.347, 0.612, 0.904, 1.255, 1.690, 2.194),
        (-0.571, -0.759, -0.563, -0.303, -0.043, 0.217, 0.488, 0.786, 1.137, 1.569, 2.064),
        (-0.992, -1.000, -0.735, -0.443, -0.167, 0.103, 0.379, 0.678, 1.028, 1.454, 1.941),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (0.486, 0.532, 0.711, 0.907, 1.098, 1.294, 1.499, 1.728, 2.005, 2.353, 2.764),
        (0.456, 0.417, 0.568, 0.757, 0.949, 1.147, 1.357, 1.593, 1.876, 2.229, 2.637),
        (0.445, 0.302, 0.427, 0.610, 0.803, 1.005, 1.223, 1.465, 1.755, 2.112, 2.514),
        (0.459, 0.186, 0.286, 0.465, 0.660, 0.868, 1.092, 1.341, 1.639, 2.000, 2.397),
        (0.483, 0.055, 0.138, 0.317, 0.519, 0.734, 0.966, 1.224, 1.528, 1.895, 2.290),
        (0.489, -0.094, -0.018, 0.167, 0.377, 0.602, 0.845, 1.112, 1.427, 1.800, 2.195),
        (0.234, -0.277, -0.190, 0.009, 0.233, 0.472, 0.727, 1.006, 1.332, 1.713, 2.114),
        (-0.146, -0.499, -0.381, -0.158, 0.086, 0.342, 0.612, 0.905, 1.244, 1.637, 2.045),
        (-0.630, -0.789, -0.605, -0.341, -0.069, 0.209, 0.498, 0.808, 1.163, 1.568, 1.978),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (0.686, 0.621, 0.741, 0.900, 1.062, 1.228, 1.399, 1.580, 1.783, 2.006, 2.210),
        (0.703, 0.550, 0.647, 0.801, 0.965, 1.134, 1.310, 1.497, 1.703, 1.925, 2.114),
        (0.715, 0.468, 0.548, 0.699, 0.867, 1.043, 1.226, 1.419, 1.631, 1.853, 2.032),
        (0.684, 0.369, 0.439, 0.593, 0.768, 0.953, 1.146, 1.349, 1.569, 1.794, 1.972),
        (0.587, 0.251, 0.320, 0.482, 0.667, 0.864, 1.069, 1.283, 1.513, 1.744, 1.924),
        (0.411, 0.112, 0.188, 0.362, 0.561, 0.774, 0.994, 1.222, 1.463, 1.704, 1.890),
        (0.177, -0.056, 0.039, 0.230, 0.448, 0.679, 0.916, 1.161, 1.417, 1.668, 1.861),
        (-0.097, -0.259, -0.138, 0.076, 0.316, 0.569, 0.827, 1.090, 1.362, 1.622, 1.815),
        (-0.437, -0.524, -0.368, -0.125, 0.143, 0.420, 0.702, 0.985, 1.271, 1.532, 1.694),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
        (0.681, 0.592, 0.688, 0.833, 0.980, 1.124, 1.259, 1.386, 1.499, 1.573, 1.534),
        (0.629, 0.532, 0.628, 0.777, 0.931, 1.080, 1.220, 1.347, 1.456, 1.516, 1.450),
        (0.549, 0.461, 0.563, 0.720, 0.882, 1.039, 1.184, 1.313, 1.419, 1.468, 1.382),
        (0.441, 0.378, 0.492, 0.660, 0.833, 0.999, 1.151, 1.283, 1.387, 1.428, 1.339),
        (0.316, 0.284, 0.412, 0.594, 0.780, 0.957, 1.117, 1.253, 1.356, 1.394, 1.314),
        (0.180, 0.175, 0.321, 0.517, 0.716, 0.905, 1.074, 1.216, 1.321, 1.359, 1.292),
        (0.009, 0.031, 0.194, 0.409, 0.627, 0.833, 1.017, 1.172, 1.290, 1.342, 1.284),
        (-0.171, -0.136, 0.038, 0.267, 0.499, 0.722, 0.923, 1.093, 1.225, 1.288, 1.221),
        (-0.374, -0.343, -0.171, 0.060, 0.303, 0.541, 0.759, 0.947, 1.097, 1.173, 1.102),
        (0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000),
    ),
}


def uses_in_plane_line(kind: str, wo: np.ndarray) -> bool:
    """Whether an isotropic ``kind`` lobe seen from ``wo`` reads its own in-plane quantiles (off
    the normal, Beckmann), not the symmetric line and the lean (prefilter.py split_sum_line)."""
    return kind in IN_PLANE_KINDS and bool(np.hypot(wo[0], wo[1]) > MIN_OBLIQUE_XY)


def in_plane_angles(kind: str, alpha: float, cos_theta_o: float) -> np.ndarray:
    """The line's node angles theta_k (radians from the normal within the plane of incidence,
    positive towards the viewer) of an isotropic ``kind`` lobe: -theta_o + alpha t_k, t bilinear in
    IN_PLANE_OFFSETS, alpha and cos theta_o clamped to the grid as oblique_alpha_ratio's
    (shaders/prefiltered.glsl in_plane_angle)."""
    table = np.asarray(IN_PLANE_OFFSETS[kind]).reshape(len(OBLIQUE_ALPHAS), len(OBLIQUE_COSINES), -1)
    theta_o = float(np.arccos(np.clip(cos_theta_o, -1.0, 1.0)))
    return -theta_o + min(float(alpha), OBLIQUE_ALPHAS[-1]) * _grid_bilinear(table, alpha, cos_theta_o)
