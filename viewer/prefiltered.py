"""GPU prefiltering of a radiance cube for the ``prefiltered`` methods (issue 6).

* split-sum: a cube map whose MIP level l holds the environment prefiltered with the GGX (or
  Beckmann) split-sum kernel of perceptual roughness l / (levels - 1) (level 0 = the source),
  plus the DFG table (materials/prefilter.py);
* lobe maps: per component a 3D texture, equirectangular in x-y and the view elevation in z
  (Kautz & McCool's 3D environment map, seed 000 section 4), one block of slices per fitted
  lobe (materials/lobe_fit.py; several in the 'multi' mode);
* Banks maps (materials/banks.py, seed 001 section 5.3): a 3D texture indexed by the fibre
  direction (equirectangular) and asin(v.t), prefiltered with Banks' ring kernel around t.

Both are made on the GPU (shaders/prefilter*.comp): every target texel integrates its kernel
over cells that tile the sphere around it (materials/prefilter.py RadialProfile.cells), each a
filtered lookup into the source MIP chain weighted by the kernel's mass over the cell.
Results are cached in memory and, with a cache directory, on disk keyed by the source radiance
and the kernel. ``memory`` reports the bytes of every map (the user's accuracy/memory trade).
"""

from __future__ import annotations

import hashlib
import time
import warnings
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.cache import read_cache_file, write_cache_file
from lobeview.core.paths import cache_dir
from lobeview.core.progress import timed_step
from lobeview.materials.banks import BanksFit
from lobeview.materials.lobe_fit import LUMINANCE, LobeMapFit
from lobeview.materials.prefilter import (
    ANISO_DFG_COS,
    ANISO_DFG_PHI,
    ANISO_DFG_ROUGHNESS,
    ANISO_DFG_STRENGTH,
    DFG_SIZE,
    SPLIT_SUM_LEVELS,
    anisotropic_dfg_table,
    dfg_table,
    split_sum_alpha,
    split_sum_profile,
)

from .mip_chain import GL_RGBA32F, read_cube_level
from .shaders import ProgramCache

# MIP bias of the RSIBR bake's fis-N lookups on the tent chain (viewer/rsibr.py). For fis-style
# samples against brute force, +1 (Colbert & Krivanek) blurred light out of bright regions (mean
# error 5.7 % vs 0.5 % at 0, GGX alpha 0.16, box chain); on the tent chain -0.5 was closer than 0.
PREFILTER_LOD_BIAS = -0.5
# ... and of the prefilter cells' lookups (materials/prefilter.py RadialProfile.cells), each
# over its cell's solid angle. Measured against brute force on the issue-45 sky (a 3-degree sun
# of 50, 256^2 faces, split-sum levels 1-5, GGX and Beckmann): at -1 the map within 5 % of brute
# force at and around the sun (the equal-mass rings: 23 % dark at its centre on level 2) and a
# mean error of 0.07-1.0 % over random directions; -0.5 gave 0.1-1.3 %, 0 up to 3.4 %.
PREFILTER_CELL_LOD_BIAS = -1.0

SPLIT_SUM_KINDS = ("beckmann", "ggx")  # index = DIST_* in shaders/bsdf.glsl
LOBE_MAP_MAX_HEIGHT = 256
LOBE_MAP_MIN_HEIGHT = 16
MULTI_LOBE_SHARE = 0.1
MULTI_MAP_MAX_HEIGHT = 128  # 256 x 128 x 64 slices (4 lobes): 33.5 MB
BANKS_MAP_MAX_HEIGHT = 128  # 256 x 128 x 24 slices: 12.6 MB; narrower rings are blurred to it
# The Banks kernel is a thin ring: few quantile rings, many azimuths (the golden-ratio offset
# per ring interleaves them), so that the filtered lookups cover the ring without gaps.
BANKS_RINGS = 3
BANKS_AZIMUTHS_PER_RING = 128
_DFG_CACHE: dict = {}


def dfg_texture_data(size: int = DFG_SIZE, directory: Path | None = None) -> np.ndarray:
    """(size, size, 4): Beckmann (A, B) in rg, GGX (A, B) in ba; rows = roughness. Computed
    once (~4 s) and kept in ``directory`` (the renderer's cache folder; default: the user cache
    folder of core/paths.py)."""
    path = Path(directory or cache_dir()) / f"dfg-v2-{size}.npy"  # v2: nodes at the ends (prefilter.py dfg_table)
    if size not in _DFG_CACHE:

        def read(file: Path) -> np.ndarray:
            table = np.load(file, allow_pickle=False)
            if table.shape != (size, size, 4) or not np.all(np.isfinite(table)):
                raise ValueError(f"not a finite table of shape {(size, size, 4)}")
            return table

        table = read_cache_file(path, read, "DFG table")
        if table is None:
            table = np.concatenate([dfg_table(kind, size) for kind in SPLIT_SUM_KINDS], axis=-1)
            write_cache_file(path, lambda handle: np.save(handle, table))  # read-only cache: recomputed
        _DFG_CACHE[size] = table
    elif not path.exists():  # this cache folder gets its copy even when the table is in memory
        write_cache_file(path, lambda handle: np.save(handle, _DFG_CACHE[size]))
    return _DFG_CACHE[size]


def dfg_texture(ctx: moderngl.Context, directory: Path | None = None) -> moderngl.Texture:
    """The DFG table (:func:`dfg_texture_data`) as a linearly filtered, edge-clamped texture:
    the split-sum lookup and the per-pixel glTF lobe albedo of normalised lobe-N read it."""
    data = dfg_texture_data(directory=directory).astype(np.float32)
    tex = ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes(), dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    return tex


ANISO_DFG_SHAPE = (ANISO_DFG_ROUGHNESS, ANISO_DFG_STRENGTH, ANISO_DFG_PHI, ANISO_DFG_COS, 2)
_ANISO_DFG_CACHE: list = []


def anisotropic_dfg_texture_data(directory: Path | None = None) -> np.ndarray:
    """materials/prefilter.py anisotropic_dfg_table, computed once (~20 s here) and kept in
    ``directory`` like the DFG table."""
    if not _ANISO_DFG_CACHE:
        path = Path(directory or cache_dir()) / "dfg-anisotropic-v4.npy"  # v4: sqrt(cos) nodes at both ends

        def read(file: Path) -> np.ndarray:
            table = np.load(file, allow_pickle=False)
            if table.shape != ANISO_DFG_SHAPE or not np.all(np.isfinite(table)):
                raise ValueError(f"not a finite table of shape {ANISO_DFG_SHAPE}")
            return table

        table = read_cache_file(path, read, "anisotropic DFG table")
        if table is None:
            with timed_step("dfg", "anisotropic DFG table of textured anisotropic glTF lobes (cached afterwards)"):
                table = anisotropic_dfg_table()
            write_cache_file(path, lambda handle: np.save(handle, table))
        _ANISO_DFG_CACHE.append(table)
    return _ANISO_DFG_CACHE[0]


def anisotropic_dfg_texture(ctx: moderngl.Context, directory: Path | None = None) -> moderngl.Texture3D:
    """The anisotropic DFG table as a 3D texture (x: sqrt(cos), y: azimuth, z: roughness node x
    ANISO_DFG_STRENGTH + strength node; RG = A, B), linear and edge-clamped: shaders/patterns.glsl
    anisotropic_dfg interpolates the strength within a roughness block and the roughness by hand."""
    data = anisotropic_dfg_texture_data(directory).astype(np.float32)
    depth = ANISO_DFG_ROUGHNESS * ANISO_DFG_STRENGTH
    texels = np.ascontiguousarray(data.reshape(depth, ANISO_DFG_PHI, ANISO_DFG_COS, 2))
    tex = ctx.texture3d((ANISO_DFG_COS, ANISO_DFG_PHI, depth), 2, texels.tobytes(), dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


def _rows_for(angle: float, most: int) -> int:
    """Rows of an equirectangular map with about two texels across ``angle`` (radians),
    between 16 and ``most`` (multiple of 8)."""
    rows = int(np.ceil(np.pi / max(angle / 2.0, 1e-6)))
    return int(np.clip(-(-rows // 8) * 8, LOBE_MAP_MIN_HEIGHT, most))


def lobe_map_height(fit: LobeMapFit | list) -> int:
    """Rows of a lobe map: two texels across the sharpest slice's median angle. With several
    fitted lobes only lobes carrying at least MULTI_LOBE_SHARE of their slice's energy count
    (a greedy minimum profile can be a spike of a few mrad with 1 % of the energy: sizing the
    map for it made 512x256x64 maps, 134 MB and 30 s on llvmpipe); the multi-lobe map is
    at most MULTI_MAP_MAX_HEIGHT rows."""
    fits = fit if isinstance(fit, list) else [fit]
    if len(fits) == 1:
        return _rows_for(min(p.median_angle for p in fits[0].profiles), LOBE_MAP_MAX_HEIGHT)
    energy = np.array([[float(e @ LUMINANCE) for e in f.energy] for f in fits])  # (lobes, S)
    total = energy.sum(axis=0)
    medians = [
        f.profile(s).median_angle
        for j, f in enumerate(fits)
        for s in range(len(f.energy))
        if energy[j, s] >= MULTI_LOBE_SHARE * total[s] and total[s] > 0.0
    ]
    return _rows_for(min(medians, default=np.pi / 8), MULTI_MAP_MAX_HEIGHT)


# A fitted lobe narrower than two texels of the largest map its mode may build (median angle below
# 2 pi / max height: 1.4 deg for the lobe maps, 2.8 deg for multi) is not resolved by that map:
# the shader reads the radiance cube's MIP chain along the lobe axis instead (shaders/prefiltered.glsl,
# footprint interface.LOBE_DIRECT_AREA_PER_MEDIAN2).


def lobe_direct_angle(mode: str) -> float:
    """Median angle below which a fitted lobe of ``mode`` is read from the radiance cube."""
    return 2.0 * np.pi / (MULTI_MAP_MAX_HEIGHT if mode == "multi" else LOBE_MAP_MAX_HEIGHT)


def needs_lobe_map(fits: list, mode: str) -> bool:
    """Whether any slice of any fitted lobe is wide enough for the map (no map is built, and no
    memory spent, for a component whose lobes are all read directly: chrome, lacquer's coat)."""
    limit = lobe_direct_angle(mode)
    return any(f.profile(s).median_angle >= limit for f in fits for s in range(len(f.cos_theta_o)))


def banks_map_shape(fit: BanksFit) -> tuple[int, int, int]:
    """(width, height, depth) of a Banks map: two texels across the ring's half width."""
    height = _rows_for(float(np.arccos(fit.s)), BANKS_MAP_MAX_HEIGHT)
    return 2 * height, height, len(fit.profiles)


def cube_bytes(face: int, levels: int, texel_bytes: int = 16) -> int:
    """GPU bytes of a cube map with ``levels`` MIP levels of a ``face``^2 level 0."""
    return sum(6 * max(face >> level, 1) ** 2 * texel_bytes for level in range(levels))


def lobe_map_shape(fit: LobeMapFit | list) -> tuple[int, int, int]:
    """(width, height, depth) of the RGBA32F 3D texture of one component's fitted lobes."""
    fits = fit if isinstance(fit, list) else [fit]
    height = lobe_map_height(fits)
    return 2 * height, height, sum(len(f.profiles) for f in fits)


def _texels_reader(shape: tuple):
    """Reader of a cached map (read_cache_file): its 'texels' array, finite and of ``shape``."""

    def read(path: Path) -> np.ndarray:
        with np.load(path, allow_pickle=False) as data:
            texels = data["texels"]
        if texels.shape != shape or not np.all(np.isfinite(texels)):
            raise ValueError(f"not a finite array of shape {shape}")
        return np.ascontiguousarray(texels, dtype=np.float32)

    return read


class PrefilteredMaps:
    """The prefiltered maps of one radiance cube (``cube``: viewer/cubemap.py RadianceCube, which
    makes this object on first use), made on demand and cached under ``cache_dir``."""

    def __init__(
        self,
        ctx: moderngl.Context,
        cube,
        programs: ProgramCache | None = None,
        cache_dir: Path | None = None,
    ):
        self.ctx = ctx
        self.cube = cube
        self.programs = programs or ProgramCache(ctx)
        self.cache_dir = Path(cache_dir) if cache_dir else None
        # level 0, how the levels the prefilters read between were made, and their bias
        # the cube without its bright sources (viewer/cubemap.py without_sources): those are added exactly
        source = np.ascontiguousarray(cube.without_sources_faces).tobytes()
        source += f"{cube.mip_filter} {PREFILTER_CELL_LOD_BIAS}".encode()
        self._source_key = hashlib.sha1(source).hexdigest()[:16]
        self._split_sum: dict = {}
        self._lobe_maps: dict = {}
        self._by_fit: dict = {}
        self._rsibr: dict = {}
        self._dfg = None
        self._anisotropic_dfg = None
        self.memory: dict[str, int] = {}
        self.seconds: dict[str, float] = {}

    # -- kernels as quadrature nodes -------------------------------------------------------------
    def _nodes(self, profiles, rings: int | None = None, azimuths: int | None = None) -> np.ndarray:
        """The quadrature cells (psi, beta, omega, weight) per kernel row, padded with weight 0:
        what the prefilter shaders read, and the key of a map in the caches. Centred kernels
        take RadialProfile.cells; with ``rings`` and ``azimuths`` (Banks' thin ring kernels)
        the equal-mass rings of RadialProfile.ring_cells."""
        cells = []
        for profile in profiles:
            if profile is None:  # the mirror level: one lookup at the centre, finest level
                cells.append(np.array([[0.0, 0.0, 1e-12, 1.0]]))
                continue
            found = profile.ring_cells(rings, azimuths) if rings and azimuths else profile.cells()
            cells.append(np.stack([found.psi, found.beta, found.omega, found.weight], axis=-1))
        nodes = np.zeros((len(profiles), max(len(c) for c in cells), 4), dtype=np.float32)
        for row, found in enumerate(cells):
            nodes[row, : len(found)] = found
        return nodes

    def _bind_source(self, shader, nodes: np.ndarray):
        """Bind the source cube and upload the cells; returns the cells texture to release."""
        cells_texture = self.ctx.texture((nodes.shape[1], nodes.shape[0]), 4, nodes.tobytes(), dtype="f4")
        cells_texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.cube.without_sources.use(0)
        cells_texture.use(1)
        shader["u_source"] = 0
        shader["u_cells"] = 1
        shader["u_source_face"] = float(self.cube.face_size)
        shader["u_cell_count"] = nodes.shape[1]
        shader["u_lod_bias"] = PREFILTER_CELL_LOD_BIAS
        return cells_texture

    def _cache_file(self, kind: str, nodes: np.ndarray, extra: str) -> Path | None:
        if self.cache_dir is None:
            return None
        key = hashlib.sha1(nodes.tobytes() + extra.encode()).hexdigest()[:16]
        return self.cache_dir / f"prefiltered-{kind}-{self._source_key}-{key}.npz"

    # -- split-sum -------------------------------------------------------------------------------
    def split_sum(self, kind: str) -> moderngl.TextureCube:
        if kind in self._split_sum:
            return self._split_sum[kind]
        t0 = time.perf_counter()
        size = self.cube.face_size
        profiles = [None] + [split_sum_profile(kind, split_sum_alpha(level)) for level in range(1, SPLIT_SUM_LEVELS)]
        nodes = self._nodes(profiles)
        cube = self.ctx.texture_cube((size, size), 4, dtype="f4")
        cube.build_mipmaps(0, SPLIT_SUM_LEVELS - 1)
        cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        cache = self._cache_file(f"splitsum-{kind}", nodes, f"{size}")

        def read(path: Path) -> list:
            with np.load(path, allow_pickle=False) as data:
                levels = [data[f"level{level}"] for level in range(SPLIT_SUM_LEVELS)]
            for level, texels in enumerate(levels):
                face = max(size >> level, 1)
                if texels.shape != (6, face, face, 4) or not np.all(np.isfinite(texels)):
                    raise ValueError(f"level {level} is not a finite array of shape {(6, face, face, 4)}")
            return levels

        levels = read_cache_file(cache, read, f"split-sum {kind} cube")
        if levels is not None:
            self._write_cube_levels(cube, levels)
        else:
            shader = self.programs.compute("prefilter_cube.comp")
            nodes_texture = self._bind_source(shader, nodes)
            what = f"split-sum {kind} cube, {size}^2 x 6, {SPLIT_SUM_LEVELS} levels (GPU, cached afterwards)"
            with timed_step("prefilter", what, announce=True):
                for level in range(SPLIT_SUM_LEVELS):
                    face = max(size >> level, 1)
                    cube.bind_to_image(0, read=False, write=True, level=level, format=GL_RGBA32F)
                    shader["u_size"] = face
                    shader["u_row"] = level
                    shader.run((face + 7) // 8, (face + 7) // 8, 6)
                self.ctx.finish()
            nodes_texture.release()
            if cache is not None:
                levels = self._read_cube_levels(cube, size)
                arrays = {f"level{i}": v for i, v in enumerate(levels)}
                write_cache_file(cache, lambda handle: np.savez(handle, **arrays))  # read-only: recomputed
        self._split_sum[kind] = cube
        self.memory[f"split-sum {kind}"] = cube_bytes(size, SPLIT_SUM_LEVELS)
        self.seconds[f"split-sum {kind}"] = time.perf_counter() - t0
        return cube

    def _read_cube_levels(self, cube, size) -> list:
        """Every MIP level of a split-sum cube."""
        return [read_cube_level(self.ctx, cube, level) for level in range(SPLIT_SUM_LEVELS)]

    def _write_cube_levels(self, cube, levels) -> None:
        shader = self.programs.compute("cube_level_write.comp")
        for level, data in enumerate(levels):
            face = data.shape[1]
            buffer = self.ctx.buffer(np.ascontiguousarray(data, dtype=np.float32).tobytes())
            buffer.bind_to_storage_buffer(0)
            cube.bind_to_image(0, read=False, write=True, level=level, format=GL_RGBA32F)
            shader["u_size"] = face
            shader.run((face + 7) // 8, (face + 7) // 8, 6)
            self.ctx.finish()
            buffer.release()

    def dfg(self) -> moderngl.Texture:
        if self._dfg is None:
            t0 = time.perf_counter()
            self._dfg = dfg_texture(self.ctx, self.cache_dir)
            self.memory["DFG table"] = self._dfg.size[0] * self._dfg.size[1] * 16
            self.seconds["DFG table"] = time.perf_counter() - t0
        return self._dfg

    def anisotropic_dfg(self) -> moderngl.Texture3D:
        """The anisotropic GGX (A, B) table (:func:`anisotropic_dfg_texture`) of split-sum's
        anisotropic GGX lobes (shaders/prefiltered.glsl)."""
        if self._anisotropic_dfg is None:
            t0 = time.perf_counter()
            self._anisotropic_dfg = anisotropic_dfg_texture(self.ctx, self.cache_dir)
            width, height, depth = self._anisotropic_dfg.size
            self.memory["anisotropic DFG table"] = width * height * depth * 8
            self.seconds["anisotropic DFG table"] = time.perf_counter() - t0
        return self._anisotropic_dfg

    # -- Kautz-McCool lobe maps and Banks maps ------------------------------------------------
    def lobe_map(self, fit: LobeMapFit | list, name: str = "lobe") -> moderngl.Texture3D:
        """3D map of one component's fitted lobes: slice s of lobe j (z = j S + s) holds the
        environment convolved with that lobe's unit-mass shape at view elevation s (one slice
        per lobe for the 2D and Phong modes)."""
        fits = fit if isinstance(fit, list) else [fit]
        label = f"{name} ({fits[0].mode}{f' x{len(fits)}' if len(fits) > 1 else ''}"
        return self._fitted_map(
            tuple(fits),
            lambda: self._latlong_map("lobemap", [p for f in fits for p in f.profiles], lobe_map_shape(fits), label),
        )

    def banks_map(self, fit: BanksFit, name: str = "banks") -> moderngl.Texture3D:
        """Banks map: slice k holds the environment convolved with the ring kernel of
        v.t = sin(a_k) around each direction t (materials/banks.py)."""
        label = f"{name} (banks s={fit.s:.4f}"
        return self._fitted_map(
            (fit,),
            lambda: self._latlong_map(
                "banks", fit.profiles, banks_map_shape(fit), label, BANKS_RINGS, BANKS_AZIMUTHS_PER_RING
            ),
        )

    def _fitted_map(self, fits: tuple, build) -> moderngl.Texture3D:
        """The map of these fit objects, looked up by their identity first: the renderer binds
        maps every frame, and keying by content means computing every profile's quadrature
        nodes (64 profiles for a multi-lobe map) per object per frame. The fits are kept in the
        entry, so their ids stay unique; the content-keyed cache behind still shares equal maps."""
        key = tuple(id(f) for f in fits)
        if key not in self._by_fit:
            self._by_fit[key] = (build(), fits)
        return self._by_fit[key][0]

    def _latlong_map(self, kind, profiles, shape, label, rings=None, azimuths=None) -> moderngl.Texture3D:
        width, height, depth = shape
        nodes = self._nodes(profiles, rings, azimuths)
        key = (nodes.tobytes(), width, azimuths)
        if key in self._lobe_maps:
            return self._lobe_maps[key]
        t0 = time.perf_counter()
        cache = self._cache_file(kind, nodes, f"{width}x{height}x{azimuths}")

        texels = read_cache_file(cache, _texels_reader((depth, height, width, 4)), f"{label}) map")
        if texels is not None:
            tex = self.ctx.texture3d((width, height, depth), 4, texels.tobytes(), dtype="f4")
        else:
            tex = self.ctx.texture3d((width, height, depth), 4, dtype="f4")
            shader = self.programs.compute("prefilter_latlong.comp")
            nodes_texture = self._bind_source(shader, nodes)
            shader["u_size"] = (width, height)
            tex.bind_to_image(0, read=False, write=True, level=0, format=GL_RGBA32F)
            what = f"{label}) map, {width}x{height}x{depth} (GPU, cached afterwards)"
            with timed_step("prefilter", what, announce=True):
                for s in range(depth):
                    shader["u_slice"] = s
                    shader.run((width + 7) // 8, (height + 7) // 8, 1)
                    self.ctx.finish()
            nodes_texture.release()
            if cache is not None:
                texels = np.frombuffer(tex.read(), dtype=np.float32).reshape(depth, height, width, 4)
                write_cache_file(cache, lambda handle: np.savez(handle, texels=texels))  # read-only: recomputed
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = True
        tex.repeat_y = False
        tex.repeat_z = False
        self._lobe_maps[key] = tex
        label = f"{label}, {width}x{height}x{depth}, {hashlib.sha1(key[0]).hexdigest()[:6]})"
        self.memory[label] = width * height * depth * 16
        self.seconds[label] = time.perf_counter() - t0
        return tex

    # -- reflection-space IBR (viewer/rsibr.py) ------------------------------------------------
    def rsibr_map(self, layout, key: str, bake) -> moderngl.TextureArray:
        """The RSIBR maps of one material (``key``: viewer/rsibr.rsibr_cache_key), read from the
        cache or made by ``bake(texture)``."""
        if key in self._rsibr:
            return self._rsibr[key]
        t0 = time.perf_counter()
        width, height, layers = layout.shape
        cache = self.cache_dir / f"prefiltered-rsibr-{self._source_key}-{key}.npz" if self.cache_dir else None
        label = f"RSIBR maps ({layout.views} views x {layout.slices} slices of {width}x{height}"
        texels = read_cache_file(cache, _texels_reader((layers, height, width, 4)), f"{label})")
        if texels is not None:
            tex = self.ctx.texture_array((width, height, layers), 4, texels.tobytes(), dtype="f4")
        else:
            tex = self.ctx.texture_array((width, height, layers), 4, dtype="f4")
            what = f"{label}, {layout.bytes / 2**20:.1f} MB (GPU, cached afterwards)"
            with timed_step("prefilter", what, announce=True):
                bake(tex)
            texels = np.frombuffer(tex.read(), dtype=np.float32).reshape(layers, height, width, 4)
            bad = int(np.count_nonzero(texels[..., 3] < 0.0))
            if bad:  # the bake writes 0 there: a material the integrator cannot evaluate
                warnings.warn(f"{label}): {bad} texels integrated to NaN/Inf were written as 0", stacklevel=2)
            if cache is not None:
                write_cache_file(cache, lambda handle: np.savez(handle, texels=texels))  # read-only: recomputed
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = True
        tex.repeat_y = False
        self._rsibr[key] = tex
        self.memory[f"{label}, {key[:6]})"] = layout.bytes
        self.seconds[f"{label}, {key[:6]})"] = time.perf_counter() - t0
        return tex

    def total_memory(self) -> int:
        return int(sum(self.memory.values()))

    def release(self):
        for tex in list(self._split_sum.values()) + list(self._lobe_maps.values()) + list(self._rsibr.values()):
            tex.release()
        for table in (self._dfg, self._anisotropic_dfg):
            if table is not None:
                table.release()
        self._split_sum.clear()
        self._lobe_maps.clear()
        self._by_fit.clear()
        self._rsibr.clear()
        self._dfg = self._anisotropic_dfg = None
