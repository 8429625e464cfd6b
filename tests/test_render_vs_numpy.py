"""GLSL against numpy through the real pipeline: the preview sphere rendered headless (EGL,
llvmpipe in CI), evaluated at a set of pixels with the numpy reference at the same position,
normal, tangent and view, reading incident radiance through the same cube-map filtering."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lobeview.core.cube_layout import face_directions
from lobeview.materials.bsdf import BSDF, diffuse_albedo
from lobeview.materials.patterns import integrate_lobe, specular_lobes
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import create_headless_context
from lobeview.viewer.gl_probes import CubeLookup
from lobeview.viewer.preview import PreviewRenderer


def smooth_sky(d):
    """A smooth but structured environment (sky gradient, warm ground, two broad lights) so
    Monte Carlo references converge quickly; max radiance ~8."""
    up = d[..., 1:2]
    sky = np.where(up > 0, [0.4, 0.6, 1.0] * (0.5 + up), [0.35, 0.25, 0.15] * (1.0 + up))
    light1 = 6.0 * np.exp(-((1 - np.sum(d * [0.6, 0.6, -0.52915], -1)) / 0.05))[..., None] * [1.0, 0.9, 0.7]
    light2 = 3.0 * np.exp(-((1 - np.sum(d * [-0.8, 0.2, 0.56569], -1)) / 0.1))[..., None] * [0.6, 0.8, 1.0]
    return sky + light1 + light2


RATIONAL_GOLD = str(Path(__file__).parent / "data" / "gold-ggx-rational.json")
ROUGH_GGX = '{"model": "microfacet", "distribution": "ggx", "alpha_u": 0.5, "alpha_v": 0.5, "scale": 1.0}'
# Anisotropic by 3.2: the line pattern, whose footprints at N = 19 are held to the lobe's width.
LINE_GGX = '{"model": "microfacet", "distribution": "ggx", "alpha_u": 0.1, "alpha_v": 0.32, "scale": 1.0}'
BECKMANN_02 = '{"model": "microfacet", "distribution": "beckmann", "alpha_u": 0.2, "alpha_v": 0.2, "scale": 1.0}'
# glTF lobes read through the fitted table too: a rough metal under a clearcoat, and a thin
# transmissive pane (its transmission lobe keeps the thesis pattern).
GLTF_COATED = ('{"model": "gltf", "base_color": [0.9, 0.6, 0.3], "metallic": 1.0, "roughness": 0.45, '
               '"clearcoat": 0.8, "clearcoat_roughness": 0.1}')  # fmt: skip
GLTF_PANE = '{"model": "gltf", "base_color": [0.9, 0.9, 0.9], "metallic": 0.0, "roughness": 0.3, "transmission": 1.0}'
SIZE = (72, 72)
CAMERA = Camera(position=(0.4, 0.6, 3.0), target=(0.0, 0.0, 0.0), fov_y=45.0)


@pytest.fixture(scope="module")
def gl():
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(smooth_sky, height=128, name="smooth-sky")
    renderer = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=SIZE, face_size=64)
    lookup = CubeLookup(ctx, renderer.programs)
    yield renderer, lookup
    renderer.release()
    ctx.release()


def _pixels(result, count=24, seed=0):
    rng = np.random.default_rng(seed)
    inside = np.argwhere(result.mask)
    # Stay off the silhouette, where a pixel mixes geometry and derivatives are unstable.
    centre = np.array(SIZE[::-1]) / 2
    dist = np.linalg.norm(inside - centre, axis=1)
    inside = inside[dist < 0.8 * dist.max()]
    return inside[rng.choice(len(inside), size=count, replace=False)]


def _frame(result, y, x):
    n = result.normal[y, x].astype(np.float64)
    t = result.tangent[y, x].astype(np.float64)
    n /= np.linalg.norm(n)
    t -= n * (t @ n)
    t /= np.linalg.norm(t)
    b = np.cross(n, t)
    frame = np.stack([t, b, n], axis=1)  # columns: local -> world
    wo_world = np.asarray(CAMERA.position) - result.position[y, x]
    wo = frame.T @ (wo_world / np.linalg.norm(wo_world))
    wo[2] = max(wo[2], 1e-4)
    return frame, wo / np.linalg.norm(wo)


def _numpy_reference(bsdf: BSDF, frame, wo, lookup, cube, n=60_000, seed=1):
    rng = np.random.default_rng(seed)
    u = rng.random((2, n))
    s = bsdf.sample(u[0], u[1], wo)
    ok = s.pdf > 0
    radiance = lookup(cube, s.wi[ok] @ frame.T, 0.0)
    return np.sum(s.weight[ok] * radiance, axis=0) / n


MATERIALS = [
    "alanod-2000gs-1lobe",
    "white-foil",
    "frosted-glass",
    "miro5-2lobe",
    "gold-ggx",
    "brushed-steel-beckmann",
    "gltf-red-plastic",
]


@pytest.mark.parametrize("preset", MATERIALS)
def test_reference_method_matches_numpy_monte_carlo(gl, preset):
    renderer, lookup = gl
    bsdf = build_bsdf(load_material(preset))
    result = renderer.render(CAMERA, bsdf, "reference", spp=1024, background=False)
    assert not result.invalid.any()
    errors = []
    for y, x in _pixels(result, count=12):
        frame, wo = _frame(result, y, x)
        expected = _numpy_reference(bsdf, frame, wo, lookup, renderer.cubes.radiance)
        got = result.radiance[y, x]
        errors.append(np.abs(got - expected) / (np.abs(expected) + 0.02))
    errors = np.array(errors)
    # Both sides are Monte Carlo estimates (GPU: 1024 QMC + 1024 environment samples per lobe,
    # MIS; numpy: 60 000 BSDF samples): mean relative error below 2 %, worst pixel below 8 %.
    assert errors.mean() < 0.02, errors.max(axis=1)
    assert errors.max() < 0.08, errors.max(axis=1)


@pytest.mark.parametrize(
    "preset,n,normalize",
    [(p, n, False) for p in MATERIALS + ["chrome", "clear-glass", "lacquer", "porcelain"] for n in (5, 11, 19)]
    + [(p, 7, True) for p in ("alanod-2000gs-2lobe", "frosted-glass", "miro5-2lobe", "gold-ggx", "gltf-red-plastic")]
    # A wide GGX lobe: its tail lookups' footprints (issue 45) and their fade at the horizon.
    + [(ROUGH_GGX, n, True) for n in (7, 15)]
    + [(LINE_GGX, n, True) for n in (5, 19)]
    # The Rational BRDF (seed 002): its lattice mapped through the rational inverse CDFs.
    + [(RATIONAL_GOLD, n, normalize) for n, normalize in ((7, False), (11, True))]
    # Eq. 4.24 (lobe-N+eq4.24) on the thesis' Fig. 4.24 materials.
    + [(p, n, "eq4.24") for p, n in (("gold-ggx", 15), ("alanod-2000gs-2lobe", 15), ("frosted-glass", 5),
                                     ("lacquer", 7), (RATIONAL_GOLD, 7))]
    # lobe-N+ring: the thesis' ring where the spiral is the default (N >= 11).
    + [(p, 15, "ring") for p in ("gold-ggx", "frosted-glass")]
    # lobe-N+norm+fit: the fitted reads (materials/fitted_pattern.py) on isotropic microfacet lobes,
    # the thesis pattern on the others (anisotropic Beckmann, frosted glass's thesis lobes).
    + [(p, 7, "fit") for p in ("gold-ggx", ROUGH_GGX, BECKMANN_02, GLTF_COATED, GLTF_PANE, "gltf-red-plastic",
                               "brushed-steel-beckmann", "frosted-glass")]
    + [(p, n, "fit") for p, n in ((ROUGH_GGX, 19), (BECKMANN_02, 3), ("gold-ggx", 11))],
)  # fmt: skip
def test_lobe_method_matches_numpy_pattern_quadrature(gl, preset, n, normalize):
    from lobeview.core.methods import Method
    from lobeview.materials.blur_stack import StackReads
    from lobeview.viewer.blur_stack_gpu import read_blur_stack
    from lobeview.viewer.material_gpu import albedo_table_for

    renderer, lookup = gl
    bsdf = build_bsdf(load_material(preset))
    weighting = "eq4.24" if normalize == "eq4.24" else "eq4.25"
    pattern = {"ring": "ring", "fit": "fitted"}.get(normalize, "auto")
    normalize = normalize is True or normalize == "fit"
    method = Method("lobe", n, normalize, weighting=weighting, pattern=pattern)
    result = renderer.render(CAMERA, bsdf, method, background=False)
    assert not result.invalid.any()
    cube = renderer.cubes.radiance
    # +fit's coarse reads come from the environment's blur stack in the preview (materials/blur_stack.py)
    stack = StackReads(read_blur_stack(renderer.cubes.blur_stack())) if pattern == "fitted" else None
    for y, x in _pixels(result, count=10, seed=n):
        frame, wo = _frame(result, y, x)

        def radiance(dirs, lod):
            return lookup(cube, dirs, lod)

        expected = np.zeros(3)
        for lobe in specular_lobes(bsdf):
            table = albedo_table_for(lobe) if normalize else None
            expected += integrate_lobe(
                lobe,
                wo,
                radiance,
                n,
                renderer.cubes.face_size,
                frame,
                weighting=weighting,
                albedo_table=table,
                pattern=pattern,
                stack=stack,
            )
        kd = diffuse_albedo(bsdf)
        if np.any(kd > 0):
            irradiance = lookup(renderer.cubes.irradiance, frame[:, 2][None], 0.0)[0]
            factor = 1.0
            for diffuse in (c for c in bsdf.components if type(c).__name__ == "GltfDiffuse"):
                factor = float(diffuse.view_weight(np.array(wo[2])))  # 1 - F(V.H) over the hemisphere
            expected += kd / np.pi * irradiance * factor
        # Same lookups, same formulas: float32 shader arithmetic against float64.
        np.testing.assert_allclose(result.radiance[y, x], expected, rtol=2e-3, atol=2e-4)


def test_cube_lookup_returns_texels_at_texel_centres(gl):
    renderer, lookup = gl
    size = renderer.cubes.face_size
    for face in range(6):
        dirs = face_directions(face, size)
        got = lookup(renderer.cubes.radiance, dirs.reshape(-1, 3), 0.0).reshape(size, size, 3)
        np.testing.assert_allclose(got, renderer.cubes.faces[face], rtol=1e-5, atol=1e-6)


def test_methods_agree_on_a_constant_environment():
    """White furnace through the renderer: under radiance 1 every method returns the lobe
    albedo (lobe-N within its pattern error), and nothing exceeds the albedo."""
    ctx = create_headless_context()
    try:
        env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=32)
        renderer = PreviewRenderer(ctx, env, uv_sphere(rings=32, segments=64), size=(48, 48), face_size=32)
        bsdf = build_bsdf(load_material("alanod-2000gs-1lobe"))
        spec = BSDF(specular_lobes(bsdf))
        for method, tolerance in (("reference", 0.02), ("fis-32", 0.02), ("lobe-11", 0.03)):
            result = renderer.render(CAMERA, spec, method, spp=512, background=False)
            for y, x in _pixels(result, count=8):
                _, wo = _frame(result, y, x)
                r, _ = spec.albedo(wo, order=96)
                np.testing.assert_allclose(result.radiance[y, x], r, rtol=tolerance, err_msg=method)
        renderer.release()
    finally:
        ctx.release()


def _numpy_mis_reference(bsdf: BSDF, frame, wo, lookup, cubes, n=40_000, seed=3):
    """BSDF sampling + environment sampling of the whole BSDF, power heuristic: an estimator
    independent of the shader's per-lobe MIS, with the same incident radiance."""
    rng = np.random.default_rng(seed)
    importance = cubes.importance
    u = rng.random((4, n))
    s = bsdf.sample(u[0], u[1], wo)
    ok = s.pdf > 0
    world = s.wi[ok] @ frame.T
    p_env = importance.pdf(world)
    w = s.pdf[ok] ** 2 / (s.pdf[ok] ** 2 + p_env**2)
    total = np.sum(s.weight[ok] * lookup(cubes.radiance, world, 0.0) * w[:, None], axis=0)
    world_e = importance.sample(u[2], u[3])
    wi_e = world_e @ frame
    f = bsdf.eval(wi_e, np.broadcast_to(wo, wi_e.shape))
    p_env = importance.pdf(world_e)
    p_bsdf = bsdf.pdf(wi_e, np.broadcast_to(wo, wi_e.shape))
    w = p_env**2 / (p_env**2 + p_bsdf**2)
    contrib = f * np.abs(wi_e[:, 2:3]) * (w / p_env)[:, None]
    total += np.sum(contrib * lookup(cubes.radiance, world_e, 0.0), axis=0)
    return total / n


@pytest.mark.parametrize("preset", ["alanod-2000gs-2lobe", "white-foil", "gltf-red-plastic"])
def test_reference_with_a_sun_matches_numpy_multiple_importance_sampling(preset):
    """The environment sampler matters when a small, very bright source dominates: builtin:sky
    has a 0.6 deg sun of radiance 2e4."""
    from lobeview.scenes.builtin_env import sky

    ctx = create_headless_context()
    try:
        env = EnvironmentMap.from_function(sky, height=256, name="sky")
        renderer = PreviewRenderer(ctx, env, uv_sphere(rings=48, segments=96), size=(48, 48), face_size=128)
        lookup = CubeLookup(ctx, renderer.programs)
        bsdf = build_bsdf(load_material(preset))
        result = renderer.render(CAMERA, bsdf, "reference", spp=1024, background=False)
        errors = []
        for y, x in _pixels(result, count=10):
            frame, wo = _frame(result, y, x)
            expected = _numpy_mis_reference(bsdf, frame, wo, lookup, renderer.cubes)
            errors.append(np.abs(result.radiance[y, x] - expected) / (np.abs(expected) + 0.05))
        errors = np.array(errors)
        assert errors.mean() < 0.03, errors.max(axis=1)
        assert errors.max() < 0.12, errors.max(axis=1)
        renderer.release()
    finally:
        ctx.release()


@pytest.fixture(scope="module")
def smooth_sphere():
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(smooth_sky, height=256, name="smooth-sky")
    renderer = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=(96, 96), face_size=128)
    yield renderer
    renderer.release()
    ctx.release()


# lobe-7+norm's relative RMSE against a 2048-spp reference on the smooth sky over the sphere's
# pixels but its silhouette's (measured 2026-11-27, llvmpipe, tent MIP chain at lobe-N's bias -1):
# GGX 0.011 / 0.034 / 0.045 at alpha 0.05 / 0.15 / 0.30 (before the tail's quadrature of
# patterns.py step 7: 0.016 / 0.038 / 0.082), Beckmann 0.009 / 0.033 / 0.041. Over every sphere
# pixel GGX 0.15 reads 0.049 (0.046 before): the box-filtered reference averages the background
# into the silhouette's pixels where lobe-7 shades their centres, and the tail now carries its
# share at grazing views (up to half of the albedo), where the silhouette is.
SMOOTH_SKY_LOBE7_BOUNDS = {
    ("ggx", 0.05): 0.02,
    ("ggx", 0.15): 0.05,
    ("ggx", 0.30): 0.06,
    ("beckmann", 0.05): 0.02,
    ("beckmann", 0.15): 0.05,
    ("beckmann", 0.30): 0.05,
}


@pytest.mark.parametrize("distribution,alpha", sorted(SMOOTH_SKY_LOBE7_BOUNDS))
def test_lobe7_is_close_to_the_converged_reference_on_a_smooth_sky(smooth_sphere, distribution, alpha):
    """Issue 20: lobe-7 (the viewer's normalised form) on env-lit isotropic GGX / Beckmann
    spheres with alpha <= 0.3 against `reference` (2048 samples per lobe, box-filtered pixels)
    under a smooth environment, relative RMSE of linear radiance over the sphere without its
    silhouette's pixels (bench/light.py interior). Issue 20's target, 5 %, is met everywhere
    (GGX 0.30 at 0.045: its bound leaves room for the reference's noise)."""
    from scipy.ndimage import binary_erosion

    from lobeview.bench.metrics import relative_rmse

    material = (
        f'{{"model": "microfacet", "distribution": "{distribution}", "alpha": {alpha}, '
        '"fresnel": {"type": "schlick", "r0": 0.9}}'
    )
    bsdf = build_bsdf(load_material(material))
    reference = smooth_sphere.render(CAMERA, bsdf, "reference", spp=2048, background=False)
    result = smooth_sphere.render(CAMERA, bsdf, "lobe-7+norm", background=False)
    mask = binary_erosion(reference.mask, iterations=1)
    error = relative_rmse(result.radiance[mask], reference.radiance[mask])
    assert error < SMOOTH_SKY_LOBE7_BOUNDS[(distribution, alpha)], error
