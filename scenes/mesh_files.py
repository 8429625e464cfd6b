"""A mesh file as one Mesh for the object preview (``shot --object FILE``): glTF through
lobeview's loader, OBJ/PLY/STL through trimesh. Above scenes/meshes.py and scenes/gltf_loader.py,
which both build on meshes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .gltf_common import GltfError
from .gltf_loader import load_gltf
from .meshes import Mesh, MeshError, merge_meshes, vertex_normals, vertex_tangents

# Triangle soups (STL: three vertices of its own per triangle, no normals) are welded and
# smoothed within this angle; sharper edges stay hard (a CAD part keeps its creases).
SMOOTHING_ANGLE_DEG = 30.0


def load_mesh_file(path: str | Path) -> Mesh:
    """A single mesh for the object preview, keeping what the file says about its surface.

    glTF/GLB go through lobeview's own loader (trust checks; the file's normals, tangents and
    TEXCOORD_0; node transforms applied; all primitives merged). Other formats (OBJ, PLY, STL)
    through trimesh: the file's vertex normals and UVs when it has them; a triangle soup without
    them is welded and smooth-shaded within SMOOTHING_ANGLE_DEG instead of rendered faceted."""
    import trimesh

    path = Path(path)
    if not path.exists():
        raise MeshError(f"{path}: no such file")
    if path.suffix.lower() in (".gltf", ".glb"):
        return _gltf_mesh(path)
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:
        raise MeshError(f"{path}: cannot load mesh: {exc}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{path}: contains no triangles")
    uv = getattr(loaded.visual, "uv", None)
    has_uv = uv is not None and len(uv) == len(loaded.vertices)
    if not has_uv and len(loaded.vertices) >= 3 * len(loaded.faces):
        loaded.merge_vertices()
        loaded = trimesh.graph.smooth_shade(loaded, angle=np.radians(SMOOTHING_ANGLE_DEG))
    positions = np.asarray(loaded.vertices, dtype=np.float32)
    indices = np.asarray(loaded.faces, dtype=np.uint32)
    uvs = np.asarray(uv, dtype=np.float32) if has_uv else np.zeros((len(positions), 2), np.float32)
    normals = np.asarray(loaded.vertex_normals, dtype=np.float32)  # the file's, else area-weighted
    bad = ~np.all(np.isfinite(normals), axis=1) | (np.linalg.norm(normals, axis=1) < 1e-6)
    if np.any(bad):
        normals[bad] = vertex_normals(positions, indices)[bad]
    return Mesh(positions, normals, vertex_tangents(positions, normals, uvs, indices), uvs, indices, path.stem)


def _gltf_mesh(path: Path) -> Mesh:
    try:
        scene = load_gltf(path)
    except GltfError as exc:
        raise MeshError(str(exc)) from None
    return merge_meshes([o.mesh for o in scene.objects], path.stem)
