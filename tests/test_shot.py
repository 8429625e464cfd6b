"""`lobeview shot`: outputs, stage report, and clear errors for bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lobeview.app.cli import main
from lobeview.scenes.hdrio import read_hdr_image, write_hdr_image

ASSETS = Path(__file__).resolve().parents[2] / "shared" / "assets" / "gltf"


def test_shot_writes_png_exr_and_npy(tmp_path, capsys):
    common = [
        "shot",
        "--object",
        "sphere",
        "--size",
        "64x48",
        "--face-size",
        "32",
        "--method",
        "lobe-5",
    ]
    assert main(common + ["--out", str(tmp_path / "a.npy")]) == 0
    out = capsys.readouterr().out
    assert "method lobe-5" in out and "stages:" in out and "--camera=0,0.35,3.2" in out
    radiance = np.load(tmp_path / "a.npy")
    assert radiance.shape == (48, 64, 3) and radiance.dtype == np.float32
    assert np.all(np.isfinite(radiance)) and radiance.min() >= 0 and radiance.max() > 0
    assert main(common + ["--out", str(tmp_path / "a.exr")]) == 0
    np.testing.assert_allclose(read_hdr_image(tmp_path / "a.exr"), radiance, rtol=1e-6)
    assert main(common + ["--out", str(tmp_path / "a.png")]) == 0
    from PIL import Image

    png = np.asarray(Image.open(tmp_path / "a.png"))
    assert png.shape == (48, 64, 3) and png.std() > 5
    # --mip-filter reaches the object preview: the box chain's levels differ from the tent's.
    assert main(common + ["--mip-filter", "box", "--out", str(tmp_path / "box.npy")]) == 0
    box = np.load(tmp_path / "box.npy")
    assert np.all(np.isfinite(box)) and np.abs(box - radiance).max() > 1e-3


def test_shot_reference_reports_samples(tmp_path, capsys):
    args = [
        "shot",
        "--object",
        "sphere",
        "--size",
        "32x32",
        "--face-size",
        "32",
        "--method",
        "reference",
        "--spp",
        "128",
        "--out",
        str(tmp_path / "r.npy"),
    ]
    assert main(args) == 0
    assert "128 spp per lobe" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra,message",
    [
        (["--object", "sphere", "some.glb"], "either a SCENE or --object"),
        (["/no/such/scene.glb"], "no such file"),
        (["--object", "sphere", "--method", "lobe-99"], "N must be in"),
        (["--object", "sphere", "--method", "phong-3"], "unknown method"),
        (["--object", "sphere", "--size", "64by48"], "--size: expected WxH"),
        (["--object", "sphere", "--camera", "0,0"], "--camera: expected three"),
        (["--object", "sphere", "--env", "/no/such/env.exr"], "no such file"),
        (["--object", "sphere", "--env", "builtin:moon"], "unknown built-in environment"),
        (
            ["--object", "sphere", "--material", '{"model": "gltf", "roughness": 2}'],
            "roughness = 2",
        ),
        (["--object", "/no/such/mesh.obj"], "no such file"),
        (["--cube-budget", "0"], "--cube-budget must be a positive number of MB"),
        (["--cube-budget", "nan"], "--cube-budget must be a positive number of MB"),
        (["--object", "sphere", "--supersample", "0"], "--supersample must be in [1, 8]"),
        (["--object", "sphere", "--size", "3000x8", "--supersample", "3"], "over 8192 pixels a side"),
    ],
)
def test_shot_bad_input_gives_a_clear_error(tmp_path, capsys, extra, message):
    size = [] if "--size" in extra else ["--size", "32x32"]
    assert main(["shot", *extra, *size, "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_supersampled_shot_is_the_box_filter_of_the_larger_render(tmp_path, capsys):
    """--supersample K renders K times --size and writes each K x K block's mean: equal to the
    larger render averaged here; against the point-sampled image it differs most where a strong
    edge crosses the pixel (the sphere's silhouette: anti-aliased), little elsewhere."""
    from lobeview.core.images import box_downsample

    block = np.arange(4 * 6 * 3, dtype=np.float32).reshape(4, 6, 3)
    np.testing.assert_allclose(box_downsample(block, 2)[1, 2], block[2:4, 4:6].mean(axis=(0, 1)))
    common = ["shot", "--object", "sphere", "--method", "lobe-7", "--material", "gold-ggx"]
    assert main([*common, "--size", "96x64", "--out", str(tmp_path / "big.npy")]) == 0
    assert main([*common, "--size", "48x32", "--supersample", "2", "--out", str(tmp_path / "ss.npy")]) == 0
    assert "48x32 (2x2 supersampled)" in capsys.readouterr().out
    big, supersampled = np.load(tmp_path / "big.npy"), np.load(tmp_path / "ss.npy")
    assert supersampled.shape == (32, 48, 3)
    np.testing.assert_allclose(supersampled, box_downsample(big, 2), rtol=1e-6, atol=1e-7)
    assert main([*common, "--size", "48x32", "--out", str(tmp_path / "point.npy")]) == 0
    point = np.load(tmp_path / "point.npy")
    grey_point, grey_ss = point.mean(axis=-1), supersampled.mean(axis=-1)
    blocks = big.mean(axis=-1).reshape(32, 2, 48, 2)
    mixed = blocks.max(axis=(1, 3)) > 1.5 * blocks.min(axis=(1, 3))  # pixels a strong edge crosses
    assert mixed.sum() > 10
    assert np.abs(grey_ss - grey_point)[mixed].mean() > np.abs(grey_ss - grey_point)[~mixed].mean()


def test_shot_into_a_missing_folder_is_an_error_and_creates_nothing(tmp_path, capsys):
    """Issue 41: `--out /nonexistent/dir/a.png` returned 0 and made /nonexistent/dir; bake made
    its folders too."""
    out = tmp_path / "missing" / "deeper" / "a.png"
    assert main(["shot", "--object", "sphere", "--size", "16x16", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "does not exist" in err and "Traceback" not in err
    assert not (tmp_path / "missing").exists()
    scene = tmp_path / "scene.glb"
    scene.write_bytes(b"")  # refused before the scene is read
    assert main(["bake", str(scene), "--out", str(out.with_suffix(".glb"))]) != 0
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "missing").exists()


def test_shot_with_nan_and_negative_environment_texels_warns_and_renders(tmp_path, capsys):
    env = np.full((16, 32, 3), 0.5, dtype=np.float32)
    env[3, 4] = np.nan
    env[5, 6] = np.inf
    env[7, 8] = -2.0
    path = write_hdr_image(tmp_path / "bad.exr", env)
    with pytest.warns(UserWarning) as record:
        assert (
            main(
                [
                    "shot",
                    "--object",
                    "sphere",
                    "--env",
                    str(path),
                    "--size",
                    "32x32",
                    "--face-size",
                    "16",
                    "--out",
                    str(tmp_path / "x.npy"),
                ]
            )
            == 0
        )
    messages = " ".join(str(w.message) for w in record)
    assert "2 texels with NaN/Inf channels repaired" in messages
    assert "1 texels with negative values (down to -2) set to 0" in messages and "energy change" in messages
    radiance = np.load(tmp_path / "x.npy")
    assert np.all(np.isfinite(radiance)) and radiance.min() >= 0


def test_corrupt_hdr_files_are_rejected_with_the_file_name(tmp_path):
    from lobeview.scenes.hdrio import HDRImageError

    (tmp_path / "junk.exr").write_bytes(b"not an exr at all")
    with pytest.raises(HDRImageError, match="junk.exr"):
        read_hdr_image(tmp_path / "junk.exr")
    (tmp_path / "junk.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 4\n\x01\x02")
    with pytest.raises(HDRImageError, match="truncated"):
        read_hdr_image(tmp_path / "junk.hdr")
    (tmp_path / "x.tga").write_bytes(b"")
    with pytest.raises(HDRImageError, match="unsupported HDR format"):
        read_hdr_image(tmp_path / "x.tga")


def test_rgbe_round_trip_and_shared_assets_statistics(tmp_path):
    rng = np.random.default_rng(0)
    image = (rng.random((20, 40, 3)) * 100).astype(np.float32)
    image[0, 0] = 0
    back = read_hdr_image(write_hdr_image(tmp_path / "x.hdr", image))
    # RGBE keeps 8 bits of mantissa: relative error below 1/128 of the brightest channel.
    assert np.all(np.abs(back - image) <= image.max(axis=-1, keepdims=True) / 128 + 1e-30)
    assert np.all(back[0, 0] == 0)


def test_object_mesh_files_keep_their_surface(tmp_path, capsys):
    """`shot --object FILE`: a glTF keeps its own normals and UVs (lobeview's loader); an STL
    triangle soup is welded and smoothed within 30 degrees, so a sphere renders round and a cube
    keeps its hard edges."""
    import trimesh

    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.mesh_files import load_mesh_file

    soup_sphere = trimesh.creation.icosphere(3)
    triangles = soup_sphere.vertices[soup_sphere.faces].reshape(-1, 3)
    soup = trimesh.Trimesh(triangles, np.arange(len(triangles)).reshape(-1, 3), process=False)
    soup.export(tmp_path / "ball.stl")
    ball = load_mesh_file(tmp_path / "ball.stl")
    assert len(ball.positions) == len(soup_sphere.vertices)  # welded
    radial = ball.positions / np.linalg.norm(ball.positions, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(np.sum(radial * ball.normals, axis=1), -1, 1))).max() < 2.0

    trimesh.creation.box().export(tmp_path / "box.stl")
    box = load_mesh_file(tmp_path / "box.stl")
    assert np.allclose(np.sort(np.abs(box.normals), axis=1), [0, 0, 1], atol=1e-6)  # faces stay flat

    suzanne = ASSETS / "Suzanne" / "Suzanne.gltf"
    if suzanne.is_file():
        mesh = load_mesh_file(suzanne)
        reference = load_gltf(suzanne).objects[0].mesh
        np.testing.assert_array_equal(mesh.normals, reference.normals)
        np.testing.assert_array_equal(mesh.uvs, reference.uvs)
        args = ["shot", "--object", str(suzanne), "--size", "32x32", "--face-size", "16", "--method", "lobe-5"]
        assert main(args + ["--out", str(tmp_path / "s.png")]) == 0
        printed = capsys.readouterr().out
        assert "renders it with its own materials" in printed
        # The printed command runs as pasted.
        import shlex

        command = shlex.split(printed.split("`")[1])
        assert command[0] == "lobeview" and main(command[1:]) == 0
        assert (tmp_path / "s_own_materials.png").is_file()


def test_printed_commands_run_this_lobeview_from_anywhere(tmp_path, monkeypatch):
    """Issue 41: a printed `lobeview shot ...` failed when pasted without the venv on PATH. The
    program is the running entry point's absolute path, or this interpreter's -m lobeview."""
    import sys

    from lobeview.app.options import default_screenshot_dir, lobeview_program

    monkeypatch.setattr(sys, "argv", ["/not/a/file/lobeview"])
    assert lobeview_program() == [sys.executable, "-m", "lobeview"]
    script = tmp_path / "bin" / "lobeview"
    script.parent.mkdir()
    script.write_text("#!/bin/sh\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["bin/lobeview", "view"])
    assert lobeview_program() == [str(script)]
    # F12's default folder: the user's Pictures, else the cache; never the working folder
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("LOBEVIEW_CACHE", str(tmp_path / "cache"))
    assert default_screenshot_dir() == tmp_path / "cache" / "screenshots"
    (tmp_path / "home" / "Pictures").mkdir(parents=True)
    assert default_screenshot_dir() == tmp_path / "home" / "Pictures" / "lobeview"
