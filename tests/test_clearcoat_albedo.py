"""A textured clearcoat under normalised lobe-N (issue 40, Khronos ClearCoatTest against Cycles):
the coat's albedo came from the material's table, made at the factors, whatever the textures said
(a striped clearcoatTexture rendered as a whole coat, 1.33x the reference; a clearcoatRoughnessTexture
under a roughness factor of 1 as the roughest coat, 0.81x). It is read per pixel from the DFG
table now, as the glTF specular's (shaders/patterns.glsl lobe_albedo; numpy twin
materials/prefilter.py dfg_albedo, tested against quadrature in test_prefilter.py)."""

from __future__ import annotations

import numpy as np
import pytest

METHODS = ("lobe-7+norm", "lobe-7+norm+fit", "reference")


def _coat_texture(factor: float, roughness: float) -> np.ndarray:
    """KHR_materials_clearcoat's textures share one image here: R the coat factor, G its roughness."""
    texel = np.zeros((4, 4, 4), np.uint8)
    texel[..., 0], texel[..., 1], texel[..., 2], texel[..., 3] = round(factor * 255), round(roughness * 255), 0, 255
    return texel


def _means(tmp_path, name: str, extension: dict, images: list) -> dict:
    from test_textures import _textured_quad_means

    # a black dielectric base (ClearCoatTest's "coating only"): the coat carries most of what is seen
    material = {"pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0,
                                         "roughnessFactor": 0.6},
                "extensions": {"KHR_materials_clearcoat": extension}}  # fmt: skip
    return _textured_quad_means(tmp_path / name, material, images, METHODS)


@pytest.mark.parametrize(
    ("factors", "textured"),
    [
        # a half coat: clearcoatTexture R = 0.5 under clearcoatFactor 1 (before: lobe-7+norm as a whole coat)
        ({"clearcoatFactor": 0.5, "clearcoatRoughnessFactor": 0.1},
         {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.1, "clearcoatTexture": {"index": 0}}),
        # a smooth coat: clearcoatRoughnessTexture G = 0.2 under clearcoatRoughnessFactor 1
        ({"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.2},
         {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 1.0, "clearcoatRoughnessTexture": {"index": 0}}),
    ],
)  # fmt: skip
def test_textured_clearcoat_renders_like_the_same_factors(tmp_path, factors, textured):
    """Through the loader and the real pipeline: the factors' coat takes the per-material table,
    the texture's the per-pixel albedo; every method within 2 % of itself either way."""
    coat_factor = 0.5 if "clearcoatTexture" in textured else 1.0
    coat_roughness = 0.2 if "clearcoatRoughnessTexture" in textured else 1.0
    with_factors = _means(tmp_path, "factors", factors, [])
    with_texture = _means(tmp_path, "texture", textured, [_coat_texture(coat_factor, coat_roughness)])
    for method in METHODS:
        expected = pytest.approx(with_factors[method], rel=0.02)
        assert with_texture[method] == expected, (method, with_factors, with_texture)
