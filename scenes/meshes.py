"""Triangle meshes for rendering: vertex positions, normals, tangents (xyz + handedness w),
UVs and indices, with normals and tangents generated when missing."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np


class MeshError(ValueError):
    pass


@dataclass
class Mesh:
    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray  # (V, 3)
    tangents: np.ndarray  # (V, 4)
    uvs: np.ndarray  # (V, 2)
    indices: np.ndarray  # (T, 3) uint32
    name: str = "mesh"

    def interleaved(self) -> np.ndarray:
        return np.concatenate([self.positions, self.normals, self.tangents], axis=1).astype(np.float32)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.positions.min(axis=0), self.positions.max(axis=0)


def uv_sphere(radius: float = 1.0, rings: int = 96, segments: int = 192) -> Mesh:
    """Sphere with analytic normals, UVs and tangents along increasing u (longitude, +phi)."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(T) * np.sin(P), np.cos(T), np.sin(T) * np.cos(P)], -1).reshape(-1, 3)
    tangent = np.stack([np.cos(P), np.zeros_like(P), -np.sin(P)], -1).reshape(-1, 3)
    uvs = np.stack([P / (2 * np.pi), T / np.pi], -1).reshape(-1, 2)
    idx = []
    cols = segments + 1
    for r in range(rings):
        for s in range(segments):
            a, b = r * cols + s, r * cols + s + 1
            c, d = a + cols, b + cols
            if r > 0:
                idx.append((a, c, b))
            if r < rings - 1:
                idx.append((b, c, d))
    tangents = np.concatenate([tangent, np.ones((len(tangent), 1))], axis=1)
    return Mesh(
        (normals * radius).astype(np.float32),
        normals.astype(np.float32),
        tangents.astype(np.float32),
        uvs.astype(np.float32),
        np.asarray(idx, dtype=np.uint32),
        "sphere",
    )


def quad(corner, edge_u, edge_v, uv_scale=1.0) -> Mesh:
    """A rectangle (two triangles): corner + s edge_u + t edge_v; front face (normal edge_u x edge_v)."""
    c, eu, ev = (np.asarray(x, dtype=np.float64) for x in (corner, edge_u, edge_v))
    pos = np.array([c, c + eu, c + eu + ev, c + ev])
    n = np.cross(eu, ev)
    n /= np.linalg.norm(n)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64) * uv_scale
    idx = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)
    t = eu / np.linalg.norm(eu)
    tangents = np.concatenate([np.tile(t, (4, 1)), np.ones((4, 1))], axis=1)
    return Mesh(
        pos.astype(np.float32),
        np.tile(n, (4, 1)).astype(np.float32),
        tangents.astype(np.float32),
        uv.astype(np.float32),
        idx,
    )


def merge_meshes(meshes: list[Mesh], name: str) -> Mesh:
    offsets = np.cumsum([0] + [len(m.positions) for m in meshes])
    return Mesh(
        np.concatenate([m.positions for m in meshes]),
        np.concatenate([m.normals for m in meshes]),
        np.concatenate([m.tangents for m in meshes]),
        np.concatenate([m.uvs for m in meshes]),
        np.concatenate([m.indices + off for m, off in zip(meshes, offsets[:-1], strict=True)]).astype(np.uint32),
        name,
    )


def translated(mesh: Mesh, offset, name: str) -> Mesh:
    """A copy of ``mesh`` moved by ``offset`` and named ``name`` (the original is untouched, so one
    mesh can be placed several times)."""
    return Mesh(
        (mesh.positions + np.asarray(offset, np.float32)).astype(np.float32),
        mesh.normals.copy(),
        mesh.tangents.copy(),
        mesh.uvs.copy(),
        mesh.indices.copy(),
        name,
    )


def box_mesh(center, size, rotation_y_deg: float = 0.0) -> Mesh:
    """Axis-aligned box (optionally rotated about +Y) with flat faces, outward normals and planar
    UVs whose tangent follows the face's first edge."""
    cx, cy, cz = center
    hx, hy, hz = np.asarray(size) / 2
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u_axis = (axis + 1) % 3
            v_axis = (axis + 2) % 3
            half = np.array([hx, hy, hz])
            eu = np.zeros(3)
            ev = np.zeros(3)
            eu[u_axis] = 2 * half[u_axis]
            ev[v_axis] = 2 * half[v_axis]
            if np.dot(np.cross(eu, ev), n) < 0:
                eu, ev = ev, eu
            corner = n * half - eu / 2 - ev / 2
            faces.append(quad(corner, eu, ev))
    mesh = merge_meshes(faces, "box")
    a = np.radians(rotation_y_deg)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    mesh.positions = (mesh.positions @ rot.T + [cx, cy, cz]).astype(np.float32)
    mesh.normals = (mesh.normals @ rot.T).astype(np.float32)
    mesh.tangents[:, :3] = mesh.tangents[:, :3] @ rot.T
    return mesh


def vertex_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals; vertices of degenerate-only triangles get +Y (warned)."""
    p = positions.astype(np.float64)
    face_n = np.cross(p[indices[:, 1]] - p[indices[:, 0]], p[indices[:, 2]] - p[indices[:, 0]])
    normals = np.zeros_like(p)
    for k in range(3):
        np.add.at(normals, indices[:, k], face_n)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    bad = length[:, 0] < 1e-20
    if np.any(bad):
        warnings.warn(
            f"{int(bad.sum())} vertices only touch degenerate triangles; normal set to +Y",
            stacklevel=2,
        )
    normals = np.where(bad[:, None], [0.0, 1.0, 0.0], normals / np.where(bad, 1.0, length[:, 0])[:, None])
    return normals.astype(np.float32)


def vertex_tangents(positions, normals, uvs, indices) -> np.ndarray:
    """Per-vertex tangents from UV derivatives (Lengyel's method), Gram-Schmidt against the
    normal, with handedness in w. Where UVs are missing or degenerate the tangent is any vector
    orthogonal to the normal (the shader does the same), so anisotropy direction is arbitrary
    there: a documented fallback."""
    p = positions.astype(np.float64)
    uv = uvs.astype(np.float64)
    i0, i1, i2 = indices[:, 0], indices[:, 1], indices[:, 2]
    e1, e2 = p[i1] - p[i0], p[i2] - p[i0]
    d1, d2 = uv[i1] - uv[i0], uv[i2] - uv[i0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    sdir = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    tdir = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    tan1 = np.zeros_like(p)
    tan2 = np.zeros_like(p)
    for k in (i0, i1, i2):
        np.add.at(tan1, k, sdir)
        np.add.at(tan2, k, tdir)
    n = normals.astype(np.float64)
    t = tan1 - n * np.sum(n * tan1, axis=1, keepdims=True)
    length = np.linalg.norm(t, axis=1, keepdims=True)
    bad = length[:, 0] < 1e-12
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    fallback = np.cross(n, helper)
    fallback /= np.linalg.norm(fallback, axis=1, keepdims=True)
    t = np.where(bad[:, None], fallback, t / np.where(bad, 1.0, length[:, 0])[:, None])
    w = np.where(np.sum(np.cross(n, t) * tan2, axis=1) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1).astype(np.float32)
