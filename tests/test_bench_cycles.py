"""The Blender Cycles comparison (bench/cycles.py) without Blender: its cache key, metrics, case
list, lobeview command and the message when bpy is missing. The Cycles side itself runs in the
bench (bpy is not a lobeview dependency); its conventions are verified there against lobeview's
reference (the chrome sphere: median pixel ratio 1.000 with the environment turned by -90
degrees, 1.16 and worse for 0, 90 and 180 degrees)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from lobeview.bench import cycles


def _job(tmp_path: Path, folder: str, env_bytes: bytes = b"env", gltf_bytes: bytes = b"glb") -> dict:
    base = tmp_path / folder
    base.mkdir()
    (base / "white.exr").write_bytes(env_bytes)
    (base / "sphere.glb").write_bytes(gltf_bytes)
    case = cycles.Case("sphere", base / "sphere.glb", "white", (0.0, 0.35, 3.2), (0.0, 0.0, 0.0))
    return cycles.cycles_job(case, base / "white.exr", (24, 18), 16, base / "out.exr")


def test_cache_key_follows_content_not_the_temporary_folder(tmp_path):
    first = cycles.cycles_key(_job(tmp_path, "a"), "4.3.0")
    assert first == cycles.cycles_key(_job(tmp_path, "b"), "4.3.0")  # same bytes, another folder
    assert first != cycles.cycles_key(_job(tmp_path, "c", env_bytes=b"other"), "4.3.0")
    assert first != cycles.cycles_key(_job(tmp_path, "d", gltf_bytes=b"other"), "4.3.0")
    assert first != cycles.cycles_key(_job(tmp_path, "e"), "4.4.0")
    job = _job(tmp_path, "f")
    job["spp"] = 32
    assert first != cycles.cycles_key(job, "4.3.0")


def test_metrics_on_known_images():
    truth = np.ones((10, 10, 3))
    mask = np.zeros((10, 10), bool)
    mask[2:8, 2:8] = True
    same = cycles.compare(truth.copy(), truth, mask)
    assert same == {"mean_ratio": 1.0, "rel_rmse": 0.0, "median_ratio": 1.0, "darkest_ratio": 1.0}
    image = truth.copy()
    image[2, 2:8] = 0.5  # 6 of 36 pixels at half: the darkest 5 % (one pixel) is 0.5
    got = cycles.compare(image, truth, mask)
    assert got["darkest_ratio"] == pytest.approx(0.5)
    assert got["mean_ratio"] == pytest.approx(1 - 6 * 0.5 / 36)
    assert got["rel_rmse"] == pytest.approx(np.sqrt(6 * 0.25 / 36))
    assert got["median_ratio"] == 1.0  # 30 of 36 pixels unchanged
    glint = truth.copy()
    glint[4, 4] = 200.0  # one pixel carrying most of the sum moves the mean, not the median
    got = cycles.compare(truth, glint, mask)
    assert got["mean_ratio"] < 0.2 and got["median_ratio"] == 1.0


def test_object_mask_drops_the_silhouette():
    alpha = np.zeros((9, 9))
    alpha[2:7, 2:7] = 1.0
    alpha[2, 2] = 0.5  # a partly covered pixel
    mask = cycles.object_mask(alpha)
    assert mask.sum() == 9 and mask[3:6, 3:6].all()


def test_shot_arguments_are_what_the_cli_accepts(tmp_path):
    from lobeview.app.cli import build_parser

    case = cycles.Case("x", tmp_path / "x.glb", "white", (1.0, -2.0, 3.0), (0.0, 0.5, 0.0))
    args = cycles.shot_arguments(case, tmp_path / "w.exr", (24, 18), "reference", tmp_path / "o.npy", 64)
    parsed = build_parser().parse_args(["shot", *args])
    assert parsed.camera == "1,-2,3" and parsed.fov == cycles.FOV_Y and parsed.spp == 64
    assert parsed.method == "reference" and parsed.size == "24x18"


def test_unknown_case_and_missing_bpy_say_what_to_do(tmp_path):
    with pytest.raises(SystemExit, match="unknown case 'nothing'"):
        cycles.make_cases(["nothing"], ["white"], tmp_path)
    if cycles.bpy_importable(sys.executable):
        pytest.skip("bpy is installed here")
    with pytest.raises(SystemExit, match="pip install bpy==4.3.0"):
        cycles.bpy_version(sys.executable)


def test_markdown_lists_every_case_and_command():
    row = {"case": "sphere-white", "env": "white", "cycles_seconds": 1.0, "pixels": 100}
    for method in ("reference", "lobe-7"):
        row[method] = {"mean_ratio": 0.975, "rel_rmse": 0.025, "median_ratio": 0.98, "darkest_ratio": 0.97}
    results = {"rows": [row], "commands": [("sphere-white / white", "python -I worker.py job.json", "lobeview shot")],
               "blender": "4.3.0", "methods": ["lobe-7"], "size": [24, 18], "spp": 16, "ref_spp": 8}  # fmt: skip
    text = cycles.markdown(results, "20261126", "python -m lobeview.bench.cycles", "bench/figures/c.png")
    assert "| sphere-white | white | 0.975 / 2.5 / 0.980 / 0.970 | 0.975 / 2.5 / 0.980 / 0.970 |" in text
    assert "python -I worker.py job.json" in text and "bench/figures/c.png" in text


def _layers(shape, gloss_dir, gloss_ind=0.0, gloss_col=0.5, diff_col=0.2):
    """Cycles' light passes of a white-sky render: diffuse fully lit, glossy seen by ``gloss_dir``."""
    full = np.ones(shape + (3,), np.float32)
    return {"DiffDir": full, "DiffInd": 0.0 * full, "DiffCol": diff_col * full, "GlossDir": gloss_dir[..., None] * full,
            "GlossInd": gloss_ind * full, "GlossCol": gloss_col * full}  # fmt: skip


def test_self_occlusion_split_on_known_passes():
    from lobeview.bench.cycles_passes import self_occlusion_split

    shape = (8, 8)
    visibility = np.ones(shape)
    visibility[:2] = 0.2  # the top two rows' glossy lobe is mostly hidden (16 of 64 pixels)
    layers = _layers(shape, visibility)
    truth = np.repeat((0.2 + 0.5 * visibility)[..., None], 3, axis=-1)  # Combined = DiffCol + GlossCol GlossDir
    mask = np.ones(shape, bool)
    image = np.repeat((0.2 + 0.5 * np.ones(shape))[..., None], 3, axis=-1)  # a renderer that hides nothing
    image[4, 4] += 0.01  # and one small error elsewhere
    split = self_occlusion_split(image, truth, layers, mask)
    assert split["hidden_pixel_share"] == pytest.approx(16 / 64)
    hidden_error = 16 * 3 * 0.4**2
    assert split["hidden_error_share"] == pytest.approx(hidden_error / (hidden_error + 3 * 0.01**2))
    rest = np.ones(shape, bool)
    rest[:2] = False
    assert split["rel_rmse_elsewhere"] == pytest.approx(np.sqrt(3 * 0.01**2 / (3 * 48)) / 0.7)
    low, *_, open_band = split["bands"]
    assert low["pixels"] == 16 and low["cycles"] == pytest.approx(0.2) and low["lobeview"] == pytest.approx(1.0)
    assert open_band["pixels"] == 48 and open_band["lobeview"] == pytest.approx(1.0)
    same = self_occlusion_split(truth, truth, layers, mask)  # a renderer equal to Cycles reads back Cycles'
    assert same["hidden_error_share"] == 0.0 and same["bands"][0]["lobeview"] == pytest.approx(0.2)
    without_gloss = self_occlusion_split(image, truth, _layers(shape, visibility, gloss_col=0.0), mask)
    assert without_gloss["hidden_pixel_share"] == 0.0  # no glossy reflectance: nothing counts as hidden


def test_passes_table_and_layered_exr(tmp_path):
    import OpenEXR

    from lobeview.bench.cycles_passes import markdown_lines, read_layers_exr, self_occlusion_split

    shape = (4, 6)
    layers = _layers(shape, np.full(shape, 0.5))
    channels = {f"ViewLayer.{name}.{c}": np.ascontiguousarray(value[..., k], np.float32)
                for name, value in layers.items() for k, c in enumerate("RGB")}  # fmt: skip
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as exr:
        exr.write(str(tmp_path / "passes.exr"))
    read = read_layers_exr(tmp_path / "passes.exr")
    assert set(read) == set(layers)
    for name, value in layers.items():
        np.testing.assert_array_equal(read[name], value)
    truth = np.full(shape + (3,), 0.45)
    split = self_occlusion_split(truth, truth, read, np.ones(shape, bool))
    rows = [{"case": "bottle", "env": "white", "self_occlusion": {"reference": split}}, {"case": "x", "env": "garden"}]
    lines = markdown_lines(rows, ["reference"])
    assert any(line.startswith("| bottle | reference | 100.0 % | 0 % |") for line in lines)
    assert not any(line.startswith("| x |") for line in lines)  # no passes, no row
    assert markdown_lines([{"case": "x", "env": "garden"}], ["reference"]) == []


def test_visibility_figure_marks_what_lobeview_keeps_too_bright():
    from lobeview.bench.cycles_passes import visibility_figure_row

    shape = (4, 4)
    visibility = np.ones(shape)
    visibility[0] = 0.2
    layers = _layers(shape, visibility)
    mask = np.ones(shape, bool)
    mask[3, 3] = False  # the background: grey in every panel
    image = np.repeat((0.2 + 0.5 * np.ones(shape))[..., None], 3, axis=-1)  # hides nothing
    row = visibility_figure_row(image, layers, mask)
    assert row.shape == (4, 12, 3) and row.min() >= 0.0 and row.max() <= 1.0
    cycles, lobeview, difference = row[:, :4], row[:, 4:8], row[:, 8:]
    np.testing.assert_allclose(cycles[0, 0], 0.2, atol=1e-6)
    np.testing.assert_allclose(lobeview[0, 0], 1.0, atol=1e-6)
    np.testing.assert_allclose(difference[0, 0], [1.0, 0.0, 0.0])  # excess 0.8, x2, clipped: red
    np.testing.assert_allclose(difference[1, 1], [0.0, 0.0, 0.0], atol=1e-6)  # equal: black
    np.testing.assert_allclose(difference[3, 3], 0.25)


def test_camera_rays_pass_through_the_pixel_centres_of_lobeviews_camera():
    """bench/cycles_trace.py's rays, projected by lobeview's own view and projection matrices, land
    on the centres of the pixels they were made for (row 0 at the top)."""
    from lobeview.bench.cycles_trace import camera_rays
    from lobeview.viewer.camera import Camera

    camera = Camera(position=(0.3, 0.25, 0.84), target=(0.0, 0.05, 0.0), fov_y=40.0)
    size = (240, 180)
    pixels = np.array([[0, 0], [179, 239], [90, 120], [17, 201]])
    rays = camera_rays(camera.position, camera.target, camera.fov_y, size, pixels)
    points = np.asarray(camera.position) + 2.0 * rays
    clip = np.c_[points, np.ones(len(points))] @ camera.view_projection(size[0] / size[1]).T
    ndc = clip[:, :2] / clip[:, 3:]
    column = (ndc[:, 0] + 1.0) / 2.0 * size[0] - 0.5
    row = (1.0 - ndc[:, 1]) / 2.0 * size[1] - 0.5
    np.testing.assert_allclose(np.c_[row, column], pixels, atol=1e-6)


def test_traced_mirror_visibility_on_a_floor_before_a_wall():
    """A floor with a wall 1 high at its back, one object, seen from above and in front: a floor
    point whose mirror direction meets the wall well below its top is hidden by its own traced
    horizons, one whose mirror direction passes well above it is not (the mirror ray traced
    exactly decides which is which), for every cut; the vertex horizons are there too."""
    import trimesh
    from test_self_visibility import _grid

    from lobeview.bench.cycles_trace import TRACE_CUTS, camera_rays, mirror_visibility
    from lobeview.scenes.meshes import merge_meshes
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject

    floor = _grid((-1.5, 0.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, -2.0), 30)
    wall = _grid((-1.5, 0.0, -1.0), (3.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30)
    mesh = merge_meshes([floor, wall], "corner")
    scene = Scene([SceneObject("corner", mesh, 0)], [SceneMaterial("metal", {"model": "gltf"})])
    eye = (0.0, 1.6, 2.6)
    pixels = np.argwhere(np.ones((24, 32), bool))
    rays = camera_rays(eye, (0.0, 0.0, -0.3), 45.0, (32, 24), pixels)
    found = mirror_visibility(scene, eye, rays)
    assert set(found) == {"vertices", *(f"cut {100 * cut:g} %" for cut in TRACE_CUTS)}

    # the same points again, and where their mirror rays go
    body = trimesh.Trimesh(mesh.positions, np.asarray(mesh.indices).reshape(-1, 3), process=False)
    points, index, _ = body.ray.intersects_location(np.repeat([eye], len(rays), axis=0), rays, multiple_hits=False)
    on_floor = points[:, 1] < 1e-6
    assert on_floor.sum() > 100
    view = rays[index]
    mirror = view * [1.0, -1.0, 1.0]  # about the floor's normal +y
    # where the mirror ray reaches the wall's plane z = -1, and how high
    travel = (-1.0 - points[:, 2]) / np.minimum(mirror[:, 2], -1e-9)
    height = points[:, 1] + travel * mirror[:, 1]
    across = np.abs(points[:, 0] + travel * mirror[:, 0])
    hidden = on_floor & (height < 0.6) & (across < 1.2)
    clear = on_floor & (height > 1.4)
    assert hidden.sum() > 20 and clear.sum() > 20
    for key, values in found.items():
        assert len(values) == len(points)
        if key == "vertices":
            continue
        assert values[hidden].max() < 0.1, key
        assert values[clear].min() > 0.9, key


def test_committed_clearcoat_model_loads_with_its_coat_textures():
    """bench/models/ClearCoatTest (Khronos, CC BY 4.0; bench/models/SOURCES.md), a default case:
    every sample and label, the coat's factor, roughness and normal textures where the model has them."""
    import warnings

    from lobeview.scenes.gltf_loader import load_gltf

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(cycles.MODELS["ClearCoatTest"])
    assert "ClearCoatTest" in cycles.DEFAULT_CASES
    assert len(scene.objects) == 27
    materials = {m.name: m for m in scene.materials}
    assert materials["Partial_Coated"].desc["clearcoat"] == 1.0 and "clearcoat" in materials["Partial_Coated"].textures
    assert "clearcoat" in materials["RoughVariations_Coated"].textures
    assert "clearcoat_normal" in materials["CoatNorm_Coated"].textures
    assert materials["Partial_Coating"].alpha_mode == "BLEND"
