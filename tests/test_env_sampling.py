"""Environment importance sampling (numpy reference) and the cube-map layout."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import sphere_integral

from lobeview.core.cube_layout import direction_to_face, face_directions, texel_solid_angles
from lobeview.scenes.builtin_env import sky, studio
from lobeview.scenes.env_sampling import CubeImportance
from lobeview.scenes.envmap import EnvironmentMap, direction_to_equirect, equirect_direction
from lobeview.viewer.cubemap import equirect_to_cube_faces


def test_face_layout_round_trips():
    for face in range(6):
        d = face_directions(face, 8)
        f, sc, tc = direction_to_face(d)
        assert np.all(f == face)
        centres = (np.arange(8) + 0.5) / 8 * 2 - 1
        np.testing.assert_allclose(sc, np.broadcast_to(centres[None, :], (8, 8)), atol=1e-12)
        np.testing.assert_allclose(tc, np.broadcast_to(centres[:, None], (8, 8)), atol=1e-12)


def test_texel_solid_angles_cover_the_sphere():
    for size in (1, 4, 64):
        assert 6 * texel_solid_angles(size).sum() == pytest.approx(4 * np.pi, rel=1e-12)


def test_equirect_orientation_convention():
    # Image centre faces -Z, u = 0.75 faces +X, the top row is +Y.
    np.testing.assert_allclose(equirect_direction(0.5, 0.5), [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(equirect_direction(0.75, 0.5), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(equirect_direction(0.25, 0.5), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(equirect_direction(0.3, 0.0), [0, 1, 0], atol=1e-12)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    u, v = direction_to_equirect(d)
    np.testing.assert_allclose(equirect_direction(u, v), d, atol=1e-12)


@pytest.mark.parametrize("env_fn", [studio, sky], ids=["studio", "sky-with-sun"])
def test_environment_sampler_matches_its_texel_probabilities(env_fn):
    """Chi-square in the sampler's own domain: bins aligned with the importance texels, each
    split 2x2, so the expected counts (P_t / 4, the pdf being uniform in (sc, tc) inside a
    texel) are exact; a histogram over (theta, phi) would cut the piecewise-constant pdf."""
    from scipy import stats

    faces = equirect_to_cube_faces(EnvironmentMap.from_function(env_fn, height=128), 64)
    importance = CubeImportance.from_faces(faces, size=16)
    n = 400_000
    rng = np.random.default_rng(5)
    d = importance.sample(*rng.random((2, n)))
    face, sc, tc = direction_to_face(d)
    sub = 2 * importance.size
    col = np.clip(((sc + 1) / 2 * sub).astype(int), 0, sub - 1)
    row = np.clip(((tc + 1) / 2 * sub).astype(int), 0, sub - 1)
    observed = np.bincount((face * sub + row) * sub + col, minlength=6 * sub * sub).astype(float)
    expected = np.repeat(np.repeat(importance.probabilities, 2, axis=1), 2, axis=2).ravel() / 4 * n
    keep = expected >= 5
    pooled_o = np.append(observed[keep], observed[~keep].sum())
    pooled_e = np.append(expected[keep], expected[~keep].sum())
    stat = np.sum((pooled_o - pooled_e) ** 2 / np.maximum(pooled_e, 1e-12))
    p_value = stats.chi2.sf(stat, len(pooled_e) - 1)
    assert p_value > 1e-4, f"chi2 {stat:.1f} dof {len(pooled_e) - 1} p {p_value:.3g}"


@pytest.mark.parametrize("env_fn", [studio, sky], ids=["studio", "sky-with-sun"])
def test_environment_pdf_is_a_density_consistent_with_the_sampler(env_fn):
    faces = equirect_to_cube_faces(EnvironmentMap.from_function(env_fn, height=128), 64)
    importance = CubeImportance.from_faces(faces, size=16)
    # Integral over the sphere by midpoint quadrature in (sc, tc)
    assert sphere_integral(importance.pdf, 256) == pytest.approx(1.0, rel=1e-9)
    # The density at sampled points is that of the texel they came from.
    rng = np.random.default_rng(2)
    u = rng.random((2, 5000))
    d = importance.sample(u[0], u[1])
    index = np.minimum(np.searchsorted(importance.cdf, u[0], side="right"), importance.cdf.size - 1)
    expected = importance.pdf_scale().ravel()[index] / np.max(np.abs(d), axis=1) ** 3
    np.testing.assert_allclose(importance.pdf(d), expected, rtol=1e-9)


def test_environment_sampler_concentrates_on_the_sun():
    faces = equirect_to_cube_faces(EnvironmentMap.from_function(sky, height=256), 128)
    importance = CubeImportance.from_faces(faces, size=64)
    sun = np.array([0.4, 0.55, -0.73])
    sun /= np.linalg.norm(sun)
    rng = np.random.default_rng(1)
    d = importance.sample(*rng.random((2, 20_000)))
    near_sun = np.mean(d @ sun > np.cos(np.radians(3)))
    # The sun (2e4 x 1.1e-4 sr) carries about half of the sky's power; a uniform sampler would
    # hit a 3 deg cap 0.07 % of the time.
    assert near_sun > 0.3
    # Estimating the total power: a tenth of the relative spread of uniform sphere sampling
    # (what remains comes from sun texels only partly covered by the 0.6 deg disc).
    env = EnvironmentMap.from_function(sky, height=256)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    weights = (env.lookup(d) @ luminance) / importance.pdf(d)
    # Exact moments of the map by texel quadrature: the integral, and the relative standard
    # deviation of uniform sphere sampling, sqrt(4 pi int L^2 / (int L)^2 - 1).
    lum = env.image @ luminance
    omega = env.texel_solid_angles()[:, None]
    integral = float(np.sum(lum * omega))
    uniform_cv = np.sqrt(4 * np.pi * np.sum(lum**2 * omega) / integral**2 - 1)
    assert weights.mean() == pytest.approx(integral, rel=0.03)
    assert weights.std() / weights.mean() < 0.1 * uniform_cv


def test_equirect_importance_density_is_normalised_and_unbiased():
    """EquirectImportance: the density integrates to 1 over the sphere (texel quadrature at the
    map's resolution), and L / pdf of its samples averages to the integral of L, with a bounded
    ratio under a 0.6-degree sun of radiance 2e4 (nearest-texel lookups, as the baker reads)."""
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.env_sampling import EquirectImportance

    env = load_environment("builtin:sky")
    importance = EquirectImportance.from_environment(env)
    dirs, weighted = env._texel_quadrature(512)
    omega = np.repeat(env.texel_solid_angles(), env.width)
    assert float((importance.pdf(dirs) * omega).sum()) == pytest.approx(1.0, abs=1e-5)
    rng = np.random.default_rng(2)
    samples = importance.sample(rng.random(100_000), rng.random(100_000))
    ratio = env.lookup_nearest(samples) / importance.pdf(samples)[:, None]
    np.testing.assert_allclose(ratio.mean(axis=0), weighted.sum(axis=0), rtol=0.01)
    assert ratio.max() < 20 * weighted.sum(axis=0).max()
    pooled = EquirectImportance.from_environment(env, max_height=128)  # max-pooled: still unbiased
    samples = pooled.sample(rng.random(100_000), rng.random(100_000))
    ratio = env.lookup_nearest(samples) / pooled.pdf(samples)[:, None]
    np.testing.assert_allclose(ratio.mean(axis=0), weighted.sum(axis=0), rtol=0.03)
