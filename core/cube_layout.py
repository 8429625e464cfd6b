"""Cube-map layout shared by the numpy side and the renderer (OpenGL specification, table 8.19,
"cube map face selection").

Faces +X, -X, +Y, -Y, +Z, -Z (index 0..5). Texel (column i, row j) of a face of size S has
(s, t) = ((i + 0.5)/S, (j + 0.5)/S), sc = 2 s - 1, tc = 2 t - 1 and direction
    +X: (1, -tc, -sc)   -X: (-1, -tc, sc)   +Y: (sc, 1, tc)
    -Y: (sc, -1, -tc)   +Z: (sc, -tc, 1)    -Z: (-sc, -tc, -1)
Rows are stored with t increasing (row 0 is t = 0, OpenGL's first row).
"""

from __future__ import annotations

import numpy as np


def face_point_directions(face: int, sc: np.ndarray, tc: np.ndarray) -> np.ndarray:
    one = np.ones_like(sc)
    dirs = {
        0: (one, -tc, -sc),
        1: (-one, -tc, sc),
        2: (sc, one, tc),
        3: (sc, -one, -tc),
        4: (sc, -tc, one),
        5: (-sc, -tc, -one),
    }[face]
    d = np.stack(dirs, axis=-1).astype(np.float64)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def face_directions(face: int, size: int, supersample: int = 1) -> np.ndarray:
    """Unit directions of the texel centres (or of supersample^2 sub-texel points, in an extra
    axis) of one face; shape (size, size, 3) or (size, size, k*k, 3), rows = t."""
    k = supersample
    offsets = (np.arange(k) + 0.5) / k
    coords = (np.arange(size)[:, None] + offsets[None, :]).reshape(-1) / size
    tc, sc = np.meshgrid(2.0 * coords - 1.0, 2.0 * coords - 1.0, indexing="ij")
    d = face_point_directions(face, sc, tc)
    if k == 1:
        return d
    return d.reshape(size, k, size, k, 3).transpose(0, 2, 1, 3, 4).reshape(size, size, k * k, 3)


def direction_to_face(d: np.ndarray):
    """(face index, sc, tc) of directions: the inverse of face_point_directions."""
    d = np.asarray(d, dtype=np.float64)
    ax, ay, az = np.abs(d[..., 0]), np.abs(d[..., 1]), np.abs(d[..., 2])
    x_major = (ax >= ay) & (ax >= az)
    y_major = ~x_major & (ay >= az)
    face = np.where(
        x_major,
        np.where(d[..., 0] >= 0, 0, 1),
        np.where(y_major, np.where(d[..., 1] >= 0, 2, 3), np.where(d[..., 2] >= 0, 4, 5)),
    )
    ma = np.where(x_major, ax, np.where(y_major, ay, az))
    ma = np.maximum(ma, 1e-300)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    sc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4], [-z, z, x, x, x], -x) / ma
    tc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4], [-y, -y, z, -z, -y], -y) / ma
    return face, sc, tc


def texel_solid_angles(size: int) -> np.ndarray:
    """Exact solid angle of every texel of one face, shape (size, size) (identical on all faces):
    the solid angle of the region [x0, x1] x [y0, y1] of the plane z = 1 is
    sum over corners of +-atan2(x y, sqrt(x^2 + y^2 + 1))."""
    edges = np.linspace(-1.0, 1.0, size + 1)

    def area(x, y):
        return np.arctan2(x * y, np.sqrt(x * x + y * y + 1.0))

    x0, y0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    x1, y1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")
    return area(x1, y1) - area(x0, y1) - area(x1, y0) + area(x0, y0)


# -- equirectangular maps (environment maps, lobe maps, RSIBR maps: the convention of shaders/cube.glsl) --
def equirect_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    phi = 2.0 * np.pi * (np.asarray(u, dtype=np.float64) - 0.5)
    theta = np.pi * np.asarray(v, dtype=np.float64)
    s = np.sin(theta)
    return np.stack([s * np.sin(phi), np.cos(theta), -s * np.cos(phi)], axis=-1)


def direction_to_equirect(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.asarray(d, dtype=np.float64)
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    phi = np.arctan2(d[..., 0], -d[..., 2])
    u = 0.5 + phi / (2.0 * np.pi)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u % 1.0, v
