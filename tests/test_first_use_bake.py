"""A user's glTF without lightmaps is baked on first use (issue 40 item 3, scenes/gltf_bake.py and
app/view.py first_use_bake): once, into the cache, keyed by everything the bake reads; the window
shows the file meanwhile and swaps the baked scene in; the next start loads it at once."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from lobeview.app.view import first_use_bake, first_use_bake_applies
from lobeview.core.trust import DEFAULT_LIMITS, UntrustedReferenceError
from lobeview.scenes.gltf_bake import BakeSettings, bake_gltf, first_use_bake_file, first_use_bake_key, has_lightmaps
from lobeview.scenes.gltf_loader import load_gltf
from lobeview.scenes.setup import default_environment


def _scene_file(folder: Path) -> Path:
    """A grey floor with a white box on it (no TEXCOORD_1, no lightmap), written as a .gltf with
    its buffer beside it, so that the key must read a referenced file."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.meshes import box_mesh
    from lobeview.scenes.scene import Scene, SceneCamera, SceneMaterial, SceneObject

    scene = Scene(
        objects=[SceneObject("floor", box_mesh([0, -0.05, 0], [4, 0.1, 4]), 0),
                 SceneObject("box", box_mesh([0, 0.5, 0], [1, 1, 1]), 1)],
        materials=[SceneMaterial("grey", validate({"model": "thesis", "kd": 0.5, "lobes": []})),
                   SceneMaterial("white", validate({"model": "thesis", "kd": 0.8, "lobes": []}))],
        cameras=[SceneCamera("front", np.array([0.0, 2.0, 4.0]), np.array([0.0, 0.3, 0.0]),
                             np.array([0.0, 1.0, 0.0]), 45)],
    )  # fmt: skip
    glb = write_glb(scene, folder / "packed.glb")
    from pygltflib import GLTF2

    gltf = GLTF2().load(str(glb))
    blob = gltf.binary_blob()
    (folder / "scene.bin").write_bytes(blob)
    gltf.buffers[0].uri = "scene.bin"
    gltf.set_binary_blob(None)
    gltf.save_json(str(folder / "scene.gltf"))
    glb.unlink()
    return folder / "scene.gltf"


def _floor_irradiance(scene, floor, point_xz) -> float:
    """The baked lightmap's mean irradiance on the floor's top face at world (x, z): the triangle
    holding the point, its barycentric TEXCOORD_1, the nearest texel."""
    positions, indices = floor.mesh.positions, floor.mesh.indices.reshape(-1, 3)
    point = np.asarray(point_xz, float)
    for triangle in indices:
        corners = positions[triangle]
        if not np.all(floor.mesh.normals[triangle][:, 1] > 0.9):
            continue
        a, b, c = corners[:, [0, 2]].astype(float)
        weights = np.linalg.solve(np.array([b - a, c - a]).T, point - a)
        bary = np.array([1 - weights.sum(), *weights])
        if np.all(bary >= -1e-6):
            uv = bary @ floor.uv1[triangle]
            image = scene.materials[floor.material].lightmap.image
            row = min(int(uv[1] * image.shape[0]), image.shape[0] - 1)
            col = min(int(uv[0] * image.shape[1]), image.shape[1] - 1)
            return float(image[row, col].mean())
    raise AssertionError(f"no top-face triangle of the floor holds {point_xz}")


def _args(**options) -> argparse.Namespace:
    base = {"scene": "x.gltf", "env": "builtin:studio", "limits": DEFAULT_LIMITS, "no_background_bake": False,
            "no_first_use_bake": False, "path": None}  # fmt: skip
    return argparse.Namespace(**{**base, **options})


def test_the_key_follows_every_input_of_the_bake(tmp_path):
    source = _scene_file(tmp_path)
    key = first_use_bake_key(source, "builtin:studio")
    assert key == first_use_bake_key(source, "builtin:studio")
    assert key != first_use_bake_key(source, "builtin:overcast")
    assert key != first_use_bake_key(source, "builtin:studio", settings=BakeSettings(rays=64))
    buffer = tmp_path / "scene.bin"
    data = bytearray(buffer.read_bytes())
    data[-1] ^= 1
    buffer.write_bytes(bytes(data))  # one bit of the referenced buffer
    assert first_use_bake_key(source, "builtin:studio") != key
    # An environment file by its bytes, not its name.
    env = tmp_path / "sky.hdr"
    env.write_bytes(b"one")
    first = first_use_bake_key(source, str(env))
    env.write_bytes(b"two")
    assert first_use_bake_key(source, str(env)) != first
    # A reference outside the scene's folder is refused as the load refuses it.
    doc = json.loads(source.read_text())
    doc["buffers"][0]["uri"] = "../elsewhere.bin"
    source.write_text(json.dumps(doc))
    with pytest.raises(UntrustedReferenceError):
        first_use_bake_key(source, "builtin:studio")


def test_a_bake_moves_its_files_in_whole(tmp_path):
    (tmp_path / "in").mkdir()
    source = _scene_file(tmp_path / "in")
    out = tmp_path / "out" / "baked.glb"
    out.parent.mkdir()
    fast = BakeSettings(resolution=32, rays=4, bounces=1, light_samples=1, env_samples=4)
    written = bake_gltf(source, "builtin:studio", out, settings=fast, say=lambda _: None)
    assert written == [out]
    assert sorted(p.name for p in out.parent.iterdir()) == ["baked.glb"]  # no partial folder left
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert has_lightmaps(load_gltf(out)) and not has_lightmaps(load_gltf(source))


def test_first_use_bake_bakes_once_and_then_reads_the_cache(tmp_path, capsys):
    source, cache = _scene_file(tmp_path), tmp_path / "cache"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the unbaked file's fallback irradiance is warned
        scene = load_gltf(source)
        args = _args(scene=str(source), no_background_bake=True)
        t0 = time.perf_counter()
        path, baked, background = first_use_bake(args, source, scene, cache)
        bake_seconds = time.perf_counter() - t0
    assert background is None and path == first_use_bake_file(source, "builtin:studio", cache)
    assert path.parent == cache / "baked" and has_lightmaps(baked)
    assert [o.name for o in baked.objects] == [o.name for o in scene.objects]
    # The box's contact shadow: the floor's lightmap is darker beside the box than at its edge.
    floor = baked.objects[0]
    lightmap = baked.materials[floor.material].lightmap
    assert lightmap is not None and np.isfinite(lightmap.image).all()
    beside, edge = _floor_irradiance(baked, floor, [0.53, 0.0]), _floor_irradiance(baked, floor, [1.9, 1.9])
    assert beside < 0.85 * edge, (beside, edge)
    # Second start: the cached bake at once, nothing baked.
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again, _, background = first_use_bake(_args(scene=str(source)), source, scene, cache)
    assert again == path and background is None
    assert time.perf_counter() - t0 < bake_seconds
    assert "lightmaps from the first-use bake" in capsys.readouterr().err
    # A damaged cache file: the file as it is, with the reason and the way out.
    path.write_bytes(path.read_bytes()[:100])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shown_path, shown, background = first_use_bake(_args(scene=str(source)), source, scene, cache)
    assert shown_path == source and shown is scene and background is None
    assert "could not be loaded" in capsys.readouterr().err


def test_what_is_not_baked_on_first_use(tmp_path, capsys):
    assert not first_use_bake_applies(_args(scene="builtin:demo"), [])
    assert not first_use_bake_applies(_args(no_first_use_bake=True), [])
    assert not first_use_bake_applies(_args(path="p.json"), [])
    assert not first_use_bake_applies(_args(), [{"action": "wait"}])
    assert first_use_bake_applies(_args(), [])
    source = _scene_file(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(source)
        # An environment file that cannot be read: the file is shown as it is, and the reason said.
        args = _args(scene=str(source), env=str(tmp_path / "missing.exr"))
        path, shown, background = first_use_bake(args, source, scene, tmp_path / "cache")
    assert path == source and shown is scene and background is None
    assert "no first-use bake" in capsys.readouterr().err
    assert not (tmp_path / "cache").exists()


def _frames(stats: Path) -> list[dict]:
    if not stats.exists():
        return []
    complete = stats.read_text().split("\n")[:-1]
    return [json.loads(line) for line in complete if line.strip()]


def _view(source: Path, cache: Path, stats: Path, xvfb: str, until) -> tuple[list[dict], str]:
    """Run the window on ``source`` until ``until(frames)`` holds (or 600 s); its frames, stderr."""
    command = [sys.executable, "-m", "lobeview", "view", str(source), "--cache", str(cache), "--size", "160x100",
               "--face-size", "16", "--stats", str(stats)]  # fmt: skip
    process = subprocess.Popen(command, env={**os.environ, "DISPLAY": xvfb}, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and process.poll() is None and not until(_frames(stats)):
            time.sleep(1.0)
        assert process.poll() is None, process.communicate()[1][-3000:]
    finally:
        process.terminate()
        _, stderr = process.communicate(timeout=60)
    return _frames(stats), stderr


def test_the_window_shows_the_file_then_swaps_in_its_bake(xvfb, tmp_path):
    source, cache = _scene_file(tmp_path), tmp_path / "cache"
    frames, stderr = _view(source, cache, tmp_path / "first.jsonl", xvfb,
                           lambda fs: any(f["background_bake"] is None for f in fs[1:]))  # fmt: skip
    assert frames and frames[0]["background_bake"] is not None, stderr[-3000:]  # shown before the bake ended
    assert any(f["background_bake"] is None for f in frames[1:]), stderr[-3000:]
    baked = first_use_bake_file(source, default_environment(str(source)), cache)  # the view's default sky
    assert baked.exists(), sorted(cache.rglob("*"))
    # The next start reads the cache: no bake at any frame.
    frames, stderr = _view(source, cache, tmp_path / "second.jsonl", xvfb, lambda fs: len(fs) >= 2)
    assert frames and all(f["background_bake"] is None for f in frames), stderr[-3000:]
    assert "lightmaps from the first-use bake" in stderr
