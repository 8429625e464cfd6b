"""Cube maps of incident radiance: conversion from equirectangular maps, upload with a full MIP
chain, an irradiance cube for the diffuse term, and a GPU lookup used by the numpy reference.

Face order and texel directions follow the OpenGL specification (table 8.19, "cube map face
selection"): faces +X, -X, +Y, -Y, +Z, -Z; texel (column i, row j) of a face of size S has
(s, t) = ((i + 0.5)/S, (j + 0.5)/S), sc = 2 s - 1, tc = 2 t - 1 and direction
+X: (1, -tc, -sc)  -X: (-1, -tc, sc)  +Y: (sc, 1, tc)  -Y: (sc, -1, -tc)
+Z: (sc, -tc, 1)   -Z: (-sc, -tc, -1).
"""

from __future__ import annotations

import moderngl
import numpy as np

from lobeview.scenes.envmap import EnvironmentMap

from .shaders import ProgramCache

GL_TEXTURE_CUBE_MAP_SEAMLESS = 0x884F


def face_directions(face: int, size: int, supersample: int = 1) -> np.ndarray:
    """Unit directions of the texel centres (or of supersample^2 sub-texel points, in an extra
    axis) of one face; shape (size, size, 3) or (size, size, k*k, 3), rows = t."""
    k = supersample
    offsets = (np.arange(k) + 0.5) / k
    coords = (np.arange(size)[:, None] + offsets[None, :]).reshape(-1) / size
    tc, sc = np.meshgrid(2.0 * coords - 1.0, 2.0 * coords - 1.0, indexing="ij")
    one = np.ones_like(sc)
    dirs = {
        0: (one, -tc, -sc),
        1: (-one, -tc, sc),
        2: (sc, one, tc),
        3: (sc, -one, -tc),
        4: (sc, -tc, one),
        5: (-sc, -tc, -one),
    }[face]
    d = np.stack(dirs, axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    if k == 1:
        return d
    return d.reshape(size, k, size, k, 3).transpose(0, 2, 1, 3, 4).reshape(size, size, k * k, 3)


def equirect_to_cube_faces(env: EnvironmentMap, size: int, supersample: int = 2) -> np.ndarray:
    """Six faces (6, size, size, 3) resampled from the equirectangular map, each texel the mean
    of supersample^2 bilinear lookups (so a sun is not lost or aliased)."""
    faces = np.empty((6, size, size, 3), dtype=np.float32)
    for face in range(6):
        dirs = face_directions(face, size, supersample)
        values = env.lookup(dirs.reshape(-1, 3)).reshape(dirs.shape[:-1] + (3,))
        faces[face] = values.mean(axis=2) if supersample > 1 else values
    return faces


def upload_cube(
    ctx: moderngl.Context, faces: np.ndarray, mipmaps: bool = True
) -> moderngl.TextureCube:
    size = faces.shape[1]
    cube = ctx.texture_cube((size, size), 4, dtype="f4")
    rgba = np.concatenate([faces, np.ones(faces.shape[:-1] + (1,), np.float32)], axis=-1)
    for face in range(6):
        cube.write(face, np.ascontiguousarray(rgba[face], dtype=np.float32).tobytes())
    if mipmaps:
        cube.build_mipmaps()
        cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    else:
        cube.filter = (moderngl.LINEAR, moderngl.LINEAR)
    ctx.enable_direct(GL_TEXTURE_CUBE_MAP_SEAMLESS)
    return cube


def mip_levels(size: int) -> int:
    return int(np.floor(np.log2(size))) + 1


class EnvironmentCubes:
    """The GPU resources of one environment: radiance cube (with MIP chain) and irradiance cube."""

    def __init__(
        self,
        ctx: moderngl.Context,
        env: EnvironmentMap,
        face_size: int = 256,
        irradiance_size: int = 16,
    ):
        self.env = env
        self.face_size = face_size
        self.faces = equirect_to_cube_faces(env, face_size)
        self.radiance = upload_cube(ctx, self.faces)
        irradiance_faces = np.stack(
            [env.irradiance(face_directions(f, irradiance_size)) for f in range(6)]
        ).astype(np.float32)
        self.irradiance = upload_cube(ctx, irradiance_faces, mipmaps=False)

    def release(self):
        self.radiance.release()
        self.irradiance.release()


class CubeLookup:
    """Evaluate ``textureLod(cube, dir, lod)`` on the GPU for arrays of queries."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None):
        self.ctx = ctx
        self.programs = programs or ProgramCache(ctx)
        self.shader = self.programs.compute("cube_lookup.comp")

    def __call__(self, cube: moderngl.TextureCube, dirs: np.ndarray, lod: np.ndarray) -> np.ndarray:
        dirs = np.asarray(dirs, dtype=np.float32).reshape(-1, 3)
        lod = np.broadcast_to(np.asarray(lod, dtype=np.float32), (len(dirs),))
        count = len(dirs)
        if count == 0:
            return np.zeros((0, 3))
        queries = np.concatenate([dirs, lod[:, None]], axis=1).astype(np.float32)
        q_buf = self.ctx.buffer(queries.tobytes())
        r_buf = self.ctx.buffer(reserve=count * 16)
        try:
            q_buf.bind_to_storage_buffer(0)
            r_buf.bind_to_storage_buffer(1)
            cube.use(0)
            self.shader["u_cube"] = 0
            self.shader["u_count"] = count
            self.shader.run(group_x=(count + 63) // 64)
            self.ctx.finish()
            out = np.frombuffer(r_buf.read(), dtype=np.float32).reshape(count, 4)[:, :3]
        finally:
            q_buf.release()
            r_buf.release()
        return out.astype(np.float64)
