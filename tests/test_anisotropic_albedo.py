"""The per-pixel albedo of textured anisotropic glTF lobes under normalised lobe-N (issue 40:
textured anisotropy rendered 33-47 % brighter than the same anisotropy given as a factor, because
the isotropic DFG table was read at the geometric-mean alpha)."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials.bsdf import BSDF
from lobeview.materials.patterns import specular_lobes
from lobeview.materials.spec import build_bsdf, validate


@pytest.fixture(scope="module")
def table():
    from lobeview.viewer.prefiltered import anisotropic_dfg_texture_data

    return anisotropic_dfg_texture_data()


def _glossy(roughness: float, strength: float, metallic: float = 1.0) -> BSDF:
    desc = {"model": "gltf", "base_color": [1.0, 1.0, 1.0], "metallic": metallic, "roughness": roughness,
            "anisotropy": strength}  # fmt: skip
    return BSDF(specular_lobes(build_bsdf(validate(desc))))


def test_anisotropic_dfg_lookup_matches_quadrature_between_its_nodes(table):
    """Random views, roughness and strength off the table's nodes: the metal's albedo A + B and
    the dielectric specular's 0.04 A + B (Schlick f0 and f90 = 1) against the BSDF's own
    quadrature (BSDF.albedo of the specular lobes, white base colour: any channel)."""
    from lobeview.materials.prefilter import anisotropic_dfg_lookup

    rng = np.random.default_rng(5)
    for _ in range(24):
        roughness, strength = rng.uniform(0.15, 1.0), rng.uniform(0.0, 1.0)
        theta, azimuth = np.arccos(rng.uniform(0.05, 1.0)), rng.uniform(0.0, 2 * np.pi)
        wo = np.array([np.sin(theta) * np.cos(azimuth), np.sin(theta) * np.sin(azimuth), np.cos(theta)])
        a, b = anisotropic_dfg_lookup(table, wo[2], azimuth, roughness, strength)
        metal = _glossy(roughness, strength).albedo(wo, order=96)[0][1]
        assert a + b == pytest.approx(metal, rel=0.03), (roughness, strength, wo)
        specular = _glossy(roughness, strength, metallic=0.0).albedo(wo, order=96)[0][1]  # lobes only
        assert 0.04 * a + b == pytest.approx(specular, rel=0.04, abs=2e-3), (roughness, strength, wo)


@pytest.mark.parametrize(("alpha_min", "alpha_max"), [(0.5, 1.0), (0.09, 1.0), (0.2, 0.8)])
@pytest.mark.parametrize("cos_o", [1.0, 0.999, 0.002])
def test_anisotropic_dfg_at_the_views_ends(table, alpha_min, alpha_max, cos_o):
    """The table's sqrt(cos) nodes include normal incidence and grazing (texel centres read cos
    0.94 at normal incidence: 0.5 x 1.0 2.7 % too bright there, 0.09 x 1.0 2.0 %)."""
    from lobeview.materials.prefilter import split_sum_dfg

    wo = np.array([np.sqrt(1.0 - cos_o * cos_o), 0.0, cos_o])
    bsdf = build_bsdf(validate({"model": "microfacet", "distribution": "ggx", "alpha_u": alpha_max,
                                "alpha_v": alpha_min, "fresnel": {"type": "none"}, "scale": 1.0}))  # fmt: skip
    exact = bsdf.albedo(wo, order=96)[0][0]
    looked_up = split_sum_dfg({"anisotropic": table}, "ggx", wo, alpha_max, alpha_min).sum()
    assert looked_up == pytest.approx(exact, rel=0.01)


def test_split_sum_dfg_of_any_anisotropic_ggx_matches_quadrature(table):
    """split_sum_dfg (shaders/prefiltered.glsl's albedo of an anisotropic GGX lobe): any alphas,
    the wider along x or along y, mapped onto the table's (roughness, strength), against the
    quadrature of a microfacet conductor without Fresnel (A + B)."""
    from lobeview.materials.prefilter import split_sum_dfg

    rng = np.random.default_rng(11)
    for _ in range(16):
        alphas = np.sort(rng.uniform(0.04, 0.9, 2))
        alpha_x, alpha_y = alphas if rng.uniform() < 0.5 else alphas[::-1]
        theta, azimuth = np.arccos(rng.uniform(0.05, 1.0)), rng.uniform(0.0, 2 * np.pi)
        wo = np.array([np.sin(theta) * np.cos(azimuth), np.sin(theta) * np.sin(azimuth), np.cos(theta)])
        bsdf = build_bsdf(validate({"model": "microfacet", "distribution": "ggx", "alpha_u": alpha_x,
                                    "alpha_v": alpha_y, "fresnel": {"type": "none"}, "scale": 1.0}))  # fmt: skip
        exact = bsdf.albedo(wo, order=96)[0][0]
        looked_up = split_sum_dfg({"anisotropic": table}, "ggx", wo, alpha_x, alpha_y).sum()
        assert looked_up == pytest.approx(exact, rel=0.03), (alpha_x, alpha_y, wo)


def test_the_isotropic_table_was_far_off(table):
    """What the table replaced: the isotropic DFG at the geometric-mean alpha (strength 1,
    roughness 0.4, a view 50 degrees off the normal along the anisotropy direction)."""
    from lobeview.materials.prefilter import anisotropic_dfg_lookup, dfg_lookup
    from lobeview.viewer.prefiltered import dfg_texture_data

    wo = np.array([np.sin(np.radians(50)), 0.0, np.cos(np.radians(50))])
    exact = _glossy(0.4, 1.0).albedo(wo, order=96)[0][1]
    alpha_y = 0.16
    alpha_x = alpha_y + (1 - alpha_y) * 1.0
    isotropic = dfg_lookup(dfg_texture_data()[..., 2:], wo[2], np.sqrt(np.sqrt(alpha_x * alpha_y))).sum()
    assert isotropic > 1.2 * exact
    assert anisotropic_dfg_lookup(table, wo[2], 0.0, 0.4, 1.0).sum() == pytest.approx(exact, rel=0.02)


def test_textured_anisotropy_renders_like_the_same_factor(tmp_path):
    """Through the loader and the real pipeline: a quad whose anisotropyTexture holds strength 1
    and direction +x renders like the same strength given as anisotropyStrength, in normalised
    lobe-7 (the factor's lobe takes the exact per-material albedo table, the texture's the new
    per-pixel one): within 2 % (47 % before), and plain lobe-7 and the reference agree too."""
    from test_textures import _textured_quad_means

    methods = ("lobe-7+norm", "lobe-7", "reference")
    means = {}
    for textured in (False, True):
        extension = {"anisotropyStrength": 1.0}
        images = []
        if textured:
            texel = np.zeros((4, 4, 4), np.uint8)
            texel[..., 0], texel[..., 1], texel[..., 2], texel[..., 3] = 255, 128, 255, 255  # +x, strength 1
            images = [texel]
            extension["anisotropyTexture"] = {"index": 0}
        material = {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1.0], "metallicFactor": 1.0,
                                             "roughnessFactor": 0.4},
                    "extensions": {"KHR_materials_anisotropy": extension}}  # fmt: skip
        folder = tmp_path / ("textured" if textured else "factor")
        for method, mean in _textured_quad_means(folder, material, images, methods).items():
            means[textured, method] = mean
    for method in methods:
        assert means[True, method] == pytest.approx(means[False, method], rel=0.02), (method, means)


@pytest.mark.parametrize("strength,reference_mean", [(1.0, 0.117), (0.8, 0.157)])
def test_strong_gltf_anisotropy_matches_the_reference(tmp_path, strength, reference_mean):
    """A glTF metal (roughness 0.4) with KHR_materials_anisotropy strength 1 / 0.8 (alpha 0.16
    across, 1.0 / 0.71 along) under builtin:studio: lobe-7+norm and prefiltered within 3 % of the
    reference's mean. Issue 40 measured 0.153 / 0.175 / 0.349 (lobe-7, lobe-7+norm, prefiltered,
    then isotropic) against 0.117; now 0.115 / 0.115 (thirty-sixth session)."""
    import warnings

    from test_textures import _textured_gltf

    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    material = {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1.0], "metallicFactor": 1.0,
                                         "roughnessFactor": 0.4},
                "extensions": {"KHR_materials_anisotropy": {"anisotropyStrength": strength}}}  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(_textured_gltf(tmp_path, material, []))
        ctx = create_headless_context()
        renderer = SceneRenderer(ctx, scene, load_environment("builtin:studio"), size=(64, 64), progress=False,
                                 settings=RenderSettings(cube_face_size=64, mirrors=False))  # fmt: skip
    try:
        camera = Camera(position=(0.6, 1.2, 1.6), target=(0.5, 0.5, 0.0), fov_y=40.0)
        means = {}
        for method in ("reference", "lobe-7+norm", "prefiltered"):
            result = renderer.render(camera, method, spp=256)
            means[method] = float(result.radiance[result.mask].mean())
    finally:
        renderer.release()
        ctx.release()
    assert means["reference"] == pytest.approx(reference_mean, rel=0.03), means
    for method in ("lobe-7+norm", "prefiltered"):
        assert means[method] == pytest.approx(means["reference"], rel=0.03), (method, means)
