"""The occlusion texture on baked and unbaked surfaces (issue 40: a baked FlightHelmet was 21 %
darker than Cycles, the texture darkening what the bake had already occluded). Unbaked, the
texture multiplies the environment's irradiance (spec 3.9.3); baked, only its detail within a
lightmap texel applies: the bake's mean is kept, the crevices stay visible."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials.spec import validate
from lobeview.scenes.meshes import quad
from lobeview.scenes.scene import (
    LINEAR,
    LINEAR_MIPMAP_LINEAR,
    Lightmap,
    Scene,
    SceneMaterial,
    SceneObject,
    TextureSlot,
)

AO_SIZE = 256
CHECK = 8  # occlusion checker squares of 8 texels: 4 per lightmap texel across
LIGHTMAP_SIZE = 8
SIZE = (128, 128)  # the quad fills the frame: 16 pixels per lightmap texel, 2 texels per pixel


def _occlusion_image() -> np.ndarray:
    """A slow ramp (1 -> 0.4 across u: occlusion the bake also sees) times a fine checker
    (1 / 0.5: detail the bake cannot resolve), in R."""
    u = (np.arange(AO_SIZE) + 0.5) / AO_SIZE
    ramp = 1.0 - 0.6 * u
    index = np.arange(AO_SIZE) // CHECK
    checker = np.where((index[:, None] + index[None, :]) % 2 == 0, 1.0, 0.5)
    ao = ramp[None, :] * checker
    image = np.zeros((AO_SIZE, AO_SIZE, 4), np.uint8)
    image[..., 0] = np.round(ao * 255)
    image[..., 1:3] = 255
    image[..., 3] = 255
    return image


def _scene(occlusion: bool, baked: bool) -> Scene:
    textures = {}
    if occlusion:
        textures["occlusion"] = TextureSlot(_occlusion_image(), mag_filter=LINEAR, min_filter=LINEAR_MIPMAP_LINEAR)
    return quad_scene(textures, baked)


def quad_scene(textures: dict, baked: bool) -> Scene:
    """A 2 m diffuse quad (kd 0.8, no lobes) with ``textures``; ``baked``: a uniform lightmap of pi
    (irradiance pi, as from a white sky over its hemisphere) on TEXCOORD_1."""
    desc = validate({"model": "thesis", "kd": [0.8, 0.8, 0.8], "lobes": []})
    material = SceneMaterial("floor", desc, textures=textures)
    if baked:
        material.lightmap = Lightmap(np.full((LIGHTMAP_SIZE, LIGHTMAP_SIZE, 3), np.pi, np.float32), tex_coord=1)
    mesh = quad([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0])
    obj = SceneObject("floor", mesh, 0)
    obj.uv1 = mesh.uvs.copy()
    obj.planar_reflector = False
    return Scene([obj], [material])


def _render(occlusion: bool, baked: bool) -> tuple[np.ndarray, np.ndarray]:
    return render_quad(_scene(occlusion, baked), SIZE)


def render_quad(scene: Scene, size) -> tuple[np.ndarray, np.ndarray]:
    """lobe-7 of :func:`quad_scene` under a white sky, the quad filling the frame: the mean
    over channels and the mask, without the two outer pixel rings."""
    return render_quad_methods(scene, size, ("lobe-7",), images=True)["lobe-7"]


def render_quad_methods(scene: Scene, size, methods, images: bool = False) -> dict:
    """:func:`render_quad` in each of ``methods`` (the reference at 256 samples): per method the
    mean over the pixels, or with ``images`` the (mean over channels, mask) pair."""
    import warnings

    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=16, name="white")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the unbaked scene's "no usable lightmap"
        renderer = SceneRenderer(ctx, scene, env, size=size, progress=False,
                                 settings=RenderSettings(cube_face_size=16))  # fmt: skip
    try:
        # 2 m quad, vertical fov 2 atan(1 / 2.6): it fills the frame (the edge pixels are dropped)
        fov = float(2 * np.degrees(np.arctan(1 / 2.6)))
        camera = Camera(position=(0.0, 0.0, 2.6), target=(0.0, 0.0, 0.0), fov_y=fov)
        out = {}
        for method in methods:
            result = renderer.render(camera, method, spp=256)
            assert result.mask[2:-2, 2:-2].all() and not result.invalid.any()
            image = result.radiance.mean(axis=-1)[2:-2, 2:-2]
            out[method] = (image, result.mask[2:-2, 2:-2]) if images else float(image.mean())
        return out
    finally:
        renderer.release()
        ctx.release()


@pytest.fixture(scope="module")
def plain_baked():
    return _render(False, True)[0]


def test_baked_surface_keeps_the_lightmap_mean_and_the_texture_detail(plain_baked):
    with_ao = _render(True, True)[0]
    ratio = with_ao / plain_baked
    # the mean over the quad is the bake's (before: the ramp's mean x the checker's, 0.53)
    assert abs(ratio.mean() - 1.0) < 0.05, ratio.mean()
    # ... and per lightmap texel (16 x 16 pixels, less the cropped border): the ramp is gone
    blocks = ratio[6:-6, 6:-6].reshape(7, 16, 7, 16).mean(axis=(1, 3))
    assert np.abs(blocks - 1.0).max() < 0.12, blocks.round(3)
    # the checker's detail stays: bright squares about 2x the dark ones
    bright, dark = np.percentile(ratio, 90), np.percentile(ratio, 10)
    assert 1.6 < bright / dark < 2.4, (bright, dark)


def test_unbaked_surface_takes_the_whole_occlusion_texture():
    plain = _render(False, False)[0]
    with_ao = _render(True, False)[0]
    ratio = with_ao / plain
    # mix(1, ao, 1) = ao: the ramp's mean (0.7) x the checker's (0.75)
    assert abs(ratio.mean() - 0.7 * 0.75) < 0.03, ratio.mean()
    left, right = ratio[:, :20].mean(), ratio[:, -20:].mean()
    assert left > 1.6 * right  # the ramp darkens across u
