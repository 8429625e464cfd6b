"""``lobeview bake``'s output: the input glTF written back unchanged except for the lightmap.

The scene a user bakes keeps its look: every material (factors, textures, samplers, alpha mode,
extensions, extras), every node, camera, skin and animation of the input JSON is copied as it
was. What changes is only what the lightmap needs:

- every material gets ``MOZ_lightmap`` (``texCoord`` 1, ``intensity`` 1) naming the baked
  atlas, which is embedded in the .glb as an EXR image (MIME type ``image/x-exr``) or written
  beside the output (``external_lightmap``);
- when the baker unwrapped the scene (xatlas), each baked primitive gets the atlas coordinates
  as TEXCOORD_1 and, because xatlas splits vertices along chart seams, every other attribute
  (and morph target) is re-gathered through the split with its component type unchanged, and
  new indices; a mesh drawn by several nodes is copied per node, since each instance has its own
  place in the atlas;
- the output is one self-contained .glb: the buffers and the images the input referenced by file
  name are embedded (the output may live anywhere, the input's folder stays untouched);
- primitives without a material get an explicit one with the values lobeview renders them with
  (it carries the lightmap), and ``extras.lobeview`` material file names are replaced by the
  material they name; a measured material's MERL table is copied beside the output as
  ``<output stem>_<table name>`` (returned among the files written) and named by it.

Everything read from the input goes through the loader's trust checks again (folder rule, sizes).
"""

from __future__ import annotations

import copy
import json
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np

from lobeview.core.trust import DEFAULT_LIMITS, Limits, read_reference

from .gltf_loader import GltfError, _parse, _Reader
from .hdrio import write_hdr_image
from .scene import Scene

_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_COMPONENT_TYPES = {np.dtype("int8"): 5120, np.dtype("uint8"): 5121, np.dtype("int16"): 5122,
                    np.dtype("uint16"): 5123, np.dtype("uint32"): 5125, np.dtype("float32"): 5126}  # fmt: skip
_IMAGE_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
               ".ktx2": "image/ktx2", ".exr": "image/x-exr", ".hdr": "image/vnd.radiance"}  # fmt: skip
LIGHTMAP_MIME = "image/x-exr"


def source_json(path: Path, limits: Limits = DEFAULT_LIMITS) -> dict:
    """The input's glTF JSON exactly as written (every field, extensions and extras included)."""
    return parse_source_json(path, read_reference(path.parent, path.name, f"{path}: scene file", limits))


def parse_source_json(path: Path, data: bytes) -> dict:
    """:func:`source_json` of the file ``path`` whose bytes ``data`` were read already."""
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != _GLB_MAGIC:
            raise GltfError(f"{path}: not a GLB file (bad magic) or truncated")
        chunk_length, chunk_type = struct.unpack_from("<II", data, 12)
        if chunk_type != _JSON_CHUNK or 20 + chunk_length > len(data):
            raise GltfError(f"{path}: GLB without a complete JSON chunk first")
        text = data[20 : 20 + chunk_length]
    else:
        text = data
    try:
        return json.loads(bytes(text).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GltfError(f"{path}: cannot parse glTF JSON: {exc}") from None


class _BinaryChunk:
    """The output's one buffer, built up view by view."""

    def __init__(self):
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def append(self, data: bytes, offset_like: int = 0) -> int:
        # Keep the input's offset modulo 16: an accessor's byteOffset inside a copied view stays
        # aligned to its component size exactly as it was.
        while len(self.blob) % 16 != offset_like % 16:
            self.blob.append(0)
        offset = len(self.blob)
        self.blob.extend(data)
        return offset

    def add_view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        view = {"buffer": 0, "byteOffset": self.append(data), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        if stride is not None:
            view["byteStride"] = stride
        self.views.append(view)
        return len(self.views) - 1

    def add_accessor(self, values: np.ndarray, kind: str, target: int, template: dict | None = None) -> int:
        """``values`` (count, components) in their final component type. Vertex attributes are
        padded to 4-byte elements as glTF requires (e.g. VEC3 of unsigned bytes)."""
        values = np.ascontiguousarray(values)
        count = len(values)
        item = values.dtype.itemsize * (values.shape[1] if values.ndim > 1 else 1)
        stride = None
        data = values.tobytes()
        if target == _ARRAY_BUFFER and item % 4:
            stride = item + (-item) % 4
            rows = np.zeros((count, stride), np.uint8)
            rows[:, :item] = np.frombuffer(data, np.uint8).reshape(count, item)
            data = rows.tobytes()
        accessor = {
            "bufferView": self.add_view(data, target, stride),
            "componentType": _COMPONENT_TYPES[values.dtype],
            "count": count,
            "type": kind,
        }
        if template is not None:
            for key in ("normalized", "name", "extras"):
                if key in template:
                    accessor[key] = template[key]
        if template is None or "min" in template or "max" in template:
            flat = values.reshape(count, -1)
            if count:
                accessor["min"] = flat.min(axis=0).tolist()
                accessor["max"] = flat.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def write_baked_gltf(
    source: str | Path,
    scene: Scene,
    lightmap: np.ndarray,
    out: str | Path,
    limits: Limits = DEFAULT_LIMITS,
    external_lightmap: bool = False,
) -> list[Path]:
    """Write ``source`` with ``scene``'s lightmap to the .glb ``out``; returns the files written.

    ``scene`` is what :func:`~lobeview.scenes.gltf_loader.load_gltf` made of ``source`` (objects
    carry their ``origin``), possibly unwrapped (``vertex_map`` and ``uv1`` set) and baked."""
    source, out = Path(source), Path(out)
    if out.suffix.lower() != ".glb":
        raise ValueError(f"{out}: the baked scene is written as a .glb (one self-contained file)")
    if not all(obj.origin is not None for obj in scene.objects):
        raise ValueError("the scene has generated objects; write_baked_gltf rewrites a loaded glTF")
    reader = _Reader(_parse(source, limits), source, limits)
    doc = source_json(source, limits)
    chunk = _BinaryChunk()

    # 1. Every bufferView copied into the one binary chunk (accessors keep their indices).
    for index, view in enumerate(doc.get("bufferViews") or []):
        data, _ = reader.view_bytes(index)
        copied = {k: v for k, v in view.items() if k not in ("buffer", "byteOffset")}
        copied["buffer"] = 0
        copied["byteOffset"] = chunk.append(bytes(data), int(view.get("byteOffset", 0)))
        chunk.views.append(copied)
    chunk.accessors = list(doc.get("accessors") or [])

    # 2. Images the input names by file: embedded, so the output stands on its own.
    for image in doc.get("images") or []:
        uri = image.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:"):
            data = read_reference(source.parent, uri, f"{source}: image", limits)
            del image["uri"]
            image["bufferView"] = chunk.add_view(data)
            image.setdefault("mimeType", _IMAGE_MIME.get(Path(uri).suffix.lower(), "image/png"))

    # 3. Geometry: atlas coordinates as TEXCOORD_1 where the baker unwrapped.
    meshes = doc.get("meshes") or []
    original_meshes = copy.deepcopy(meshes)
    nodes = doc.get("nodes") or []
    default_material = None
    claimed: dict[int, int] = {}  # mesh index -> the node that keeps the original mesh
    for obj in scene.objects:
        node_index, mesh_index, prim_index, flipped = obj.origin
        owner = claimed.setdefault(mesh_index, node_index)
        if obj.vertex_map is not None and owner != node_index and nodes[node_index]["mesh"] == mesh_index:
            meshes.append(copy.deepcopy(original_meshes[mesh_index]))
            nodes[node_index]["mesh"] = len(meshes) - 1
        prim = meshes[nodes[node_index]["mesh"]]["primitives"][prim_index]
        if prim.get("material") is None:
            if default_material is None:
                default_material = _append_default_material(doc, scene)
            prim["material"] = default_material
        if obj.vertex_map is None:
            if obj.uv1 is None:
                continue
            if "TEXCOORD_1" in prim.get("attributes", {}):
                continue  # the file's own lightmap coordinates, baked into as they are
            prim["attributes"]["TEXCOORD_1"] = chunk.add_accessor(obj.uv1.astype(np.float32), "VEC2", _ARRAY_BUFFER)
            continue
        vertex_map = np.asarray(obj.vertex_map, dtype=np.int64)

        def regather(accessor_index: int, vertex_map: np.ndarray = vertex_map) -> int:
            template = doc["accessors"][accessor_index]
            values = reader.accessor(accessor_index, raw=True)[vertex_map]
            return chunk.add_accessor(values, template["type"], _ARRAY_BUFFER, template)

        attributes = {name: regather(a) for name, a in prim["attributes"].items() if name != "TEXCOORD_1"}
        attributes["TEXCOORD_1"] = chunk.add_accessor(obj.uv1.astype(np.float32), "VEC2", _ARRAY_BUFFER)
        prim["attributes"] = attributes
        if prim.get("targets"):
            prim["targets"] = [{name: regather(a) for name, a in target.items()} for target in prim["targets"]]
        triangles = obj.mesh.indices.reshape(-1, 3)
        if flipped:  # the loader reversed them for a mirroring node; the file keeps its own winding
            triangles = triangles[:, ::-1]
        index_type = np.uint16 if len(vertex_map) < 65535 else np.uint32
        prim["indices"] = chunk.add_accessor(
            triangles.reshape(-1, 1).astype(index_type), "SCALAR", _ELEMENT_ARRAY_BUFFER, {}
        )
        prim.pop("mode", None)  # triangles, the default (the loader bakes nothing else)

    # 4. The lightmap as a texture, and every material pointing at it.
    written = [out]
    image = {"name": "lightmap"}
    if external_lightmap:
        name = out.stem + "_lightmap.exr"
        written.append(write_hdr_image(out.parent / name, lightmap))
        image["uri"] = name
    else:
        with tempfile.TemporaryDirectory(prefix="lobeview-bake-") as folder:
            data = write_hdr_image(Path(folder) / "lightmap.exr", lightmap).read_bytes()
        image["bufferView"] = chunk.add_view(data)
        image["mimeType"] = LIGHTMAP_MIME
    doc.setdefault("images", []).append(image)
    doc.setdefault("samplers", []).append({"magFilter": 9729, "minFilter": 9729, "wrapS": 33071, "wrapT": 33071})
    doc.setdefault("textures", []).append({"source": len(doc["images"]) - 1, "sampler": len(doc["samplers"]) - 1})
    lightmap_texture = len(doc["textures"]) - 1
    for index, material in enumerate(doc.get("materials") or []):
        extensions = material.setdefault("extensions", {})
        extensions["MOZ_lightmap"] = {"index": lightmap_texture, "texCoord": 1, "intensity": 1.0}
        extras = material.get("extras")
        if isinstance(extras, dict) and "lobeview" in extras and index < len(scene.materials):
            desc = scene.materials[index].desc
            if desc.get("model") == "measured":
                # The table travels with the output (a scene names files only in its own folder).
                extras["lobeview"] = {**desc, "file": _copy_table(Path(desc["file"]), out, written)}
            elif isinstance(extras["lobeview"], str):
                extras["lobeview"] = desc  # a file or preset name: the material itself
    used = doc.setdefault("extensionsUsed", [])
    if "MOZ_lightmap" not in used:
        used.append("MOZ_lightmap")

    doc["bufferViews"] = chunk.views
    doc["accessors"] = chunk.accessors
    doc["buffers"] = [{"byteLength": len(chunk.blob)}]
    generator = doc.setdefault("asset", {}).get("generator")
    doc["asset"]["generator"] = f"{generator} + lobeview bake" if generator else "lobeview bake"
    _write_glb(out, doc, bytes(chunk.blob))
    return written


def _copy_table(table: Path, out: Path, written: list) -> str:
    """Copy a measured material's table beside the baked scene ``out`` (once per table) and
    return the name the output's material names it by."""
    name = f"{out.stem}_{table.name}"
    target = out.parent / name
    if target not in written:
        shutil.copyfile(table, target)
        written.append(target)
    return name


def _append_default_material(doc: dict, scene: Scene) -> int:
    """The material lobeview gives primitives that have none, written out explicitly."""
    default = scene.materials[-1]
    doc.setdefault("materials", []).append(
        {
            "name": "lobeview default",
            "pbrMetallicRoughness": {
                "baseColorFactor": [*map(float, default.desc.get("base_color", [0.8, 0.8, 0.8])), 1.0],
                "metallicFactor": float(default.desc.get("metallic", 0.0)),
                "roughnessFactor": float(default.desc.get("roughness", 1.0)),
            },
        }
    )
    return len(doc["materials"]) - 1


def _write_glb(path: Path, doc: dict, blob: bytes) -> None:
    text = json.dumps(doc, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    length = 12 + 8 + len(text) + 8 + len(blob)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<4sII", _GLB_MAGIC, 2, length))
        f.write(struct.pack("<II", len(text), _JSON_CHUNK) + text)
        f.write(struct.pack("<II", len(blob), _BIN_CHUNK) + blob)
    tmp.replace(path)
