"""A first frame in seconds (issue 42 item 2): the viewer's renderer starts on preview cube maps
and builds the exact ones over later frames, nearest to the camera first; finished, they are
the non-progressive build's bit for bit and cached, and a material edit restarts the build."""

from __future__ import annotations

import warnings

import numpy as np
from test_frames_unchanged import _demo_scene, _scene_camera
from test_textures import _smooth_env

from lobeview.scenes.envmap import EnvironmentMap
from lobeview.viewer.scene_renderer import SceneRenderer
from lobeview.viewer.settings import RenderSettings

SIZE = (80, 50)


def _renderer(ctx, scene, cache_dir=None, progressive=False):
    env = EnvironmentMap.from_function(_smooth_env, height=32, name="smooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SceneRenderer(
            ctx, scene, env, size=SIZE, progress=False, cache_dir=cache_dir,
            settings=RenderSettings(cube_face_size=32), progressive_cubes=progressive,
        )  # fmt: skip


def _cube_sizes(renderer) -> dict:
    return {obj.index: obj.cube.face_size for obj in renderer.objects if obj.cube is not None}


def test_progressive_build_ends_with_the_exact_cube_maps_and_caches_them(ctx, tmp_path):
    scene = _demo_scene()
    camera = _scene_camera(scene, "overview")
    exact = _renderer(ctx, scene)
    progressive = _renderer(ctx, scene, cache_dir=tmp_path, progressive=True)
    try:
        final_sizes = _cube_sizes(exact)
        preview_sizes = _cube_sizes(progressive)
        assert preview_sizes.keys() == final_sizes.keys()
        assert all(preview_sizes[i] < final_sizes[i] for i in final_sizes)  # previews first
        assert progressive.cube_build_status is not None
        preview = progressive.render(camera, "lobe-7", spp=1).radiance
        assert np.all(np.isfinite(preview)) and preview.max() > 0.01
        assert not list(tmp_path.glob("cubes-*.npz"))  # nothing cached before the build ends
        # The first step renders the cube map of the object nearest the camera.
        progressive.continue_cube_build(0.0, camera)
        grown = [i for i, s in _cube_sizes(progressive).items() if s != preview_sizes[i]]
        eye = np.asarray(camera.position)
        nearest = min(final_sizes, key=lambda i: float(np.linalg.norm(progressive.objects[i].probe_centre - eye)))
        assert grown == [nearest]
        steps = 1
        while progressive.cube_build_status is not None:
            steps += progressive.continue_cube_build(0.0, camera)
        # A render per object and bounce, an install per object and later bounce, the cache
        # file, and the generator's end.
        bounces = progressive.cube_bounces
        assert steps == (2 * bounces - 1) * len(final_sizes) + 1 + 1
        assert _cube_sizes(progressive) == final_sizes
        for method in ("lobe-7", "reference"):
            spp = 3 if method == "reference" else 1
            exact.invalidate_mirrors()
            np.testing.assert_array_equal(
                progressive.render(camera, method, spp=spp).radiance, exact.render(camera, method, spp=spp).radiance
            )
        progressive.probes.bake.cache_writer.join()  # written in a thread: no frame waits for it
        assert list(tmp_path.glob("cubes-*.npz"))  # cached at the end: the next start is warm
    finally:
        progressive.release()
        exact.release()
    warm = _renderer(ctx, scene, cache_dir=tmp_path, progressive=True)
    try:
        assert warm.cube_build_status is None and _cube_sizes(warm) == final_sizes
    finally:
        warm.release()


def test_a_material_edit_restarts_the_build_for_the_edited_scene(ctx, tmp_path):
    scene = _demo_scene()
    progressive = _renderer(ctx, scene, cache_dir=tmp_path, progressive=True)
    try:
        progressive.continue_cube_build(0.0)
        index = next(o.index for o in progressive.objects if o.name == "walls")
        desc = dict(scene.materials[scene.objects[index].material].desc)
        desc["kd"] = [0.2, 0.6, 0.2]
        progressive.update_material(index, desc)
        done, total = progressive.probes.pending_progress
        assert done == 0 and total > 0  # started again
        while progressive.cube_build_status is not None:
            progressive.continue_cube_build(1.0)
        assert not list(tmp_path.glob("cubes-*.npz"))  # an edited scene's cube maps are not cached
    finally:
        progressive.release()
