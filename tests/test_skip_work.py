"""Work a scene does not need is skipped (issue 18), and skipping changes no pixel: frustum
culling (the box test is conservative, the renderer counts what it culls, frame and cube maps are
unchanged) and the reference's importance tables (built only when a reference pass runs)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from lobeview.viewer.camera import (
    Camera,
    box_corners,
    outside_frustum,
    outside_frustum_boxes,
    outside_frustum_many,
    perspective,
)
from lobeview.viewer.camera import look_at as camera_look_at


def _points_in_frustum(points: np.ndarray, view_proj: np.ndarray) -> np.ndarray:
    clip = np.c_[points, np.ones(len(points))] @ view_proj.T
    w = clip[:, 3:4]
    return np.all((np.abs(clip[:, :3]) <= w) & (w > 0), axis=1)


def test_box_test_never_drops_a_box_with_a_point_in_view_and_drops_far_away_boxes():
    rng = np.random.default_rng(3)
    view_proj = perspective(60.0, 1.6, 0.1, 50.0) @ camera_look_at((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0, 1, 0))
    culled = kept_empty = 0
    boxes, verdicts, extents = [], [], []
    for _ in range(3000):
        centre = rng.uniform(-30.0, 30.0, 3)
        half = rng.uniform(0.05, 6.0, 3)
        corners = box_corners(centre - half, centre + half)
        extents.append((centre - half, centre + half))
        points = centre + half * rng.uniform(-1.0, 1.0, (400, 3))
        visible = _points_in_frustum(np.vstack([points, corners]), view_proj).any()
        boxes.append(corners)
        verdicts.append(outside_frustum(corners, view_proj))
        if verdicts[-1]:
            culled += 1
            assert not visible, (centre, half)  # conservative: a visible box is never culled
        elif not visible:
            kept_empty += 1
    # Most boxes out of view are culled (the rest straddle a frustum edge outside two planes).
    assert culled > 1500 and kept_empty < 0.2 * culled, (culled, kept_empty)
    # The per-pass batch (every object of a pass in one product) gives the same verdicts.
    np.testing.assert_array_equal(outside_frustum_many(np.array(boxes), view_proj), verdicts)
    # ... and so does the boxes' plane test (no corners: the drawer's and occlusion test's cull).
    lows, highs = np.array(extents).transpose(1, 0, 2)
    np.testing.assert_array_equal(outside_frustum_boxes(lows, highs, view_proj), verdicts)
    # Behind the eye (w < 0 at every corner) and beyond the far plane.
    assert outside_frustum(box_corners((-1, -1, 2), (1, 1, 4)), view_proj)
    assert outside_frustum(box_corners((-1, -1, -80), (1, 1, -60)), view_proj)
    # A box around the eye is kept.
    assert not outside_frustum(box_corners((-1, -1, -1), (1, 1, 1)), view_proj)


def test_box_plane_test_is_the_corner_test_for_oblique_and_flat_boxes():
    """A mirror camera's oblique near plane (scenes/planar_mirror.py) and boxes flat in one axis
    (floors, walls: what reflectors and quads have) give the same verdicts both ways."""
    from lobeview.scenes.planar_mirror import PlanarReflector, mirror_camera

    rng = np.random.default_rng(11)
    view = camera_look_at((0.5, 1.6, 3.0), (0.0, 0.4, -2.0), (0, 1, 0))
    floor = PlanarReflector(np.array([0.0, 1.0, 0.0, 0.0]), np.array([-5.0, 0.0, -5.0]), np.array([5.0, 0.0, 5.0]))
    oblique = mirror_camera(view, perspective(55.0, 1.5, 0.05, 80.0), floor, (150, 100)).view_projection
    low = rng.uniform(-12.0, 12.0, (4000, 3))
    size = rng.uniform(0.0, 4.0, (4000, 3)) * (rng.uniform(size=(4000, 3)) > 0.2)  # a fifth flat per axis
    high = low + size
    corners = np.array([box_corners(a, b) for a, b in zip(low, high, strict=True)])
    for view_proj in (oblique, perspective(70.0, 1.0, 0.1, 30.0) @ view):
        expected = outside_frustum_many(corners, view_proj)
        assert 0.1 < expected.mean() < 0.9
        np.testing.assert_array_equal(outside_frustum_boxes(low, high, view_proj), expected)


def test_culling_skips_objects_and_changes_no_pixel(ctx):
    from lobeview.scenes.demo import build_demo_scene
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = load_gltf(build_demo_scene())
    env = EnvironmentMap.from_function(lambda d: 0.5 + 0.5 * np.clip(d[..., 1:2], 0, 1) * np.ones(3), 16)
    renderers, images = {}, {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for culling in (True, False):
            renderers[culling] = SceneRenderer(
                ctx,
                scene,
                env,
                size=(96, 60),
                progress=False,
                settings=RenderSettings(cube_face_size=32, frustum_culling=culling),
            )
    # Real-time methods never build the environment importance tables (nor does the bake).
    assert not any(o.cube.importance_built for r in renderers.values() for o in r.objects if o.cube is not None)
    cam = next(c for c in scene.cameras if c.name == "table")  # the close-up: part of the room is behind it
    camera = Camera(tuple(cam.position), tuple(cam.target), tuple(cam.up), cam.fov_y)
    for culling, renderer in renderers.items():
        images[culling] = renderer.render(camera, "lobe-5", spp=1).radiance
    on, off = renderers[True], renderers[False]
    counts_on, counts_off = on.draw_counts.passes, off.draw_counts.passes
    # The camera sees part of the room: some objects are culled, and everything else is drawn.
    assert counts_on["camera"].culled > 0
    assert counts_on["camera"].drawn + counts_on["camera"].culled == counts_off["camera"].drawn
    assert counts_off["camera"].culled == 0 and counts_off["cube map"].culled == 0
    # A cube-map face sees a sixth of the room: most draws there are skipped.
    assert counts_on["cube map"].culled > counts_on["cube map"].drawn
    assert counts_on["mirror"].drawn + counts_on["mirror"].culled == counts_off["mirror"].drawn
    assert any("culled" in line for line in on.draw_report)
    # Nothing that was skipped could have reached a pixel: cube maps and frame are the same.
    for a, b in zip(on.objects, off.objects, strict=True):
        if a.cube is not None:
            np.testing.assert_allclose(a.cube.faces, b.cube.faces, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(images[True], images[False], rtol=1e-6, atol=1e-7)
    assert not any(o.cube.importance_built for o in on.objects if o.cube is not None)
    # The reference builds them for the cubes it reads, and the memory report counts what it built.
    on.render(camera, "reference", spp=4)
    drawn = [o for o in on.objects if o.cube is not None and o.cube.importance_built]
    assert drawn
    for o in drawn:
        cube = o.cube
        built = cube.env_cdf.width * cube.env_cdf.height * 4 + 6 * cube.env_pdf.size[0] * cube.env_pdf.size[1] * 4
        assert cube.importance_memory() == built
    for renderer in renderers.values():
        renderer.release()


def test_depth_pre_pass_draws_the_opaque_objects_and_leaves_the_frame_as_it_was(ctx):
    """The camera pass's depth pre-pass (viewer/occlusion.py) shades each pixel once; the frame
    is the one drawn without it but at exact depth ties (surfaces meeting at an edge), where the
    last drawn rather than the first drawn surface wins."""
    from lobeview.scenes.demo import build_demo_scene
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = load_gltf(build_demo_scene())
    scene.materials[0].alpha_mode = "BLEND"  # blended and masked surfaces write no pre-pass depth
    scene.materials[1].alpha_mode = "MASK"
    env = EnvironmentMap.from_function(lambda d: 0.5 + 0.5 * np.clip(d[..., 1:2], 0, 1) * np.ones(3), 16)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(
            ctx, scene, env, size=(160, 100), progress=False, settings=RenderSettings(cube_face_size=32)
        )
    not_opaque = {i for i, o in enumerate(scene.objects) if o.material in (0, 1)}
    assert not_opaque
    opaque = {obj.index for obj, _ in renderer.drawer.opaque_objects(False)}
    assert opaque == set(range(len(scene.objects))) - not_opaque
    cam = next(c for c in scene.cameras if c.name == "table")
    camera = Camera(tuple(cam.position), tuple(cam.target), tuple(cam.up), cam.fov_y)
    images = {}
    for prepass in (False, True):
        renderer.configure(depth_prepass=prepass)
        images[prepass] = renderer.render(camera, "lobe-5", spp=1).radiance
        counts = renderer.draw_counts.of("depth pre-pass")
        if prepass:
            # Every opaque object the camera pass draws had its depth drawn first.
            assert counts.drawn + counts.culled == len(scene.objects) - len(not_opaque)
            assert 0 < counts.drawn <= renderer.draw_counts.of("camera").drawn
        else:
            assert counts.drawn == counts.culled == 0
    same = np.all(images[True] == images[False], axis=2)
    assert same.mean() > 0.999
    renderer.release()


def test_a_damaged_cube_map_cache_is_warned_about_and_rendered_again(ctx, tmp_path):
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.mirror_scene import mirror_floor_scene
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = mirror_floor_scene(0.05)
    env = EnvironmentMap.from_function(lambda d: 0.5 + 0.5 * np.clip(d[..., 1:2], 0, 1) * np.ones(3), 16)

    def start():
        # The floor is a reflector: with its cube map built at start-up like any glossy object.
        return SceneRenderer(
            ctx,
            scene,
            env,
            size=(32, 20),
            cache_dir=tmp_path,
            progress=False,
            settings=RenderSettings(cube_face_size=16, reflector_cubes_on_demand=False),
        )

    first = start()
    (cache_file,) = tmp_path.glob("cubes-*.npz")
    expected = first.objects[0].cube.faces
    first.release()
    for damage in (cache_file.read_bytes()[:300], b"PK\x03\x04garbage", b""):
        cache_file.write_bytes(damage)
        with pytest.warns(UserWarning, match="unusable cached cube maps"):
            again = start()
        np.testing.assert_array_equal(again.objects[0].cube.faces, expected)
        again.release()
        with np.load(cache_file) as data:  # rewritten whole
            assert data["cube_0"].shape == (6, 16, 16, 3)
    assert not list(tmp_path.glob("*.tmp"))


def test_radiance_cubes_keep_no_cpu_copy_and_read_back_exactly_what_was_uploaded(ctx):
    from lobeview.scenes.env_sampling import CubeImportance
    from lobeview.viewer.cubemap import RadianceCube

    rng = np.random.default_rng(7)
    faces = (rng.random((6, 32, 32, 3)) * 10.0 ** rng.uniform(-6, 6, (6, 32, 32, 1))).astype(np.float32)
    faces[2, 5, 7] = 1.0e9  # a sun seen through a window: beyond half precision
    cube = RadianceCube(ctx, faces)
    kept = [name for name, value in vars(cube).items() if isinstance(value, np.ndarray) and value.size >= 6 * 32 * 32]
    assert kept == []  # nothing face-sized stays on the CPU
    np.testing.assert_array_equal(cube.faces, faces)  # float32 texels: bit-exact
    np.testing.assert_array_equal(cube.importance.cdf, CubeImportance.from_faces(faces, size=32).cdf)
    cube.release()


def test_albedo_tables_are_cached_on_disk_and_damaged_files_rebuilt(tmp_path, monkeypatch):
    """A second start does not rebuild the normalisation tables (issue 18 item 4); a damaged or
    foreign cache file is rebuilt with a warning, never used."""
    from lobeview.materials.patterns import AlbedoTable, specular_lobes
    from lobeview.materials.spec import build_bsdf, load_material
    from lobeview.viewer import material_gpu

    lobe = specular_lobes(build_bsdf(load_material("brushed-steel-beckmann")))[0]
    material_gpu._ALBEDO_TABLES.clear()
    built = material_gpu.albedo_table_for(lobe, tmp_path).values
    files = list((tmp_path / "albedo").glob("albedo-v*.npy"))
    assert len(files) == 1
    np.testing.assert_array_equal(built, AlbedoTable.build(lobe).values)

    def no_build(*_):
        raise AssertionError("rebuilt although cached")

    material_gpu._ALBEDO_TABLES.clear()
    with monkeypatch.context() as patch:
        patch.setattr(AlbedoTable, "build", classmethod(no_build))
        np.testing.assert_array_equal(material_gpu.albedo_table_for(lobe, tmp_path).values, built)
    for damage in (b"not a numpy file", None):
        if damage is None:
            np.save(files[0], np.full((3, 3), np.nan))  # a readable array of the wrong shape and values
        else:
            files[0].write_bytes(damage)
        material_gpu._ALBEDO_TABLES.clear()
        with pytest.warns(UserWarning, match="albedo table"):
            again = material_gpu.albedo_table_for(lobe, tmp_path).values
        np.testing.assert_array_equal(again, built)
    material_gpu._ALBEDO_TABLES.clear()


@pytest.mark.parametrize(
    ("preset", "mode"),
    [("frosted-glass", "lobe"), ("alanod-2000gs-1lobe", "multi"), ("plastic", "phong"), ("plastic", "lobe2d")],
)
def test_lobe_map_fits_round_trip_through_the_disk_cache(tmp_path, monkeypatch, preset, mode):
    """A second start with `prefiltered` loads its lobe-map fits instead of fitting again (5.7 s
    of the demo's 8 s shade); what comes back is the same fit, and a damaged file is refitted."""
    from lobeview.materials import lobe_fit
    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf, load_material

    lobe = specular_lobes(build_bsdf(load_material(preset)))[-1]
    lobe_fit._FITS.clear()
    fitted = lobe_fit.fit_lobe_maps(lobe, mode, directory=tmp_path)
    files = list((tmp_path / "lobe_fits").glob("fit-v*.npz"))
    assert len(files) == 1

    def no_fit(*_args, **_kwargs):
        raise AssertionError("fitted again although cached")

    lobe_fit._FITS.clear()
    with monkeypatch.context() as patch:
        patch.setattr(lobe_fit, "_fit", no_fit)
        patch.setattr(lobe_fit, "_fit_multi", no_fit)
        loaded = lobe_fit.fit_lobe_maps(lobe, mode, directory=tmp_path)
    assert len(loaded) == len(fitted)
    for a, b in zip(fitted, loaded, strict=True):
        assert (a.mode, a.isotropic_approximation, a.transmission, a.phong_exponent) == (
            b.mode, b.isotropic_approximation, b.transmission, b.phong_exponent,
        )  # fmt: skip
        for name in ("cos_theta_o", "peak_theta", "energy", "error", "axes"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        for pa, pb in zip(a.profiles, b.profiles, strict=True):
            np.testing.assert_array_equal(
                np.stack([pa.psi, pa.density, pa.radial_mass]), np.stack([pb.psi, pb.density, pb.radial_mass])
            )
        np.testing.assert_array_equal(a.mirror_relative_axes(), b.mirror_relative_axes())
    files[0].write_bytes(b"PK damaged")
    lobe_fit._FITS.clear()
    with pytest.warns(UserWarning, match="unusable cached lobe-map fit"):
        again = lobe_fit.fit_lobe_maps(lobe, mode, directory=tmp_path)
    np.testing.assert_array_equal(again[0].energy, fitted[0].energy)
    lobe_fit._FITS.clear()


def test_progress_lines_for_slow_steps_and_quiet_mode(capsys, monkeypatch):
    from lobeview.core import progress

    with progress.timed_step("prefilter", "a short step"):
        pass
    assert capsys.readouterr().err == ""  # fast and not announced: nothing
    with progress.timed_step("prefilter", "a long step", announce=True):
        pass
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "[prefilter] a long step ..." and err[1].startswith("[prefilter] a long step: done in ")
    monkeypatch.setattr(progress, "SLOW_STEP_SECONDS", -1.0)  # every step counts as slow
    with progress.timed_step("albedo", "a table"):
        pass
    assert capsys.readouterr().err.startswith("[albedo] a table: done in ")
    monkeypatch.setenv("LOBEVIEW_QUIET", "1")
    with progress.timed_step("albedo", "a table", announce=True):
        pass
    assert capsys.readouterr().err == ""


def test_the_frames_clear_keeps_a_depth_pre_pass_drawn_before_it():
    """SceneRenderer.draw_frame draws the depth pre-pass before the mirror passes (their occlusion
    test reads it) and then clears the frame's colour targets only (FrameTargets.begin keep_depth)."""
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.frame import FrameTargets

    ctx = create_headless_context()
    try:
        frame = FrameTargets(ctx, (8, 8))
        frame.depth_fbo.use()
        ctx.viewport = (0, 0, 8, 8)
        frame.depth_fbo.clear(depth=0.25)

        def depth(fbo):
            return np.frombuffer(fbo.read(attachment=-1, components=1, dtype="f4"), dtype="f4")

        np.testing.assert_allclose(depth(frame.begin(keep_depth=True)), 0.25, atol=1e-6)
        assert frame.fbo.depth_mask  # restored for the shading pass
        np.testing.assert_allclose(depth(frame.begin()), 1.0)
        frame.release()
    finally:
        ctx.release()
