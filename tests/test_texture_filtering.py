"""Anisotropic filtering of material textures (issue 40: the WaterBottle's label blurred at
oblique angles): a texture seen at a grazing angle keeps its detail along the axis the view does
not compress, as a supersampled render shows it; on drivers whose anisotropic filter is
defective (Mesa 22.3's llvmpipe) the viewer keeps trilinear filtering."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials.spec import validate
from lobeview.scenes.meshes import quad
from lobeview.scenes.scene import LINEAR, LINEAR_MIPMAP_LINEAR, Scene, SceneMaterial, SceneObject, TextureSlot

STRIPES = 6  # stripe pairs across the quad along u: 3-4 pixels a stripe at the far end
TEXELS_PER_STRIPE = 4
ROWS = 512  # along v, which the view compresses: the MIP level a far pixel needs is high


def _striped_floor() -> Scene:
    """A 2 m x 8 m floor whose base colour alternates black/white along x (u) in 2 x STRIPES
    stripes; seen from above one end, it recedes along -z, compressing v far more than u."""
    columns = np.arange(2 * STRIPES * TEXELS_PER_STRIPE)
    row = np.where((columns // TEXELS_PER_STRIPE) % 2 == 0, 255, 0).astype(np.uint8)
    image = np.zeros((ROWS, columns.size, 4), np.uint8)
    image[..., :3] = row[None, :, None]
    image[..., 3] = 255
    slot = TextureSlot(image, srgb=False, mag_filter=LINEAR, min_filter=LINEAR_MIPMAP_LINEAR)
    desc = validate({"model": "gltf", "base_color": [1.0, 1.0, 1.0], "metallic": 0.0, "roughness": 1.0})
    material = SceneMaterial("stripes", desc, textures={"base_color": slot})
    mesh = quad([-1.0, 0.0, 1.0], [2.0, 0.0, 0.0], [0.0, 0.0, -8.0])
    scene = Scene([SceneObject("floor", mesh, 0)], [material])
    scene.objects[0].planar_reflector = False
    return scene


def _render(size, anisotropy: float | None, monkeypatch, scene=None, camera=None) -> np.ndarray:
    """The grey value of the floor (or ``scene``; 0 off its objects) with the material
    samplers' anisotropy forced to ``anisotropy`` on any driver (None: the viewer's choice)."""
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer import scene_shading
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    if anisotropy is not None:
        monkeypatch.setattr(scene_shading, "TEXTURE_ANISOTROPY", anisotropy)
        monkeypatch.setattr(scene_shading, "ANISOTROPY_DEFECTIVE_RENDERERS", ())
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=16, name="white")
    with pytest.warns(UserWarning, match="no usable lightmap"):
        renderer = SceneRenderer(ctx, scene or _striped_floor(), env, size=size, progress=False,
                                 settings=RenderSettings(cube_face_size=16))  # fmt: skip
    try:
        camera = camera or Camera(position=(0.0, 0.35, 1.6), target=(0.0, 0.0, -3.0), fov_y=30.0)
        result = renderer.render(camera, "lobe-7")
        assert result.mask.any() and not result.invalid.any()
        return np.where(result.mask, result.radiance.mean(axis=-1), 0.0)
    finally:
        renderer.release()
        ctx.release()


def _far_contrast(image: np.ndarray) -> float:
    """The standard deviation across x of the floor's far rows (top third of the floor in
    the frame, where v is compressed about 8x), relative to their mean."""
    rows = np.nonzero(image.max(axis=1) > 0)[0]
    far = image[rows[0] + 2 : rows[0] + 2 + max(2, len(rows) // 8)]
    core = far[:, image.shape[1] // 4 : 3 * image.shape[1] // 4]
    return float(core.std(axis=1).mean() / max(core.mean(), 1e-6))


def test_anisotropic_filtering_keeps_detail_at_grazing_angles(monkeypatch):
    """16x anisotropic filtering against a 4x4-supersampled render (its own MIP levels are then
    four times finer, so filtering hardly matters) and against plain trilinear filtering."""
    size = (128, 96)
    anisotropic = _render(size, 16.0, monkeypatch)
    supersampled = _render((size[0] * 4, size[1] * 4), 16.0, monkeypatch)
    truth = supersampled.reshape(size[1], 4, size[0], 4).mean(axis=(1, 3))
    isotropic = _render(size, 1.0, monkeypatch)
    c_truth, c_aniso, c_iso = (_far_contrast(x) for x in (truth, anisotropic, isotropic))
    assert c_truth > 0.3, c_truth  # the stripes are resolvable across x in the truth
    assert c_iso < 0.5 * c_truth, (c_iso, c_truth)  # trilinear alone washes them out
    assert c_aniso > 0.7 * c_truth, (c_aniso, c_truth)
    # and the mean brightness stays what it is (filtering moves detail, not energy)
    mask = truth > 0
    assert abs(anisotropic[mask].mean() / truth[mask].mean() - 1.0) < 0.02


def test_the_viewer_filters_anisotropically_where_the_driver_does_it_right():
    from lobeview.viewer.scene_shading import TEXTURE_ANISOTROPY, texture_anisotropy

    assert texture_anisotropy("llvmpipe (LLVM 15.0.6, 256 bits)", 16.0) == 1.0
    assert texture_anisotropy("NVIDIA H100 80GB HBM3/PCIe/SSE2", 16.0) == TEXTURE_ANISOTROPY == 16.0
    assert texture_anisotropy("AMD Radeon Pro", 8.0) == 8.0
    assert texture_anisotropy("a driver without the extension", 0.0) == 1.0


def _head_on_checker():
    """A 2 m quad filling the frame head-on with a 0.5/1 checker of 8-texel squares (256^2
    texels on 124 pixels): a footprint as wide as it is tall, where anisotropic filtering must
    equal trilinear."""
    index = np.arange(256) // 8
    grey = np.where((index[:, None] + index[None, :]) % 2 == 0, 255, 128).astype(np.uint8)
    image = np.zeros((256, 256, 4), np.uint8)
    image[..., :3] = grey[..., None]
    image[..., 3] = 255
    slot = TextureSlot(image, srgb=False, mag_filter=LINEAR, min_filter=LINEAR_MIPMAP_LINEAR)
    desc = validate({"model": "thesis", "kd": [0.8, 0.8, 0.8], "lobes": []})
    scene = Scene([SceneObject("quad", quad([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]), 0)],
                  [SceneMaterial("checker", desc, textures={"base_color": slot})])  # fmt: skip
    scene.objects[0].planar_reflector = False
    return scene


def test_head_on_textures_equal_trilinear_or_the_driver_is_listed_defective(monkeypatch):
    """Seen head-on, anisotropic filtering must give trilinear's image. Where it does not
    (llvmpipe: garbled columns), the driver must be in ANISOTROPY_DEFECTIVE_RENDERERS, and the
    viewer's own frame is then trilinear's exactly; should a Mesa update fix it, this test
    says so and the entry can go."""
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_shading import texture_anisotropy

    ctx = create_headless_context()
    renderer_name = ctx.info["GL_RENDERER"]
    defective = texture_anisotropy(renderer_name, ctx.max_anisotropy) == 1.0 and ctx.max_anisotropy > 1.0
    ctx.release()
    camera = Camera(position=(0.0, 0.0, 2.6), target=(0.0, 0.0, 0.0), fov_y=float(2 * np.degrees(np.arctan(1 / 2.6))))
    frames = {}
    for anisotropy in (16.0, 1.0, None):
        with monkeypatch.context() as patch:
            frames[anisotropy] = _render((128, 128), anisotropy, patch, _head_on_checker(), camera)[2:-2, 2:-2]
    forced_error = float(np.abs(frames[16.0] - frames[1.0]).mean())
    if defective:
        assert forced_error > 0.02, f"{renderer_name}: anisotropic filtering looks right now ({forced_error:.4f})"
        np.testing.assert_array_equal(frames[None], frames[1.0])
    else:
        assert forced_error < 0.01, f"{renderer_name}: anisotropic filtering differs head-on ({forced_error:.4f})"
