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


def test_progressive_build_ends_with_the_exact_cube_maps_and_caches_them(ctx, tmp_path, monkeypatch):
    scene = _demo_scene()
    camera = _scene_camera(scene, "overview")
    exact = _renderer(ctx, scene)
    from lobeview.viewer.cube_bake import CubeBake

    preview_renders = []  # the specular flag of every face render the progressive start makes
    original = CubeBake.render_faces
    monkeypatch.setattr(CubeBake, "render_faces", lambda self, *a, **k: preview_renders.append(
        k.get("specular", False)) or original(self, *a, **k))  # fmt: skip
    progressive = _renderer(ctx, scene, cache_dir=tmp_path, progressive=True)
    monkeypatch.undo()
    try:
        final_sizes = _cube_sizes(exact)
        preview_sizes = _cube_sizes(progressive)
        assert preview_sizes.keys() == final_sizes.keys()
        assert all(preview_sizes[i] < final_sizes[i] for i in final_sizes)  # previews first
        # of the first bounce only (cube_probes.PREVIEW_BOUNCES): one diffuse render per cube map
        assert progressive.cube_bounces > 1 and preview_renders == [False] * len(final_sizes)
        assert progressive.cube_build_status is not None
        preview = progressive.render(camera, "lobe-7", spp=1).radiance
        assert np.all(np.isfinite(preview)) and preview.max() > 0.01
        assert not list(tmp_path.glob("cubes-*.npz"))  # nothing cached before the build ends
        # Its horizon map is not in yet (the window's worker traces it, app/finishing.py): the build
        # holds after its first bounce until it is, as the worker's tracing leaves it in the cache.
        assert progressive.shading.missing_horizon_maps == 1
        progressive.horizon_maps_traced_elsewhere = True  # what the window sets while its worker runs
        # The first step renders the cube map of the object nearest the camera.
        progressive.continue_cube_build(0.0, camera)
        grown = [i for i, s in _cube_sizes(progressive).items() if s != preview_sizes[i]]
        eye = np.asarray(camera.position)
        nearest = min(final_sizes, key=lambda i: float(np.linalg.norm(progressive.objects[i].probe_centre - eye)))
        assert grown == [nearest]
        steps = 1
        while not progressive.probes.held:
            steps += progressive.continue_cube_build(0.0, camera)
        assert steps == len(final_sizes) and progressive.continue_cube_build(0.0, camera) == 0
        assert "waits for the self-occlusion horizons" in progressive.cube_build_status
        from lobeview.scenes.horizon_maps import trace_horizon_maps

        assert trace_horizon_maps(scene, tmp_path) == 1  # the worker's job
        assert progressive.shading.prepare_horizon_maps(trace=False) == 0  # what the window does then
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
        # no worker traced the horizon map: the build traced it itself before its specular bounces
        assert progressive.shading.missing_horizon_maps == 0 and progressive.shading.horizon_maps
        assert not list(tmp_path.glob("cubes-*.npz"))  # an edited scene's cube maps are not cached
    finally:
        progressive.release()
