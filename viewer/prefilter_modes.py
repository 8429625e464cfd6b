"""The prefiltered modes in one table (issue 38): ``prefiltered-MODE`` chooses, per lobe, a kind
of prefiltered lookup (:data:`LOBE_KINDS`: what is fitted to the lobe, the rows it gets in the
lobe table, the map it reads, its bytes), and the mode's own extras (:data:`PREFILTER_MODES`:
the reflection-space maps of ``rsibr``). The shading binder (viewer/shading.py) and the memory
column of the benchmarks read these tables and nothing else about the modes.

A new mode touches core/methods.py (its name in PREFILTER_MODES) and this file (its row); a new
kind of map adds its fit (materials/) and its lookup (shaders/prefiltered.glsl, its name in
core/methods.py PREFILTER_LOOKUPS): four files at most. docs/architecture.md says how.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lobeview.core.methods import MAX_LOBES
from lobeview.core.methods import PREFILTER_MODES as MODE_NAMES
from lobeview.materials.banks import BANKS_AZIMUTHS, fit_banks
from lobeview.materials.conductor import MicrofacetReflection
from lobeview.materials.lobe_fit import LOBE_SLICES, fit_lobe_maps, is_isotropic
from lobeview.materials.prefilter import SPLIT_SUM_LEVELS

from .interface import LOBE_MAP_MODES, LOBE_TABLE_ROWS
from .material_gpu import PackedMaterial
from .prefiltered import DFG_SIZE, banks_map_shape, cube_bytes, lobe_direct_angle, lobe_map_shape, needs_lobe_map
from .rsibr import rsibr_layout

TEXEL_BYTES = 16  # RGBA32F


@dataclass(frozen=True)
class LobeKind:
    """How one lobe is prefiltered. ``lookup``: the shader's lookup (interface.LOBE_MAP_MODES);
    ``fit(component, cache_folder)``: what its map is built from (None: nothing);
    ``table_rows(rows, fitted)``: fills the lobe's rows of the lobe table (LOBE_TABLE_ROWS x
    2 LOBE_SLICES texels) and returns (u_lobe_map_count, u_banks_fibre); ``texture(maps,
    fitted, label)``: its 3D map from viewer/prefiltered.py PrefilteredMaps (None: a dummy is
    bound); ``depth(fitted)``: u_lobe_map_depth; ``direct_angle``: the median angle below which a
    fitted lobe is read from the radiance cube (0: never); ``memory(component, index, fitted,
    face)``: {label: bytes} of what it reads besides the radiance cube; ``split_sum``: it reads
    the split-sum cube of its distribution (built on first use)."""

    lookup: str
    split_sum: bool = False
    fit: Callable = lambda component, folder: None
    table_rows: Callable = lambda rows, fitted: (0, 0)
    texture: Callable = lambda maps, fitted, label: None
    depth: Callable = lambda fitted: 1
    direct_angle: float = 0.0
    memory: Callable = lambda component, index, fitted, face: {}


def _split_sum_memory(component, index: int, fitted, face: int) -> dict[str, int]:
    return {
        f"split-sum {component.distribution.kind}": cube_bytes(face, SPLIT_SUM_LEVELS),
        "DFG table": DFG_SIZE * DFG_SIZE * TEXEL_BYTES,
    }


def _fitted_lobe_rows(rows: np.ndarray, fitted: list) -> tuple[int, int]:
    """Fitted lobe j's axis relative to the slice's mirror direction
    (LobeMapFit.mirror_relative_axes) and median angle (w) in texels 0..S-1, its energy in
    S..2S-1."""
    for j, lobe in enumerate(fitted):
        rows[j, :LOBE_SLICES, :3] = lobe.mirror_relative_axes()
        # w: the lobe's median angle per slice (the direct read of narrow lobes)
        rows[j, :LOBE_SLICES, 3] = [lobe.profile(s).median_angle for s in range(LOBE_SLICES)]
        rows[j, LOBE_SLICES:, :3] = lobe.energy
    return len(fitted), 0


def _lobe_map_kind(fit_mode: str) -> LobeKind:
    """A Kautz-McCool style lobe map fitted by materials/lobe_fit.py in ``fit_mode``."""

    def memory(component, index: int, fitted, face: int) -> dict[str, int]:
        if not needs_lobe_map(fitted, fit_mode):
            return {}
        width, height, depth = lobe_map_shape(fitted)
        return {f"lobe map {index}": width * height * depth * TEXEL_BYTES}

    return LobeKind(
        lookup="lobes",
        fit=lambda component, folder: fit_lobe_maps(component, fit_mode, directory=folder),
        table_rows=_fitted_lobe_rows,
        texture=lambda maps, fitted, label: maps.lobe_map(fitted, label) if needs_lobe_map(fitted, fit_mode) else None,
        depth=lambda fitted: len(fitted[0].profiles),
        direct_angle=lobe_direct_angle(fit_mode),
        memory=memory,
    )


def _banks_rows(rows: np.ndarray, fitted) -> tuple[int, int]:
    """The albedo at view azimuth j pi / (2 (BANKS_AZIMUTHS - 1)) from the fibre in texels
    S..2S-1; the fibre axis (0 = tangent, 1 = bitangent)."""
    rows[:BANKS_AZIMUTHS, LOBE_SLICES:, :3] = fitted.energy.transpose(1, 0, 2)
    return 1, fitted.axis


def _banks_memory(component, index: int, fitted, face: int) -> dict[str, int]:
    width, height, depth = banks_map_shape(fitted)
    return {f"Banks map {index}": width * height * depth * TEXEL_BYTES}


#: per-lobe kinds of prefiltered lookup
LOBE_KINDS: dict[str, LobeKind] = {
    "splitsum": LobeKind(lookup="splitsum", split_sum=True, memory=_split_sum_memory),
    **{mode: _lobe_map_kind(mode) for mode in ("lobe", "lobe2d", "phong", "multi")},
    "banks": LobeKind(
        lookup="banks",
        fit=lambda component, folder: fit_banks(component),
        table_rows=_banks_rows,
        texture=lambda maps, fitted, label: maps.banks_map(fitted, label),
        depth=lambda fitted: len(fitted.profiles),
        memory=_banks_memory,
    ),
    # Baked into the material's reflection-space maps (viewer/rsibr.py), read by shaders/rsibr.glsl;
    # the per-lobe lookup leaves it out.
    "rsibr": LobeKind(lookup="splitsum"),
}


def _automatic(component) -> str:
    """Split-sum needs a microfacet BRDF (its DFG table; glTF lobes included): the thesis' Kurt
    lobes use lobe maps."""
    return "splitsum" if isinstance(component, MicrofacetReflection) else "lobe"


def _banks_where_anisotropic(component) -> str:
    """A Banks map needs an anisotropic lobe (a fibre direction): isotropic lobes use lobe maps."""
    anisotropic = getattr(component, "distribution", None) is not None and not is_isotropic(component)
    return "banks" if anisotropic else "lobe"


@dataclass(frozen=True)
class PrefilterMode:
    """``choose(component)``: the LOBE_KINDS name of each lobe; ``rsibr``: the lobes
    viewer/rsibr.py bakes into the material's reflection-space maps take the 'rsibr' kind (none
    where textures change the lobes per pixel) and the maps are bound."""

    choose: Callable
    rsibr: bool = False


#: ``prefiltered-MODE`` -> its row (every name of core/methods.py PREFILTER_MODES)
PREFILTER_MODES: dict[str, PrefilterMode] = {
    "auto": PrefilterMode(_automatic),
    "splitsum": PrefilterMode(_automatic),
    **{mode: PrefilterMode(lambda component, mode=mode: mode) for mode in ("lobe", "lobe2d", "phong", "multi")},
    "banks": PrefilterMode(_banks_where_anisotropic),
    "rsibr": PrefilterMode(_automatic, rsibr=True),
}
assert tuple(PREFILTER_MODES) == MODE_NAMES, "core/methods.py PREFILTER_MODES and this table must agree"
assert {kind.lookup for kind in LOBE_KINDS.values()} <= set(LOBE_MAP_MODES)


def prefilter_plan(material: PackedMaterial, mode: str, per_pixel_lobes: bool = False) -> list[str]:
    """The LOBE_KINDS name of each of ``material``'s lobes under ``prefiltered-MODE``."""
    entry = PREFILTER_MODES[mode]
    plan = [entry.choose(component) for component in material.lobe_components]
    if entry.rsibr:
        baked = rsibr_layout(material, per_pixel_lobes).lobes
        plan = ["rsibr" if baked >> i & 1 else kind for i, kind in enumerate(plan)]
    return plan


def fit_plan(plan: list[str], components: list, folder=None) -> list:
    """Per lobe what its map is built from (cached under ``folder``), as lobe_table takes it."""
    return [LOBE_KINDS[kind].fit(component, folder) for kind, component in zip(plan, components, strict=True)]


def lobe_table(plan: list[str], fitted: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The table the lookups read (shaders/prefiltered.glsl u_lobe_table), as (table, counts,
    fibres): (MAX_LOBES * LOBE_TABLE_ROWS, 2 LOBE_SLICES, 4) texels, lobe i owning rows
    i LOBE_TABLE_ROWS.. (LobeKind.table_rows), and per lobe u_lobe_map_count and u_banks_fibre."""
    table = np.zeros((MAX_LOBES * LOBE_TABLE_ROWS, 2 * LOBE_SLICES, 4), dtype=np.float32)
    counts = np.zeros(MAX_LOBES, dtype=np.int32)
    fibres = np.zeros(MAX_LOBES, dtype=np.int32)
    for i, (kind, fit) in enumerate(zip(plan, fitted, strict=True)):
        rows = table[i * LOBE_TABLE_ROWS : (i + 1) * LOBE_TABLE_ROWS]
        counts[i], fibres[i] = LOBE_KINDS[kind].table_rows(rows, fit)
    return table, counts, fibres


def prefiltered_memory(material: PackedMaterial, mode: str, face: int, folder=None) -> dict[str, int]:
    """{label: bytes} of the prefiltered maps ``prefiltered-MODE`` reads for ``material`` from a
    radiance cube of ``face``^2 (besides the cube itself)."""
    plan = prefilter_plan(material, mode)
    memory = {}
    for i, (kind, component) in enumerate(zip(plan, material.lobe_components, strict=True)):
        entry = LOBE_KINDS[kind]
        memory.update(entry.memory(component, i, entry.fit(component, folder), face))
    if PREFILTER_MODES[mode].rsibr and "rsibr" in plan:
        memory["RSIBR maps"] = rsibr_layout(material).bytes
    return memory
