"""Every sampler against its own pdf (chi-square), pdf mass against the sampled mass, and the
sample weight against eval * |cos| / pdf."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lobeview.bench.chi2 import SphereDomain, bsdf_chi2_test, chi2_test
from lobeview.materials.bsdf import BSDF
from lobeview.materials.conductor import MicrofacetReflection
from lobeview.materials.fresnel import Fresnel
from lobeview.materials.gltf import gltf_bsdf
from lobeview.materials.microfacet import MicrofacetDistribution
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.materials.thesis import KurtLobe, thesis_bsdf
from lobeview.materials.vec import direction_from_angles_deg, mirror_z, reflect

N_SAMPLES = 400_000


def _rational_gold() -> BSDF:
    path = Path(__file__).parent / "data" / "gold-ggx-rational.json"
    return build_bsdf(load_material(str(path)))


def _single(component) -> BSDF:
    return BSDF([component], name=component.name)


# (id, bsdf factory, viewer theta deg, viewer phi deg, lobe-centred cap angle or None)
CASES = [
    ("kurt-iso-rough", lambda: _single(KurtLobe(1.0, 0.3, 0.3, 0.5, 0.3)), 0, 0, None),
    ("kurt-iso-rough-oblique", lambda: _single(KurtLobe(1.0, 0.3, 0.3, 0.5, 0.3)), 60, 30, None),
    ("kurt-aniso-alanod", lambda: _single(KurtLobe(0.9, 0.11, 0.072, 0.89, 0.43)), 40, 70, 0.6),
    (
        "kurt-near-mirror-miro",
        lambda: _single(KurtLobe(0.98, 0.0068, 0.0297, 0.84, 0.49)),
        35,
        10,
        0.12,
    ),
    ("kurt-aniso-ratio-25", lambda: _single(KurtLobe(1.0, 0.02, 0.5, 0.9, 0.0)), 20, 45, None),
    ("kurt-grazing", lambda: _single(KurtLobe(1.0, 0.2, 0.2, 0.9, 0.5)), 80, 0, None),
    (
        "kurt-transmission",
        lambda: _single(KurtLobe(0.67, 0.25, 0.17, 0.75, 0.6, transmission=True)),
        30,
        0,
        None,
    ),
    (
        "kurt-transmission-sharp",
        lambda: _single(KurtLobe(1.0, 0.01, 0.02, 0.08, 0.0, transmission=True)),
        50,
        60,
        0.15,
    ),
    (
        "thesis-mixture-foil",
        lambda: thesis_bsdf(0.76, [(0.78, 0.124, 0.136, 0.029, 0.5)], [(0.67, 0.25, 0.17, 0.75, 0.6)]),
        45,
        0,
        None,
    ),
    (
        "thesis-mixture-alanod2",
        lambda: thesis_bsdf(0.003, [(0.9, 0.11, 0.07, 0.87, 0.45), (0.12, 0.25, 0.17, 0.89, 0.6)]),
        25,
        0,
        None,
    ),
    (
        "ggx-vndf-iso",
        lambda: _single(MicrofacetReflection(MicrofacetDistribution("ggx", 0.5, 0.5), Fresnel("none"))),
        30,
        0,
        None,
    ),
    (
        "ggx-vndf-aniso",
        lambda: _single(MicrofacetReflection(MicrofacetDistribution("ggx", 0.1, 0.6), Fresnel("schlick", r0=0.5))),
        70,
        40,
        None,
    ),
    (
        "ggx-vndf-near-mirror",
        lambda: _single(MicrofacetReflection(MicrofacetDistribution("ggx", 0.01, 0.01), Fresnel("none"))),
        45,
        0,
        0.2,
    ),
    (
        "ggx-vndf-grazing",
        lambda: _single(MicrofacetReflection(MicrofacetDistribution("ggx", 0.3, 0.3), Fresnel("none"))),
        85,
        0,
        None,
    ),
    (
        "beckmann-aniso",
        lambda: _single(MicrofacetReflection(MicrofacetDistribution("beckmann", 0.05, 0.3), Fresnel("none"))),
        40,
        20,
        None,
    ),
    ("gltf-dielectric", lambda: gltf_bsdf([0.6, 0.05, 0.04], 0.0, 0.4), 50, 0, None),
    ("gltf-metal-smooth", lambda: gltf_bsdf([0.9, 0.8, 0.5], 1.0, 0.2), 30, 0, 0.5),
    ("gltf-anisotropic", lambda: gltf_bsdf([0.9, 0.8, 0.5], 1.0, 0.3, 0.8), 40, 30, None),
    (
        "gltf-thin-transmission",
        lambda: BSDF([gltf_bsdf([0.8, 0.9, 0.7], 0.0, 0.4, transmission=1.0, ior=1.5).components[2]]),
        40,
        0,
        None,
    ),
    (
        "gltf-clearcoat",
        lambda: BSDF([gltf_bsdf([0.5] * 3, 0.0, 0.5, clearcoat=1.0, clearcoat_roughness=0.2).components[2]]),
        30,
        0,
        None,
    ),  # fmt: skip
    # The Rational BRDF's inverse-CDF sampler (seed 002, Eq. 7-9), fitted to GGX gold.
    ("rational-gold", lambda: _rational_gold(), 35, 20, None),
    ("rational-gold-grazing", lambda: _rational_gold(), 70, 20, None),
]


def _lobe_centre(bsdf: BSDF, wo: np.ndarray) -> np.ndarray:
    centre = reflect(wo, np.array([0.0, 0.0, 1.0]))
    if all(c.hemisphere == "transmission" for c in bsdf.components):
        centre = mirror_z(centre)
    return centre


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_sampler_matches_pdf_chi_square(case, tmp_path):
    name, factory, theta, phi, cap = case
    bsdf = factory()
    wo = direction_from_angles_deg(theta, phi)
    if cap is None:
        domain = SphereDomain()
    else:
        domain = SphereDomain(res_a=25, res_b=41, centre=_lobe_centre(bsdf, wo), cap_angle=cap)
    result = bsdf_chi2_test(bsdf, wo, N_SAMPLES, domain, tmp_path, name, seed=12345)
    assert result.passed, result.message
    if cap is None:
        # The pdf integrates to the fraction of samples that did not fail (1 - lost mass).
        assert result.mass_pdf == pytest.approx(result.mass_observed, abs=0.004), result.message
    else:
        assert result.mass_pdf == pytest.approx(result.mass_observed, abs=0.01), result.message


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_sample_weight_is_eval_cos_over_pdf(case):
    _, factory, theta, phi, _ = case
    bsdf = factory()
    wo = direction_from_angles_deg(theta, phi)
    rng = np.random.default_rng(7)
    u = rng.random((2, 20_000))
    s = bsdf.sample(u[0], u[1], wo)
    ok = s.pdf > 0
    assert ok.mean() > 0.3
    wo_b = np.broadcast_to(wo, s.wi.shape)
    np.testing.assert_allclose(s.pdf[ok], bsdf.pdf(s.wi[ok], wo_b[ok]), rtol=1e-10)
    expected = bsdf.eval(s.wi[ok], wo_b[ok]) * np.abs(s.wi[ok, 2:3]) / s.pdf[ok, None]
    np.testing.assert_allclose(s.weight[ok], expected, rtol=1e-10, atol=1e-14)
    assert np.all(s.weight[~ok] == 0.0)
    assert np.all(np.isfinite(s.wi)) and np.all(np.isfinite(s.weight))


def test_thesis_pdf_integrates_to_one_at_normal_incidence_for_moderate_lobe():
    """With wo = n and a moderate lobe almost no sample is lost below the horizon, so the
    Eq. 4.9 pdf must integrate to ~1 over the sphere (independent midpoint quadrature)."""
    lobe = KurtLobe(1.0, 0.2, 0.1, 0.5, 0.0)
    wo = np.array([0.0, 0.0, 1.0])
    n_t, n_p = 2000, 256
    theta = (np.arange(n_t) + 0.5) * (np.pi / 2) / n_t
    phi = (np.arange(n_p) + 0.5) * 2 * np.pi / n_p
    T, P = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    pdf = lobe.pdf(dirs, np.broadcast_to(wo, dirs.shape))
    total = np.sum(pdf * np.sin(T)) * (np.pi / 2 / n_t) * (2 * np.pi / n_p)
    # Mass below the horizon: h beyond 45 deg, P = exp(-tan^2(45)/m^2) <= exp(-1/0.2^2) ~ 1e-11.
    assert total == pytest.approx(1.0, abs=2e-3)


def test_chi_square_rejects_a_pdf_missing_the_reflection_jacobian(tmp_path):
    """The test must be able to fail: the half-vector density D cos(theta_h) without the
    1 / (4 wo.h) Jacobian of Eq. 4.9 is rejected (rescaled so only the shape is wrong)."""
    lobe = KurtLobe(1.0, 0.3, 0.3, 0.5, 0.0)
    wo = direction_from_angles_deg(50, 0)
    rng = np.random.default_rng(3)

    def sample_fn(n):
        u = rng.random((2, n))
        s = _single(lobe).sample(u[0], u[1], wo)
        return s.wi, s.pdf > 0

    def wrong_pdf(dirs):
        wo_b = np.broadcast_to(wo, dirs.shape)
        h = dirs + wo_b
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        return np.where(dirs[..., 2] > 0, lobe.distribution.pdf_half_vector(h) / 4.0, 0.0)

    result = chi2_test(sample_fn, wrong_pdf, 100_000, SphereDomain(), tmp_path, "wrong-jacobian")
    assert not result.passed, result.message
