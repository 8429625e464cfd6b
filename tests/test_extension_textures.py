"""The KHR_materials_* extension textures (issue 16): the GLSL path against the numpy twin
(scenes/texturing.py) per pixel through the real pipeline, and the loader combining textures
that share a slot. The quad, its renderer and pixel helpers are tests/test_textures.py's."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_textures import CAMERA, _pixels, _rendered_quad, _textured_gltf, _textured_quad_scene, _uv_of

from lobeview.materials.patterns import integrate_lobe, specular_lobes
from lobeview.materials.spec import validate
from lobeview.scenes.gltf_loader import load_gltf
from lobeview.scenes.scene import (
    NEAREST,
    TextureSlot,
)
from lobeview.scenes.texturing import mapped_normal, pixel_bsdf, texel_material


# -- KHR extension textures ---------------------------------------------------------------------
def _random_map(rng, low=0, high=256, alpha=None):
    n = 8
    image = rng.integers(low, high, size=(n, n, 4), dtype=np.uint8)
    if alpha is not None:
        image[..., 3] = alpha
    return image


def _coat_frame(frame: np.ndarray, coat_normal_texel, scale: float) -> np.ndarray:
    """shaders/scene.frag's clearcoat frame: its normal map in the vertex frame, the vertex tangent
    made orthogonal to it (frame.glsl shading_frame, handedness +1)."""
    if coat_normal_texel is None:
        return frame
    n = mapped_normal(frame, coat_normal_texel[0], scale)
    t = frame[:, 0] - n * (frame[:, 0] @ n)
    t /= np.linalg.norm(t)
    return np.stack([t, np.cross(n, t), n], axis=1)


EXTENSION_TEXTURE_CASES = {
    # KHR_materials_anisotropy: per-texel direction (RG) and strength (B) over rotation 0.4
    "anisotropy": (
        {"metallic": 1.0, "roughness": 0.35, "anisotropy": 0.9, "anisotropy_rotation": 0.4},
        {"anisotropy": lambda rng: _random_map(rng, alpha=255)},
    ),
    # KHR_materials_clearcoat: factor (R) and roughness (G) per texel, its own normal map; the
    # base has another normal map, which must not reach the coat
    "clearcoat": (
        {"metallic": 0.0, "roughness": 0.6, "clearcoat": 1.0, "clearcoat_roughness": 0.5},
        {
            "clearcoat": lambda rng: _random_map(rng, 30, 256, alpha=255),
            "clearcoat_normal": "tilted",
            "normal": "tilted",
        },
    ),  # fmt: skip
    # KHR_materials_specular (colour RGB sRGB, factor A), _transmission (R) and _sheen colour
    "specular-transmission-sheen": (
        {
            "metallic": 0.0,
            "roughness": 0.3,
            "ior": 1.8,
            "specular": 0.9,
            "specular_color": [1.6, 1.0, 0.7],
            "transmission": 0.8,
            "sheen_color": [0.6, 0.5, 0.9],
            "sheen_roughness": 0.5,
        },
        {
            "specular": lambda rng: _random_map(rng, 60, 256),
            "transmission": lambda rng: _random_map(rng, alpha=255),
            "sheen_color": lambda rng: _random_map(rng, alpha=255),
        },
    ),  # fmt: skip
}


def _tilted_normal_map(rng):
    normal = np.zeros((8, 8, 4), np.uint8)
    tilt = rng.uniform(-0.4, 0.4, size=(8, 8, 2))
    normal[..., :2] = np.round((tilt * 0.5 + 0.5) * 255)
    normal[..., 2:] = 230, 255
    return normal


@pytest.mark.parametrize("case", list(EXTENSION_TEXTURE_CASES))
def test_khr_extension_textures_match_numpy_per_pixel(case):
    """The KHR extensions' textures through the real pipeline (lobe-7, per-pixel glTF path)
    against scenes/texturing.py: every texel scales its factor, the anisotropy texture turns the
    tangent per pixel, the clearcoat lobe is integrated in its own normal's frame and its Fresnel
    over the base taken at N_c.V."""
    from lobeview.materials.gltf import GltfClearcoat, GltfDiffuse, GltfSheen, anisotropy_frame

    factors, maps = EXTENSION_TEXTURE_CASES[case]
    rng = np.random.default_rng(11)
    scene = _textured_quad_scene()
    material = scene.materials[0]
    textures = {"base_color": material.textures["base_color"]}
    for slot, make in maps.items():
        image = _tilted_normal_map(rng) if make == "tilted" else make(rng)
        srgb = slot in ("specular", "sheen_color")
        textures[slot] = TextureSlot(image, srgb=srgb, mag_filter=NEAREST, min_filter=NEAREST)
    material.textures = textures
    material.clearcoat_normal_scale = 0.9
    material.desc = validate({"model": "gltf", "base_color": [0.9, 0.8, 1.0], **factors})
    with _rendered_quad(scene) as (renderer, lookup, result):
        cube = renderer.objects[0].cube
        vertex_frame = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
        pixels = _pixels(result, 12, seed=5)
        assert len(pixels) == 12
        coat_seen = 0
        for y, x in pixels:
            params = texel_material(material, _uv_of(result.position[y, x])[None])
            view = np.asarray(CAMERA.position) - result.position[y, x]
            view /= np.linalg.norm(view)
            n = result.normal[y, x].astype(np.float64)
            t = result.tangent[y, x].astype(np.float64)
            t -= n * (t @ n)
            t /= np.linalg.norm(t)
            frame = np.stack([t, np.cross(n, t), n], axis=1)
            if "anisotropy" in maps:  # the tangent the texture's direction and the rotation give
                turned = anisotropy_frame(vertex_frame, float(params["extensions"]["anisotropy_rotation"][0]))
                np.testing.assert_allclose(t, turned[:, 0], atol=3e-3)
                frame = turned
            coat_frame = _coat_frame(vertex_frame, params["coat_normal_texel"], 0.9)
            coat_wo = coat_frame.T @ view
            wo = frame.T @ view
            bsdf = pixel_bsdf(params, 0, coat_cos=float(coat_wo[2]))
            expected = np.zeros(3)
            for lobe in specular_lobes(bsdf):
                in_coat = isinstance(lobe, GltfClearcoat)
                coat_seen += in_coat
                expected += integrate_lobe(
                    lobe,
                    coat_wo if in_coat else wo,
                    lambda d, lod: lookup(cube.radiance, d, lod),
                    7,
                    cube.face_size,
                    coat_frame if in_coat else frame,
                )
            diffuse = next(c for c in bsdf.components if isinstance(c, GltfDiffuse))
            irradiance = lookup(renderer.environment_irradiance, n[None], 0.0)[0]
            expected += diffuse.diffuse_albedo / np.pi * irradiance * diffuse.view_weight(np.array(wo[2]))
            for sheen in (c for c in bsdf.components if isinstance(c, GltfSheen)):
                expected += sheen.view_albedo(np.array(wo[2])) / np.pi * irradiance
            np.testing.assert_allclose(result.radiance[y, x], expected, rtol=1e-2, atol=1e-3)
        assert (coat_seen > 0) == ("clearcoat" in maps)
        # The textures matter: without them the same factors light the quad differently.
        plain = validate(dict(material.desc))
        material.textures = {"base_color": textures["base_color"]}
        renderer.update_material(0, plain)
        untextured = renderer.render(CAMERA, "lobe-7")
        difference = np.abs(untextured.radiance - result.radiance)[result.mask].mean()
        assert difference > 0.02 * result.radiance[result.mask].mean(), difference


def test_loader_combines_the_textures_that_share_a_slot(tmp_path):
    """clearcoatTexture (R) and clearcoatRoughnessTexture (G) fill one slot: two images of one
    size and sampling are merged channel-wise (other channels white), one image used for both is
    kept as it is, and a texture of another size is said not to fit (its factor applies)."""
    rng = np.random.default_rng(3)
    first, second = (rng.integers(0, 256, size=(4, 4, 4), dtype=np.uint8) for _ in range(2))
    small = np.zeros((2, 2, 4), np.uint8)

    def load(coat_index, roughness_index):
        coat = {"clearcoatFactor": 0.8, "clearcoatRoughnessFactor": 0.5, "clearcoatTexture": {"index": coat_index},
                "clearcoatRoughnessTexture": {"index": roughness_index}}  # fmt: skip
        material = {"extensions": {"KHR_materials_clearcoat": coat}}
        return load_gltf(_textured_gltf(tmp_path, material, [first, second, small])).materials[0]

    merged = load(0, 1).texture("clearcoat")
    np.testing.assert_array_equal(merged.image[..., 0], first[..., 0])
    np.testing.assert_array_equal(merged.image[..., 1], second[..., 1])
    np.testing.assert_array_equal(merged.image[..., 2:], 255)
    shared = load(0, 0).texture("clearcoat")
    np.testing.assert_array_equal(shared.image, first)
    with pytest.warns(UserWarning, match="clearcoatRoughnessTexture differs from clearcoatTexture"):
        mismatched = load(0, 2).texture("clearcoat")
    np.testing.assert_array_equal(mismatched.image[..., 0], first[..., 0])
    np.testing.assert_array_equal(mismatched.image[..., 1], 255)  # roughness factor only
    params = texel_material(load(0, 1), np.array([[0.125, 0.125]]))  # texel (0, 0), nearest centre
    assert params["extensions"]["clearcoat"][0] == pytest.approx(0.8 * first[0, 0, 0] / 255, rel=1e-6)
    assert params["extensions"]["clearcoat_roughness"][0] == pytest.approx(0.5 * second[0, 0, 1] / 255, rel=1e-6)


def test_khr_texture_figure_scene_loads_every_extension_texture(tmp_path):
    """bench/khr_textures.py's generated glTF goes through the loader without a warning, with
    every extension texture in its slot (the clearcoat's two textures merged), and renders finite."""
    from lobeview.bench.khr_textures import render_figure, write_gltf

    path = write_gltf(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = load_gltf(path)
    slots = [set(m.textures) for m in scene.materials[:3]]
    assert slots == [{"anisotropy"}, {"clearcoat", "clearcoat_normal"}, {"specular"}]
    coat = scene.materials[1].texture("clearcoat").image
    assert set(np.unique(coat[..., 0])) == {0, 255} and coat[..., 1].min() < 10 and coat[..., 1].max() > 245
    stats = render_figure(path, "builtin:studio", (96, 32), "lobe-3", tmp_path / "figure.png")
    assert (tmp_path / "figure.png").exists() and all(np.isfinite(v) and v > 0 for v in stats.values())
