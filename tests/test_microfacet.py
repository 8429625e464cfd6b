"""Microfacet distributions and Fresnel terms against closed forms and independent quadrature."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from lobeview.materials.fresnel import Fresnel, conductor, conductor_f0, schlick
from lobeview.materials.microfacet import MicrofacetDistribution
from lobeview.materials.vec import direction_from_angles_deg


def _hemisphere_grid(n_theta: int, n_phi: int, theta_max: float = np.pi / 2):
    """Midpoint grid in (theta, phi) with solid-angle weights, refined towards the pole by
    using u = theta^2 so narrow lobes around +z are resolved."""
    u = (np.arange(n_theta) + 0.5) / n_theta
    theta = theta_max * u**2
    dtheta = theta_max * 2 * u / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    w = (np.sin(theta) * dtheta)[:, None] * (2 * np.pi / n_phi)
    dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    return dirs, np.broadcast_to(w, T.shape)


DISTRIBUTIONS = [
    ("beckmann", 0.3, 0.3),
    ("beckmann", 0.05, 0.4),
    ("beckmann", 0.01, 0.01),
    ("ggx", 0.5, 0.5),
    ("ggx", 0.1, 0.7),
    ("ggx", 0.02, 0.02),
    ("ggx", 1.0, 1.0),
]


@pytest.mark.parametrize("kind,ax,ay", DISTRIBUTIONS)
def test_projected_microfacet_area_is_one(kind, ax, ay):
    """Normalisation: integral of D(wm) cos(theta_m) d wm = 1 (thesis Eq. 3.3 is normalised)."""
    dist = MicrofacetDistribution(kind, ax, ay)
    dirs, w = _hemisphere_grid(4000, 512)
    total = np.sum(dist.D(dirs) * dirs[..., 2] * w)
    # GGX tails decay like theta^-4: the grid captures them to ~1e-3.
    assert total == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("kind,ax,ay", DISTRIBUTIONS)
@pytest.mark.parametrize("theta_o", [0.0, 45.0, 80.0])
def test_smith_lambda_satisfies_visible_area_identity(kind, ax, ay, theta_o):
    """Independent check of Lambda: integral of G1(wo) max(0, wo.wm) D(wm) d wm = cos(theta_o)
    (the projected area of the visible microsurface equals that of the macrosurface)."""
    dist = MicrofacetDistribution(kind, ax, ay)
    wo = direction_from_angles_deg(theta_o, 30.0)
    dirs, w = _hemisphere_grid(4000, 720)
    projected = np.sum(np.maximum(np.sum(dirs * wo, -1), 0.0) * dist.D(dirs) * w)
    lhs = dist.G1(wo[None])[0] * projected
    assert lhs == pytest.approx(wo[2], rel=3e-3, abs=1e-4)


def test_beckmann_lambda_matches_numerical_integral_of_slopes():
    """Lambda for Beckmann from its definition: integral over slopes (Heitz 2014, Eq. 72)."""
    alpha = 0.35
    dist = MicrofacetDistribution("beckmann", alpha, alpha)

    def slope_pdf(q):  # 1D marginal of the Beckmann slope distribution
        return np.exp(-(q**2) / alpha**2) / (np.sqrt(np.pi) * alpha)

    for theta in (20.0, 60.0, 85.0):
        mu = 1.0 / np.tan(np.radians(theta))
        # Lambda = 1/mu * integral_{mu}^{inf} (q - mu) P2(q) dq.
        value, _ = integrate.quad(lambda q, mu=mu: (q - mu) * slope_pdf(q), mu, np.inf)
        reference = value / mu
        w = direction_from_angles_deg(theta, 0.0)
        assert dist.lambda_(w[None])[0] == pytest.approx(reference, rel=1e-6)


def test_ggx_matches_gltf_closed_form_isotropic():
    alpha = 0.3
    dist = MicrofacetDistribution("ggx", alpha, alpha)
    theta = np.radians(np.linspace(0, 89, 50))
    wm = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], -1)
    n_dot_h = np.cos(theta)
    closed = alpha**2 / (np.pi * (n_dot_h**2 * (alpha**2 - 1) + 1) ** 2)
    np.testing.assert_allclose(dist.D(wm), closed, rtol=1e-12)


def test_schlick_endpoints_and_conductor_closed_forms():
    r0 = np.array([0.04, 0.5, 0.9])
    np.testing.assert_allclose(schlick(np.array(1.0), r0), r0)
    np.testing.assert_allclose(schlick(np.array(0.0), r0), 1.0)
    eta = np.array([0.1678, 0.3504, 1.5085])
    k = np.array([3.1378, 2.7141, 1.8788])
    np.testing.assert_allclose(conductor(np.array(1.0), eta, k), conductor_f0(eta, k), rtol=1e-12)
    np.testing.assert_allclose(conductor(np.array(0.0), eta, k), 1.0, atol=1e-12)
    # k = 0 reduces to the dielectric Fresnel equations (independent formula).
    n = 1.5
    for theta in (0.0, 30.0, 60.0, 85.0):
        c = np.cos(np.radians(theta))
        s = np.sqrt(1 - c * c)
        ct = np.sqrt(1 - (s / n) ** 2)
        rs = ((c - n * ct) / (c + n * ct)) ** 2
        rp = ((n * c - ct) / (n * c + ct)) ** 2
        got = conductor(np.array(c), np.full(3, n), np.zeros(3))
        np.testing.assert_allclose(got, 0.5 * (rs + rp), rtol=1e-10)


def test_fresnel_kinds_and_errors():
    assert np.all(Fresnel("none")(np.array([0.3, 0.9])) == 1.0)
    assert Fresnel("schlick", r0=0.04)(np.array(1.0)) == pytest.approx(np.full(3, 0.04))
    with pytest.raises(ValueError, match="unknown Fresnel"):
        Fresnel("fancy")
    with pytest.raises(ValueError, match="alpha_x"):
        MicrofacetDistribution("ggx", 0.0, 0.5)
    with pytest.raises(ValueError, match="unknown microfacet"):
        MicrofacetDistribution("phong", 0.5, 0.5)
