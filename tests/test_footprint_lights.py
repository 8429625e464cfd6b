"""Footprint-aware lights (issue 39 item 3; materials/cap_lights.py footprint_alpha2, shaders
/cap_lights.glsl): a source narrower than a pixel's reflection keeps its energy in the image."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials.cap_lights import FOOTPRINT_DIVISOR, footprint_alpha2, widened_alphas


def _ggx_slope_density(s2, a2):
    """GGX's density of microfacet slopes (integrates to 1 over the slope plane)."""
    return a2 / (np.pi * (a2 + s2) ** 2)


def _grid_sums(a2: float, trials: int = 60) -> np.ndarray:
    """The lobe's values at pixel centres (one slope unit apart) summed, for random positions of
    the source between the centres: 1 where the pixels keep its energy."""
    rng = np.random.default_rng(3)
    g = np.arange(-150, 151)
    x, y = np.meshgrid(g, g)
    return np.array([_ggx_slope_density((x + ox) ** 2 + (y + oy) ** 2, a2).sum() for ox, oy in rng.random((trials, 2))])


def test_the_widening_is_wide_enough_for_pixel_centres():
    """One pixel step of the half vector's slope is |dn| = |dr| / 2. With footprint_alpha2 the
    centres' sum is within 8 % of the integral wherever the source lies; at the box filter's own
    variance (alpha^2 = 2 |dn|^2 / 12) it ranges over a factor 3.7."""
    dr = np.array([2.0, 0.0, 0.0])  # |dn| = 1 along x and along y
    a2 = float(footprint_alpha2(dr, np.array([0.0, 2.0, 0.0])))
    assert a2 == pytest.approx(min(8.0 / FOOTPRINT_DIVISOR, 0.1))
    # The property at the rule's ratio (the cap at 0.1 only acts at silhouettes).
    sums = _grid_sums(8.0 / FOOTPRINT_DIVISOR)
    assert sums.min() > 0.92 and sums.max() < 1.09, (sums.min(), sums.max())
    narrow = _grid_sums(2.0 / 12.0)
    assert narrow.max() / narrow.min() > 3.0
    ax, ay = widened_alphas(0.3, 0.1, 0.02)
    assert (ax, ay) == pytest.approx((np.sqrt(0.11), np.sqrt(0.03)))


def _glint_truth(sun, size, camera, radius_deg, radiance, window=1, per_pixel=384) -> float:
    """The sun's energy in a mirror sphere's image (radius 1 at the origin), per channel, summed
    over pixels: ray traced at per_pixel^2 points in each pixel of the (2 window + 1)^2 pixels
    around its glint (found by iterating the mirror condition), box-filtered."""
    eye = np.asarray(camera.position, dtype=np.float64)
    inverse = np.linalg.inv(camera.view_projection(1.0))
    n = sun + eye / np.linalg.norm(eye)
    n /= np.linalg.norm(n)
    for _ in range(100):
        v = (eye - n) / np.linalg.norm(eye - n)
        n = (v + sun) / np.linalg.norm(v + sun)
    clip = camera.view_projection(1.0) @ np.array([*n, 1.0])
    col, row = int((clip[0] / clip[3] * 0.5 + 0.5) * size), int((0.5 - clip[1] / clip[3] * 0.5) * size)
    total, cos_sun = 0.0, np.cos(np.radians(radius_deg))
    sub = (np.arange(per_pixel) + 0.5) / per_pixel
    for r in range(row - window, row + window + 1):
        for c in range(col - window, col + window + 1):
            x, y = np.meshgrid(2 * (c + sub) / size - 1, 1 - 2 * (r + sub) / size)
            ones = np.ones_like(x)
            near = np.stack([x, y, -ones, ones], -1) @ inverse.T
            far = np.stack([x, y, ones, ones], -1) @ inverse.T
            d = far[..., :3] / far[..., 3:] - near[..., :3] / near[..., 3:]
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            b = d @ eye
            disc = b * b - (eye @ eye - 1.0)
            p = eye + (-b - np.sqrt(np.maximum(disc, 0.0)))[..., None] * d
            reflected = d - 2.0 * np.sum(d * p, -1, keepdims=True) * p
            total += radiance * np.mean((disc > 0) & (reflected @ sun > cos_sun))
    return total


@pytest.mark.parametrize("sun", [(0.5, 0.6, 0.62), (-0.3, 0.2, 0.93), (0.1, -0.45, 0.89)])
def test_a_sub_pixel_sun_on_a_mirror_sphere_keeps_its_energy(sun):
    """A 0.5-degree sun of 2e4 on a GGX 0.01 sphere (its glint ~1 % of a pixel at 32 px): the sun's
    part of the image (lights on minus off) within 5 % of the ray-traced box-filtered image, in
    lobe-7, fis-16 and prefiltered; at the pixel centre's lobe it is lost or multiplied."""
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    direction = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
    radius, radiance, size = 0.5, 2e4, 32

    def sky(d):
        out = np.full(d.shape[:-1] + (3,), 0.05)
        out[np.sum(d * direction, -1) > np.cos(np.radians(radius))] = radiance
        return out

    camera = Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0)
    truth = _glint_truth(direction, size, camera, radius, radiance)
    mirror = build_bsdf(validate({"model": "microfacet", "distribution": "ggx", "alpha": 0.01,
                                  "fresnel": {"type": "none"}}))  # fmt: skip
    ctx = create_headless_context()
    try:
        renderer = PreviewRenderer(ctx, EnvironmentMap.from_function(sky, height=1024),
                                   uv_sphere(rings=96, segments=192), size=(size, size), face_size=128,
                                   bright_sources=True)  # fmt: skip
        assert len(renderer.cubes.lights) == 1
        energies = {}
        for method in ("lobe-7", "fis-16", "prefiltered"):
            for footprint in (True, False):
                lit = renderer.render(camera, mirror, method, footprint_lights=footprint).radiance
                lights, renderer.cubes.lights = renderer.cubes.lights, []
                unlit = renderer.render(camera, mirror, method, footprint_lights=footprint).radiance
                renderer.cubes.lights = lights
                energies[method, footprint] = float((lit - unlit)[..., 0].sum())
        renderer.release()
    finally:
        ctx.release()
    for method in ("lobe-7", "fis-16", "prefiltered"):
        assert energies[method, True] == pytest.approx(truth, rel=0.05), (method, energies, truth)
    assert abs(energies["lobe-7", False] / truth - 1) > 0.2, (energies, truth)
