"""prefiltered-rsibr: reflection-space image-based rendering on the GPU (Cabral, Olano and Nemec
1999, seed 004; numpy reference materials/rsibr.py, lookup shaders/rsibr.glsl).

Per object cube and material, one RGBA32F texture array holds the radiance environment maps of
every view of the geodesic view sphere (and, for an anisotropic material, every tangent-angle
slice), one layer per map (a "tile"). Each tile is baked by shaders/rsibr_bake.comp with fis-RSIBR_BAKE_SAMPLES from
the object's radiance cube, which is the part of lobeview that already integrates any material
(Kurt, microfacet, glTF lobes with their Fresnel terms); the maps are cached beside the other
prefiltered maps (viewer/prefiltered.py) and their bytes reported with them.

Which lobes go into the maps (:func:`rsibr_layout`; prefilter_modes.prefilter_plan): reflection lobes with a microfacet
distribution, when no texture changes the lobes per pixel. The rest keep the automatic
prefiltered lookup: thin transmission lobes (the mirror warp cannot follow a lobe centred on -v),
Rational lobes (no distribution to size the maps by), and every lobe of a textured glTF material
(a map is baked for one set of parameters).
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from lobeview.core.cache import BoundedCache
from lobeview.core.methods import Method
from lobeview.materials.lobe_fit import is_isotropic
from lobeview.materials.rsibr import (
    RSIBR_MAX_FACES,
    RSIBR_MAX_VIEWS,
    RSIBR_SLICES,
    RSIBR_SUBDIVISIONS,
    albedo_table,
    geodesic_sphere,
    map_rows,
)

from .interface import set_uniform
from .mip_chain import GL_RGBA32F
from .prefiltered import PREFILTER_LOD_BIAS

RSIBR_BAKE_SAMPLES = 256  # fis-N per texel of a map (filtered lookups, LOD bias PREFILTER_LOD_BIAS)
RSIBR_CACHE_VERSION = 2  # 2: each map's slices in its own tangent field (materials/rsibr.py map_tangent)
_ALBEDO_TABLES = BoundedCache(64)  # rsibr_cache_key -> albedo_table of the baked lobes (~0.7 s each)


def rsibr_eligible(component) -> bool:
    """Whether a lobe can be baked into the maps: a reflection lobe with a microfacet distribution
    whose value the bake shader computes from the packed lobe alone (a Rational or measured
    BRDF's data live in per-material buffers that shaders/rsibr_bake.comp does not bind: its
    distribution is a proxy, not the lobe)."""
    return (
        getattr(component, "distribution", None) is not None
        and not getattr(component, "transmission", False)
        and not getattr(component, "material_buffers", False)
    )


@dataclass(frozen=True)
class RsibrLayout:
    """What the maps of one material hold and how they are laid out: at most 42 views x 8 slices
    = 336 texture-array layers, within the 2048 every OpenGL 4.5 driver supports."""

    lobes: int  # bit i: lobe i is in the maps
    rows: int  # H: each tile is 2H x H, equirectangular in the reflection direction
    slices: int  # K: tangent-angle slices (1 for an isotropic material)
    subdivisions: int = RSIBR_SUBDIVISIONS

    @property
    def views(self) -> int:
        return 10 * 4**self.subdivisions + 2

    @property
    def faces(self) -> int:
        return 20 * 4**self.subdivisions

    @property
    def tiles(self) -> int:
        return self.views * self.slices

    @property
    def shape(self) -> tuple[int, int, int]:
        """(width, height, layers) of the texture array: one layer per tile."""
        return 2 * self.rows, self.rows, self.tiles

    @property
    def bytes(self) -> int:
        width, height, layers = self.shape
        return width * height * layers * 16


def rsibr_layout(material, per_pixel_lobes: bool = False, subdivisions: int = RSIBR_SUBDIVISIONS) -> RsibrLayout:
    """The maps ``material`` (viewer/material_gpu.PackedMaterial) needs: lobes 0 when none is
    eligible (or a texture changes the lobes per pixel)."""
    chosen = [] if per_pixel_lobes else [i for i, c in enumerate(material.lobe_components) if rsibr_eligible(c)]
    lobes = sum(1 << i for i in chosen)
    components = [material.lobe_components[i] for i in chosen]
    anisotropic = any(not is_isotropic(c) for c in components)
    rows = map_rows([c.distribution for c in components], anisotropic)
    return RsibrLayout(lobes, rows, RSIBR_SLICES if anisotropic else 1, subdivisions)


@functools.lru_cache(maxsize=2)
def view_sphere_uniforms(subdivisions: int) -> dict[str, np.ndarray]:
    """The view directions, faces and the faces' edge-plane normals the lookup searches (made
    once: every draw of an RSIBR object uploads them)."""
    vertices, faces = geodesic_sphere(subdivisions)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    edges = np.stack([np.cross(a, b), np.cross(b, c), np.cross(c, a)], axis=1)
    edges /= np.linalg.norm(edges, axis=-1, keepdims=True)

    def padded(values: np.ndarray, length: int, dtype) -> np.ndarray:  # the arrays' declared length
        out = np.zeros((length, 3), dtype=dtype)
        out[: len(values)] = values
        return out

    uniforms = {
        "u_rsibr_views": padded(vertices, RSIBR_MAX_VIEWS, np.float32),
        "u_rsibr_faces": padded(faces, RSIBR_MAX_FACES, np.int32),
        "u_rsibr_edges": padded(edges.reshape(-1, 3), 3 * RSIBR_MAX_FACES, np.float32),
    }
    for values in uniforms.values():
        values.flags.writeable = False  # shared by every caller of the cache
    return uniforms


def rsibr_cache_key(material, layout: RsibrLayout) -> str:
    """Content key of a material's maps for one radiance source: the packed rows of the baked
    lobes (what the bake shader reads), the layout and the bake's sample count."""
    lobes = tuple(key for i, key in enumerate(material.lobes_key) if layout.lobes >> i & 1)
    text = repr((RSIBR_CACHE_VERSION, RSIBR_BAKE_SAMPLES, lobes, layout))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def rsibr_albedo(material, layout: RsibrLayout, key: str) -> np.ndarray:
    """(RSIBR_ALBEDO_SIZE, 3) directional albedo of the baked lobes (the elevation correction);
    ``key``: the maps' rsibr_cache_key, under which it is kept."""
    components = [c for i, c in enumerate(material.lobe_components) if layout.lobes >> i & 1]
    return _ALBEDO_TABLES.get(key, lambda: albedo_table(components))


def bake_rsibr(shading, cube, material, layout: RsibrLayout, texture) -> None:
    """Fill ``texture`` (RGBA32F array, layout.shape) tile by tile: ``shading`` (viewer/shading.py
    ShadingBinder) binds the material and the cube to the bake shader as for a fis-N draw."""
    method = Method("fis", RSIBR_BAKE_SAMPLES)
    shader = shading.programs.compute("rsibr_bake.comp", {"METHOD_FIS": True})
    shading.set_material(shader, material, method, lod_bias=PREFILTER_LOD_BIAS, seed=0)
    shading.bind_cube(shader, cube, method)
    # Through set_uniform like set_material's: the program's uniform shadow (interface._store)
    # must see every write to a program it tracks.
    set_uniform(shader, "u_rows", layout.rows)
    set_uniform(shader, "u_rsibr_lobes", layout.lobes)
    vertices, _ = geodesic_sphere(layout.subdivisions)
    texture.bind_to_image(0, read=False, write=True, level=0, format=GL_RGBA32F)
    groups = ((2 * layout.rows + 7) // 8, (layout.rows + 7) // 8, 1)
    for view_index, view in enumerate(vertices):
        set_uniform(shader, "u_view", tuple(float(x) for x in view))
        for k in range(layout.slices):
            set_uniform(shader, "u_tile", view_index * layout.slices + k)
            set_uniform(shader, "u_angle", float(k * np.pi / layout.slices))
            shader.run(*groups)
        shading.ctx.finish()
