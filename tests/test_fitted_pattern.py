"""materials/fitted_pattern.py: reads fitted to the lobe (issue 45), against independent checks:
the gradient against differences, a fit that must find a known kernel, the MIP read model's
inverse, exactness under uniform light, and the committed table against the thesis pattern on the
kernel and on issue 45's sky with ideal reads."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.bench import lobe_kernel as lk
from lobeview.materials import fitted_pattern as fp
from lobeview.materials import patterns
from lobeview.materials.microfacet import MicrofacetDistribution


@pytest.fixture(scope="module")
def oblique_target():
    return fp.lobe_target(MicrofacetDistribution("beckmann", 0.15, 0.15), float(np.cos(np.radians(70.0))), points=48)


def test_gradient_matches_central_differences(oblique_target):
    rng = np.random.default_rng(3)
    params = fp.initial_parameters(7) + rng.normal(0.0, 0.1, len(fp.initial_parameters(7)))
    _, grad = fp._kernel_and_gradient(params, 7, oblique_target)
    step = 1e-6

    def loss(p):
        return fp._kernel_and_gradient(p, 7, oblique_target)[0]

    numeric = np.array([(loss(params + e) - loss(params - e)) / (2 * step) for e in np.eye(len(params)) * step])
    np.testing.assert_allclose(grad, numeric, rtol=1e-4, atol=1e-7 * np.abs(grad).max())


def test_the_fit_finds_a_kernel_it_can_represent(oblique_target):
    """A target made of 7 reads of the topology (not the lobe) is found again from a start away from it."""
    start = fp.initial_parameters(7)
    known = start + np.random.default_rng(5).normal(0.0, 0.25, len(start))
    pattern = fp.pattern_of(known, 7, oblique_target)
    cosines = oblique_target.directions @ pattern.directions(oblique_target).T
    shapes = np.exp(np.minimum((cosines - 1.0) / pattern.sigma**2, 0.0)) / fp.gaussian_norm(pattern.sigma)
    target = fp.LobeTarget(**{**oblique_target.__dict__, "values": shapes @ pattern.weight})
    fitted, _ = fp.fit_target(target, 7)
    assert fitted.distance < 0.02
    assert fp.kernel_distance(pattern, target) == pytest.approx(0.0, abs=1e-12)


def test_a_fit_beats_the_thesis_pattern_at_grazing():
    distribution = MicrofacetDistribution("ggx", 0.3, 0.3)
    pattern, _, target = fp.fit_pattern(distribution, float(np.cos(np.radians(70.0))), 11)
    lobe = lk.lobe_of("ggx:0.3")
    grid, solid = lk.direction_grid(128)
    thesis, _ = lk.kernel_distances(lobe, 70.0, 7, patterns.AlbedoTable.build(lobe), grid, solid)
    assert pattern.distance < 0.05 < thesis  # 0.03 against 0.32 (bench/results/lobe-kernel-*.md)
    assert pattern.weight.sum() == pytest.approx(1.0)


def test_lod_for_sigma_inverts_the_read_model():
    directions = np.array([[0.0, 0.0, 1.0], [0.6, 0.6, 0.53], [1.0, 0.2, -0.1]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for level in (0.0, 0.3, 0.7, 2.0, 2.5, 4.9):
        sigma = fp.read_sigma_texels(level) * fp.texel_angle(directions, 128)
        np.testing.assert_allclose(fp.lod_for_sigma(directions, sigma, 128), level, atol=1e-9)
    # level 0 is the sharpest read: the bilinear tent alone, sqrt(1/6) texel; sharper asks give 0
    assert fp.read_sigma_texels(0.0) == pytest.approx(np.sqrt(1.0 / 6.0))
    assert fp.lod_for_sigma(directions[:1], np.array([1e-6]), 128)[0] == 0.0


@pytest.fixture(scope="module")
def ggx_table():
    try:
        return fp.load_table("ggx", fp.read_count("ggx", 7))
    except (OSError, KeyError) as error:
        pytest.fail(f"the committed fitted table is missing: {error}")


def test_the_estimator_is_exact_under_uniform_light(ggx_table):
    lobe = lk.lobe_of("ggx:0.3")
    albedo = patterns.AlbedoTable.build(lobe)
    for theta in (0.0, 40.0, 75.0):
        wo = np.array([np.sin(np.radians(theta)) * 0.6, np.sin(np.radians(theta)) * 0.8, np.cos(np.radians(theta))])
        value = fp.integrate_fitted(lobe, wo, lambda d, lod: np.ones((len(d), 3)), ggx_table, 128, None, albedo)
        np.testing.assert_allclose(value, albedo.lookup(wo), rtol=1e-9)


def test_the_table_fits_between_its_nodes(ggx_table):
    """Interpolated reads (alpha and view between nodes) stay close to the lobe: the fits moved
    continuously across the table (without the anchor, 0.13 at GGX 0.25, 45 degrees). The thesis
    pattern is 0.15-0.32 at these views; near grazing a narrow lobe is the table's hardest case."""
    for alpha, view in ((0.25, 45.0), (0.12, 65.0), (0.45, 20.0), (0.07, 60.0), (0.03, 10.0)):
        distance = lk.fitted_kernel_distance("ggx", alpha, view, ggx_table)
        assert distance < 0.07, (alpha, view, distance)
    lobe = lk.lobe_of("ggx:0.07")
    grid, solid = lk.direction_grid(256)
    thesis, _ = lk.kernel_distances(lobe, 75.0, 7, patterns.AlbedoTable.build(lobe), grid, solid)
    assert lk.fitted_kernel_distance("ggx", 0.07, 75.0, ggx_table) < 0.5 * thesis


def test_fitted_reads_beat_the_thesis_pattern_on_the_sky(ggx_table):
    """Issue 45's sky without its sun, ideal reads, 16 x 16 pixels: the fitted pattern's floor is a
    fraction of the thesis pattern's (1.0 against 7.2 % at 32 x 32, bench/results/lobe-kernel-*.md)."""
    lobe = lk.lobe_of("ggx:0.3")
    thesis = lk.ideal_floor(lobe, 7, pixels=16)
    fitted = lk.ideal_floor(lobe, 7, pixels=16, fitted=ggx_table)
    assert fitted < 0.3 * thesis and thesis > 0.05


def test_the_fit_suffix_parses_back_and_needs_the_normalisation():
    from lobeview.core.methods import Method, MethodError

    method = Method.parse("lobe-7+norm+fit")
    assert method.pattern == "fitted" and method.normalize and str(method) == "lobe-7+norm+fit"
    with pytest.raises(MethodError, match="lobe-7\\+norm\\+fit"):
        Method.parse("lobe-7+fit")
    with pytest.raises(MethodError, match="choose one"):
        Method.parse("lobe-7+norm+ring+fit")
    assert str(method.with_normalize(False)) == "lobe-7"  # the fitted reads need the albedo


def test_a_sample_count_without_a_table_names_the_command_that_makes_it():
    from lobeview.viewer.fitted_gpu import fitted_texture_data

    assert 7 in fp.fitted_sample_counts() and 4 not in fp.fitted_sample_counts()  # the panel's list
    data = fitted_texture_data(7)
    assert data.shape[2] == 1 + fp.read_count("ggx", 7) and np.isfinite(data).all()
    with pytest.raises(ValueError, match="bench.fitted_patterns --n 4"):
        fitted_texture_data(4)


def test_more_reads_fit_ggx_at_least_as_well():
    """The GGX tables of lobe-7/11/15/19 (11/15/19/23 reads): fitted with the anchor's pull of
    their size (anchor_stiffness), each is closer to the lobe than the one of fewer reads on
    average at the nodes and between them, and on the GGX 0.3 row (where at one pull for all, the
    19-read table was farther than the 11-read one from 35 degrees and lobe-15 rendered issue 45's
    sky less accurately than lobe-7)."""
    tables = [fp.load_table("ggx", reads) for reads in (11, 15, 19, 23)]
    views = np.asarray(fp.TABLE_VIEWS_DEG) <= 80.0
    alpha_03 = fp.TABLE_ALPHAS.index(0.3)
    # between the nodes (the estimator interpolates): 99 midpoints, alpha 0.02-0.65, views <= 80 degrees
    alphas, view_nodes = np.asarray(fp.TABLE_ALPHAS), np.asarray(fp.TABLE_VIEWS_DEG)
    midpoints = [(float(np.sqrt(alphas[i] * alphas[i + 1])), float((view_nodes[j] + view_nodes[j + 1]) / 2))
                 for i in range(9) for j in range(0, 21, 2)]  # fmt: skip
    between = [np.mean([lk.fitted_kernel_distance("ggx", a, v, t) for a, v in midpoints]) for t in tables]
    for k in range(1, len(tables)):
        smaller, larger = tables[k - 1], tables[k]
        assert larger.distance[:, views].mean() < smaller.distance[:, views].mean(), k
        assert between[k] < between[k - 1], between
    row = [t.distance[alpha_03, views] for t in tables]
    assert np.all(row[2] <= row[0]) and np.all(row[1] <= row[0] * 1.05), row
    assert fp.anchor_stiffness("ggx", 19) < fp.anchor_stiffness("ggx", 11) == fp.anchor_stiffness("beckmann", 19)
