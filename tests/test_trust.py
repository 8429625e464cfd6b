"""The trust boundary (core/trust.py, scenes/gltf_loader.py): a scene file reads nothing outside
its folder, nothing that is not a regular file, and allocates nothing its declared sizes would
take past the budget. Each test builds a small hostile file and checks the refusal and that the
canary file outside the folder was never opened (a Python audit hook sees every open)."""

from __future__ import annotations

import json
import os
import struct
import sys
import tracemalloc
import zlib
from pathlib import Path

import numpy as np
import pytest

from lobeview.core.trust import Limits, LoadBudget, parse_budget, resolve_reference
from lobeview.scenes.gltf_common import GltfError, GltfWarning
from lobeview.scenes.gltf_loader import load_gltf
from lobeview.scenes.hdrio import HDRImageError, read_hdr_image

TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()

_opened: list[str] = []


def _audit(event, args):
    if event == "open" and args and isinstance(args[0], (str, bytes, os.PathLike)):
        _opened.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)  # process-wide and permanent; only appends paths to a list


def _gltf(buffer_uri="tri.bin", image_uri=None, extras=None, **changes) -> dict:
    g = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {}}],
        "buffers": [{"uri": buffer_uri, "byteLength": 36}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
    }
    if image_uri is not None:
        g["images"] = [{"uri": image_uri}]
        g["textures"] = [{"source": 0}]
        g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    if extras is not None:
        g["materials"][0]["extras"] = {"lobeview": extras}
    g.update(changes)
    return g


@pytest.fixture
def scene_dir(tmp_path):
    """tmp/scene/ holds the scene; tmp/canary.bin (outside it) must never be opened."""
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "tri.bin").write_bytes(TRIANGLE)
    (tmp_path / "canary.bin").write_bytes(TRIANGLE)
    return folder


def _load(folder: Path, g: dict, limits: Limits | None = None):
    path = folder / "s.gltf"
    path.write_text(json.dumps(g))
    _opened.clear()
    try:
        return load_gltf(path, limits) if limits else load_gltf(path)
    finally:
        canary = str(folder.parent / "canary.bin")
        assert not any(os.path.abspath(p) == canary for p in _opened), "the canary outside the folder was opened"


@pytest.mark.parametrize(
    "uri",
    [
        "../canary.bin",
        "%2E%2E/canary.bin",
        "sub/../../canary.bin",
        "{abs}",
        "file://{abs}",
        "//{abs}",
        "/etc/passwd",
        "/dev/zero",
        "/proc/self/cmdline",
        "link.bin",  # a symlink in the folder pointing out
    ],
)
def test_buffer_uris_outside_the_folder_are_refused(scene_dir, uri):
    os.symlink(scene_dir.parent / "canary.bin", scene_dir / "link.bin")
    uri = uri.format(abs=scene_dir.parent / "canary.bin")
    with pytest.raises(GltfError, match="outside the scene's folder"):
        _load(scene_dir, _gltf(buffer_uri=uri))


def test_the_opt_in_reads_outside_but_never_a_device(scene_dir):
    allow = Limits(allow_outside=True)
    path = scene_dir / "s.gltf"
    path.write_text(json.dumps(_gltf(buffer_uri="../canary.bin")))
    assert len(load_gltf(path, allow).objects) == 1
    with pytest.raises(GltfError, match="not a regular file"):
        _load(scene_dir, _gltf(buffer_uri="/dev/zero"), allow)


def test_images_and_material_files_outside_are_refused(scene_dir):
    with pytest.warns(GltfWarning, match="outside the scene's folder"):
        scene = _load(scene_dir, _gltf(image_uri="../canary.bin"))
    assert scene.materials[0].texture("base_color") is None
    with pytest.raises(GltfError, match="outside the scene's folder"):
        _load(scene_dir, _gltf(extras="../canary.bin"))
    (scene_dir / "mat.json").write_text(json.dumps({"model": "gltf", "base_color": [0.2, 0.3, 0.4]}))
    assert _load(scene_dir, _gltf(extras="mat.json")).materials[0].desc["base_color"] == [0.2, 0.3, 0.4]


def test_indices_strides_and_graphs_are_checked(scene_dir):
    cases = {
        "accessor index -1": (_gltf(meshes=[{"primitives": [{"attributes": {"POSITION": -1}}]}]), "out of range"),
        "strided past the end": (
            _gltf(
                bufferViews=[{"buffer": 0, "byteLength": 36, "byteStride": 24}],
            ),
            "reads past the end",
        ),
        "stride below element": (
            _gltf(bufferViews=[{"buffer": 0, "byteLength": 36, "byteStride": 4}]),
            "less than one element",
        ),
        "negative offset": (
            _gltf(accessors=[{"bufferView": 0, "byteOffset": -8, "componentType": 5126, "count": 3, "type": "VEC3"}]),
            "non-negative integer",
        ),
        "negative count": (
            _gltf(accessors=[{"bufferView": 0, "componentType": 5126, "count": -3, "type": "VEC3"}]),
            "non-negative integer",
        ),
        "cycle": (_gltf(nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}]), "reached twice"),
        "shared children": (
            _gltf(nodes=[{"children": [1, 1]}, {"mesh": 0}]),
            "reached twice",
        ),
        "material index": (
            _gltf(meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "material": 5}]}]),
            "material index 5",
        ),
        "bad byteLength": (_gltf(buffers=[{"uri": "tri.bin", "byteLength": 10**12}]), "truncated"),
    }
    for name, (g, message) in cases.items():
        with pytest.raises(GltfError, match=message):
            _load(scene_dir, g)
            pytest.fail(f"{name}: loaded")


def test_declared_sizes_are_refused_before_allocation(scene_dir):
    huge = _gltf(accessors=[{"componentType": 5126, "count": 2_000_000_000, "type": "VEC3"}])
    tracemalloc.start()
    with pytest.raises(GltfError, match="memory budget"):
        _load(scene_dir, huge)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 50 * 2**20
    # A PNG whose header declares 100000 x 100000 pixels: refused from the header, warned.
    import io

    from PIL import Image

    small = io.BytesIO()
    Image.new("RGB", (4, 4)).save(small, "PNG")
    png = bytearray(small.getvalue())
    struct.pack_into(">II", png, 16, 100_000, 100_000)  # IHDR width, height
    struct.pack_into(">I", png, 29, zlib.crc32(bytes(png[12:29])))  # and its CRC
    (scene_dir / "big.png").write_bytes(bytes(png))
    with pytest.warns(GltfWarning, match="100000x100000|10000000000 pixels"):
        scene = _load(scene_dir, _gltf(image_uri="big.png"))
    assert scene.materials[0].texture("base_color") is None
    # A Radiance header declaring the same.
    (scene_dir / "big.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n" + b"\0" * 64)
    with pytest.raises(HDRImageError, match="100000x100000"):
        read_hdr_image(scene_dir / "big.hdr")


def test_budget_and_limits_units():
    assert parse_budget("6G") == 6 << 30 and parse_budget("512M") == 512 << 20 and parse_budget("1.5GiB") == 3 << 29
    for bad in ("lots", "-1G", "10"):
        with pytest.raises(ValueError):
            parse_budget(bad)
    budget = LoadBudget(Limits(memory_budget_bytes=1 << 20), "x")
    budget.take(1 << 19, "half")
    with pytest.raises(ValueError, match="memory budget"):
        budget.take(1 << 20, "too much")
    with pytest.raises(ValueError, match="NUL"):
        resolve_reference(Path("."), "a\x00b", "image")


def test_cli_refuses_outside_references_and_documents_the_opt_in(scene_dir, capsys):
    from lobeview.app.cli import main

    path = scene_dir / "s.gltf"
    path.write_text(json.dumps(_gltf(buffer_uri="../canary.bin")))
    assert main(["shot", str(path), "--size", "16x16", "--out", str(scene_dir / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "--allow-outside-references" in err and "Traceback" not in err
    assert main(["shot", str(path), "--memory-budget", "lots", "--out", str(scene_dir / "x.png")]) == 2
    assert "--memory-budget" in capsys.readouterr().err
