"""The walkthrough scene and its recorded camera paths (scenes/apartment.py, scenes/camera_path.py)
and the walkthrough bench's measurements (bench/walkthrough.py): the path interpolates its keys
smoothly, never walks through a wall, bad path files are refused with a message; the apartment
has the size, materials and reflectors it promises, survives the .glb round trip with its
lightmap, renders finite and lit; the bench's counters add up and show the skips happening."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from lobeview.scenes.analysis import analyse
from lobeview.scenes.apartment import (
    CEILING,
    apartment_geometry,
    apartment_path,
    apartment_path_file,
    build_apartment_scene,
)
from lobeview.scenes.camera_path import MAX_PATH_BYTES, CameraPath, CameraPathError
from lobeview.scenes.demo import demo_path

# -- camera paths ---------------------------------------------------------------------------------


def test_path_passes_through_its_keys_and_is_smooth():
    path = apartment_path(12)
    for t, position, target in zip(path.times, path.positions, path.targets, strict=True):
        camera = path.camera_at(t)
        assert np.allclose(camera.position, position, atol=1e-9)
        assert np.allclose(camera.target, target, atol=1e-9)
    # C1 in time: the one-sided velocities at an inner key agree.
    for k in range(1, len(path.times) - 1):
        h = 1e-5
        left = np.subtract(path.camera_at(path.times[k]).position, path.camera_at(path.times[k] - h).position) / h
        right = np.subtract(path.camera_at(path.times[k] + h).position, path.camera_at(path.times[k]).position) / h
        assert np.allclose(left, right, atol=1e-3 * (1 + np.abs(left).max()))
    # Beyond the ends the camera stays at the end keys.
    assert np.allclose(path.camera_at(-1.0).position, path.positions[0])
    assert np.allclose(path.camera_at(path.duration + 5).position, path.positions[-1])
    frames = path.frame_times(24)
    assert frames[0] == 0.0 and frames[-1] == path.duration and np.all(np.diff(frames) > 0)


def test_path_file_round_trip(tmp_path):
    path = demo_path()
    path.save(tmp_path / "walk.json")
    again = CameraPath.load(tmp_path / "walk.json")
    assert again.fov_y == path.fov_y
    for t in np.linspace(0, path.duration, 17):
        assert np.allclose(again.camera_at(t).position, path.camera_at(t).position, atol=1e-3)


def _two_keys(first: dict, fov=60.0) -> str:
    second = {"t": 1, "position": [0, 1, 1], "target": [1, 1, 0]}
    return json.dumps({"fov_y": fov, "keys": [{"t": 0, "position": [0, 1, 0], "target": [1, 1, 0], **first}, second]})


@pytest.mark.parametrize(
    "content, message",
    [
        ("not json", "not valid JSON"),
        ('{"keys": 3}', "expected an object with a 'keys' list"),
        ('{"keys": [{"t": 0, "position": [0, 1, 0], "target": [1, 1, 0]}]}', "2 to"),
        (_two_keys({"position": [0, 1]}), "3 numbers"),
        (_two_keys({"t": 1}), "start at 0 and increase strictly"),
        (_two_keys({"target": [0, 0, 0]}), "straight up or down"),
        (_two_keys({"target": [0, 1, 0]}), "equals its position"),
        (_two_keys({"position": [0, float("nan"), 0]}), "finite"),
        (_two_keys({"position": "x"}), "needs 't'"),
        (_two_keys({}, fov=500), "fov_y"),
    ],
)
def test_bad_path_files_are_refused_with_a_message(tmp_path, content, message):
    (tmp_path / "bad.json").write_text(content)
    with pytest.raises(CameraPathError, match=message):
        CameraPath.load(tmp_path / "bad.json")


def test_oversized_path_file_is_refused_before_reading(tmp_path):
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(MAX_PATH_BYTES + 1)
    with pytest.raises(CameraPathError, match="exceeds the .* limit for one file"):
        CameraPath.load(big)
    with pytest.raises(CameraPathError, match="no such file"):
        CameraPath.load(tmp_path / "missing.json")


# -- the apartment ------------------------------------------------------------------------------


def test_apartment_size_materials_and_reflectors():
    counts = {rooms: len(apartment_geometry(rooms).objects) for rooms in (1, 6, 12, 18)}
    assert 15 <= counts[1] <= 30 and 80 <= counts[6] <= 120 and 150 <= counts[12] <= 300 and counts[18] <= 320
    scene = apartment_geometry(4)
    names = [o.name for o in scene.objects]
    assert len(set(names)) == len(names)
    for obj in scene.objects:
        mesh = obj.mesh
        assert np.all(np.isfinite(mesh.positions)) and np.asarray(mesh.indices).size % 3 == 0
        assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-4)
    analysis = analyse(scene)
    reflectors = {scene.objects[i].name for i in analysis.reflectors}
    # Every floor (4 rooms + corridor), the dining table's top and the bedroom's mirror.
    assert {"corridor floor", "dining 3 table top", "bedroom 4 mirror"} <= reflectors
    assert sum(1 for n in reflectors if n.endswith(" floor")) == 5
    kinds = {scene.materials[o.material].name for o in scene.objects}
    for preset in ("chrome", "gold-ggx", "lacquer", "miro5-2lobe", "frosted-glass", "clear-glass", "plastic"):
        assert preset in kinds
    # Windows look at the sky: no reflection proxy that would put it on the pane.
    assert all(o.reflection_proxy is None for o in scene.objects if o.name.endswith("window"))
    assert any(o.name.endswith("chair 4") for o in scene.objects)  # repeated furniture


@pytest.mark.parametrize("rooms", [1, 4, 12])
def test_recorded_path_never_walks_through_a_wall(rooms):
    """Segments between 600 points along the path hit no surface: the walk goes through doors."""
    import trimesh

    scene = apartment_geometry(rooms)
    meshes = [trimesh.Trimesh(o.mesh.positions, np.asarray(o.mesh.indices).reshape(-1, 3), process=False)
              for o in scene.objects]  # fmt: skip
    everything = trimesh.util.concatenate(meshes)
    path = apartment_path(rooms)
    points = np.array([path.camera_at(t).position for t in np.linspace(0, path.duration, 600)])
    lo, hi = scene.bounds
    assert np.all(points > lo) and np.all(points[:, 1] < CEILING)
    starts, ends = points[:-1], points[1:]
    directions = ends - starts
    lengths = np.linalg.norm(directions, axis=1)
    moving = lengths > 1e-9
    hits, rays, _ = everything.ray.intersects_location(
        starts[moving], directions[moving] / lengths[moving, None], multiple_hits=False
    )
    if len(hits):
        distance = np.linalg.norm(hits - starts[moving][rays], axis=1)
        assert np.all(distance > lengths[moving][rays] + 0.05), "the path crosses a surface"


def test_apartment_bakes_writes_and_loads_with_its_path(tmp_path):
    from lobeview.scenes.gltf_loader import load_gltf

    glb = build_apartment_scene(1, resolution=128, rays=4, bounces=1, directory=tmp_path)
    assert glb.exists() and apartment_path_file(glb).exists()
    assert build_apartment_scene(1, resolution=128, rays=4, bounces=1, directory=tmp_path) == glb  # cached
    scene = load_gltf(glb)
    assert [o.name for o in scene.objects] == [o.name for o in apartment_geometry(1).objects]
    assert {o.name for o in scene.objects if o.planar_reflector is True} == {"corridor floor", "study 1 floor"}
    lightmap = scene.materials[scene.objects[0].material].lightmap
    assert lightmap is not None
    image = lightmap.image
    assert np.all(np.isfinite(image)) and image.min() >= 0 and image.mean() > 0.05
    path = CameraPath.load(apartment_path_file(glb))
    assert np.allclose(path.positions, apartment_path(1).positions, atol=1e-3)


def test_builtin_scene_names():
    from lobeview.core.errors import OptionError
    from lobeview.scenes.setup import builtin_apartment_rooms

    assert builtin_apartment_rooms("builtin:apartment") == 12
    assert builtin_apartment_rooms("builtin:apartment-3") == 3
    for bad in ("builtin:apartment-0", "builtin:apartment-x", "builtin:house", "builtin:apartment-99"):
        with pytest.raises(OptionError, match="builtin:apartment"):
            builtin_apartment_rooms(bad)
    from lobeview.app.view import builtin_camera_path

    assert np.allclose(builtin_camera_path(None, None).positions, demo_path().positions)
    with pytest.raises(OptionError, match="only the built-in scenes"):
        builtin_camera_path("my.glb", None)


# -- rendering and the bench's counters -------------------------------------------------------------


@pytest.fixture(scope="module")
def small_apartment(tmp_path_factory):
    from lobeview.scenes.gltf_loader import load_gltf

    folder = tmp_path_factory.mktemp("apartment")
    return load_gltf(build_apartment_scene(4, resolution=256, rays=8, bounces=1, directory=folder))


def test_walk_through_the_apartment_counts_add_up_and_skips_happen(small_apartment):
    from lobeview.bench.walkthrough import measure_scene
    from lobeview.core.methods import Method
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.viewer.context import create_headless_context

    scene = small_apartment
    ctx = create_headless_context()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = measure_scene(
                ctx, "apartment-4", scene, load_environment("builtin:overcast"), apartment_path(4),
                Method.parse("lobe-5"), (96, 60), 6, 16,
            )  # fmt: skip
    finally:
        ctx.release()
    analysis = analyse(scene)
    assert result["objects"] == len(scene.objects)
    # Reflectors build no cube map at start-up (their mirror passes shade them); every other
    # glossy object does, at face 16 (MIN_CUBE_FACE: the lobe-width rule cannot go below it)
    # (shared probes are an option, off here: tests/test_probe_groups.py).
    assert result["probe_groups"] == []
    assert result["cube_maps"] == len(analysis.cube_mapped) - len(analysis.reflectors) > 0
    assert result["cube_face_sizes"] == {16: result["cube_maps"]}
    assert result["reflector_cubes_deferred"] == len(analysis.reflectors)
    assert result["cubes_built_on_demand"] == 0  # lobe-5 shades every reflector from its mirror pass
    # one MIP chain per cube, a second (the residual) for each cube that holds bright sources:
    # the apartment's cubes see its windows
    chains = result["cube_maps"] + result["cube_maps_with_bright_sources"]
    assert 0 < result["cube_maps_with_bright_sources"] <= result["cube_maps"]
    assert result["cube_memory_mb"] == pytest.approx(chains * 6 * 16 * sum(4**-k for k in range(5)) * 256 / 2**20)
    assert result["startup_warm_s"] < result["startup_cold_s"]
    rows = result["frames"]
    assert len(rows) == 6
    for row in rows:
        # Every object is either drawn or culled by the camera pass; every reflector gets its
        # pass or a reason.
        assert row["camera_drawn"] + row["camera_culled"] == len(scene.objects)
        assert row["mirror_passes"] + row["mirror_skipped"] == len(analysis.reflectors)
        assert sum(row["skip_reasons"].values()) == row["mirror_skipped"]
        assert row["frame_ms"] >= row["camera_ms"] > 0
        # The same frame without the occlusion test draws exactly the hidden reflectors more.
        hidden = row["skip_reasons"].get("hidden behind other objects", 0)
        assert row["mirror_passes_without_test"] == row["mirror_passes"] + hidden
        assert row["occlusion_test_ms"] >= 0 and row["mirror_ms_without_test"] > 0
        assert row["camera_ms_without_prepass"] > 0
    # Along the path objects behind the camera are culled and mirror passes skipped.
    assert all(row["camera_culled"] > 0 for row in rows)
    assert sum(row["mirror_skipped"] for row in rows) > 0
    assert result["cube_face_culled"] > 0


def test_budget_walk_evicts_and_restores_along_the_path(small_apartment):
    from lobeview.bench.walkthrough import _budget_markdown, budget_walk
    from lobeview.core.methods import Method
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.viewer.context import create_headless_context

    ctx = create_headless_context()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = budget_walk(
                ctx, "apartment-4", small_apartment, load_environment("builtin:overcast"), apartment_path(4),
                Method.parse("lobe-3"), (64, 40), 6, 16, 0.2,
            )  # fmt: skip
    finally:
        ctx.release()
    rows = result["frames"]
    assert len(rows) == 6 and result["memory_without_budget_mb"] > 0.2
    assert sum(r["evicted"] for r in rows) > 0 and sum(r["restored"] for r in rows) > 0
    assert all(r["frame_ms"] > 0 and r["frame_ms_without_budget"] > 0 for r in rows)
    text = "\n".join(_budget_markdown(result))
    assert "with a cube-map budget of 0.2 MB" in text and "| 5 |" in text
    json.dumps(result)


def test_apartment_renders_lit_and_finite(small_apartment, tmp_path):
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = small_apartment
    ctx = create_headless_context()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            renderer = SceneRenderer(
                ctx,
                scene,
                load_environment("builtin:overcast"),
                size=(160, 100),
                progress=False,
                settings=RenderSettings(cube_face_size=32),
            )
        path = apartment_path(4)
        for t in (0.0, path.times[3]):
            result = renderer.render(Camera.from_scene_camera(path.camera_at(t)), "lobe-5", spp=1)
            radiance = result.radiance
            assert np.all(np.isfinite(radiance)) and radiance.min() >= 0
            assert result.mask.mean() > 0.9  # indoors: geometry everywhere but the windows
            assert np.median(radiance.mean(axis=2)) > 0.02  # lit, not black
        renderer.release()
    finally:
        ctx.release()


def test_walkthrough_report_tables(tmp_path):
    from lobeview.bench.walkthrough import _count_markdown, _scene_markdown

    row = {"frame": 0, "t": 0.0, "mirror_ms": 3.0, "camera_ms": 5.0, "frame_ms": 8.0, "camera_drawn": 4,
           "camera_culled": 2, "mirror_draws": 7, "mirror_culled": 1, "mirror_passes": 2, "mirror_skipped": 2,
           "mirror_buffers": 1,
           "skip_reasons": {"outside the view": 2}, "occlusion_test_ms": 1.0, "mirror_ms_without_test": 9.0,
           "mirror_passes_without_test": 2, "camera_ms_without_prepass": 6.0, "mirror_ms_without_scissor": 4.0,
           "mirror_pixels_scissored": 300, "mirror_pixels": 1200, "frame_ms_without_records": 11.0, "draws": 11,
           "uniform_values_set": 400, "uniform_writes": 90, "mirror_ms_full_buffers": 7.0,
           "mirror_pixels_full_buffers": 4800}  # fmt: skip
    result = {"scene": "x", "objects": 6, "reflectors": 3, "cube_maps": 2, "cube_memory_mb": 16.0,
              "cube_memory_full_mb": 20.0, "cube_face_sizes": {256: 1, 64: 1}, "startup_cold_full_s": 2.5,
              "reflector_cubes_deferred": 3, "cubes_built_on_demand": 0,
              "startup_cold_s": 2.0, "startup_warm_s": 0.5, "cold_stages": {"cube maps": 1.5},
              "warm_stages": {"cube maps": 0.1}, "cube_face_draws": 40, "cube_face_culled": 20,
              "frames": [row], "rooms": 1}  # fmt: skip
    text = "\n".join(_scene_markdown(result) + _count_markdown([result]))
    # two reflectors in one plane: 2 with buffers from 1 pass drawn
    assert "| 0 | 0.0 | 8 | 3 | 1 | 5 | 4 / 2 | 7 / 1 | 2 / 2 (1) | outside the view: 2 | 2, 9 | 4 | 25 % | 7 |" in text
    assert (
        "| 1 | 6 | 3 | 2 | 16 (20) | 2.0 (2.5) | 40 / 20 | 0.5 | 8 | 3 | 5 | 4 / 2 | 2.0 / 2.0 (1.0) | 2.0, 9 | 4 "
        "| 25 % | 7 (25 %) | 6 | 11, 400 / 90 | 11 (8) |" in text
    )
    del row["mirror_buffers"]  # a result of an older run: the passes drawn unknown
    older = "\n".join(_count_markdown([result]))
    assert "| 2.0 / 2.0 (-) |" in older
    assert "with every buffer at the mirror scale (no lobe sizes) 7 ms (the lobe sizes keep 25 %" in text
    assert "11 draws a frame set 400 uniform values, of which 90 were not already" in text
    assert "faces 1 x 256^2, 1 x 64^2" in text
    json.dumps(result)  # the record is JSON
