"""The input fuzzer (issue 17): deterministic mutations of lobeview's inputs, each run in a
sandboxed worker process, each outcome checked against the promise that bad input gets a clean
error or a warned fallback with finite output, never a traceback, crash, hang, runaway memory
or a file outside the scene's folder opened.

    python -m lobeview.bench.fuzz --cases 2000 --seed 1        # long run, report in bench/results
    python -m lobeview.bench.fuzz --cases 200 --quick          # what CI runs (tests/test_fuzz.py)

Sources (written fresh into the work folder, so a run needs nothing but lobeview): a baked
MOZ_lightmap .glb with an EXR lightmap, cameras, a preset material in extras; a .gltf with an
external interleaved (strided) buffer, a PNG texture, a data-URI texture and a node hierarchy;
EXR and Radiance environment maps; a material JSON; a material-edits JSON; a goniophotometer CSV;
a measured material naming its MERL table by file (a short stand-in table: its path and size
checks are fuzzed, a 35 MB table per case is not); a camera path; a viewer script; and, when
../shared/assets is present, the Khronos CornellBox.glb and Suzanne.gltf.

Mutations (:data:`OPERATORS`): byte flips, truncation, inserted junk, structured JSON edits of
the glTF (hostile values at a random field, deleted fields, node cycles and shared children),
hostile URIs (absolute, ``..``, percent-encoded, ``file://``, devices, /proc, a symlink out),
header tampering (GLB lengths, PNG IHDR, Radiance resolution), mutated companion files (the
.bin/.png/.exr a scene references), NaN/Inf/negative texels in valid HDR files, and CSV edits
(hostile cells, duplicated or dropped columns, short and long rows, huge weights, a BOM).

Targets: ``load`` (load_gltf + scene analysis), ``env`` (environment map), ``material``
(``lobeview material show``), ``edits`` (``--materials`` on a scene), ``shot`` (the full
renderer through the CLI, a 24x16 image), ``bake`` (the CLI baker at 16^2 texels, long mode), ``fit``
(``lobeview fit`` on the CSV, a small grid), ``path`` (``view --path``'s reader, sampled) and
``script`` (``view --script``'s reader).

Outcome classes: ``ok``, ``warned`` (a documented fallback, output finite), ``error`` (a clean
lobeview error), and the failures ``traceback``, ``crash`` (signal), ``hang`` (past the time
limit), ``memory`` (past the worker's address-space limit), ``escape`` (a canary or a system
file opened), ``nonfinite`` (NaN/Inf/negative output). The worker is a plain script run with
``python bench/fuzz_worker.py`` so the same cases can be run against another checkout of
lobeview (``--pythonpath``) for a before/after comparison.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import zlib
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .fuzz_inputs import measurement_sources, mutate_csv
from .fuzz_worker import CANARY, SYSTEM_FILES

FAILURES = ("traceback", "crash", "hang", "memory", "escape", "nonfinite")
CLASSES = ("ok", "warned", "error") + FAILURES
TIME_LIMIT_S = {
    "load": 60, "env": 60, "material": 60, "edits": 60, "shot": 300, "bake": 300,
    "fit": 60, "path": 60, "script": 60,
}  # fmt: skip
CANARY_TEXT = "lobeview fuzz canary: this file lies outside every scene folder\n"

HOSTILE_VALUES = [
    -1,
    0,
    1,
    3,
    255,
    2**31 - 1,
    2**32 + 3,
    2**63,
    -(2**31),
    1e308,
    -1e308,
    0.5,
    "",
    "A" * 5000,
    [],
    {},
    None,
    True,
    [0, 0, 0, 0, 0],
    {"a": 1},
    "../" + CANARY,
]


def hostile_uris(case_dir: Path) -> list[str]:
    canary = case_dir.parent / CANARY
    return [
        "../" + CANARY,
        "..%2F" + CANARY,
        "%2e%2e/" + CANARY,
        "sub/../../" + CANARY,
        str(canary),
        "//" + str(canary).lstrip("/"),
        "file://" + str(canary),
        "link_out.bin",  # symlink to the canary, made in every case folder
        "http://example.invalid/x.bin",
        *SYSTEM_FILES,
    ]


@dataclass
class Case:
    index: int
    source: str
    operator: str
    target: str
    detail: str = ""
    entry: str = ""  # file the target reads, relative to the case folder


@dataclass
class Outcome:
    index: int
    source: str
    operator: str
    target: str
    detail: str
    outcome: str
    message: str = ""
    seconds: float = 0.0
    opened_outside: list = field(default_factory=list)
    peak_mib: float = 0.0  # the worker's peak resident set during the case (VmHWM after a reset)


# -- sources -------------------------------------------------------------------------------------


def _png_bytes(rgb: np.ndarray) -> bytes:
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, "PNG")
    return buf.getvalue()


def _textured_gltf(folder: Path) -> None:
    """A quad (interleaved POSITION/NORMAL/UV, stride 32) under a parent node, a camera, a PNG
    texture file and a second, data-URI texture."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    normals = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    interleaved = np.concatenate([positions, normals, uvs], axis=1).astype(np.float32).tobytes()
    indices = np.array([0, 1, 2, 0, 2, 3], np.uint16).tobytes()
    (folder / "quad.bin").write_bytes(interleaved + indices)
    checker = (np.indices((8, 8)).sum(axis=0) % 2 * 200 + 30).astype(np.uint8)
    (folder / "checker.png").write_bytes(_png_bytes(np.stack([checker] * 3, axis=-1)))
    tiny = base64.b64encode(_png_bytes(np.full((2, 2, 3), 128, np.uint8))).decode()
    gltf = {
        "asset": {"version": "2.0", "generator": "lobeview fuzz"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "root", "children": [1, 2], "scale": [2, 2, 2]},
            {"name": "quad", "mesh": 0, "translation": [0, 0, -1]},
            {"name": "cam", "camera": 0, "translation": [0.5, 0.5, 2]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1, "aspectRatio": 1.5}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3}]}],
        "materials": [
            {
                "name": "painted",
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0},
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.4,
                },
                "emissiveFactor": [0.1, 0.0, 0.0],
                "extras": {"lobeview": "alanod-2000gs-1lobe"},
            }
        ],
        "textures": [{"source": 0}, {"source": 1}],
        "images": [{"uri": "checker.png"}, {"uri": "data:image/png;base64," + tiny}],
        "buffers": [{"uri": "quad.bin", "byteLength": len(interleaved) + len(indices)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(interleaved), "byteStride": 32, "target": 34962},
            {"buffer": 0, "byteOffset": len(interleaved), "byteLength": len(indices), "target": 34963},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "byteOffset": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 0],
            },
            {"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 0, "byteOffset": 24, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }
    gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    (folder / "textured.gltf").write_text(json.dumps(gltf, indent=1))


def _lit_glb(folder: Path) -> None:
    """A small lightmapped scene as `lobeview bake` writes it: floor + sphere + box, one camera."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.meshes import box_mesh, quad, uv_sphere
    from lobeview.scenes.scene import Scene, SceneCamera, SceneMaterial, SceneObject

    floor = quad((-2, 0, 2), (4, 0, 0), (0, 0, -4))
    sphere = uv_sphere(0.5, rings=8, segments=16)
    sphere.positions = sphere.positions + np.array([0, 0.5, 0], np.float32)
    box = box_mesh((1, 0.3, 0), (0.6, 0.6, 0.6))
    objects = []
    for i, mesh in enumerate((floor, sphere, box)):
        uv1 = (mesh.uvs * 0.3 + np.array([0.33 * i, 0.0])).astype(np.float32)
        objects.append(SceneObject(f"object{i}", mesh, min(i, 1), uv1))
    materials = [
        SceneMaterial("floor", validate({"model": "gltf", "base_color": [0.6, 0.6, 0.6], "roughness": 0.6})),
        SceneMaterial("glossy", validate({"model": "gltf", "base_color": [0.8, 0.2, 0.2], "roughness": 0.2})),
    ]
    cameras = [SceneCamera("overview", np.array([0, 1.5, 4.0]), np.array([0, 0.3, 0.0]), np.array([0, 1.0, 0]), 45.0)]
    lightmap = np.full((16, 16, 3), 0.7, np.float32)
    write_glb(Scene(objects, materials, cameras), folder / "lit.glb", lightmap, lightmap_name="lit_lightmap.exr")


def write_sources(folder: Path) -> dict[str, str]:
    """Write the sources into ``folder``; returns source name -> entry file."""
    from lobeview.materials.presets import PRESETS
    from lobeview.scenes.hdrio import write_hdr_image

    folder.mkdir(parents=True, exist_ok=True)
    _textured_gltf(folder)
    _lit_glb(folder)
    d = np.stack(np.meshgrid(np.linspace(0, 1, 32), np.linspace(0, 1, 16)), -1)
    env = np.concatenate([d, np.ones_like(d[..., :1])], -1).astype(np.float32) * 2.0
    write_hdr_image(folder / "env.exr", env)
    write_hdr_image(folder / "env.hdr", env)
    (folder / "material.json").write_text(json.dumps(PRESETS["alanod-2000gs-1lobe"], indent=1))
    (folder / "edits.json").write_text(
        json.dumps({"glossy": {"model": "gltf", "base_color": [0.1, 0.5, 0.9], "roughness": 0.1}}, indent=1)
    )
    measurement_sources(folder)
    sources = {
        "textured.gltf": "textured.gltf",
        "lit.glb": "lit.glb",
        "env.exr": "env.exr",
        "env.hdr": "env.hdr",
        "material.json": "material.json",
        "edits.json": "edits.json",
        "measurement.csv": "measurement.csv",
        "measured.json": "measured.json",
        "path.json": "path.json",
        "script.json": "script.json",
    }
    shared = Path(__file__).resolve().parents[1].parent / "shared" / "assets" / "gltf"
    for name in ("CornellBox/CornellBox.glb", "Suzanne/Suzanne.gltf"):
        src = shared / name
        if src.is_file():
            for f in src.parent.iterdir():
                shutil.copy(f, folder / f.name)
            sources[src.name] = src.name
    return sources


# -- mutations -----------------------------------------------------------------------------------


def _json_paths(value, prefix=()):
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _json_paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value[:64]):
            yield from _json_paths(v, prefix + (i,))


def _set(root, path, value):
    target = root
    for key in path[:-1]:
        target = target[key]
    if value is _DELETE:
        del target[path[-1]]
    else:
        target[path[-1]] = value


_DELETE = object()


def _split_glb(data: bytes) -> tuple[dict, bytes]:
    json_length = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20 : 20 + json_length])
    rest = data[20 + json_length :]
    binary = b""
    if len(rest) >= 8:
        bin_length = struct.unpack_from("<I", rest, 0)[0]
        binary = rest[8 : 8 + bin_length]
    return doc, binary


def _join_glb(doc: dict, binary: bytes) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    if binary:
        chunks += struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def _read_doc(path: Path):
    data = path.read_bytes()
    if path.suffix == ".glb":
        return _split_glb(data)
    return json.loads(data), None


def _write_doc(path: Path, doc, binary) -> None:
    if path.suffix == ".glb":
        path.write_bytes(_join_glb(doc, binary))
    else:
        path.write_text(json.dumps(doc))


def _mutate_bytes(data: bytes, rng, op: str) -> tuple[bytes, str]:
    data = bytearray(data)
    if op == "flip":
        k = int(rng.integers(1, 17))
        for _ in range(k):
            if data:
                data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        return bytes(data), f"{k} bit flips"
    if op == "truncate":
        cut = int(rng.integers(0, max(len(data), 1)))
        return bytes(data[:cut]), f"truncated to {cut} of {len(data)} bytes"
    if op == "insert":
        at = int(rng.integers(0, len(data) + 1))
        junk = rng.integers(0, 256, int(rng.integers(1, 64))).astype(np.uint8).tobytes()
        return bytes(data[:at]) + junk + bytes(data[at:]), f"{len(junk)} junk bytes at {at}"
    if op == "zero":
        at = int(rng.integers(0, max(len(data), 1)))
        n = int(rng.integers(1, 256))
        data[at : at + n] = b"\0" * len(data[at : at + n])
        return bytes(data), f"{n} bytes zeroed at {at}"
    raise ValueError(op)


def _mutate_json(doc, rng, case_dir: Path, kind: str | None = None) -> str:
    """One structured edit of a JSON document (in place); returns what was done."""
    paths = [p for p in _json_paths(doc) if p]
    kind = kind or rng.choice(["value", "value", "value", "delete", "cycle", "uri", "count"])
    if kind == "cycle" and isinstance(doc, dict) and doc.get("nodes"):
        n = len(doc["nodes"])
        a, b = int(rng.integers(n)), int(rng.integers(n))
        doc["nodes"][a].setdefault("children", []).append(b)
        return f"nodes[{a}].children += [{b}]"
    if kind == "uri":
        holders = [p for p in paths if p[-1] in ("uri", "file")]  # "file": a measured material's table
        if holders:
            where = holders[int(rng.integers(len(holders)))]
            uris = hostile_uris(case_dir)
            uri = uris[int(rng.integers(len(uris)))]
            _set(doc, where, uri)
            return f"{'.'.join(map(str, where))} = {uri!r}"
    if kind == "count":
        holders = [p for p in paths if p[-1] in ("count", "byteLength", "byteStride", "byteOffset")]
        if holders:
            where = holders[int(rng.integers(len(holders)))]
            value = [0, 1, 3, 2**20, 2**31 - 1, 2**40, -4, 4, 7, 253][int(rng.integers(10))]
            _set(doc, where, value)
            return f"{'.'.join(map(str, where))} = {value}"
    if not paths:
        return "no field to mutate"
    where = paths[int(rng.integers(len(paths)))]
    if kind == "delete":
        _set(doc, where, _DELETE)
        return f"del {'.'.join(map(str, where))}"
    value = HOSTILE_VALUES[int(rng.integers(len(HOSTILE_VALUES)))]
    _set(doc, where, value)
    return f"{'.'.join(map(str, where))} = {str(value)[:40]!r}"


def _tamper_header(path: Path, rng) -> str:
    data = bytearray(path.read_bytes())
    suffix = path.suffix.lower()
    if suffix == ".glb":
        field_at = [8, 12, 20 + struct.unpack_from("<I", data, 12)[0]][int(rng.integers(3))]
        value = [0, 1, 2**31, 2**32 - 1, len(data) + 8][int(rng.integers(5))]
        if field_at + 4 <= len(data):
            struct.pack_into("<I", data, field_at, value)
        path.write_bytes(bytes(data))
        return f"GLB length field at {field_at} = {value}"
    if suffix == ".png":
        w, h = [(100000, 100000), (0, 5), (1, 2**31 - 1), (65535, 65535), (9, 9)][int(rng.integers(5))]
        struct.pack_into(">II", data, 16, w, h)
        struct.pack_into(">I", data, 29, zlib.crc32(bytes(data[12:29])))
        path.write_bytes(bytes(data))
        return f"PNG IHDR {w}x{h}"
    if suffix == ".hdr":
        text = bytes(data)
        at = text.find(b"-Y ")
        end = text.find(b"\n", at)
        line = [b"-Y 100000 +X 200000", b"-Y 0 +X 0", b"+Y 16 +X 32", b"-Y 16 +X 99999999999", b"-Y 1 +X 32"][
            int(rng.integers(5))
        ]
        path.write_bytes(text[:at] + line + text[end:])
        return f"Radiance resolution {line.decode()}"
    if suffix == ".exr":
        # dataWindow is box2i: 4 int32 after the attribute name and type.
        at = bytes(data).find(b"dataWindow\0box2i\0")
        if at >= 0:
            value_at = at + len(b"dataWindow\0box2i\0") + 4
            corner = [(0, 0, 99999, 99999), (0, 0, -5, -5), (2**31 - 1, 0, -(2**31), 7)][int(rng.integers(3))]
            struct.pack_into("<4i", data, value_at, *corner)
            path.write_bytes(bytes(data))
            return f"EXR dataWindow {corner}"
    return _apply_bytes(path, rng, "flip")


def _apply_bytes(path: Path, rng, op: str) -> str:
    data, detail = _mutate_bytes(path.read_bytes(), rng, op)
    path.write_bytes(data)
    return f"{path.name}: {detail}"


def _companions(folder: Path, entry: str) -> list[Path]:
    kinds = (".bin", ".png", ".exr")
    return sorted(p for p in folder.iterdir() if p.is_file() and p.name != entry and p.suffix in kinds)


def _special_texels(path: Path, rng) -> str:
    from lobeview.scenes.hdrio import read_hdr_image, write_hdr_image

    image = read_hdr_image(path)
    n = int(rng.integers(1, 20))
    ys, xs = rng.integers(0, image.shape[0], n), rng.integers(0, image.shape[1], n)
    values = np.array([np.nan, np.inf, -np.inf, -3.0, -1e-3, 6.5e4, 1e30], np.float32)
    image[ys, xs, rng.integers(0, 3, n)] = values[rng.integers(0, len(values), n)]
    write_hdr_image(path, image)
    return f"{n} special texels (NaN/Inf/negative/huge)"


OPERATORS = ("flip", "truncate", "insert", "zero", "json", "uri", "header", "companion", "texels")


def make_case(index: int, seed: int, sources: dict[str, str], source_dir: Path, work: Path, long_mode: bool) -> Case:
    """Copy the sources into ``work/case_NNNNN`` and apply one mutation chosen by (seed, index)."""
    rng = np.random.default_rng([seed, index])
    names = sorted(sources)
    source = names[int(rng.integers(len(names)))]
    entry = sources[source]
    case_dir = work / f"case_{index:05d}"
    if case_dir.exists():
        shutil.rmtree(case_dir)
    shutil.copytree(source_dir, case_dir)
    os.symlink(work / CANARY, case_dir / "link_out.bin")
    path = case_dir / entry
    suffix = path.suffix.lower()
    if suffix in (".gltf", ".glb"):
        operators = ["json", "json", "json", "uri", "flip", "truncate", "insert", "zero", "header", "companion"]
        targets = ["load"] * 8 + ["shot"] + (["bake"] if long_mode else ["load"])
    elif suffix in (".exr", ".hdr"):
        operators = ["flip", "truncate", "insert", "zero", "header", "texels", "texels"]
        targets = ["env"] * 4 + ["shot"]
    elif suffix == ".csv":
        operators = ["csv", "csv", "csv", "flip", "truncate", "insert"]
        targets = ["fit"]
    else:
        operators = ["json", "json", "json", "flip", "truncate", "insert"]
        targets = {"material.json": ["material"], "measured.json": ["material"], "path.json": ["path"],
                   "script.json": ["script"]}.get(source, ["edits"])  # fmt: skip
    operator = operators[int(rng.integers(len(operators)))]
    target = targets[int(rng.integers(len(targets)))]
    if operator in ("flip", "truncate", "insert", "zero"):
        detail = _apply_bytes(path, rng, operator)
    elif operator == "csv":
        detail = mutate_csv(path, rng)
    elif operator == "json":
        try:
            doc, binary = _read_doc(path)
        except (ValueError, struct.error):
            doc, binary = None, None
        if doc is None:
            detail = _apply_bytes(path, rng, "flip")
        else:
            detail = _mutate_json(doc, rng, case_dir)
            _write_doc(path, doc, binary)
    elif operator == "uri":
        doc, binary = _read_doc(path)
        if any(p and p[-1] == "uri" for p in _json_paths(doc)):
            detail = _mutate_json(doc, rng, case_dir, kind="uri")
        else:  # a .glb with no URIs: add an external image that escapes
            uris = hostile_uris(case_dir)
            doc.setdefault("images", []).append({"uri": uris[int(rng.integers(len(uris)))]})
            doc.setdefault("textures", []).append({"source": len(doc["images"]) - 1})
            if doc.get("materials"):
                doc["materials"][0].setdefault("pbrMetallicRoughness", {})["baseColorTexture"] = {
                    "index": len(doc["textures"]) - 1
                }
            detail = f"added image uri {doc['images'][-1]['uri']!r}"
        _write_doc(path, doc, binary)
    elif operator == "header":
        detail = _tamper_header(path, rng)
    elif operator == "companion":
        companions = _companions(case_dir, entry)
        victim = companions[int(rng.integers(len(companions)))] if companions else path
        if victim.suffix in (".png", ".exr") and rng.random() < 0.4:
            detail = _tamper_header(victim, rng)
        else:
            detail = _apply_bytes(victim, rng, ["flip", "truncate", "zero"][int(rng.integers(3))])
    else:  # texels
        detail = _special_texels(path, rng)
    return Case(index, source, operator, target, detail, str(path.relative_to(work)))


# -- the driver ----------------------------------------------------------------------------------


def run_fuzz(
    cases: int,
    seed: int,
    work: Path,
    long_mode: bool = False,
    pythonpath: str | None = None,
    progress=print,
    targets: tuple[str, ...] | None = None,
) -> list[Outcome]:
    work = Path(work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    (work / CANARY).write_text(CANARY_TEXT)
    source_dir = work / "sources"
    if source_dir.exists():
        shutil.rmtree(source_dir)
    sources = write_sources(source_dir)
    todo = []
    for i in range(cases):
        case = make_case(i, seed, sources, source_dir, work, long_mode)
        if targets is not None and case.target not in targets:
            case.target = "load" if case.target in ("shot", "bake") and "load" in targets else case.target
        todo.append(case)
    (work / "cases.jsonl").write_text("".join(json.dumps(asdict(c)) + "\n" for c in todo))
    env = {**os.environ, "PYTHONFAULTHANDLER": "1"}
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    results: dict[int, Outcome] = {}
    position = 0
    t_start = time.perf_counter()
    while position < len(todo):
        proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve().parent / "fuzz_worker.py"), str(work), str(position)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=env,
            text=True,
        )
        current = None
        started_at = time.perf_counter()
        import selectors

        selector = selectors.DefaultSelector()
        selector.register(proc.stdout, selectors.EVENT_READ)
        while True:
            limit = TIME_LIMIT_S[todo[current].target] if current is not None else 120
            ready = selector.select(timeout=max(0.1, limit - (time.perf_counter() - started_at)))
            if not ready:
                if current is None:  # the worker did not even start
                    proc.kill()
                    raise RuntimeError("fuzz worker did not start within 120 s")
                proc.kill()
                proc.wait()
                c = todo[current]
                results[current] = Outcome(**_case_fields(c), outcome="hang", message=f"no result in {limit} s")
                position = current + 1
                break
            line = proc.stdout.readline()
            if not line:  # worker died
                code = proc.wait()
                if current is None:
                    raise RuntimeError(f"fuzz worker exited with {code} before its first case")
                c = todo[current]
                kind = "crash"
                message = f"worker died with {signal.Signals(-code).name if code < 0 else f'exit {code}'}"
                results[current] = Outcome(**_case_fields(c), outcome=kind, message=message)
                position = current + 1
                break
            record = json.loads(line)
            if "start" in record:
                current = record["start"]
                started_at = time.perf_counter()
                continue
            c = todo[record["index"]]
            results[c.index] = Outcome(
                **_case_fields(c),
                outcome=record["outcome"],
                message=record["message"],
                seconds=record["seconds"],
                peak_mib=record.get("peak_mib", 0.0),
            )
            position = c.index + 1
            current = None
            started_at = time.perf_counter()
            if record["outcome"] not in FAILURES:  # keep only failing cases' folders, for reproduction
                shutil.rmtree(work / f"case_{c.index:05d}", ignore_errors=True)
            if progress and (position % 50 == 0 or position == len(todo)):
                counts = Counter(r.outcome for r in results.values())
                progress(f"[fuzz] {position}/{len(todo)} cases, {time.perf_counter() - t_start:.0f} s: {dict(counts)}")
            if position == len(todo):
                proc.wait()
                break
        selector.close()
    return [results[i] for i in range(len(todo))]


def _case_fields(c: Case) -> dict:
    return {"index": c.index, "source": c.source, "operator": c.operator, "target": c.target, "detail": c.detail}


def summarise(outcomes: list[Outcome]) -> dict:
    by_class = Counter(o.outcome for o in outcomes)
    by_target: dict[str, Counter] = {}
    by_operator: dict[str, Counter] = {}
    for o in outcomes:
        by_target.setdefault(o.target, Counter())[o.outcome] += 1
        by_operator.setdefault(o.operator, Counter())[o.outcome] += 1
    return {
        "cases": len(outcomes),
        "classes": {k: by_class.get(k, 0) for k in CLASSES},
        "failures": sum(by_class.get(k, 0) for k in FAILURES),
        "by_target": {k: dict(v) for k, v in sorted(by_target.items())},
        "by_operator": {k: dict(v) for k, v in sorted(by_operator.items())},
        "failed_cases": [asdict(o) for o in outcomes if o.outcome in FAILURES],
        # issue 43: every hostile input under 2 GB and 60 s; the worst case per target
        "cost_by_target": {
            target: {
                "max_seconds": round(max(o.seconds for o in outcomes if o.target == target), 2),
                "max_peak_mib": round(max(o.peak_mib for o in outcomes if o.target == target), 1),
                "slowest": max((o for o in outcomes if o.target == target), key=lambda o: o.seconds).detail[:120],
            }
            for target in sorted(by_target)
        },
        "examples": _examples(outcomes),
    }


def _examples(outcomes: list[Outcome], per_kind: int = 3) -> dict:
    """A few messages per (target, class): what users see for each kind of bad input."""
    out: dict[str, list] = {}
    for o in outcomes:
        bucket = out.setdefault(f"{o.target}/{o.outcome}", [])
        if len(bucket) < per_kind and o.message:
            bucket.append(f"#{o.index} {o.operator} ({o.detail[:80]}): {o.message[:240]}")
    return dict(sorted(out.items()))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.fuzz", description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=2000, help="number of mutated inputs (default 2000)")
    p.add_argument("--seed", type=int, default=1, help="seed of the mutations (default 1): same seed, same cases")
    p.add_argument("--work", default=None, help="work folder (default: a temporary folder, removed afterwards)")
    p.add_argument("--quick", action="store_true", help="no bake cases (what CI runs)")
    p.add_argument("--report", default=None, help="write the JSON report here (default bench/results/fuzz_SEED.json)")
    p.add_argument("--pythonpath", default=None, help="run the cases against the lobeview found on this path")
    args = p.parse_args(argv)
    if args.cases < 1:
        p.error("--cases must be at least 1")
    import tempfile

    from lobeview.core.paths import bench_results_dir

    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="lobeview-fuzz-"))
    t0 = time.perf_counter()
    outcomes = run_fuzz(args.cases, args.seed, work, long_mode=not args.quick, pythonpath=args.pythonpath)
    summary = summarise(outcomes)
    summary.update(
        seed=args.seed,
        long_mode=not args.quick,
        seconds=round(time.perf_counter() - t0, 1),
        lobeview=args.pythonpath or "this checkout",
        command=" ".join(["python -m lobeview.bench.fuzz", *(argv if argv is not None else sys.argv[1:])]),
    )
    report = Path(args.report) if args.report else bench_results_dir() / f"fuzz_seed{args.seed}.json"
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"[fuzz] {summary['cases']} cases in {summary['seconds']} s: {summary['classes']}")
    print(f"[fuzz] report: {report}" + (f"; failing cases kept in {work}" if summary["failures"] else ""))
    if not args.work and not summary["failures"]:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if summary["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
