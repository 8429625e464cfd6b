"""What the glTF loader's parts share (scenes/gltf_loader.py, scenes/gltf_materials.py): its
error and warning types and the checks of values read from an untrusted file."""

from __future__ import annotations

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
