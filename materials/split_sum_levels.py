"""The split-sum cube's roughness levels and the MIP level a lobe reads (numpy reference of
shaders/prefiltered.glsl split_sum_lod; materials/prefilter.py holds the kernels and the maps)."""

from __future__ import annotations

import numpy as np

SPLIT_SUM_LEVELS = 6  # MIP levels 0..5 of the prefiltered cube; level l has roughness l / 5


def split_sum_alpha(level: int, levels: int = SPLIT_SUM_LEVELS) -> float:
    """Roughness of a MIP level: perceptual roughness r = level / (levels - 1), alpha = r^2."""
    return (level / (levels - 1)) ** 2


PEAK_MATCHED_FROM = 2.0  # split_sum_lod matches the kernel's peak from this level on


def split_sum_lod(alpha, levels: int = SPLIT_SUM_LEVELS, kind: str = "beckmann"):
    """The MIP level of the split-sum cube a lobe of roughness ``alpha`` reads (shaders/
    prefiltered.glsl split_sum_lod). GGX: the table SPLIT_SUM_LOD_GGX (prefilter.py :func:`split_sum_lod_table`,
    the blend whose radial mass matches alpha's own kernel), linear in sqrt(alpha). Beckmann:
    between levels l0 >= PEAK_MATCHED_FROM and l0 + 1 the weight
    w of the upper level makes the blend's peak the peak of alpha's own kernel, which is
    proportional to 1 / alpha^2 for both distributions: w = (1/a0^2 - 1/alpha^2) / (1/a0^2 -
    1/a1^2). The plain level sqrt(alpha) (levels - 1) blended too much of the narrower level: a
    sun's highlight 1.11-1.09x too bright at alpha 0.5 / 0.3 against Mitsuba (1.08 / 1.04 now;
    sphere rel-RMSE 18.5 -> 17.5 %, 15.3 -> 14.7 %). Below level 2 the plain level: there the
    two levels' alphas differ 4x (0.04, 0.16) and matching the peak blurred GGX 0.05 from 7.5 to
    15.3 % rel-RMSE (and 0.15 from 11.9 to 12.7 %) against Mitsuba (issue 45)."""
    alpha = np.asarray(alpha, dtype=np.float64)
    top = levels - 1
    if kind == "ggx" and levels == SPLIT_SUM_LEVELS:
        table = np.asarray(SPLIT_SUM_LOD_GGX)
        roughness = np.sqrt(np.clip(alpha, 0.0, 1.0))
        return np.interp(roughness, np.linspace(0.0, 1.0, len(table)), table)
    lod = np.sqrt(alpha) * top
    lower = np.clip(np.floor(lod), PEAK_MATCHED_FROM, top - 1)
    inv_lower, inv_upper = (top / lower) ** 4, (top / (lower + 1.0)) ** 4
    inv = 1.0 / np.maximum(alpha, 1e-12) ** 2
    matched = lower + (inv_lower - inv) / (inv_lower - inv_upper)
    return np.where((lod <= PEAK_MATCHED_FROM) | (lod >= top), np.clip(lod, 0.0, top), matched)


# GGX's level blend (issue 45). Its kernel is the lobe itself (microfacet_kernel_values), whose
# tail the peak-matched blend of the Beckmann rule overweights: at GGX 0.3 (levels 0.16 / 0.36)
# the blend held 0.46 of the mass within the lobe's median angle, too wide (the rectangles'
# reflections on the Mitsuba sphere too dark: rel-RMSE against lobeview's reference 2.73 % with
# Karis' kernel, 2.91 with the lobe and the peak rule, 2.55 with this table; GGX 0.5 2.58 / 1.81 /
# 1.88). So the blend weight w of the two levels around alpha is the one whose
# radial mass (the share of the kernel within each angle) is closest to alpha's own, in the mean
# absolute difference over the angle (prefilter.py :func:`split_sum_lod_table`); over 60 pixels of the Mitsuba
# sphere (numpy, the levels' exact kernels) it took GGX 0.05 / 0.1 / 0.3 / 0.7 from 12.6 / 6.7 /
# 5.0 / 4.2 % (plain level) and 5.9 % (peak, 0.3) to 11.3 / 5.6 / 5.0 / 3.9 %. The same numbers in
# shaders/prefiltered.glsl.
SPLIT_SUM_LOD_NODES = 41  # sqrt(alpha) = k / 40: every level's roughness is a node
SPLIT_SUM_LOD_GGX = (  # split_sum_lod_table("ggx")
    0.0000,
    0.0000,
    0.0075,
    0.0425,
    0.1275,
    0.2850,
    0.5050,
    0.7575,
    1.0000,
    1.0775,
    1.1750,
    1.2925,
    1.4250,
    1.5700,
    1.7150,
    1.8625,
    2.0000,
    2.1300,
    2.2650,
    2.4000,
    2.5325,
    2.6600,
    2.7825,
    2.8950,
    3.0000,
    3.1650,
    3.3175,
    3.4600,
    3.5900,
    3.7100,
    3.8175,
    3.9150,
    4.0000,
    4.1850,
    4.3500,
    4.4975,
    4.6275,
    4.7425,
    4.8400,
    4.9275,
    5.0000,
)
