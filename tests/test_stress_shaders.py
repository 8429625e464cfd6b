"""Numerical stress through the real shaders (a CI-sized subset of the stability suite):
extreme roughness, anisotropy, alpha and r0, grazing and back-facing views, radiance from 1e-6
to 1e6, degenerate tangents and normals, and bad environment texels. Nothing may come out NaN,
Inf or negative; the white-furnace bound, the mirror limit and monotonicity in roughness hold."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

from lobeview.bench.stress import (
    CI_METHODS,
    LOBE_METHOD_MAX_ROUGHNESS,
    STRESS_CAMERA,
    STRESS_SIZE,
    broken_sphere,
    furnace_check,
    furnace_tolerance,
    grazing_plane,
    injected_environment,
    inward_sphere,
    is_clean,
    local_view,
    sun_environment,
    white_environment,
)
from lobeview.bench.stress import thesis_material as thesis
from lobeview.materials.bsdf import BSDF
from lobeview.materials.patterns import specular_lobes
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import uv_sphere
from lobeview.viewer.gl_probes import CubeLookup
from lobeview.viewer.preview import PreviewRenderer

SIZE = STRESS_SIZE
CAMERA = STRESS_CAMERA
METHODS = CI_METHODS


@pytest.fixture(scope="module")
def furnace(ctx):
    renderer = PreviewRenderer(ctx, white_environment(), uv_sphere(rings=32, segments=64), size=SIZE, face_size=16)
    yield renderer
    renderer.release()


EXTREMES = [
    dict(m=1e-4),
    dict(m=1e-4, ratio=1.0, alpha=1.0),
    dict(m=1.0),
    dict(m=1.0, alpha=1.0, r0=1.0),
    dict(m=0.5, ratio=1000.0),
    dict(m=0.3, r0=0.0),
    dict(m=0.05, transmission=True),
    dict(m=1.0, alpha=0.5, transmission=True),
    dict(m=1.0, ratio=1000.0, alpha=1.0, r0=0.0),  # found by `lobeview bench --stress` (albedo table)
    dict(m=1e-4, r0=0.0),  # found by `lobeview bench --stress` (lobe fit of a vanishing slice raised)
    dict(m=1e-4, alpha=1.0, r0=0.0),  # found by `lobeview bench --stress` (lobe-map slices near grazing)
    dict(m=0.05, alpha=1.0, r0=0.0),  # found by `lobeview bench --stress` (plain Eq. 4.25, horizon-cut lobe)
]
# Plain lobe-N (Eq. 4.25 as printed) misses the furnace bound here; the normalised variant, the
# viewer's default, passes (test_normalised_lobe_method_is_exact_in_the_white_furnace).
PLAIN_LOBE_KNOWN_DEFECTS = [dict(m=0.05, alpha=1.0, r0=0.0)]


@pytest.mark.parametrize("params", EXTREMES, ids=[str(p) for p in EXTREMES])
@pytest.mark.parametrize("method", METHODS)
def test_extreme_parameters_stay_finite_and_obey_the_white_furnace(furnace, params, method):
    """Tolerances per method: lobeview.bench.stress.furnace_tolerance."""
    check = furnace_check(furnace, thesis(**params), method, anisotropic=params.get("ratio", 1.0) > 1.0)
    assert check.clean, f"{params} {method}: NaN/Inf/negative pixels"
    if method.startswith("lobe") and (params["m"] > LOBE_METHOD_MAX_ROUGHNESS or params in PLAIN_LOBE_KNOWN_DEFECTS):
        return  # known defect, pinned by test_lobe_method_overshoots_the_furnace_*
    assert check.passed, (params, method, check.rule, check.got[:, 0], check.albedo[:, 0])


# The multi-lobe and Banks maps (issue 6) on the extremes most likely to break their fits: a
# spike narrower than the fitting grid, vanishing slices, full roughness, transmission, and
# anisotropy ratio 1000 (Banks' s at its bound).
MAP_EXTREMES = [
    ("prefiltered-multi", dict(m=1e-4, r0=0.0)),
    ("prefiltered-multi", dict(m=1e-4, alpha=1.0, r0=0.0)),
    ("prefiltered-multi", dict(m=1.0, alpha=1.0, r0=1.0)),
    ("prefiltered-multi", dict(m=0.05, transmission=True)),
    ("prefiltered-banks", dict(m=0.5, ratio=1000.0)),
    ("prefiltered-banks", dict(m=1.0, ratio=1000.0, alpha=1.0, r0=0.0)),
    ("prefiltered-banks", dict(m=1e-4, ratio=1.0)),  # isotropic: lobe map
]


@pytest.mark.parametrize(("method", "params"), MAP_EXTREMES, ids=[f"{m} {p}" for m, p in MAP_EXTREMES])
def test_multi_lobe_and_banks_maps_stay_finite_and_obey_the_white_furnace(furnace, method, params):
    check = furnace_check(furnace, thesis(**params), method, anisotropic=params.get("ratio", 1.0) > 1.0)
    assert check.clean, f"{params} {method}: NaN/Inf/negative pixels"
    assert check.passed, (params, method, check.rule, check.worst_ratio)


@pytest.mark.xfail(
    strict=True, reason="lobe-N (Eq. 4.25) ignores the lobe mass its pattern does not cover; see issue notes"
)
def test_lobe_method_overshoots_the_furnace_for_very_rough_lobes(furnace):
    bsdf = thesis(1.0)
    result = furnace.render(CAMERA, bsdf, "lobe-7", background=False)
    albedo_at_normal = BSDF(specular_lobes(bsdf)).albedo(np.array([0.0, 0.0, 1.0]), order=96)[0][0]
    centre = result.radiance[SIZE[1] // 2 - 1 : SIZE[1] // 2 + 1, SIZE[0] // 2 - 1 : SIZE[0] // 2 + 1]
    # Measured: ~0.37 against an albedo of ~0.16 (2.2x).
    assert np.all(centre <= albedo_at_normal * 1.1)


@pytest.mark.xfail(
    strict=True, reason="lobe-N (Eq. 4.25) is biased for horizon-cut lobes whose albedo climbs toward grazing"
)
@pytest.mark.parametrize("params", PLAIN_LOBE_KNOWN_DEFECTS, ids=[str(p) for p in PLAIN_LOBE_KNOWN_DEFECTS])
def test_lobe_method_overshoots_the_furnace_for_horizon_cut_lobes(furnace, params):
    # Measured by the stress grid: 1.27x (lobe-7) and 1.36x (lobe-19) the albedo near grazing.
    check = furnace_check(furnace, thesis(**params), "lobe-7")
    assert check.clean and check.passed, check.worst_ratio


@pytest.mark.parametrize("params", EXTREMES, ids=[str(p) for p in EXTREMES])
def test_normalised_lobe_method_is_exact_in_the_white_furnace(furnace, params):
    """The fix for the defect above (lobeview's energy normalisation of Eq. 4.25): under
    uniform radiance lobe-N returns the lobe's tabulated directional albedo, for every lobe."""
    from lobeview.core.methods import Method

    bsdf = thesis(**params)
    result = furnace.render(CAMERA, bsdf, Method("lobe", 7, True), background=False)
    assert is_clean(result)
    spec = BSDF(specular_lobes(bsdf))
    rng = np.random.default_rng(1)
    pixels = np.argwhere(result.mask)
    # The table interpolates 32 x 16 albedo samples: 3 % + 0.005 covers its error for isotropic
    # lobes; the stated bound for anisotropic ones is looser (furnace_tolerance).
    rtol, _ = furnace_tolerance("lobe-7+norm", params.get("ratio", 1.0) > 1.0)
    for y, x in pixels[rng.choice(len(pixels), size=10, replace=False)]:
        r, t_ = spec.albedo(local_view(result, y, x), order=96)
        np.testing.assert_allclose(result.radiance[y, x], r + t_, rtol=rtol, atol=0.005, err_msg=str(params))


def test_huge_dynamic_range_environment(ctx):
    """1e-6 background with a 1e6 'sun' (0.5 deg): finite everywhere, and the sun shows up."""
    renderer = PreviewRenderer(ctx, sun_environment(), uv_sphere(rings=32, segments=64), size=SIZE, face_size=64)
    for m, method in itertools.product((1e-4, 0.05, 0.6), METHODS):
        result = renderer.render(CAMERA, thesis(m, alpha=0.5, r0=0.9), method, spp=128, background=False)
        assert is_clean(result), (m, method)
    # The sun is visible in the rough sphere's reflection.
    result = renderer.render(CAMERA, thesis(0.3, r0=0.9), "reference", spp=256, background=False)
    assert result.radiance.max() > 1.0
    renderer.release()


def test_plane_seen_at_89_9_degrees_renders_finite(ctx):
    mesh, camera = grazing_plane(89.9)
    renderer = PreviewRenderer(ctx, sun_environment(1e3, 0.1, 5.0), mesh, size=SIZE, face_size=32)
    for method in METHODS:
        result = renderer.render(camera, thesis(0.05, alpha=0.5, r0=0.9), method, spp=64, background=False)
        assert is_clean(result), method
        assert result.mask.mean() > 0.3  # the plane fills the lower part of the image
    renderer.release()


def test_degenerate_normals_and_tangents_render_finite(ctx):
    env = EnvironmentMap.from_function(lambda d: 0.5 + 0.5 * np.abs(d), height=32)
    for mesh in (broken_sphere(), inward_sphere()):
        renderer = PreviewRenderer(ctx, env, mesh, size=SIZE, face_size=32)
        for method in METHODS:
            result = renderer.render(CAMERA, thesis(0.1, ratio=10.0, alpha=0.3), method, spp=64, background=False)
            assert is_clean(result), method
            assert result.mask.mean() > 0.2
        renderer.release()


def test_nan_inf_negative_environment_texels_are_sanitised(ctx):
    image = np.full((32, 64, 3), 0.5, np.float32)
    image[4, 4] = np.nan
    with pytest.warns(UserWarning, match="NaN/Inf"):
        EnvironmentMap(image, "injected")
    renderer = PreviewRenderer(ctx, injected_environment(), uv_sphere(rings=24, segments=48), size=SIZE, face_size=16)
    for method in METHODS:
        result = renderer.render(CAMERA, thesis(0.2), method, spp=64)
        assert is_clean(result), method
    renderer.release()


def test_lobe_method_approaches_the_mirror_reflection(ctx):
    """roughness -> 0: lobe-N's value tends to (albedo x) the radiance in the mirror direction."""

    def env_fn(d):
        return np.stack([1.0 + d[..., 0], 1.0 + 0.5 * d[..., 1], 1.0 + 0.5 * d[..., 2] ** 2], -1)

    env = EnvironmentMap.from_function(env_fn, height=256)
    renderer = PreviewRenderer(ctx, env, uv_sphere(rings=48, segments=96), size=SIZE, face_size=128)
    lookup = CubeLookup(ctx, renderer.programs)
    errors = []
    for m in (0.1, 0.01, 1e-3, 1e-4):
        bsdf = thesis(m, r0=1.0)
        result = renderer.render(CAMERA, bsdf, "lobe-7", background=False)
        y, x = SIZE[1] // 2, SIZE[0] // 2 + 5
        n = result.normal[y, x] / np.linalg.norm(result.normal[y, x])
        view = np.asarray(CAMERA.position) - result.position[y, x]
        view /= np.linalg.norm(view)
        mirror = 2 * (view @ n) * n - view
        expected = lookup(renderer.cubes.radiance, mirror[None], 0.0)[0] * (view @ n)  # alpha=0: albedo ~ cos
        errors.append(np.max(np.abs(result.radiance[y, x] - expected) / expected))
    assert errors[-1] < 0.01, errors
    assert errors[0] > errors[-1]
    renderer.release()


def test_peak_highlight_falls_monotonically_with_roughness(ctx):
    """A single small light: the brightest pixel of the highlight gets dimmer as the lobe widens
    (energy spreads), for the deterministic and the unbiased method alike."""
    light = np.array([0.0, 0.3, 1.0])
    light /= np.linalg.norm(light)

    def env_fn(d):
        return 0.01 + 200.0 * (d @ light > np.cos(np.radians(3)))[..., None] * np.ones(3)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = PreviewRenderer(
            ctx,
            EnvironmentMap.from_function(env_fn, height=256),
            uv_sphere(rings=48, segments=96),
            size=(64, 64),
            face_size=128,
        )
    for method in ("lobe-11", "reference"):
        peaks = []
        for m in (0.02, 0.05, 0.1, 0.2, 0.4):
            result = renderer.render(CAMERA, thesis(m, r0=1.0), method, spp=512, background=False)
            peaks.append(float(result.radiance[result.mask].max()))
        assert all(a > b for a, b in zip(peaks, peaks[1:], strict=False)), (method, peaks)
    renderer.release()
