"""glTF 2.0 loading (.gltf and .glb) into a world-space :class:`~lobeview.scenes.scene.Scene`.

pygltflib parses the container (JSON, GLB chunks); accessors, transforms and materials are read
here with numpy because lobeview needs what general loaders drop: TEXCOORD_1 and the
``MOZ_lightmap`` material extension (``index`` = texture with linear irradiance in EXR or
Radiance .hdr, ``texCoord``, ``intensity``), and a thesis-model material in ``extras.lobeview``
(a preset name or a material object, docs/guide.md "Material JSON").

Scene files are untrusted (docs/guide.md "Untrusted files and limits"): every URI goes through
:mod:`lobeview.core.trust` (only regular files inside the scene's folder unless the user opts in),
every index is range-checked (a negative index would silently wrap in Python), every accessor is
bounds-checked against its bufferView before a numpy view is made, the node graph must be a
forest (a node reached twice is refused: cycles and exponential instancing), and decoded arrays
count against a :class:`~lobeview.core.trust.LoadBudget` before they are allocated.

Bad input gets a :class:`GltfError` naming the file and the problem (missing file, corrupt or
truncated GLB, unsupported required extension, sparse accessors, missing buffers); recoverable
problems (missing images, non-triangle primitives, degenerate triangles, missing lightmaps) are
warned and use the documented fallbacks listed in :data:`FALLBACKS`.
"""

from __future__ import annotations

import base64
import io
import struct
import warnings
from pathlib import Path

import numpy as np

from lobeview.core.trust import (
    DEFAULT_LIMITS,
    BudgetError,
    Limits,
    LoadBudget,
    UntrustedReferenceError,
    check_regular_file,
    read_reference,
    resolve_reference,
)
from lobeview.materials.spec import MaterialError

from .gltf_common import FALLBACKS, GltfError, _count, _index, _warn, make_names_printable, printable_name
from .gltf_materials import GLTF_MODEL_EXTENSIONS, _material
from .hdrio import read_hdr_image
from .meshes import Mesh, vertex_normals, vertex_tangents
from .scene import (
    LIGHT_TYPES,
    PunctualLight,
    Scene,
    SceneCamera,
    SceneObject,
)

SUPPORTED_EXTENSIONS = {
    "MOZ_lightmap",
    "KHR_materials_emissive_strength",
    "KHR_texture_transform",
    *GLTF_MODEL_EXTENSIONS,
}


MAX_COORDINATE = 1e15  # |world position| bound: float32 holds it, products of two stay finite

_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_NORMALIZE = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}


def _check_node_count(data: bytes, path: Path, limits: Limits) -> None:
    """Refuse more than ``limits.max_nodes`` nodes from the JSON itself (Python's C parser),
    before pygltflib builds an object per node: 200 000 nodes took it 45 s. Malformed JSON is
    left to the parser below, which says what is wrong."""
    import json

    try:
        if path.suffix.lower() == ".glb":
            (chunk_length,) = struct.unpack_from("<I", data, 12)
            text = data[20 : 20 + chunk_length]
        else:
            text = data
        nodes = json.loads(text).get("nodes")
    except (ValueError, struct.error, AttributeError, RecursionError):
        return
    if isinstance(nodes, list) and len(nodes) > limits.max_nodes:
        raise GltfError(
            f"{path}: {len(nodes)} nodes, more than the limit of {limits.max_nodes} (--max-objects "
            "raises both limits for a scene you trust)"
        )


def _parse(path: Path, limits: Limits):
    import pygltflib

    try:
        check_regular_file(path, "scene file", limits)
    except UntrustedReferenceError as exc:
        raise GltfError(str(exc)) from None
    data = path.read_bytes()
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise GltfError(f"{path}: not a GLB file (bad magic) or truncated")
        version, length = struct.unpack_from("<II", data, 4)
        if version != 2:
            raise GltfError(f"{path}: GLB version {version}; only glTF 2.0 is supported")
        if length > len(data):
            raise GltfError(f"{path}: truncated GLB ({len(data)} of {length} bytes)")
    _check_node_count(data, path, limits)
    try:
        if path.suffix.lower() == ".glb":
            gltf = pygltflib.GLTF2.load_from_bytes(data)
        else:
            gltf = pygltflib.GLTF2.gltf_from_json(data.decode("utf-8"))
    except Exception as exc:
        raise GltfError(f"{path}: cannot parse glTF: {exc}") from None
    if gltf is None or gltf.asset is None:
        raise GltfError(f"{path}: cannot parse glTF (no asset description)")
    if not str(gltf.asset.version).startswith("2"):
        raise GltfError(f"{path}: glTF version {printable_name(gltf.asset.version)}; only 2.0 is supported")
    make_names_printable(gltf)
    return gltf


class _Reader:
    def __init__(self, gltf, path: Path, limits: Limits = DEFAULT_LIMITS):
        self.gltf = gltf
        self.path = path
        self.limits = limits
        self.budget = LoadBudget(limits, str(path))
        # Decoded images by (image index, stored): a texture or lightmap several materials share
        # is decoded and charged to the budget once, and its materials share one array (one
        # GPU texture, so their objects can be drawn by one multi-draw: viewer/object_batches.py).
        self._images: dict[tuple[int, bool], tuple[np.ndarray | None, str]] = {}
        self.sanitized: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # id(image) -> (image, clean)
        self._buffers: dict[int, bytes] = {}

    def buffer(self, index: int) -> bytes:
        if index in self._buffers:
            return self._buffers[index]
        buf = _index(self.gltf.buffers, index, "buffer", self.path)
        byte_length = _count(buf.byteLength, f"buffer {index} byteLength", self.path)
        if buf.uri is None:
            blob = self.gltf.binary_blob()
            if blob is None:
                raise GltfError(f"{self.path}: buffer {index} has no uri and there is no GLB binary chunk")
            data = bytes(blob)
        elif not isinstance(buf.uri, str):
            raise GltfError(f"{self.path}: buffer {index} has a non-string uri {buf.uri!r}")
        elif buf.uri.startswith("data:"):
            data = _decode_data_uri(buf.uri, f"{self.path}: buffer {index}")
        else:
            try:
                data = read_reference(self.path.parent, buf.uri, f"{self.path}: buffer {index}", self.limits)
            except FileNotFoundError:
                raise GltfError(f"{self.path}: buffer file {buf.uri!r} not found") from None
            except (UntrustedReferenceError, OSError) as exc:
                raise GltfError(str(exc)) from None
        if len(data) < byte_length:
            raise GltfError(f"{self.path}: buffer {index} is truncated ({len(data)} of {byte_length} bytes)")
        self._buffers[index] = data
        return data

    def view_bytes(self, view_index: int) -> tuple[bytes, int | None]:
        """The bytes of a bufferView and its byteStride."""
        view = _index(self.gltf.bufferViews, view_index, "bufferView", self.path)
        data = self.buffer(view.buffer)
        start = _count(view.byteOffset, f"bufferView {view_index} byteOffset", self.path, default=0)
        end = start + _count(view.byteLength, f"bufferView {view_index} byteLength", self.path)
        if end > len(data):
            raise GltfError(f"{self.path}: bufferView {view_index} runs past the end of its buffer")
        stride = view.byteStride
        if stride is not None:
            _count(stride, f"bufferView {view_index} byteStride", self.path)
        if stride is not None and not 4 <= stride <= 252:
            raise GltfError(f"{self.path}: bufferView {view_index} byteStride {stride} is outside 4..252")
        return memoryview(data)[start:end], stride

    def accessor(self, index: int, raw: bool = False) -> np.ndarray:
        """An accessor's elements as (count, components): float64 for floats and normalized
        integers (scaled to [0, 1] / [-1, 1]), else the integer type; with ``raw`` exactly the
        stored component type (to copy the data elsewhere unchanged)."""
        acc = _index(self.gltf.accessors, index, "accessor", self.path)
        if acc.sparse is not None:
            raise GltfError(f"{self.path}: accessor {index} is sparse; sparse accessors are not supported")
        if acc.componentType not in _DTYPES or acc.type not in _COMPONENTS:
            raise GltfError(f"{self.path}: accessor {index} has an unsupported type {acc.type}/{acc.componentType}")
        dtype = np.dtype(_DTYPES[acc.componentType]).newbyteorder("<")
        ncomp = _COMPONENTS[acc.type]
        count = _count(acc.count, f"accessor {index} count", self.path)
        # The decoded copy is float64 (or the integer type): charge it before anything is made.
        self.budget.take(count * ncomp * 8, f"accessor {index} ({count} x {acc.type})")
        if acc.bufferView is None:
            # All zeros by the specification (meant for sparse accessors, which are refused):
            # nothing real needs many, and a huge count would only allocate.
            if count > 1 << 16:
                raise GltfError(f"{self.path}: accessor {index} has no bufferView but declares {count} elements")
            out = np.zeros((count, ncomp), dtype=np.float64)
        else:
            view_data, stride = self.view_bytes(acc.bufferView)
            offset = _count(acc.byteOffset, f"accessor {index} byteOffset", self.path, default=0)
            item = dtype.itemsize * ncomp
            stride = stride or item
            if stride < item:
                raise GltfError(f"{self.path}: accessor {index}: byteStride {stride} is less than one element ({item})")
            needed = offset + stride * (count - 1) + item if count else 0
            if needed > len(view_data):
                raise GltfError(f"{self.path}: accessor {index} reads past the end of its bufferView")
            if count == 0:
                out = np.zeros((0, ncomp), dtype=dtype)
            elif stride == item:
                out = np.frombuffer(view_data, dtype=dtype, count=count * ncomp, offset=offset).reshape(count, ncomp)
            else:
                # Gather whole rows by index (bounds already checked, no as_strided past the end).
                rows = np.frombuffer(view_data, dtype=np.uint8, count=needed - offset, offset=offset)
                starts = np.arange(count, dtype=np.int64)[:, None] * stride + np.arange(item, dtype=np.int64)[None, :]
                out = rows[starts].copy().view(dtype).reshape(count, ncomp)
        if raw:
            return np.ascontiguousarray(out)
        out = out.astype(np.float64) if acc.componentType == 5126 or acc.normalized else out
        if acc.normalized and acc.componentType in _NORMALIZE:
            out = np.maximum(out / _NORMALIZE[acc.componentType], -1.0)
        return out

    def image(self, texture_index: int, stored: bool = False) -> np.ndarray | None:
        """A texture's image: EXR/Radiance files as float32 (H, W, 3) linear values; PNG/JPEG as
        (H, W, 4) uint8 as stored with ``stored`` (material textures: colour stays sRGB-encoded
        for the GPU to decode before filtering), else as float32 (H, W, 3) values / 255 (an
        8-bit lightmap holds linear irradiance). None when unreadable, with the reason in
        ``last_image_problem``."""
        self.last_image_problem = "file not found"
        try:
            texture = _index(self.gltf.textures, texture_index, "texture", self.path)
            image = _index(self.gltf.images, texture.source, "image", self.path)
        except GltfError as exc:
            self.last_image_problem = str(exc)
            return None
        key = (int(texture.source), bool(stored))
        if key not in self._images:
            decoded = self._decode_image(texture, image, stored)
            self._images[key] = (decoded, self.last_image_problem)
        decoded, self.last_image_problem = self._images[key]
        return decoded

    def _decode_image(self, texture, image, stored: bool) -> np.ndarray | None:
        try:
            if image.uri is not None and not image.uri.startswith("data:"):
                file = resolve_reference(self.path.parent, image.uri, "image", self.limits)
                if file.suffix.lower() in (".exr", ".hdr", ".pic"):
                    return read_hdr_image(file, self.budget)
                data = file.read_bytes()
            elif image.uri is not None:
                data = _decode_data_uri(image.uri, f"{self.path}: image")
            else:
                data, _ = self.view_bytes(image.bufferView)
            hdr_suffix = _embedded_hdr_suffix(image.mimeType, data)
            if hdr_suffix is not None:
                return _read_embedded_hdr(bytes(data), hdr_suffix, self.budget)
            from PIL import Image

            pil = Image.open(io.BytesIO(data))
            width, height = pil.size  # from the header: checked before the pixels are decoded
            label = f"image {image.name or texture.source!r}"
            if stored:
                self.budget.check_image(width, height, 4, 2, label)
                return np.ascontiguousarray(np.asarray(pil.convert("RGBA"), dtype=np.uint8))
            self.budget.check_image(width, height, 3, 4 + 1, label)
            return np.asarray(pil.convert("RGB"), dtype=np.float32) / 255.0
        except FileNotFoundError:
            return None
        except Exception as exc:  # noqa: BLE001 - any decoder failure means "no image": warned by the caller
            # Pillow raises OSError, ValueError, SyntaxError, struct.error or DecompressionBombError
            # for corrupt or huge files; BudgetError/UntrustedReferenceError carry their reason.
            self.last_image_problem = str(exc) or type(exc).__name__
            return None


# Embedded HDR images (a baked lightmap inside its .glb): the MIME types lobeview writes and the
# files' magic numbers, which decide when the MIME type is missing.
HDR_MIME_TYPES = {"image/x-exr": ".exr", "image/vnd.radiance": ".hdr"}


def _embedded_hdr_suffix(mime_type, data) -> str | None:
    if mime_type in HDR_MIME_TYPES:
        return HDR_MIME_TYPES[mime_type]
    head = bytes(data[:10])
    if head[:4] == b"\x76\x2f\x31\x01":
        return ".exr"
    if head.startswith((b"#?RADIANCE", b"#?RGBE")):
        return ".hdr"
    return None


def _read_embedded_hdr(data: bytes, suffix: str, budget: LoadBudget) -> np.ndarray:
    """An EXR/Radiance image held in a buffer: OpenEXR reads files, so the bytes go through a
    private temporary file; the header is checked against ``budget`` before any pixels are read."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="lobeview-image-") as folder:
        file = Path(folder) / f"embedded{suffix}"
        file.write_bytes(data)
        return read_hdr_image(file, budget)


def _decode_data_uri(uri: str, what: str) -> bytes:
    header, sep, payload = uri.partition(",")
    if not sep:
        raise GltfError(f"{what}: data URI without a ',' separator")
    try:
        if header.endswith(";base64"):
            return base64.b64decode(payload, validate=False)
        from urllib.parse import unquote_to_bytes

        return unquote_to_bytes(payload)
    except Exception:
        raise GltfError(f"{what}: corrupt data URI") from None


QUATERNION_TOLERANCE = 1e-3  # |q| - 1 allowed before a node's rotation is normalised with a warning


def _node_vector(value, default: list, label: str) -> np.ndarray:
    """A node's translation / rotation / scale: ``default``'s length, else the load stops."""
    vector = np.asarray(default if value is None else value, dtype=np.float64)
    if vector.shape != (len(default),):
        raise GltfError(f"{label} has {vector.size} numbers, not {len(default)}")
    return vector


def _node_matrix(node, label: str, scene_warnings: list) -> np.ndarray:
    """The node's local transform (its matrix, else translation x rotation x scale). A matrix or
    vector of the wrong length stops the load; a rotation that is not a unit quaternion (the
    specification requires one) is normalised with a warning, a zero one is the identity."""
    if node.matrix is not None:
        if len(node.matrix) != 16:
            raise GltfError(f"{label}: matrix has {len(node.matrix)} numbers, not 16")
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    t = _node_vector(node.translation, [0.0, 0.0, 0.0], f"{label}: translation")
    q = _node_vector(node.rotation, [0.0, 0.0, 0.0, 1.0], f"{label}: rotation")
    s = _node_vector(node.scale, [1.0, 1.0, 1.0], f"{label}: scale")
    length = float(np.linalg.norm(q))
    if np.isfinite(length) and abs(length - 1.0) > QUATERNION_TOLERANCE:
        if length > 1e-12:
            _warn(scene_warnings, f"{label}: rotation {q.tolist()} is not a unit quaternion; normalised")
            q = q / length
        else:
            _warn(scene_warnings, f"{label}: rotation {q.tolist()} is zero; no rotation used")
            q = np.array([0.0, 0.0, 0.0, 1.0])
    x, y, z, w = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def load_gltf(path: str | Path, limits: Limits = DEFAULT_LIMITS) -> Scene:
    """Load a glTF/GLB file as an untrusted input (see the module docstring and ``limits``)."""
    path = Path(path)
    if not path.exists():
        raise GltfError(f"{path}: no such file")
    if path.suffix.lower() not in (".gltf", ".glb"):
        raise GltfError(f"{path}: not a glTF file (expected .gltf or .glb)")
    try:
        return _load(path, limits)
    except GltfError:
        raise
    except (BudgetError, UntrustedReferenceError, MaterialError) as exc:
        raise GltfError(f"{path}: {exc}" if str(path) not in str(exc) else str(exc)) from None
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError, RecursionError) as exc:
        # A field of the wrong JSON type or shape that no explicit check above names: still the
        # file's fault, reported as such rather than as a traceback.
        raise GltfError(f"{path}: malformed glTF ({type(exc).__name__}: {exc})") from None
    except MemoryError:
        raise GltfError(f"{path}: out of memory while loading (the file declares more data than fits)") from None


def _load(path: Path, limits: Limits) -> Scene:
    gltf = _parse(path, limits)
    required = set(gltf.extensionsRequired or [])
    unsupported = required - SUPPORTED_EXTENSIONS
    if unsupported:
        raise GltfError(
            f"{path}: requires unsupported extension(s) {sorted(unsupported)}; "
            f"supported: {sorted(SUPPORTED_EXTENSIONS)}"
        )
    reader = _Reader(gltf, path, limits)
    scene_warnings: list[str] = []
    lamp_definitions = _lamp_definitions(gltf, path, scene_warnings)
    lights: list[PunctualLight] = []
    materials = [_material(reader, i, scene_warnings) for i in range(len(gltf.materials or []))]
    default_material = len(materials)
    materials.append(_material(reader, None, scene_warnings))

    objects: list[SceneObject] = []
    cameras: list[SceneCamera] = []
    node_extras: list = []  # (object, node extras) for the reflection proxies, resolved with the bounds
    scene_index = gltf.scene if gltf.scene is not None else 0
    if not gltf.scenes:
        raise GltfError(f"{path}: contains no scene")
    roots = _index(gltf.scenes, scene_index, "scene", path).nodes or []
    if len(gltf.nodes or []) > limits.max_nodes:
        raise GltfError(
            f"{path}: {len(gltf.nodes)} nodes, more than the limit of {limits.max_nodes} (--max-objects "
            "raises both limits for a scene you trust)"
        )
    visited: set[int] = set()

    def visit(node_index: int, parent: np.ndarray, depth: int):
        if depth > 64:
            raise GltfError(f"{path}: node hierarchy deeper than 64 levels")
        node = _index(gltf.nodes, node_index, "node", path)
        # The glTF node graph is a forest: a node with two parents (or a cycle) would be drawn
        # twice, or without end, and k levels of shared children would make 2^k instances.
        if node_index in visited:
            raise GltfError(
                f"{path}: node {node_index} is reached twice (a cycle or a shared child); glTF nodes have one parent"
            )
        visited.add(node_index)
        world = parent @ _node_matrix(node, f"{path}: node {node_index}", scene_warnings)
        if not np.all(np.isfinite(world)):
            raise GltfError(f"{path}: node {node_index} has a NaN/Inf transform")
        if node.mesh is not None:
            mesh = _index(gltf.meshes, node.mesh, "mesh", path)
            for p_index, prim in enumerate(mesh.primitives or []):
                name = f"{node.name or mesh.name or f'node{node_index}'}" + (f"#{p_index}" if p_index else "")
                obj = _primitive(reader, prim, world, name, scene_warnings, (node_index, node.mesh, p_index))
                if obj is not None:
                    if obj.material < 0:
                        obj.material = default_material
                    if len(objects) >= limits.max_objects:
                        raise GltfError(
                            f"{path}: more than {limits.max_objects} drawable objects (mesh primitives placed by "
                            "nodes); each costs work per frame: --max-objects N raises the limit"
                        )
                    objects.append(obj)
                    node_extras.append((obj, node.extras))
        lamp = ((node.extensions or {}).get("KHR_lights_punctual") or {}).get("light")
        if lamp is not None:
            light = _placed_lamp(lamp_definitions, lamp, world, node.name or f"node{node_index}", path, scene_warnings)
            if light is not None:
                lights.append(light)
        if node.camera is not None:
            cam = _index(gltf.cameras, node.camera, "camera", path)
            yfov = getattr(cam.perspective, "yfov", None)
            axes_ok = np.linalg.norm(np.cross(world[:3, 2], world[:3, 1])) > 1e-12
            if (
                cam.type == "perspective"
                and cam.perspective is not None
                and not (isinstance(yfov, (int, float)) and 0 < yfov < np.pi and axes_ok)
            ):
                _warn(
                    scene_warnings,
                    f"{path}: camera {cam.name or node.camera!r} has yfov {yfov!r} or a degenerate transform; skipped",
                )
            elif cam.type == "perspective" and cam.perspective is not None:
                position = world[:3, 3]
                forward = -world[:3, 2] / np.linalg.norm(world[:3, 2])
                up = world[:3, 1] / np.linalg.norm(world[:3, 1])
                cameras.append(
                    SceneCamera(
                        cam.name or f"camera{node.camera}",
                        position,
                        position + forward,
                        up,
                        float(np.degrees(cam.perspective.yfov)),
                    )
                )
        for child in node.children or []:
            visit(child, world, depth + 1)

    for root in roots:
        visit(root, np.eye(4), 0)
    if not objects:
        raise GltfError(f"{path}: no triangle geometry in the default scene")
    for obj in objects:
        mat = materials[obj.material]
        if mat.lightmap is not None and obj.uv1 is None and mat.lightmap.tex_coord == 1:
            _warn(
                scene_warnings,
                f"{path}: object {obj.name!r} uses a lightmap but has no TEXCOORD_1; {FALLBACKS['missing lightmap']}",
            )
    if lights:
        _warn(
            scene_warnings,
            f"{path}: {len(lights)} KHR_lights_punctual lamp(s): `lobeview bake` bakes their light into the "
            "lightmaps with exact shadows; live, the lobes reflect them (spheres of 5 cm) and unbaked objects "
            "get their diffuse light, both shadowed per object only",
        )
    scene = Scene(objects, materials, cameras, str(path), scene_warnings, lights)
    if objects:
        from .planar_mirror import reflector_mode
        from .reflection_proxy import object_proxy

        bounds = scene.bounds
        for obj, extras in node_extras:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                obj.reflection_proxy = object_proxy(extras, bounds, obj.name)
                obj.planar_reflector = reflector_mode(extras, obj.name)
            for w in caught:
                _warn(scene_warnings, f"{path}: {w.message}")
    return scene


def _lamp_definitions(gltf, path: Path, scene_warnings: list) -> list[dict | None]:
    """The file's KHR_lights_punctual lamps, validated (None for a lamp that is skipped)."""
    lamps = ((gltf.extensions or {}).get("KHR_lights_punctual") or {}).get("lights") or []
    if not isinstance(lamps, list):
        _warn(scene_warnings, f"{path}: KHR_lights_punctual lights is not a list; no lamps used")
        return []
    out = []
    for index, lamp in enumerate(lamps):
        name = lamp.get("name", f"light{index}") if isinstance(lamp, dict) else f"light{index}"
        try:
            if not isinstance(lamp, dict) or lamp.get("type") not in LIGHT_TYPES:
                raise ValueError(
                    f"type {lamp.get('type') if isinstance(lamp, dict) else lamp!r} is not one of {LIGHT_TYPES}"
                )
            colour = np.asarray(lamp.get("color", [1.0, 1.0, 1.0]), dtype=np.float64).reshape(3)
            intensity = float(lamp.get("intensity", 1.0))
            lamp_range = lamp.get("range")
            lamp_range = None if lamp_range is None else float(lamp_range)
            spot = lamp.get("spot") or {}
            inner, outer = float(spot.get("innerConeAngle", 0.0)), float(spot.get("outerConeAngle", np.pi / 4))
            if not (np.all(np.isfinite(colour)) and np.all(colour >= 0) and np.isfinite(intensity) and intensity >= 0):
                raise ValueError("colour and intensity must be finite and not negative")
            if lamp_range is not None and not (np.isfinite(lamp_range) and lamp_range > 0):
                raise ValueError(f"range {lamp_range} must be positive")
            if lamp["type"] == "spot" and not (0 <= inner < outer <= np.pi / 2):
                raise ValueError(f"spot cone angles {inner}, {outer} need 0 <= inner < outer <= pi/2")
        except (TypeError, ValueError, AttributeError) as exc:
            _warn(scene_warnings, f"{path}: lamp {name!r} (KHR_lights_punctual) skipped: {exc}")
            out.append(None)
            continue
        out.append(dict(name=name, type=lamp["type"], colour=colour, intensity=intensity, range=lamp_range,
                        inner_cone=inner, outer_cone=outer))  # fmt: skip
    return out


def _placed_lamp(definitions: list, lamp, world: np.ndarray, node_name: str, path: Path, scene_warnings: list):
    """A node's lamp in world space: at the node's origin, shining along its -Z axis."""
    if not isinstance(lamp, int) or not 0 <= lamp < len(definitions):
        _warn(scene_warnings, f"{path}: node {node_name!r} names lamp {lamp!r}, which does not exist; ignored")
        return None
    definition = definitions[lamp]
    if definition is None:
        return None
    axis = -world[:3, 2]
    length = float(np.linalg.norm(axis))
    if not length > 1e-12:
        _warn(scene_warnings, f"{path}: lamp node {node_name!r} has a degenerate transform; lamp ignored")
        return None
    return PunctualLight(position=world[:3, 3].copy(), direction=axis / length, **definition)


def _primitive(
    reader: _Reader, prim, world: np.ndarray, name: str, scene_warnings: list, origin: tuple[int, int, int]
) -> SceneObject | None:
    path = reader.path
    mode = 4 if prim.mode is None else prim.mode
    if mode != 4:
        _warn(
            scene_warnings,
            f"{path}: primitive {name!r} has mode {mode} (not triangles); {FALLBACKS['non-triangle primitive']}",
        )
        return None
    attrs = prim.attributes
    if attrs.POSITION is None:
        raise GltfError(f"{path}: primitive {name!r} has no POSITION attribute")
    positions = reader.accessor(attrs.POSITION)[:, :3]
    count = len(positions)
    if prim.indices is not None:
        indices = reader.accessor(prim.indices).astype(np.int64).reshape(-1)
    else:
        indices = np.arange(count)
    if len(indices) % 3:
        raise GltfError(f"{path}: primitive {name!r} has {len(indices)} indices (not a multiple of 3)")
    if len(indices) and (indices.min() < 0 or indices.max() >= count):
        raise GltfError(f"{path}: primitive {name!r} has indices outside its {count} vertices")
    tris = indices.reshape(-1, 3)
    if not np.all(np.isfinite(positions)):
        raise GltfError(f"{path}: primitive {name!r} has NaN/Inf vertex positions")
    world_pos = positions @ world[:3, :3].T + world[:3, 3]
    if not np.all(np.abs(world_pos) < MAX_COORDINATE):
        raise GltfError(
            f"{path}: primitive {name!r} has vertex positions beyond +-{MAX_COORDINATE:g} after its node transforms "
            "(float32 geometry and the renderer's depth range cannot hold them)"
        )
    area = np.linalg.norm(
        np.cross(
            world_pos[tris[:, 1]] - world_pos[tris[:, 0]],
            world_pos[tris[:, 2]] - world_pos[tris[:, 0]],
        ),
        axis=1,
    )
    degenerate = area <= 1e-12 * max(float(np.max(area)) if len(area) else 0.0, 1e-30)
    if np.any(degenerate):
        _warn(
            scene_warnings,
            f"{path}: primitive {name!r}: {int(degenerate.sum())} degenerate triangles; "
            + FALLBACKS["degenerate triangles"],
        )
        tris = tris[~degenerate]
    if len(tris) == 0:
        _warn(scene_warnings, f"{path}: primitive {name!r} has no usable triangles; skipped")
        return None
    normal_matrix = np.linalg.inv(world[:3, :3]).T
    flip = np.linalg.det(world[:3, :3]) < 0
    if flip:  # mirrored transform: keep counter-clockwise front faces
        tris = tris[:, ::-1]

    def attribute(index: int, semantic: str) -> np.ndarray:
        # Every attribute of a primitive has POSITION's count (glTF 2.0, 3.7.2.1): a shorter one
        # would be indexed past its end (fuzzer case: a NORMAL of count 1 crashed the baker).
        values = reader.accessor(index)
        if len(values) != count:
            raise GltfError(
                f"{path}: primitive {name!r}: {semantic} has {len(values)} elements, POSITION {count} "
                "(every attribute of a primitive has the same count)"
            )
        return values

    uv0 = attribute(attrs.TEXCOORD_0, "TEXCOORD_0")[:, :2] if attrs.TEXCOORD_0 is not None else np.zeros((count, 2))
    uv1 = attribute(attrs.TEXCOORD_1, "TEXCOORD_1")[:, :2] if attrs.TEXCOORD_1 is not None else None
    tri32 = tris.astype(np.uint32)
    if attrs.NORMAL is not None:
        normals = attribute(attrs.NORMAL, "NORMAL")[:, :3] @ normal_matrix.T
        lengths = np.linalg.norm(normals, axis=1, keepdims=True)
        bad = ~np.isfinite(lengths[:, 0]) | (lengths[:, 0] < 1e-12)
        normals = np.where(bad[:, None], 0.0, normals / np.where(bad, 1.0, lengths[:, 0])[:, None])
        if np.any(bad):
            generated = vertex_normals(world_pos.astype(np.float32), tri32)
            normals[bad] = generated[bad]
            _warn(
                scene_warnings,
                f"{path}: primitive {name!r}: {int(bad.sum())} zero/NaN normals replaced by generated ones",
            )
    else:
        normals = vertex_normals(world_pos.astype(np.float32), tri32)
    if attrs.TANGENT is not None:
        t = attribute(attrs.TANGENT, "TANGENT")
        # A mirroring transform swaps the bitangent's side: w changes sign with det(world).
        handedness = np.where(t[:, 3:4] < 0, -1.0, 1.0) * (-1.0 if flip else 1.0)
        tangents = np.concatenate([t[:, :3] @ world[:3, :3].T, handedness], axis=1)
        if not np.all(np.isfinite(tangents)):
            tangents = vertex_tangents(world_pos, normals, uv0, tri32)
    else:
        tangents = vertex_tangents(world_pos, normals, uv0, tri32)
    if not np.all(np.isfinite(uv0)):
        raise GltfError(f"{path}: primitive {name!r} has NaN/Inf TEXCOORD_0")
    mesh = Mesh(
        world_pos.astype(np.float32),
        normals.astype(np.float32),
        tangents.astype(np.float32),
        uv0.astype(np.float32),
        tri32,
        name,
    )
    if prim.material is not None:
        _index(reader.gltf.materials, prim.material, "material", path)
    material = -1 if prim.material is None else prim.material
    return SceneObject(
        name,
        mesh,
        material,
        None if uv1 is None else uv1.astype(np.float32),
        origin=(origin[0], origin[1], origin[2], bool(flip)),
        # KHR_materials_volume's thickness is in mesh units: the node's scale makes it world units.
        volume_scale=float(abs(np.linalg.det(world[:3, :3])) ** (1.0 / 3.0)),
    )
