"""What the glTF loader's parts share (scenes/gltf_loader.py, scenes/gltf_materials.py): its
error and warning types and the checks of values read from an untrusted file."""

from __future__ import annotations

import unicodedata
import warnings
from pathlib import Path

import numpy as np

# The documented fallbacks of recoverable problems (docs/guide.md "Scene format"): problem -> what is done.
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


def _finite(value, default: float) -> float:
    try:
        value = float(value if value is not None else default)
    except (TypeError, ValueError):
        return default
    return value if np.isfinite(value) else default


# Names from the file are printed (warnings, the scene analysis, the panel): control and format
# characters are escaped (an ANSI sequence in a node name recoloured the terminal, issue 43) and a
# name is cut to this many characters.
NAME_LIMIT = 200
_UNPRINTABLE = ("Cc", "Cf", "Cs")  # controls (ESC, CR), formats (bidirectional overrides), surrogates


def printable_name(value) -> str | None:
    """A name read from the file as lobeview keeps and prints it (None stays None)."""
    if value is None:
        return None
    text = value if isinstance(value, str) else repr(value)
    text = "".join(ascii(ch)[1:-1] if unicodedata.category(ch) in _UNPRINTABLE else ch for ch in text)
    return text if len(text) <= NAME_LIMIT else text[: NAME_LIMIT - 3] + "..."


def make_names_printable(gltf) -> None:
    """Every ``name`` of the parsed file's objects (and of its KHR_lights_punctual lamps) through
    :func:`printable_name`, once, before anything reads them."""
    for field in ("nodes", "meshes", "materials", "cameras", "images", "textures", "samplers", "scenes",
                  "accessors", "bufferViews", "buffers", "skins", "animations"):  # fmt: skip
        for item in getattr(gltf, field, None) or []:
            if getattr(item, "name", None) is not None:
                item.name = printable_name(item.name)
    lamps = ((gltf.extensions or {}).get("KHR_lights_punctual") or {}) if isinstance(gltf.extensions, dict) else {}
    for lamp in (lamps.get("lights") or []) if isinstance(lamps, dict) else []:
        if isinstance(lamp, dict) and lamp.get("name") is not None:
            lamp["name"] = printable_name(lamp["name"])
