"""A cube texel reads the whole footprint of the environment it covers, at every face size: small
lamps are neither lost nor multiplied when a capture is read into small faces (the lobe-width
rule's 32^2 and 64^2 faces, issue 45's method table).

numpy: equirect_to_cube_faces conserves the light of lamps smaller than a face texel (against the
equirectangular map's own integral); GL: the environment drawn into a small face (as cube_bake
draws every object's cube map) reads the environment cube's MIP level of its texel, so its mean
is the mean of the region it covers (level 0 at one point per pixel gave 0 or 64 times it)."""

from __future__ import annotations

import moderngl
import numpy as np
import pytest

from lobeview.core.cube_layout import face_directions, texel_solid_angles
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.viewer.cubemap import RadianceCube, equirect_to_cube_faces, face_supersample


def _lamp_env(seed: int, height: int = 512) -> EnvironmentMap:
    """A dark sky (0.01) with one lamp of one texel, 1e4 (a studio capture's bulb: it carries three
    quarters of the light), somewhere away from the poles."""
    rng = np.random.default_rng(seed)
    pixels = np.full((height, 2 * height, 3), 0.01, dtype=np.float32)
    pixels[rng.integers(height // 6, 5 * height // 6), rng.integers(0, 2 * height)] = 1e4
    return EnvironmentMap(image=pixels, name="lamp")


def _env_integral(env: EnvironmentMap) -> np.ndarray:
    """The equirectangular map's own integral over the sphere (its texels' solid angles)."""
    return np.einsum("i,ijc->c", env.texel_solid_angles(), env.image.astype(np.float64))


def _integral(faces: np.ndarray) -> np.ndarray:
    """Radiance integrated over the sphere of directions from cube faces (exact texel solid angles)."""
    omega = texel_solid_angles(faces.shape[1])
    return np.einsum("ij,fijc->c", omega, faces.astype(np.float64))


def test_face_supersample_covers_the_source_texels():
    assert face_supersample(512, 256) == 2  # the environment cube of a 1k capture: as before
    assert face_supersample(512, 32) == 16
    assert face_supersample(2048, 32) == 32  # capped (MAX_FACE_SUPERSAMPLE)
    assert face_supersample(32, 256, supersample=2) == 2


@pytest.mark.parametrize("size", [16, 32, 64, 256])
def test_small_faces_keep_the_light_of_lamps_smaller_than_a_texel(size):
    # Within 6 %: a one-texel spike read by bilinear lookups half a source texel apart keeps its
    # light only up to the sampling grid's phase (measured 0.95-1.05; the former rule at 256^2,
    # where it already took 2 x 2 points per source texel, gave the same). The former rule at
    # 16^2-64^2: 0.25 to 13.5 (the next test).
    for seed in range(5):
        env = _lamp_env(seed)
        np.testing.assert_allclose(_integral(equirect_to_cube_faces(env, size)), _env_integral(env), rtol=0.06)


def test_the_former_two_by_two_points_lose_or_multiply_a_lamp_at_32():
    """The test above fails for the former rule (2 x 2 points per texel at every size): at 32^2
    a texel covers 8 x 8 source texels, and its 4 bilinear points catch a lamp or miss it."""
    ratios = []
    for seed in range(5):
        env = _lamp_env(seed)
        faces = np.empty((6, 32, 32, 3))
        for face in range(6):
            faces[face] = env.lookup(face_directions(face, 32, 2).reshape(-1, 3)).reshape(32, 32, 4, 3).mean(axis=2)
        ratios.append(_integral(faces)[0] / _env_integral(env)[0])
    assert max(abs(r - 1.0) for r in ratios) > 0.3, ratios


def test_the_environment_drawn_into_a_small_face_reads_its_footprint(ctx):
    """draw_environment (shaders/background.frag) into an 8 x 8 face of a 128^2 lamp cube: each
    pixel is the mean of the 16 x 16 texels it covers (the MIP level), not one of them."""
    from lobeview.viewer.cube_bake import face_view
    from lobeview.viewer.render_base import draw_environment
    from lobeview.viewer.shaders import ProgramCache

    size, small = 128, 8
    rng = np.random.default_rng(3)
    faces = np.full((6, size, size, 3), 0.1, dtype=np.float32)
    lamps = rng.integers(0, size, (6, 60, 2))
    for face in range(6):
        faces[face, lamps[face, :, 0], lamps[face, :, 1]] = 200.0
    cube = RadianceCube(ctx, faces, mip_filter="box")
    target = ctx.texture((small, small), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[target])
    programs, vaos = ProgramCache(ctx), {}
    near, far = 0.1, 10.0
    depth = (-(far + near) / (far - near), -2 * far * near / (far - near))
    projection = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, *depth], [0, 0, -1, 0]], dtype=np.float64)
    try:
        for face in range(6):
            fbo.use()
            fbo.clear()
            ctx.disable(moderngl.DEPTH_TEST)
            draw_environment(ctx, programs, vaos, cube, projection @ face_view(face, np.zeros(3)))
            got = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32).reshape(small, small, 4)[..., :3]
            # The face's texels averaged over each pixel's 16 x 16 block (rows = t, as face_view lays them out).
            expected = faces[face].reshape(small, size // small, small, size // small, 3).mean(axis=(1, 3))
            assert abs(got.mean() / expected.mean() - 1.0) < 0.03, face
            # Per pixel: within the level's box average and its bilinear neighbours' (a footprint
            # of one 16 x 16 block, read at its centre between four level-4 texels).
            assert np.corrcoef(got.ravel(), expected.ravel())[0, 1] > 0.6, face
    finally:
        for vao in vaos.values():
            vao.release()
        fbo.release()
        target.release()
        cube.release()
