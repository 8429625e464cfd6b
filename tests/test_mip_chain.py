"""The tent MIP chain of radiance cubes (viewer/cubemap.py tent_mipmaps, issue 20 item 1): the
GPU levels against the numpy reference away from face edges, constants and means preserved
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
    with pytest.raises(ValueError, match="even square"):
        tent_downsample_face(np.zeros((5, 5, 1)))


def _levels(ctx, cube, size: int, count: int) -> list[np.ndarray]:
    from lobeview.viewer.shaders import ProgramCache

    shader = ProgramCache(ctx).compute("cube_level_read.comp")
    levels = []
    for level in range(count):
        face = max(size >> level, 1)
        out = ctx.buffer(reserve=6 * face * face * 16)
        cube.bind_to_image(0, read=True, write=False, level=level, format=0x8814)
        shader["u_size"] = face
        out.bind_to_storage_buffer(0)
        shader.run((face + 7) // 8, (face + 7) // 8, 6)
        ctx.finish()
        levels.append(np.frombuffer(out.read(), dtype=np.float32).reshape(6, face, face, 4)[..., :3].copy())
        out.release()
    return levels


def test_gpu_tent_levels_match_numpy_inside_faces_and_keep_constants_and_means():
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.cubemap import upload_cube

    ctx = create_headless_context()
    try:
        rng = np.random.default_rng(1)
        faces = rng.random((6, 32, 32, 3)).astype(np.float32) * np.array([1.0, 5.0, 100.0], np.float32)
        cube = upload_cube(ctx, faces, mip_filter="tent")
        levels = _levels(ctx, cube, 32, 3)
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
        for level in _levels(ctx, constant, 16, 5):
            np.testing.assert_allclose(level, 0.7, rtol=1e-6)
        constant.release()
        with pytest.raises(ValueError, match="unknown MIP filter"):
            upload_cube(ctx, faces, mip_filter="gauss")
    finally:
        ctx.release()
