"""An anisotropic lobe's split-sum line at its own f cos quantiles (materials/split_sum_anisotropic.py,
issue 45): the nodes against the quantiles by quadrature, and the lookups against the exact lobe
integral of the sky (bench/split_sum_line.py's numpy twin)."""

import numpy as np
import pytest

from lobeview.materials.conductor import MicrofacetReflection
from lobeview.materials.fresnel import Fresnel
from lobeview.materials.microfacet import MicrofacetDistribution
from lobeview.materials.split_sum_anisotropic import (
    LINE_QUANTILES,
    anisotropic_line_slopes,
)
from lobeview.materials.split_sum_in_plane import _sphere, weighted_quantiles


def _quadrature_slopes(kind, alpha_x, alpha_y, wo, points=600_000):
    """The lobe's f cos quantiles of the half-vector slope along its wider axis, by a Fibonacci
    quadrature of the hemisphere, shrunk about the median as anisotropic_line_slopes shrinks."""
    wi = _sphere(points)
    wi = wi[wi[:, 2] > 0.0]
    lobe = MicrofacetReflection(MicrofacetDistribution(kind, alpha_x, alpha_y), Fresnel("none"))
    weight = lobe.eval(wi, np.broadcast_to(wo, wi.shape))[:, 0] * wi[:, 2]
    major = np.array([1.0, 0.0]) if alpha_x >= alpha_y else np.array([0.0, 1.0])
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    slope = -(h[:, :2] @ major) / h[:, 2]
    quantiles = weighted_quantiles(slope, weight, np.concatenate([LINE_QUANTILES, [0.5]]))
    a_min, a_max = min(alpha_x, alpha_y), max(alpha_x, alpha_y)
    return quantiles[-1] + (quantiles[:-1] - quantiles[-1]) * np.sqrt(1.0 - (a_min / a_max) ** 2)


def _view(theta_degrees, phi_degrees):
    theta, phi = np.radians(theta_degrees), np.radians(phi_degrees)
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


@pytest.mark.parametrize(
    "kind,alpha_x,alpha_y,inner,outer",
    [("beckmann", 0.05, 0.3, 0.03, 0.06), ("beckmann", 0.4, 0.15, 0.03, 0.12), ("ggx", 0.05, 0.3, 0.5, None),
     ("ggx", 0.3, 0.1, 0.3, None)],
)  # fmt: skip
def test_nodes_at_the_lobes_own_quantiles(kind, alpha_x, alpha_y, inner, outer):
    """Eleven reweighted intervals of the slope marginal against the quantiles of the lobe's f cos
    by quadrature (an independent computation: no marginal, no G2 formula of its own), at views
    up to 70 degrees from the normal across and along the wider axis, in units of alpha_max.
    Measured (36th session): Beckmann's nodes within 0.03 / 0.11 (inner nine / outer two); GGX's
    inner nine within 0.49, its median within 0.03, its outer two (at 1/72 and 71/72 of a heavy
    tail) up to 1.7 off: one interval's reweighting is coarse where the horizon cuts it; the
    radiance they read is what test_line_is_closer_to_the_lobe_on_the_sky measures. At normal
    incidence the nodes are symmetric, but not the marginal's: G2 still thins the tails (GGX 0.05
    x 0.3's outer node at -0.68 against the marginal's -1.23 x alpha_max)."""
    a_max = max(alpha_x, alpha_y)
    slopes, _ = anisotropic_line_slopes(np.array([0.0, 0.0, 1.0]), kind, alpha_x, alpha_y)
    np.testing.assert_allclose(slopes, -slopes[::-1], atol=1e-9)
    for theta, phi in [(0, 0), (40, 0), (40, 90), (70, 30), (70, 90)]:
        wo = _view(theta, phi)
        slopes, _ = anisotropic_line_slopes(wo, kind, alpha_x, alpha_y)
        difference = (slopes - _quadrature_slopes(kind, alpha_x, alpha_y, wo)) / a_max
        assert np.all(np.diff(slopes) > 0.0), slopes
        assert np.abs(difference[1:-1]).max() < inner, (theta, phi, difference)
        assert abs(difference[5]) < 0.04, (theta, phi, difference)
        if outer is not None:
            assert np.abs(difference).max() < outer, (theta, phi, difference)


def test_grazing_views_keep_their_nodes_finite():
    """A view at the horizon along and across the wider axis (every node's g small or zero), and
    one whose every marginal node reflects below the surface: finite, ordered slopes."""
    for wo in (_view(89.9, 90.0), _view(89.9, 0.0), np.array([0.0, 1.0, 1e-7]) / np.hypot(1.0, 1e-7)):
        for kind in ("ggx", "beckmann"):
            slopes, _ = anisotropic_line_slopes(wo, kind, 0.02, 0.8)
            assert np.isfinite(slopes).all() and np.all(np.diff(slopes) >= 0.0), (wo, kind, slopes)


@pytest.mark.parametrize("case,limit", [("ggx:0.05x0.3", 0.04), ("beckmann:0.05x0.3", 0.025)])
def test_line_is_closer_to_the_lobe_on_the_sky(case, limit):
    """Issue 45: split-sum's lookups of anisotropic lobes against the exact lobe integral of issue
    45's sunless sky (bench/split_sum_line.py's numpy twin, 12 x 12 sphere pixels and the sun's 9 x 9
    window of the 192-pixel frame): the line at the lobe's own quantiles within ``limit`` relative
    RMSE and below the symmetric line's (12 x 12: GGX 4.6 -> 3.6 %, Beckmann 5.1 -> 1.9), and the
    sun window within 2 % (the symmetric line, leant: GGX 0.971, Mitsuba's window 0.975 with it)."""
    from lobeview.bench import split_sum_line as bench

    twin = bench.SplitSumTwin(*bench.light_texels("sky", 256))
    errors = bench.case_errors(twin, case, pixels=12, window=True)
    symmetric, own = errors[bench.WAYS[0]], errors[bench.WAYS[1]]
    assert own[0] < min(limit, symmetric[0]), errors
    assert abs(own[2] - 1.0) < 0.02, errors
