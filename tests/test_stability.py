"""Numerical stability sweep of the numpy references: extreme roughness, anisotropy, alpha,
grazing and below-horizon directions. Nothing may be NaN, Inf or negative."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lobeview.materials.conductor import microfacet_bsdf
from lobeview.materials.fresnel import Fresnel
from lobeview.materials.gltf import gltf_bsdf
from lobeview.materials.patterns import integrate_specular, lobe_samples, specular_lobes
from lobeview.materials.thesis import thesis_bsdf
from lobeview.materials.vec import direction_from_angles_deg

ROUGHNESS = [1e-4, 1e-3, 0.01, 0.1, 0.5, 1.0]
ANISOTROPY = [1.0, 10.0, 1000.0]
ALPHAS = [0.0, 0.5, 1.0]
THETAS = [0.0, 45.0, 80.0, 89.0, 89.9, 89.99, 90.0, 95.0, 135.0, 180.0]


def _directions():
    dirs = [direction_from_angles_deg(t, p) for t in THETAS for p in (0.0, 33.0, 90.0)]
    return np.array(dirs)


def _models():
    for m, ratio, alpha in itertools.product(ROUGHNESS, ANISOTROPY, ALPHAS):
        my = m
        mx = max(m / ratio, 1e-4)
        yield (
            f"thesis m={m} ratio={ratio} a={alpha}",
            thesis_bsdf(0.1, [(1.0, mx, my, 0.5, alpha)], [(1.0, my, mx, 0.04, alpha)]),
        )
    for kind, m, ratio in itertools.product(("ggx", "beckmann"), ROUGHNESS, ANISOTROPY):
        fresnel = Fresnel("conductor", eta=[0.2, 0.4, 1.5], k=[3.1, 2.7, 1.9])
        yield f"{kind} m={m} ratio={ratio}", microfacet_bsdf(kind, max(m / ratio, 1e-4), m, fresnel)
    for rough, metal in itertools.product((0.0, 0.01, 0.5, 1.0), (0.0, 1.0)):
        yield f"gltf r={rough} metal={metal}", gltf_bsdf([0.9, 0.5, 0.1], metal, rough)


MODELS = list(_models())


def _clean(x):
    return np.all(np.isfinite(x)) and np.all(x >= 0.0)


@pytest.mark.parametrize("name,bsdf", MODELS, ids=[m[0] for m in MODELS])
def test_eval_pdf_sample_are_finite_and_non_negative(name, bsdf):
    dirs = _directions()
    wi = np.repeat(dirs, len(dirs), axis=0)
    wo = np.tile(dirs, (len(dirs), 1))
    with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
        f = bsdf.eval(wi, wo)
        p = bsdf.pdf(wi, wo)
    assert _clean(f) and _clean(p), name
    rng = np.random.default_rng(0)
    u = rng.random((2, len(wo)))
    # Include the exact corners of the unit square.
    u[:, :4] = [[0.0, 0.0, 1 - 1e-16, 1 - 1e-16], [0.0, 1 - 1e-16, 0.0, 1 - 1e-16]]
    with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
        s = bsdf.sample(u[0], u[1], wo)
    assert np.all(np.isfinite(s.wi)) and _clean(s.weight) and _clean(s.pdf), name
    # Viewer below the horizon: nothing is reflected.
    below = wo[:, 2] <= 0
    assert np.all(f[below] == 0) and np.all(s.weight[below] == 0)


@pytest.mark.parametrize("name,bsdf", MODELS[::3], ids=[m[0] for m in MODELS[::3]])
def test_albedo_and_patterns_are_finite(name, bsdf):
    for theta in (0.0, 60.0, 89.99):
        wo = direction_from_angles_deg(theta, 20.0)
        with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
            r, t = bsdf.albedo(wo, order=48)
            spec = integrate_specular(bsdf, wo, lambda d, lod: np.full((len(d), 3), 1e6), 7)
        assert _clean(r) and _clean(t) and _clean(spec), name
        for lobe in specular_lobes(bsdf):
            s = lobe_samples(lobe, wo, 11)
            assert np.all(np.isfinite(s.lod)) and np.all(np.isfinite(s.wi))


def test_near_mirror_pattern_converges_to_the_mirror_direction():
    """As roughness -> 0, lobe-N of a radiance function approaches the value in the mirror
    direction (thesis: the deterministic patterns degrade gracefully to a mirror lookup)."""
    wo = direction_from_angles_deg(40.0, 15.0)
    mirror = np.array([-wo[0], -wo[1], wo[2]])

    def radiance(dirs, lod):
        return np.stack([2 + dirs[:, 0], 1 + dirs[:, 1] ** 2, np.exp(dirs[:, 2])], -1)

    errors = []
    for m in (0.1, 0.01, 1e-3, 1e-4):
        bsdf = thesis_bsdf(0.0, [(1.0, m, m, 1.0, 0.0)])
        value = integrate_specular(bsdf, wo, radiance, 9)
        # With r0 = 1 and alpha = 0 the lobe albedo tends to cos(theta_o): divide it out.
        ratio = value / wo[2]
        errors.append(np.max(np.abs(ratio - radiance(mirror[None], None)[0])))
    assert errors[-1] < 1e-4
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False))
