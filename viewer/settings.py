"""The scene renderer's options in one frozen value (issue 38): what the command line, the panel,
the benchmarks and the tests set, checked once, changed only through SceneRenderer.configure."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from lobeview.scenes.probe_groups import SHARED_PROBE_LINK

from .mip_chain import DEFAULT_MIP_FILTER, check_mip_filter

MIRROR_SCALE_RANGE = (0.05, 2.0)


@dataclass(frozen=True)
class RenderSettings:
    """Every option of SceneRenderer. Those under "cube maps" decide what the cube maps hold and
    are fixed for a renderer's life (a new renderer rebuilds them: ``shot`` and the viewer do);
    the rest take effect on the next frame through ``SceneRenderer.configure``."""

    # -- cube maps (fixed) ---------------------------------------------------------------------
    cube_face_size: int = 256  # the narrowest lobes' face size (scenes/analysis.py)
    cube_bounces: int = 2  # specular bounces between cube maps
    # Each object's cube map as large as its lobes resolve (issue 18); False: all at cube_face_size.
    lobe_width_cubes: bool = True
    # A planar reflector's mirror pass replaces its cube map: it gets one only when a frame needs
    # it (prefiltered method, its mirror pass turned off).
    reflector_cubes_on_demand: bool = True
    cube_budget_mb: float | None = None  # GPU memory for cube maps (None: unbounded), LRU eviction
    mip_filter: str = DEFAULT_MIP_FILTER  # how the radiance MIP chains are made (viewer/mip_chain.py)
    # Nearby small objects with wide lobes share one cube map (scenes/probe_groups.py).
    shared_probes: bool = False
    probe_link: float = SHARED_PROBE_LINK  # group_probes' link (bench/probe_sharing.py sweeps it)
    # Bright sources (suns, windows, lamps seen in a cube) become cap lights integrated exactly,
    # the cube keeps their surroundings (scenes/bright_sources.py, issue 39); not for the reference.
    bright_sources: bool = True
    # Per object, the cheapest real-time method whose measured error is at most this (relative
    # RMSE; materials/method_choice.py); None: every object takes the frame's method.
    method_target: float | None = None
    # -- per frame ---------------------------------------------------------------------------
    mirrors: bool = True  # planar mirror passes (thesis 4.5)
    mirror_scale: float = 1.0  # mirror buffers at this times the frame's resolution
    # Glossy objects seen in a mirror are shaded from their cube maps (lobe-3) instead of the
    # thesis' diffuse-only mirror pass.
    mirror_specular: bool = True
    # Refinement (mc-N, reference) on reflectors averages the tangent planes its samples found at
    # each pixel (Fig. 4.46b); False gives the plain two-step projection (for comparison).
    mirror_plane_average: bool = True
    enabled_reflectors: frozenset | None = None  # None: every reflector of the analysis
    # No mirror pass for a reflector that opaque objects hide from the camera (viewer/occlusion.py).
    mirror_occlusion: bool = True
    # A lobe-N reflector's pass shades only the buffer region its lookups can read.
    mirror_scissor: bool = True
    # A lobe-N reflector's buffers at 1/2 or 1/4 of mirror_scale where its finest lookups read that
    # much coarser (scenes/planar_mirror.py mirror_buffer_levels); False: every buffer at mirror_scale.
    mirror_lobe_sizes: bool = True
    # Reflectors in one plane (an apartment's floors) share its passes (scenes/planar_mirror.py
    # coplanar_groups); False: a pass per reflector (for comparison).
    mirror_plane_sharing: bool = True
    frustum_culling: bool = True  # objects outside a pass's frustum are not drawn
    depth_prepass: bool = True  # opaque depth first: the camera pass shades once per pixel
    # Per-object draw state recorded once and replayed per draw (viewer/interface.py DrawRecorder).
    draw_records: bool = True
    # The diffuse-shaded objects drawn by a few multi-draws whose commands a compute pass culls
    # (viewer/object_batches.py, issue 42); False: one draw call per object (kept for comparison).
    indirect_draws: bool = True
    # Specular lookups that an object's own surface hides from the shading point see the object
    # (its visibility cones, scenes/self_visibility.py) instead of its cube map; False: the cube
    # map everywhere (as before issue 40's Cycles comparison found the difference).
    self_occlusion: bool = True

    def __post_init__(self):
        check_mip_filter(self.mip_filter)
        low, high = MIRROR_SCALE_RANGE
        if not low <= float(self.mirror_scale) <= high:
            raise ValueError(f"mirror_scale must be in [{low:g}, {high:g}], got {self.mirror_scale}")
        if self.cube_budget_mb is not None and not float(self.cube_budget_mb) > 0:
            raise ValueError(f"cube_budget_mb must be positive, got {self.cube_budget_mb}")
        if int(self.cube_face_size) < 1:
            raise ValueError(f"cube_face_size must be positive, got {self.cube_face_size}")
        if self.method_target is not None and not 0.0 < float(self.method_target) <= 1.0:
            raise ValueError(f"method_target must be in (0, 1] (a relative error), got {self.method_target}")
        if not float(self.probe_link) > 0:
            raise ValueError(f"probe_link must be positive, got {self.probe_link}")
        if self.enabled_reflectors is not None:
            object.__setattr__(self, "enabled_reflectors", frozenset(int(i) for i in self.enabled_reflectors))

    def replace(self, **changes) -> RenderSettings:
        """These settings with ``changes`` (checked as a new value is)."""
        return dataclasses.replace(self, **changes)


#: the options that decide what the cube maps hold: a renderer keeps them for its life
CUBE_MAP_FIELDS = (
    "cube_face_size", "cube_bounces", "lobe_width_cubes", "reflector_cubes_on_demand", "cube_budget_mb",
    "mip_filter", "shared_probes", "probe_link", "bright_sources",
)  # fmt: skip
