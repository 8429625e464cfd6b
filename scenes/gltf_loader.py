"""glTF 2.0 loading (.gltf and .glb) into a world-space :class:`~lobeview.scenes.scene.Scene`.

pygltflib parses the container (JSON, GLB chunks); accessors, transforms and materials are read
here with numpy because lobeview needs what general loaders drop: TEXCOORD_1 and the
``MOZ_lightmap`` material extension (``index`` = texture with linear irradiance in EXR or
Radiance .hdr, ``texCoord``, ``intensity``), and a thesis-model material in ``extras.lobeview``
(a preset name or a material object, see README).

Scene files are untrusted (README "Security and limits"): every URI goes through
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
import dataclasses
import io
import json
import struct
import types
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
from lobeview.materials.spec import MaterialError, validate

from .hdrio import read_hdr_image, sanitize_radiance
from .meshes import Mesh, vertex_normals, vertex_tangents
from .scene import (
    ALPHA_MODES,
    COLOUR_SLOTS,
    LIGHT_TYPES,
    MAG_FILTERS,
    MIN_FILTERS,
    WRAP_MODES,
    Lightmap,
    PunctualLight,
    Scene,
    SceneCamera,
    SceneMaterial,
    SceneObject,
    TextureSlot,
)

# glTF material extensions lobeview maps onto the gltf model: extension -> {glTF field: (desc
# key, default, (low, high))}; their textures are read per pixel (EXTENSION_SLOTS).
GLTF_MODEL_EXTENSIONS = {
    "KHR_materials_anisotropy": {
        "anisotropyStrength": ("anisotropy", 0.0, (0.0, 1.0)),
        "anisotropyRotation": ("anisotropy_rotation", 0.0, None),
    },
    "KHR_materials_ior": {"ior": ("ior", 1.5, None)},
    "KHR_materials_specular": {
        "specularFactor": ("specular", 1.0, (0.0, 1.0)),
        "specularColorFactor": ("specular_color", [1.0, 1.0, 1.0], (0.0, 10.0)),
    },
    "KHR_materials_clearcoat": {
        "clearcoatFactor": ("clearcoat", 0.0, (0.0, 1.0)),
        "clearcoatRoughnessFactor": ("clearcoat_roughness", 0.0, (0.0, 1.0)),
    },
    "KHR_materials_transmission": {"transmissionFactor": ("transmission", 0.0, (0.0, 1.0))},
    "KHR_materials_sheen": {
        "sheenColorFactor": ("sheen_color", [0.0, 0.0, 0.0], (0.0, 1.0)),
        "sheenRoughnessFactor": ("sheen_roughness", 0.0, (0.0, 1.0)),
    },
    # Read for what it says about the wall: lobeview's transmission is thin-walled, so a volume
    # (thickness > 0, attenuation) is said to be ignored, not silently dropped.
    "KHR_materials_volume": {},
}
# The extensions' textures lobeview reads per pixel: extension -> {glTF field: (slot of
# scene.TEXTURE_SLOTS, the channels the extension reads from it)}. Two textures that share a slot
# (clearcoat factor R + roughness G; specular colour RGB + factor A) are combined channel-wise
# (_extension_slot); the factors multiply the texels as each extension specifies.
EXTENSION_SLOTS = {
    "KHR_materials_anisotropy": {"anisotropyTexture": ("anisotropy", (0, 1, 2))},
    "KHR_materials_clearcoat": {
        "clearcoatTexture": ("clearcoat", (0,)),
        "clearcoatRoughnessTexture": ("clearcoat", (1,)),
        "clearcoatNormalTexture": ("clearcoat_normal", (0, 1, 2)),
    },
    "KHR_materials_specular": {
        "specularColorTexture": ("specular", (0, 1, 2)),
        "specularTexture": ("specular", (3,)),
    },
    "KHR_materials_transmission": {"transmissionTexture": ("transmission", (0,))},
    "KHR_materials_sheen": {"sheenColorTexture": ("sheen_color", (0, 1, 2))},
}
# Extension textures that are read but not honoured (warned: the factor applies uniformly).
EXTENSION_TEXTURES_UNUSED = {
    "KHR_materials_sheen": ("sheenRoughnessTexture",),  # the E_s table is per material roughness
    "KHR_materials_volume": ("thicknessTexture",),  # transmission is thin-walled
}
SUPPORTED_EXTENSIONS = {
    "MOZ_lightmap",
    "KHR_materials_emissive_strength",
    "KHR_texture_transform",
    *GLTF_MODEL_EXTENSIONS,
}
MATERIAL_EXTENSIONS_USED = {"MOZ_lightmap", "KHR_materials_emissive_strength", *GLTF_MODEL_EXTENSIONS}

FALLBACKS = {
    "missing image": "the texture is ignored (factor only)",
    "missing normal map": "the interpolated vertex normals are used",
    "missing occlusion map": "no ambient occlusion",
    "missing lightmap": "the object is lit by the environment's irradiance, unoccluded (see Scene.warnings)",
    "non-triangle primitive": "skipped",
    "degenerate triangles": "dropped",
    "missing normals": "area-weighted vertex normals",
    "missing tangents": "from TEXCOORD_0, or any vector orthogonal to the normal",
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


class GltfError(ValueError):
    pass


class GltfWarning(UserWarning):
    pass


def _warn(scene_warnings: list, message: str) -> None:
    scene_warnings.append(message)
    warnings.warn(message, GltfWarning, stacklevel=3)


def _index(items, index, kind: str, path: Path):
    """``items[index]`` for an index read from the file: a checked non-negative int in range."""
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items or []):
        raise GltfError(f"{path}: {kind} index {index!r} is out of range (the file has {len(items or [])})")
    return items[index]


def _count(value, what: str, path: Path, default: int | None = None) -> int:
    """A non-negative integer field of the file (offsets, lengths, counts, strides)."""
    if value is None and default is not None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise GltfError(f"{path}: {what} must be a non-negative integer, not {value!r}")
    return value


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
        raise GltfError(f"{path}: glTF version {gltf.asset.version}; only 2.0 is supported")
    return gltf


class _Reader:
    def __init__(self, gltf, path: Path, limits: Limits = DEFAULT_LIMITS):
        self.gltf = gltf
        self.path = path
        self.limits = limits
        self.budget = LoadBudget(limits, str(path))
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


def _texture_transform(info, where: str, scene_warnings: list) -> tuple[np.ndarray, int | None]:
    """KHR_texture_transform of a textureInfo: the 3x3 UV matrix translation x rotation x scale
    (the extension's definition) and its texCoord override (None: the textureInfo's)."""
    extension = (getattr(info, "extensions", None) or {}).get("KHR_texture_transform")
    if extension is None:
        return np.eye(3), None
    try:
        offset = np.asarray(extension.get("offset", [0.0, 0.0]), dtype=np.float64).reshape(2)
        rotation = float(extension.get("rotation", 0.0))
        scale = np.asarray(extension.get("scale", [1.0, 1.0]), dtype=np.float64).reshape(2)
        tex_coord = extension.get("texCoord")
        if not (np.all(np.isfinite(offset)) and np.isfinite(rotation) and np.all(np.isfinite(scale))):
            raise ValueError("non-finite value")
    except (TypeError, ValueError, AttributeError) as exc:
        _warn(scene_warnings, f"{where}: KHR_texture_transform unreadable ({exc}); ignored")
        return np.eye(3), None
    c, s = np.cos(rotation), np.sin(rotation)
    translation = np.array([[1.0, 0.0, offset[0]], [0.0, 1.0, offset[1]], [0.0, 0.0, 1.0]])
    rotate = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return translation @ rotate @ np.diag([scale[0], scale[1], 1.0]), tex_coord


def _texture_slot(reader: _Reader, info, slot: str, material: str, scene_warnings: list, fallback: str):
    """A material's textureInfo as a :class:`TextureSlot`, or None (warned) when unusable."""
    if info is None:
        return None
    where = f"{reader.path}: material {material!r}: {slot.replace('_', ' ')} texture"
    image = reader.image(info.index, stored=True)
    if image is None:
        _warn(scene_warnings, f"{where} missing or unusable ({reader.last_image_problem}); {fallback}")
        return None
    out = TextureSlot(image, srgb=slot in COLOUR_SLOTS and image.dtype == np.uint8, source=where)
    texture = reader.gltf.textures[info.index]
    if texture.sampler is not None:
        try:
            sampler = _index(reader.gltf.samplers, texture.sampler, "sampler", reader.path)
        except GltfError as exc:
            _warn(scene_warnings, f"{where}: {exc}; default sampler (repeat, trilinear)")
            sampler = None
        if sampler is not None:
            # A missing or invalid value keeps the TextureSlot default (repeat, trilinear).
            for attribute, field, allowed in (
                ("wrapS", "wrap_s", WRAP_MODES),
                ("wrapT", "wrap_t", WRAP_MODES),
                ("magFilter", "mag_filter", MAG_FILTERS),
                ("minFilter", "min_filter", MIN_FILTERS),
            ):
                value = getattr(sampler, attribute)
                if value is not None and value not in allowed:
                    _warn(scene_warnings, f"{where}: sampler {attribute} {value!r} is not a glTF value; default used")
                elif value is not None:
                    setattr(out, field, int(value))
    transform, override = _texture_transform(info, where, scene_warnings)
    out.transform = transform
    tex_coord = override if override is not None else (info.texCoord or 0)
    if not isinstance(tex_coord, int) or tex_coord not in (0, 1):
        _warn(scene_warnings, f"{where}: texCoord {tex_coord!r} (lobeview reads TEXCOORD_0 and _1); TEXCOORD_0 used")
        tex_coord = 0
    out.tex_coord = tex_coord
    return out


def _finite(value, default: float) -> float:
    try:
        value = float(value if value is not None else default)
    except (TypeError, ValueError):
        return default
    return value if np.isfinite(value) else default


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


def _node_matrix(node) -> np.ndarray:
    if node.matrix is not None and len(node.matrix) == 16:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    t = np.asarray(node.translation or [0, 0, 0], dtype=np.float64)
    x, y, z, w = np.asarray(node.rotation or [0, 0, 0, 1], dtype=np.float64)
    s = np.asarray(node.scale or [1, 1, 1], dtype=np.float64)
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


def _model_extensions(mat, where: str, scene_warnings: list) -> dict:
    """KHR_materials_anisotropy/_ior/_specular/_clearcoat/_transmission/_sheen as the gltf
    model's optional keys (materials/spec.py GLTF_EXTENSION_KEYS). Out-of-range factors are
    clamped with a warning; the textures are read by _extension_textures."""
    out: dict = {}
    for extension, fields in GLTF_MODEL_EXTENSIONS.items():
        data = (mat.extensions or {}).get(extension)
        if data is None:
            continue
        if not isinstance(data, dict):
            _warn(scene_warnings, f"{where}: {extension} is not an object; ignored")
            continue
        for field, (key, default, limits) in fields.items():
            value = data.get(field, default)
            try:
                array = np.asarray(value, dtype=np.float64)
                if array.shape != np.shape(default) or not np.all(np.isfinite(array)):
                    raise ValueError(f"{value!r}")
            except (TypeError, ValueError) as exc:
                _warn(scene_warnings, f"{where}: {extension}.{field} {exc} is unusable; {default} used")
                array = np.asarray(default, dtype=np.float64)
            if limits is not None and (np.any(array < limits[0]) or np.any(array > limits[1])):
                _warn(scene_warnings, f"{where}: {extension}.{field} {array.tolist()} clamped to {list(limits)}")
                array = np.clip(array, *limits)
            out[key] = array.tolist() if array.ndim else float(array)
        unused = [name for name in EXTENSION_TEXTURES_UNUSED.get(extension, ()) if data.get(name) is not None]
        if unused:
            _warn(
                scene_warnings,
                f"{where}: {extension} {', '.join(unused)} not used yet; its factor applies uniformly",
            )
    volume = (mat.extensions or {}).get("KHR_materials_volume")
    if isinstance(volume, dict):
        thick = volume.get("thicknessFactor", 0.0)
        if not (isinstance(thick, (int, float)) and thick == 0) or "attenuationColor" in volume:
            _warn(
                scene_warnings,
                f"{where}: KHR_materials_volume (thickness {thick}) is rendered thin-walled: no refraction "
                "through the volume, no attenuation",
            )
    if "anisotropy_rotation" in out:
        out["anisotropy_rotation"] = float(np.remainder(out["anisotropy_rotation"] + np.pi, 2 * np.pi) - np.pi)
    ior = out.get("ior")
    if ior is not None and not (ior == 0.0 or 1.0 <= ior <= 10.0):
        _warn(scene_warnings, f"{where}: KHR_materials_ior ior {ior} is neither 0 nor in [1, 10]; 1.5 used")
        out["ior"] = 1.5
    return out


def _texture_info(value, where: str, scene_warnings: list):
    """An extension's textureInfo (a JSON object) as the attributes _texture_slot reads."""
    if value is None:
        return None
    index = value.get("index") if isinstance(value, dict) else None
    if not isinstance(index, int) or isinstance(index, bool):
        _warn(scene_warnings, f"{where} is not a textureInfo with an integer index; its factor applies uniformly")
        return None
    return types.SimpleNamespace(
        index=index,
        texCoord=value.get("texCoord", 0),
        extensions=value.get("extensions") if isinstance(value.get("extensions"), dict) else None,
        scale=value.get("scale", 1.0),
    )


def _same_sampling(a: TextureSlot, b: TextureSlot) -> bool:
    return (a.tex_coord, a.wrap_s, a.wrap_t, a.mag_filter, a.min_filter) == (
        b.tex_coord, b.wrap_s, b.wrap_t, b.mag_filter, b.min_filter
    ) and np.array_equal(a.transform, b.transform)  # fmt: skip


def _extension_slot(slot: str, parts: list, where: str, scene_warnings: list) -> TextureSlot:
    """One slot from the extension textures that fill it: ``parts`` = [(TextureSlot, channels,
    glTF field)]. A texture that is the slot's only source and the same image for every channel
    is used as it is; otherwise the channels are copied into one image whose other channels
    are 1 (the texel that leaves the factor unchanged). A texture of another size, UV set,
    transform or sampler than the first cannot share its slot: warned, its factor applies."""
    first = parts[0][0]
    shared = all(
        _same_sampling(part[0], first) and (part[0].image is first.image or np.array_equal(part[0].image, first.image))
        for part in parts
    )
    if shared and (len(parts) > 1 or slot not in ("clearcoat", "specular")):
        return first
    as_uint8 = all(part[0].image.dtype == np.uint8 for part in parts)
    height, width = first.image.shape[:2]
    combined = np.full((height, width, 4), 255 if as_uint8 else 1.0, np.uint8 if as_uint8 else np.float32)
    for texture, channels, field_name in parts:
        if texture.image.shape[:2] != (height, width) or not _same_sampling(texture, first):
            _warn(
                scene_warnings,
                f"{where}: {field_name} differs from {parts[0][2]} in size, UV set, transform or sampler and "
                "cannot share its slot; its factor applies uniformly",
            )
            continue
        # uint8 images are RGBA as stored (Reader.image(stored=True)); others decode to linear RGBA.
        values = texture.image if as_uint8 else texture.linear()
        combined[..., list(channels)] = values[..., list(channels)]
    return dataclasses.replace(first, image=combined, srgb=as_uint8 and slot in COLOUR_SLOTS)


def _extension_textures(reader: _Reader, mat, name: str, out: SceneMaterial, scene_warnings: list) -> None:
    """The KHR material extensions' textures (EXTENSION_SLOTS) as per-pixel slots of ``out``."""
    gathered: dict[str, list] = {}
    for extension, fields in EXTENSION_SLOTS.items():
        data = (mat.extensions or {}).get(extension)
        if not isinstance(data, dict):
            continue
        for field_name, (slot, channels) in fields.items():
            where = f"{reader.path}: material {name!r}: {extension}.{field_name}"
            info = _texture_info(data.get(field_name), where, scene_warnings)
            texture = _texture_slot(reader, info, slot, name, scene_warnings, "its factor applies uniformly")
            if texture is None:
                continue
            gathered.setdefault(slot, []).append((texture, channels, field_name))
            if field_name == "clearcoatNormalTexture":
                out.clearcoat_normal_scale = _finite(info.scale, 1.0)
    for slot, parts in gathered.items():
        where = f"{reader.path}: material {name!r}: {slot.replace('_', ' ')} texture"
        out.textures[slot] = _extension_slot(slot, parts, where, scene_warnings)


def _custom_material(reader: _Reader, custom) -> dict:
    """``extras.lobeview`` of a material: a preset name, a material object, or the name of a JSON
    file in the scene's folder (never a path outside it: the scene file is untrusted)."""
    from lobeview.materials.presets import PRESETS

    if isinstance(custom, dict):
        return validate(custom)
    if not isinstance(custom, str):
        raise MaterialError(f"extras.lobeview must be a preset name, a material object or a JSON file, not {custom!r}")
    if custom in PRESETS:
        return validate(PRESETS[custom])
    try:
        text = read_reference(reader.path.parent, custom, f"{reader.path}: material file", reader.limits)
    except FileNotFoundError:
        names = ", ".join(sorted(PRESETS))
        raise MaterialError(f"{custom!r} is neither a preset name ({names}) nor a file in the scene's folder") from None
    except UntrustedReferenceError as exc:
        raise MaterialError(str(exc)) from None
    try:
        return validate(json.loads(text))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MaterialError(f"material file {custom!r} is not valid JSON: {exc}") from None


def _material(reader: _Reader, index: int | None, scene_warnings: list) -> SceneMaterial:
    gltf = reader.gltf
    path = reader.path
    if index is None:
        return SceneMaterial(
            "default",
            validate({"model": "gltf", "base_color": [0.8, 0.8, 0.8], "metallic": 0.0, "roughness": 1.0}),
        )
    mat = gltf.materials[index]
    name = mat.name or f"material{index}"
    pbr = mat.pbrMetallicRoughness
    extras = mat.extras or {}
    custom = extras.get("lobeview") if isinstance(extras, dict) else None
    try:
        if custom is not None:
            desc = _custom_material(reader, custom)
        else:
            base = list(pbr.baseColorFactor[:3]) if pbr and pbr.baseColorFactor else [1.0, 1.0, 1.0]
            desc = validate(
                {
                    "model": "gltf",
                    "base_color": [min(max(float(c), 0.0), 1.0) for c in base],
                    "metallic": min(
                        max(
                            float(pbr.metallicFactor if pbr and pbr.metallicFactor is not None else 1.0),
                            0.0,
                        ),
                        1.0,
                    ),
                    "roughness": min(
                        max(
                            float(pbr.roughnessFactor if pbr and pbr.roughnessFactor is not None else 1.0),
                            0.0,
                        ),
                        1.0,
                    ),
                    **_model_extensions(mat, f"{path}: material {name!r}", scene_warnings),
                }
            )
    except MaterialError as exc:
        raise GltfError(f"{path}: material {name!r}: {exc}") from None
    out = SceneMaterial(name, desc, double_sided=bool(mat.doubleSided))
    gltf_model = desc["model"] == "gltf"
    factor = list(pbr.baseColorFactor) if pbr and pbr.baseColorFactor else [1.0, 1.0, 1.0, 1.0]
    out.base_alpha = min(max(float(factor[3]), 0.0), 1.0) if len(factor) > 3 and np.isfinite(factor[3]) else 1.0
    mode = mat.alphaMode or "OPAQUE"
    if mode not in ALPHA_MODES:
        _warn(scene_warnings, f"{path}: material {name!r}: alphaMode {mode!r} is not a glTF mode; OPAQUE used")
        mode = "OPAQUE"
    out.alpha_mode = mode
    cutoff = 0.5 if mat.alphaCutoff is None else mat.alphaCutoff
    if not (isinstance(cutoff, (int, float)) and np.isfinite(cutoff) and cutoff >= 0):
        _warn(scene_warnings, f"{path}: material {name!r}: alphaCutoff {cutoff!r} is invalid; 0.5 used")
        cutoff = 0.5
    out.alpha_cutoff = float(cutoff)
    slots = {
        "base_color": (pbr.baseColorTexture if pbr else None, FALLBACKS["missing image"]),
        "metallic_roughness": (
            (pbr.metallicRoughnessTexture if pbr else None) if gltf_model else None,
            "metallic and roughness factors only",
        ),
        "normal": (mat.normalTexture, FALLBACKS["missing normal map"]),
        "occlusion": (mat.occlusionTexture, FALLBACKS["missing occlusion map"]),
        "emissive": (mat.emissiveTexture, "the emissive factor alone"),
    }
    if not gltf_model and pbr is not None and pbr.metallicRoughnessTexture is not None:
        _warn(
            scene_warnings,
            f"{path}: material {name!r}: metallicRoughnessTexture ignored (extras.lobeview replaces the glTF BRDF)",
        )
    if not gltf_model:  # the glTF model's extensions have nothing to act on
        for extension in sorted(set(mat.extensions or {}) & set(GLTF_MODEL_EXTENSIONS)):
            _warn(
                scene_warnings,
                f"{path}: material {name!r}: {extension} ignored (extras.lobeview replaces the glTF BRDF)",
            )
    for slot, (info, fallback) in slots.items():
        texture = _texture_slot(reader, info, slot, name, scene_warnings, fallback)
        if texture is not None:
            out.textures[slot] = texture
    if gltf_model:
        _extension_textures(reader, mat, name, out, scene_warnings)
    if mat.normalTexture is not None and "normal" in out.textures:
        out.normal_scale = _finite(getattr(mat.normalTexture, "scale", 1.0), 1.0)
    if mat.occlusionTexture is not None and "occlusion" in out.textures:
        out.occlusion_strength = min(max(_finite(getattr(mat.occlusionTexture, "strength", 1.0), 1.0), 0.0), 1.0)
    # Material extensions lobeview does not honour yet: said once per material, never dropped silently.
    for extension in sorted(set(mat.extensions or {}) - MATERIAL_EXTENSIONS_USED):
        _warn(
            scene_warnings,
            f"{path}: material {name!r}: {extension} is not supported yet; the material renders without it"
            " (README: glTF support)",
        )
    emissive = np.asarray(mat.emissiveFactor or [0, 0, 0], dtype=np.float64)
    strength = (mat.extensions or {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    out.emission = emissive * float(strength)
    lightmap_ext = (mat.extensions or {}).get("MOZ_lightmap")
    if lightmap_ext is not None:
        image = reader.image(lightmap_ext.get("index", -1))
        if image is None:
            _warn(
                scene_warnings,
                f"{path}: material {name!r}: lightmap image missing or unusable ({reader.last_image_problem}); "
                + FALLBACKS["missing lightmap"],
            )
        else:
            clean, _ = sanitize_radiance(image, f"{path}: lightmap of {name!r}")
            out.lightmap = Lightmap(
                clean,
                tex_coord=int(lightmap_ext.get("texCoord", 1)),
                intensity=float(lightmap_ext.get("intensity", 1.0)),
                source=name,
            )
    return out


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
        world = parent @ _node_matrix(node)
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
            "lightmaps; live shading does not see them (no lamp highlights in the specular lobes, unbaked "
            "objects get no lamp light)",
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
    uv0 = reader.accessor(attrs.TEXCOORD_0)[:, :2] if attrs.TEXCOORD_0 is not None else np.zeros((count, 2))
    uv1 = reader.accessor(attrs.TEXCOORD_1)[:, :2] if attrs.TEXCOORD_1 is not None else None
    tri32 = tris.astype(np.uint32)
    if attrs.NORMAL is not None:
        normals = reader.accessor(attrs.NORMAL)[:, :3] @ normal_matrix.T
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
        t = reader.accessor(attrs.TANGENT)
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
    )
