"""Cube maps of incident radiance: conversion from equirectangular maps, upload with a full MIP
chain, an irradiance cube for the diffuse term, and a GPU lookup used by the numpy reference.
Face layout: :mod:`lobeview.core.cube_layout`.
"""

from __future__ import annotations

import math

import moderngl
import numpy as np

from lobeview.core.cube_layout import face_directions
from lobeview.scenes.env_sampling import CubeImportance
from lobeview.scenes.envmap import EnvironmentMap

from .interface import CDF_ROW
from .mip_chain import DEFAULT_MIP_FILTER, check_mip_filter, upload_cube
from .shaders import ProgramCache

#: the most sub-texel points per cube texel and axis (a 4k map read into 32^2 faces needs 64)
MAX_FACE_SUPERSAMPLE = 32
FACE_CHUNK_VALUES = 1 << 22  # lookups per numpy batch (bounds the memory of one batch to ~100 MB)


def face_supersample(env_height: int, size: int, supersample: int = 2) -> int:
    """Sub-texel points per cube texel and axis: at least ``supersample``, and at least the map's
    rows per face texel (an equirectangular map of height H has H / 2 rows per 90 degrees, a face
    ``size`` texels there, so H / size points step half a source texel at the face's centre). Fewer
    points alias: a small bright lamp or window is caught by one texel's points and missed by the
    next, and a capture read into small faces gains or loses the lamp's light (measured: lobe-7 on
    the interior capture, GGX 0.05, 3.8 % against the reference with 256^2 faces, 20.6 % with 64^2,
    39.6 % with 32^2 at 2 x 2 points)."""
    return int(min(MAX_FACE_SUPERSAMPLE, max(supersample, math.ceil(env_height / size))))


def equirect_to_cube_faces(env: EnvironmentMap, size: int, supersample: int = 2) -> np.ndarray:
    """Six faces (6, size, size, 3) resampled from the equirectangular map, each texel the mean
    of k^2 bilinear lookups, k = :func:`face_supersample` (at least ``supersample``; enough to
    average every source texel the face texel covers, so a sun or a lamp is neither lost nor
    aliased at any face size)."""
    k = face_supersample(env.height, size, supersample)
    rows_per_batch = max(1, FACE_CHUNK_VALUES // (size * k * k))
    faces = np.empty((6, size, size, 3), dtype=np.float32)
    for face in range(6):
        dirs = face_directions(face, size, k)
        if k == 1:
            faces[face] = env.lookup(dirs.reshape(-1, 3)).reshape(size, size, 3)
            continue
        for row in range(0, size, rows_per_batch):
            block = dirs[row : row + rows_per_batch]
            values = env.lookup(block.reshape(-1, 3)).reshape(block.shape[:-1] + (3,))
            faces[face, row : row + rows_per_batch] = values.mean(axis=2)
    return faces


# Blur stacks built so far (the multi-draws' records name stacks: a new one makes them again).
BLUR_STACK_BUILDS = [0]


class RadianceCube:
    """Incident radiance as a cube map with a full MIP chain, plus its importance map (texel CDF
    + per-texel density cube) for the reference method's environment sampling, built on first use
    (issue 18: a cube that no reference pass reads, e.g. a first-bounce cube of the bake or any
    cube of a real-time session, never builds it). No CPU copy of the faces is kept (4.7 MB per
    256^2 cube, 0.6 GB for the 18-room apartment): ``faces`` reads them back from the GPU."""

    def __init__(
        self,
        ctx: moderngl.Context,
        faces: np.ndarray,
        importance_size: int = 64,
        mip_filter: str = DEFAULT_MIP_FILTER,
        bright_sources: bool = False,
    ):
        faces = np.asarray(faces, dtype=np.float32)
        self.face_size = faces.shape[1]
        self.mip_filter = check_mip_filter(mip_filter)
        self.radiance = upload_cube(ctx, faces, mip_filter=mip_filter)
        # Bright-source separation (issue 39): the lights taken out, and the cube without their
        # caps (signed: what a source holds beyond its cap stays), which every method but the
        # reference and the prefiltered maps reads (the reference keeps the whole radiance: its
        # environment sampler already converges on suns; the prefiltered maps are made from
        # ``without_sources``). No lights: the same texture.
        # ``lights`` are what ``without_sources`` lost, ``residual_lights`` what ``residual`` lost:
        # the same but for a source whose cap is not its shape (a strip light), which the residual
        # keeps whole (bright_sources.py Separation.kept_whole).
        self.lights: list = []
        self._kept_whole: list = []  # those of ``lights`` that ``residual`` keeps whole
        self.residual = self.radiance
        self.signed_residual = False  # whether ``residual`` keeps a source's shape (signed)
        self._residual_is_without_sources = True  # no shape kept, no source kept whole
        self._without_sources = None  # on first use (prefiltered maps only)
        if bright_sources:
            from lobeview.scenes.bright_sources import separate_cube

            separation = separate_cube(faces)
            if separation.lights:
                self.lights = separation.lights
                self._kept_whole = [separation.lights[k] for k in separation.kept_whole]
                self.signed_residual = bool(separation.shapes_kept)
                self._residual_is_without_sources = not (separation.shapes_kept or separation.kept_whole)
                if self.residual_lights:
                    self.residual = upload_cube(ctx, separation.residual, mip_filter=mip_filter)
        self.importance_size = min(int(importance_size), self.face_size)
        self._importance: tuple | None = None  # (CubeImportance, env_cdf, env_pdf) once built
        self._prefiltered = None
        self._blur_stack = None  # lobe-N+norm+fit's coarse reads (viewer/blur_stack_gpu.py), on first use
        self.cache_dir = None  # where prefiltered maps are cached (set by the owner)

    @property
    def residual_lights(self) -> list:
        """The lights ``residual`` lost: ``lights`` but those it keeps whole."""
        return [light for light in self.lights if not any(light is whole for whole in self._kept_whole)]

    @property
    def has_blur_stack(self) -> bool:
        """Whether the blur stack is built (blur_stack() then costs nothing)."""
        return self._blur_stack is not None

    def blur_stack(self) -> moderngl.TextureArray:
        """The blur stack of ``residual`` (materials/blur_stack.py), built on first use (a few
        hundred thousand texture reads: milliseconds on a GPU, about a second on llvmpipe)."""
        if self._blur_stack is None:
            from .blur_stack_gpu import build_blur_stack

            self._blur_stack = build_blur_stack(self.residual.ctx, self.residual, self.face_size)
            BLUR_STACK_BUILDS[0] += 1
        return self._blur_stack

    @property
    def faces(self) -> np.ndarray:
        """(6, S, S, 3) float32: level 0 as stored on the GPU (float32 texels, so exactly what
        was uploaded), read back on each call; the importance tables are its only user."""
        return self._read_faces(self.radiance)

    @property
    def without_sources(self) -> moderngl.TextureCube:
        """The cube with each bright source at its surroundings' level (>= 0; bright_sources.py
        Separation.without_sources): what the prefiltered maps are made from, since their finest
        levels are looked up as they are and would show ``residual``'s signed detail. Separated
        again from ``faces`` on first use (a few tenths of a second for 256^2 faces; the same
        lights, since the faces read back are the float32 texels separated at construction), so no
        cube of a session without prefiltered maps holds it. Where no light's shape was kept (most
        captures: their suns are below SHAPE_FROM_TEXELS) and none kept whole ``residual`` already
        is that cube."""
        if self._residual_is_without_sources:
            return self.residual
        if self._without_sources is None:
            from lobeview.scenes.bright_sources import separate_cube

            faces = separate_cube(self.faces).without_sources
            self._without_sources = upload_cube(self.radiance.ctx, faces, mip_filter=self.mip_filter)
        return self._without_sources

    @property
    def without_sources_faces(self) -> np.ndarray:
        """The faces of ``without_sources``: what the prefiltered maps are made from and keyed by."""
        return self._read_faces(self.without_sources)

    @property
    def texture_chains(self) -> int:
        """How many cube textures with MIP chains this cube holds now (radiance, residual,
        without_sources)."""
        return 1 + (self.residual is not self.radiance) + (self._without_sources is not None)

    def _read_faces(self, texture) -> np.ndarray:
        size = self.face_size
        return np.stack(
            [
                np.frombuffer(texture.read(face, alignment=1), np.float32).reshape(size, size, 4)[..., :3]
                for face in range(6)
            ]
        )

    @property
    def importance_built(self) -> bool:
        return self._importance is not None

    def _importance_tables(self) -> tuple:
        if self._importance is None:
            ctx = self.radiance.ctx
            importance = CubeImportance.from_faces(self.faces, size=self.importance_size)
            cdf = importance.cdf.astype(np.float32)
            rows = (len(cdf) + CDF_ROW - 1) // CDF_ROW
            padded = np.ones(rows * CDF_ROW, dtype=np.float32)
            padded[: len(cdf)] = cdf
            env_cdf = ctx.texture((CDF_ROW, rows), 1, padded.tobytes(), dtype="f4")
            env_cdf.filter = (moderngl.NEAREST, moderngl.NEAREST)
            size = importance.size
            env_pdf = ctx.texture_cube((size, size), 1, dtype="f4")
            scale = importance.pdf_scale().astype(np.float32)
            for face in range(6):
                env_pdf.write(face, np.ascontiguousarray(scale[face]).tobytes())
            env_pdf.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._importance = (importance, env_cdf, env_pdf)
        return self._importance

    @property
    def importance(self) -> CubeImportance:
        """The importance map of the environment sampler (built on first use)."""
        return self._importance_tables()[0]

    @property
    def env_cdf(self) -> moderngl.Texture:
        return self._importance_tables()[1]

    @property
    def env_pdf(self) -> moderngl.TextureCube:
        return self._importance_tables()[2]

    def importance_memory(self) -> int:
        """Bytes of the importance tables (whether built or not): the CDF texture, rows of
        CDF_ROW floats, and the density cube."""
        texels = 6 * self.importance_size * self.importance_size
        rows = (texels + CDF_ROW - 1) // CDF_ROW
        return rows * CDF_ROW * 4 + 6 * self.importance_size * self.importance_size * 4

    def prefiltered_maps(self, programs: ProgramCache | None = None):
        """The prefiltered maps of this radiance (viewer/prefiltered.py), created on first use."""
        if self._prefiltered is None:
            from .prefiltered import PrefilteredMaps

            self._prefiltered = PrefilteredMaps(self.radiance.ctx, self, programs, self.cache_dir)
        return self._prefiltered

    @property
    def built_prefiltered_maps(self):
        """The prefiltered maps if any were built (for memory reports), else None."""
        return self._prefiltered

    def release(self):
        if self._prefiltered is not None:
            self._prefiltered.release()
        if self._blur_stack is not None:
            self._blur_stack.release()
        if self.residual is not self.radiance:
            self.residual.release()
        if self._without_sources is not None:
            self._without_sources.release()
        self.radiance.release()
        if self._importance is not None:
            self._importance[1].release()
            self._importance[2].release()


IRRADIANCE_FACE = 16  # E(n) is a cosine convolution: smooth enough for 16^2 texels a face, bilinear


def irradiance_cube(ctx: moderngl.Context, env: EnvironmentMap, face_size: int = IRRADIANCE_FACE):
    """The environment's irradiance E(n) (exact summation over its texels, EnvironmentMap.irradiance)
    at the texel centres of a cube map, without MIP levels: the diffuse light of the preview and of
    unbaked scene objects (shaders/scene.frag), read bilinearly."""
    faces = np.stack([env.irradiance(face_directions(f, face_size)) for f in range(6)]).astype(np.float32)
    return upload_cube(ctx, faces, mipmaps=False)


class EnvironmentCubes(RadianceCube):
    """A distant environment: radiance cube resampled from the equirectangular map, and an
    irradiance cube for diffuse shading without lightmaps (object preview)."""

    def __init__(
        self,
        ctx: moderngl.Context,
        env: EnvironmentMap,
        face_size: int = 256,
        irradiance_size: int = IRRADIANCE_FACE,
        importance_size: int = 64,
        mip_filter: str = DEFAULT_MIP_FILTER,
        bright_sources: bool = False,
    ):
        self.env = env
        super().__init__(ctx, equirect_to_cube_faces(env, face_size), importance_size, mip_filter, bright_sources)
        self.irradiance = irradiance_cube(ctx, env, irradiance_size)

    def release(self):
        super().release()
        self.irradiance.release()
