"""The table behind Beckmann's in-plane quantile line (materials/split_sum_oblique.py
IN_PLANE_OFFSETS; the comment there says what and why): the lobe's f cos quantiles of the angle
within the plane of incidence, shrunk by the split-sum kernel's own (prefilter.py), computed by
quadrature. ``python -m lobeview.materials.split_sum_in_plane`` prints the table as it is stored."""

from __future__ import annotations

import numpy as np

from .microfacet import MicrofacetDistribution
from .prefilter import split_sum_profile
from .split_sum_anisotropic import LINE_QUANTILES, SPLIT_SUM_LINE_EDGES
from .split_sum_oblique import OBLIQUE_ALPHAS, OBLIQUE_COSINES, _hemisphere, oblique_alpha_ratio

IN_PLANE_LOBE_POINTS = 200_000
IN_PLANE_KERNEL_POINTS = 400_000


def _sphere(points: int) -> np.ndarray:
    """A Fibonacci lattice of the whole sphere, equal solid angle per point."""
    k = np.arange(points) + 0.5
    z = 1.0 - 2.0 * k / points
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def weighted_quantiles(values: np.ndarray, weights: np.ndarray, q) -> np.ndarray:
    """Quantiles ``q`` of ``values`` under ``weights`` (zero weights left out)."""
    keep = weights > 0.0
    order = np.argsort(values[keep])
    cumulative = np.cumsum(weights[keep][order])
    return np.interp(q, cumulative / cumulative[-1], values[keep][order])


def kernel_line_quantiles(kind: str, alpha: float, points: int = IN_PLANE_KERNEL_POINTS) -> np.ndarray:
    """The split-sum kernel's own offsets at the line's quantiles: the angle out of a great circle
    through its centre, weighted by prefilter.py's kernel at ``alpha``."""
    directions = _sphere(points)
    weights = split_sum_profile(kind, alpha).of_cosine(directions[:, 2])
    return weighted_quantiles(np.arcsin(np.clip(directions[:, 1], -1.0, 1.0)), weights, LINE_QUANTILES)


def in_plane_node_angles(kind: str, alpha: float, cos_theta_o: float, points: int = IN_PLANE_LOBE_POINTS,
                         kernel_points: int = IN_PLANE_KERNEL_POINTS) -> np.ndarray:  # fmt: skip
    """The line's node angles theta_k from the normal within the plane of incidence (positive
    towards wo = (sin theta_o, 0, cos theta_o)) of an isotropic lobe: the lobe's f cos quantiles
    shrunk by the level kernel's (alpha rho) own, as split_sum_oblique.py's comment says. At
    normal incidence all of them at the normal: the lobe is round there and a line would pick a
    direction (the plane of incidence turns round the centre of a sphere: a pinwheel at Beckmann
    0.8), so the line closes towards cos theta_o = 1 as the symmetric line's does."""
    if cos_theta_o >= 1.0:
        return np.zeros(len(SPLIT_SUM_LINE_EDGES) - 1)
    from .conductor import MicrofacetReflection
    from .fresnel import Fresnel

    wi = _hemisphere(points)
    lobe = MicrofacetReflection(MicrofacetDistribution(kind, alpha, alpha), Fresnel("none"))
    wo = np.array([np.sqrt(max(1.0 - cos_theta_o**2, 0.0)), 0.0, cos_theta_o])
    weight = lobe.eval(wi, np.broadcast_to(wo, wi.shape))[:, 0] * wi[:, 2]
    quantiles = np.concatenate([LINE_QUANTILES, [0.5]])
    angles = weighted_quantiles(np.arctan2(wi[:, 0], wi[:, 2]), weight, quantiles)
    nodes, median = angles[:-1], angles[-1]
    level_alpha = alpha * oblique_alpha_ratio(kind, alpha, cos_theta_o)
    kernel = kernel_line_quantiles(kind, level_alpha, kernel_points)
    offsets = nodes - median
    return median + np.sign(offsets) * np.sqrt(np.maximum(offsets**2 - kernel**2, 0.0))


def in_plane_offset_table(kind: str = "beckmann", points: int = IN_PLANE_LOBE_POINTS,
                          kernel_points: int = IN_PLANE_KERNEL_POINTS, alphas=OBLIQUE_ALPHAS,
                          cosines=OBLIQUE_COSINES) -> np.ndarray:  # fmt: skip
    """t_k = (theta_k + theta_o) / alpha for every (alpha, cos theta_o): (alphas, cosines, nodes)."""
    table = []
    for alpha in alphas:
        row = []
        for cosine in cosines:
            theta_o = float(np.arccos(np.clip(cosine, -1.0, 1.0)))
            row.append((in_plane_node_angles(kind, alpha, cosine, points, kernel_points) + theta_o) / alpha)
        table.append(row)
    return np.asarray(table)


def main() -> None:
    table = in_plane_offset_table()
    for kind in ("beckmann",):
        print(f'    "{kind}": (')
        for row in table.reshape(-1, table.shape[-1]):
            print("        (" + ", ".join(f"{x:.3f}" for x in row) + "),")
        print("    ),")


if __name__ == "__main__":
    main()
