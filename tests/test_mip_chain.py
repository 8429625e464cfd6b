"""The tent MIP chain of radiance cubes and mirror buffers (viewer/mip_chain.py, issue 20 item 1):
the GPU levels against the numpy reference away from face edges, constants and means preserved
across the seamless edges, and the numpy filter itself against its definition."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.scenes.env_sampling import tent_downsample_face


def test_numpy_tent_is_the_separable_1331_filter():
    rng = np.random.default_rng(0)
    face = rng.random((8, 8, 3))
    out = tent_downsample_face(face)
    w = np.array([1, 3, 3, 1]) / 8
    j, i = 2, 1  # an interior destination texel: source rows 3..6, columns 1..4
    expected = np.einsum("a,b,abc->c", w, w, face[2 * j - 1 : 2 * j + 3, 2 * i - 1 : 2 * i + 3])
    np.testing.assert_allclose(out[j, i], expected, rtol=1e-12)
    np.testing.assert_allclose(tent_downsample_face(np.full((8, 8, 1), 2.5)), 2.5)
    with pytest.raises(ValueError, match="even sizes"):
        tent_downsample_face(np.zeros((5, 6, 1)))
    assert tent_downsample_face(np.zeros((4, 10, 2))).shape == (2, 5, 2)


def _levels(ctx, cube, count: int) -> list[np.ndarray]:
    from lobeview.viewer.mip_chain import read_cube_level

    return [read_cube_level(ctx, cube, level)[..., :3] for level in range(count)]


def test_gpu_tent_levels_match_numpy_inside_faces_and_keep_constants_and_means():
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.mip_chain import upload_cube

    ctx = create_headless_context()
    try:
        rng = np.random.default_rng(1)
        faces = rng.random((6, 32, 32, 3)).astype(np.float32) * np.array([1.0, 5.0, 100.0], np.float32)
        cube = upload_cube(ctx, faces, mip_filter="tent")
        levels = _levels(ctx, cube, 3)
        np.testing.assert_array_equal(levels[0], faces)
        for level in (1, 2):
            for f in range(6):
                expected = tent_downsample_face(levels[level - 1][f])
                border = 1  # texels whose taps reach across a face edge (seamless there, clamped in numpy)
                np.testing.assert_allclose(
                    levels[level][f][border:-border, border:-border], expected[border:-border, border:-border],
                    rtol=1e-5, atol=1e-5,
                )  # fmt: skip
            # Means over all faces survive the edges (each face's texels have equal solid angle
            # only roughly, so this is a loose check of the seams, not an identity).
            np.testing.assert_allclose(levels[level].mean(axis=(0, 1, 2)), faces.mean(axis=(0, 1, 2)), rtol=0.02)
        cube.release()
        constant = upload_cube(ctx, np.full((6, 16, 16, 3), 0.7, np.float32), mip_filter="tent")
        for level in _levels(ctx, constant, 5):
            np.testing.assert_allclose(level, 0.7, rtol=1e-6)
        constant.release()
        with pytest.raises(ValueError, match="unknown MIP filter"):
            upload_cube(ctx, faces, mip_filter="gauss")
    finally:
        ctx.release()


def _levels_2d(ctx, texture, count: int) -> list[np.ndarray]:
    """Levels of a 2D RGBA32F texture through a framebuffer per level."""
    levels = []
    for level in range(count):
        width, height = max(texture.size[0] >> level, 1), max(texture.size[1] >> level, 1)
        data = texture.read(level=level)
        levels.append(np.frombuffer(data, np.float32).reshape(height, width, 4)[..., :3].copy())
    return levels


def test_gpu_tent_levels_of_2d_buffers_match_numpy_and_keep_constants():
    """Mirror buffers are 2D and of any size: levels of an even-sized buffer equal the numpy tent
    (clamped at the edges like the sampler), odd sizes keep constants and means."""
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.mip_chain import build_mip_chain

    ctx = create_headless_context()
    try:
        rng = np.random.default_rng(2)
        image = (rng.random((16, 40, 4)) * np.array([1.0, 5.0, 100.0, 1.0])).astype(np.float32)
        texture = ctx.texture((40, 16), 4, image.tobytes(), dtype="f4")
        build_mip_chain(ctx, texture, "tent")
        levels = _levels_2d(ctx, texture, 4)
        for level in (1, 2, 3):
            np.testing.assert_allclose(levels[level], tent_downsample_face(levels[level - 1]), rtol=1e-5, atol=1e-5)
        box = ctx.texture((40, 16), 4, image.tobytes(), dtype="f4")
        build_mip_chain(ctx, box, "box")
        assert np.abs(_levels_2d(ctx, box, 2)[1] - levels[1]).max() > 0.1  # the tent is not the box
        odd = ctx.texture((37, 23), 4, np.full((23, 37, 4), 0.7, np.float32).tobytes(), dtype="f4")
        build_mip_chain(ctx, odd, "tent")
        for level in _levels_2d(ctx, odd, 6):  # 37x23 .. 1x1
            np.testing.assert_allclose(level, 0.7, rtol=1e-6)
        noisy = ctx.texture((37, 23), 4, rng.random((23, 37, 4)).astype(np.float32).tobytes(), dtype="f4")
        build_mip_chain(ctx, noisy, "tent")
        noisy_levels = _levels_2d(ctx, noisy, 3)
        np.testing.assert_allclose(noisy_levels[2].mean(axis=(0, 1)), noisy_levels[0].mean(axis=(0, 1)), atol=0.03)
        for item in (texture, box, odd, noisy):
            item.release()
        with pytest.raises(ValueError, match="unknown MIP filter"):
            build_mip_chain(ctx, texture, "gauss")
    finally:
        ctx.release()


def test_lobe_n_default_bias_follows_the_chain_in_the_renderers():
    """--mip-filter box renders lobe-N at the box chain's best bias (-0.5) and the tent chain at
    -1 (core/methods.py); fis-N keeps -0.5 on both. The renderer's default equals the explicit bias."""
    from lobeview.core.methods import Method
    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    lobe, fis = Method("lobe", 7, normalize=True), Method("fis", 8)
    assert (lobe.default_lod_bias(), lobe.default_lod_bias("tent"), lobe.default_lod_bias("box")) == (-1.0, -1.0, -0.5)
    assert fis.default_lod_bias("tent") == fis.default_lod_bias("box") == -0.5
    ctx = create_headless_context()
    try:
        env = EnvironmentMap.from_function(lambda d: 1.0 + 4.0 * np.maximum(d[..., :1], 0.0) ** 8 * [1.0, 0.8, 0.6],
                                           height=32, name="lobe")  # fmt: skip
        bsdf = build_bsdf(load_material("gold-ggx"))
        camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
        images = {}
        for chain in ("box", "tent"):
            renderer = PreviewRenderer(ctx, env, uv_sphere(rings=16, segments=32), size=(32, 32), face_size=32,
                                       mip_filter=chain)  # fmt: skip
            for bias in (None, -0.5, -1.0):
                images[chain, bias] = renderer.render(camera, bsdf, lobe, lod_bias=bias, background=False).radiance
            renderer.release()
        np.testing.assert_array_equal(images["box", None], images["box", -0.5])
        np.testing.assert_array_equal(images["tent", None], images["tent", -1.0])
        assert np.abs(images["box", -0.5] - images["box", -1.0]).max() > 1e-4  # the bias matters here
    finally:
        ctx.release()


def test_chains_compile_their_shaders_once_per_context():
    """A mirror buffer re-filtered every frame and cube maps uploaded one after another reuse the
    context's compute shaders (a new GL program per chain was made and never released)."""
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.mip_chain import build_mip_chain, read_cube_level, upload_cube

    ctx = create_headless_context()
    compiled = []
    compile_shader = ctx.compute_shader
    ctx.compute_shader = lambda source: compiled.append(source) or compile_shader(source)
    try:
        buffer = ctx.texture((24, 16), 4, dtype="f4")
        buffer.build_mipmaps()
        for _ in range(3):  # three frames of one mirror buffer
            build_mip_chain(ctx, buffer, "tent", allocated=True)
        for _ in range(2):
            cube = upload_cube(ctx, np.full((6, 8, 8, 3), 0.5, np.float32), mip_filter="tent")
            np.testing.assert_allclose(read_cube_level(ctx, cube, 1)[..., :3], 0.5, rtol=1e-6)
            cube.release()
        assert len(compiled) == 3  # the 2D tent, the cube tent, the level read-back: once each
    finally:
        ctx.release()
