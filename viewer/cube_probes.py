"""The scene's cube maps and who reads which (issue 38: one owner): the cube-map pass
(viewer/cube_bake.py CubeBake: bake, bounces, disk cache, stale queue), shared probes
(scenes/probe_groups.py), the memory budget's residency (CubeResidency) and the reflectors' cube
maps on demand. An object's cube map is ``drawer.objects[i].cube``; an object of a shared probe
reads its group owner's (``probe_owner``)."""

from __future__ import annotations

import hashlib
import time

import numpy as np

from lobeview.core.methods import Method
from lobeview.materials.lobe_spread import lobe_width_face_size
from lobeview.scenes.analysis import DEFAULT_CUBE_FACE
from lobeview.scenes.probe_groups import SHARED_PROBE_MAX_FACE, group_probes

from .camera import box_corners, outside_frustum_many
from .cube_bake import CubeBake, CubeResidency, scene_content_key
from .object_drawer import ObjectDrawer
from .settings import RenderSettings

# Progressive start: preview cube maps this many times smaller across (never below PREVIEW_MIN_FACE).
PREVIEW_DIVISOR = 8
PREVIEW_MIN_FACE = 8
PREVIEW_BOUNCES = 1


class CubeProbes:
    """Builds the cube maps the analysis asks for at start-up (``environment_key``: the
    environment's content hash, part of the cache key) and keeps them current."""

    def __init__(
        self,
        ctx,
        drawer: ObjectDrawer,
        settings: RenderSettings,
        environment_key: str,
        progress=True,
        cache_dir=None,
        progressive: bool = False,
    ):
        self.drawer = drawer
        self.objects = drawer.objects
        self.settings = settings
        extent = float(np.max(drawer.scene.bounds[1] - drawer.scene.bounds[0]))
        self.bake = CubeBake(
            ctx,
            settings.cube_face_size,
            settings.cube_bounces,
            extent,
            drawer,
            progress,
            cache_dir,
            settings.mip_filter,
            settings.bright_sources,
        )
        budget = settings.cube_budget_mb
        self.residency = CubeResidency(None if budget is None else int(float(budget) * 2**20))
        drawer.residency = self.residency
        # Per cube map, the box whose visibility needs it (a shared probe's: its group's).
        self.probe_corners = drawer.object_corners.copy()
        self.groups: list = []
        self.apply_groups(self.rule_groups())
        self.environment_key = environment_key
        self.edited = False  # a material edit makes the start-up cache files outdated
        # Progressive start (the viewer, issue 42 item 2): without a cache, every cube map at a
        # preview size first, then the exact build one object per step (continue_build).
        self.progressive = bool(progressive) and settings.cube_budget_mb is None
        self.pending = None  # the exact build's steps while it runs (CubeBake.build_steps)
        self.pending_progress = (0, 0)
        self.pending_first_bounce = 0  # its first bounce's steps (diffuse renders, no lookup)
        # True while what the later (specular) bounces draw is not final yet (the horizon maps a
        # worker traces: SceneRenderer sets it): the build stops after its first bounce, so that
        # the cube maps it caches are those `shot` makes.
        self.hold_specular_bounces = lambda: False
        self.focus = None  # the camera's position: the first bounce renders its nearest first
        at_start, sizes, key = self._start_plan()
        if not self.progressive:
            self.bake.build(self.objects, at_start, key, sizes)
        elif not self.bake.build_from_cache(self.objects, at_start, key, sizes):
            self._start_progressive(at_start, sizes)

    def _start_plan(self) -> tuple[list[int], dict, str]:
        """(the cube maps made at start-up, their face sizes, the cache key)."""
        analysis, settings = self.drawer.analysis, self.settings
        sizes = {i: self.cube_size(i) for i in analysis.cube_mapped}
        key = scene_content_key(
            self.drawer.scene,
            self.environment_key,
            self.bake.face_size,
            self.bake.bounces,
            sizes,
            settings.mip_filter,
            settings.bright_sources,
        )
        if settings.reflector_cubes_on_demand:  # the second bounce then sees reflectors without lobes
            key += "-r"
        if self.groups:
            key += "-g" + hashlib.sha256(repr([g.members for g in self.groups]).encode()).hexdigest()[:8]
        # Objects of a group read the owner's cube map: only owners get one.
        at_start = [i for i in analysis.cubes_at_start if self.objects[i].probe_owner == i]
        return at_start, sizes, key

    # -- progressive start ---------------------------------------------------------------------
    def _start_progressive(self, at_start: list[int], sizes: dict) -> None:
        """Every cube map at PREVIEW_DIVISOR times smaller faces now (the first bounce only: the
        scene's diffuse light, as the exact build's first bounce shows it until its last bounce
        ends; half the preview's cost, which is the first frame's and the baked scene's swap's on
        a CPU; not cached), then the exact build as steps; its cache file is written when it
        finishes."""
        preview = {i: max(PREVIEW_MIN_FACE, sizes.get(i, self.bake.face_size) // PREVIEW_DIVISOR) for i in at_start}
        for _ in self.bake.build_steps(self.objects, at_start, preview, cache=False, bounces=PREVIEW_BOUNCES):
            pass
        self._pend_exact_build(at_start, sizes, cache=not self.edited)

    def _pend_exact_build(self, at_start: list[int], sizes: dict, cache: bool) -> None:
        """The exact build as pending steps (continue_build runs them between a window's frames:
        no loading overlay for them, the panel says how far it is)."""
        self.pending = self.bake.build_steps(
            self.objects, at_start, sizes, cache=cache, nearest=self._nearest, announce=False, background_write=True
        )
        self.pending_progress = (0, self.bake.steps_for(len(at_start), cache and self.bake.cache_dir is not None))
        self.pending_first_bounce = len(at_start)

    def _nearest(self, remaining: list[int]) -> int:
        if self.focus is None:
            return remaining[0]
        focus = np.asarray(self.focus, dtype=np.float64)
        return min(remaining, key=lambda i: float(np.linalg.norm(self.objects[i].probe_centre - focus)))

    def continue_build(self, seconds: float) -> int:
        """Advance the progressive build by whole steps (one object's faces each) while
        ``seconds`` last, at least one; returns the steps made, its end (the last bounce's
        install and the cache file) counting as one (0: nothing pending)."""
        if self.pending is None or self.held:
            return 0
        t0, steps = time.perf_counter(), 0
        while self.pending is not None and not self.held and (steps == 0 or time.perf_counter() - t0 < seconds):
            step = next(self.pending, None)
            steps += 1
            if step is None:
                self.pending = None
            else:
                self.pending_progress = step
        return steps

    @property
    def held(self) -> bool:
        """Whether the build waits before its specular bounces (hold_specular_bounces)."""
        if self.pending is None or self.pending_progress[0] < self.pending_first_bounce:
            return False
        return bool(self.hold_specular_bounces())

    @property
    def building(self) -> bool:
        """Whether the progressive build still runs (the cube maps are previews or partial)."""
        return self.pending is not None

    # -- shared probes (scenes/probe_groups.py) ---------------------------------------------------
    def rule_groups(self) -> list:
        """The groups scenes/probe_groups.py forms from the current analysis."""
        analysis = self.drawer.analysis
        candidates = {
            i: self.objects[i].box
            for i in analysis.cubes_at_start
            if analysis.objects[i].reflector is None
            and self._wide_lobes(i)
            and not analysis.objects[i].emissive  # a lamp left out of a probe would be missed
            # What a pane transmits is what lies right behind it: seen from a probe elsewhere it
            # moves (the demo's frosted pane grouped with the table: 11 % relative RMSE).
            and not analysis.objects[i].transmission_lobes
        }
        return group_probes(candidates, link=self.settings.probe_link) if self.settings.shared_probes else []

    def _wide_lobes(self, index: int) -> bool:
        """Whether object ``index``'s lobes are wide enough to share: the lobe-width rule gives them
        a face of at most SHARED_PROBE_MAX_FACE out of the default 256 (whatever --face-size is)."""
        footprint = self.drawer.analysis.objects[index].sample_solid_angle
        return footprint is not None and lobe_width_face_size(footprint, DEFAULT_CUBE_FACE) <= SHARED_PROBE_MAX_FACE

    def apply_groups(self, groups: list) -> set:
        """Point every member of ``groups`` at its group's owner and every other object at its own
        cube map; the scene analysis says who shares with whom (its report and the panel). Returns
        the objects whose probe changed."""
        analysis = self.drawer.analysis
        before = {obj.index: (obj.probe_owner, obj.probe_exclude) for obj in self.objects}
        for obj in self.objects:
            obj.probe_owner, obj.probe_centre, obj.probe_exclude = obj.index, obj.centre, frozenset((obj.index,))
            self.probe_corners[obj.index] = obj.corners
            analysis.objects[obj.index].shared_probe = ""
        for group in groups:
            for index in group.members:
                obj = self.objects[index]
                obj.probe_owner = group.owner
                if index == group.owner:
                    obj.probe_centre = group.centre
                    obj.probe_exclude = frozenset(group.members)
                    # restored when any member is in view
                    self.probe_corners[index] = box_corners(group.box_min, group.box_max)
        self.groups = list(groups)
        for group in self.groups:
            names = [self.objects[i].name for i in group.members]
            size = self.cube_size(group.owner)
            for index in group.members:
                others = ", ".join(repr(n) for n in names if n != self.objects[index].name)
                analysis.objects[index].shared_probe = f"{size}^2 with {others}"
        changed = {o.index for o in self.objects if before[o.index] != (o.probe_owner, o.probe_exclude)}
        if changed:
            self.drawer.shading.invalidate_records()  # the members' proxies read the probe's centre
        return changed

    def cube_size(self, index: int) -> int:
        """Face size of object ``index``'s own cube map: its lobes', or the widest of its group's."""
        group = self.group_of(index)
        members = group.members if group is not None and index == group.owner else (index,)
        return max(self.drawer.analysis.objects[i].cube_face for i in members)

    def group_of(self, index: int):
        return next((g for g in self.groups if index in g.members), None)

    def dissolve_group(self, index: int) -> None:
        """Give every member of object ``index``'s group its own cube map again (refinement
        converges to a cube map per object, as `shot --method reference` renders), and say so."""
        group = self.group_of(index)
        if group is None:
            return
        for member in sorted(self.apply_groups([g for g in self.groups if g is not group])):
            if self.drawer.analysis.objects[member].needs_cube_map:
                self.bake.build_one(self.objects, member, self.drawer.analysis.objects[member].cube_face, cached=False)

    # -- residency and cube maps on demand ------------------------------------------------------
    def restore(self, view_projection, exclude=None) -> None:
        """Restore the evicted cube maps (``cube_budget_mb``) of objects a pass with this frustum
        may draw, before it binds its framebuffer (restoring renders or reads cube faces)."""
        wanted = self.residency.wanted(self.probe_corners, view_projection, exclude)
        for index in wanted:
            t0 = time.perf_counter()
            where = self.bake.restore(self.objects, index, self.cube_size(index), self.edited)
            self.residency.evicted.discard(index)
            self.residency.restores[where] = self.residency.restores.get(where, 0) + 1
            self.residency.restore_seconds += time.perf_counter() - t0

    def reflector_cubes_for(self, method: Method, enabled: dict) -> None:
        """Build the cube maps of reflectors that this frame shades from a cube map (the
        prefiltered method, globally or as their override, or their mirror pass turned off:
        not in ``enabled``)."""
        analysis = self.drawer.analysis
        reflectors = analysis.reflectors
        if method.kind == "prefiltered":
            wanted = reflectors.keys()
        else:  # only those without a pass or overridden to prefiltered: not a scan of all, each frame
            overridden = {
                i for i in self.drawer.object_methods
                if i in reflectors and self.drawer.object_method(i, method).kind == "prefiltered"
            }  # fmt: skip
            wanted = (reflectors.keys() - enabled.keys()) | overridden
        for index in sorted(wanted):
            if self.objects[index].cube is not None:
                continue
            # Read or written to the cache only over finished cube maps (not during a progressive build).
            self.bake.build_one(self.objects, index, analysis.objects[index].cube_face, cached=not self.building)

    def request_full_faces(self, view_projection) -> int:
        """Queue the sized cube maps of the objects in this frustum for re-rendering at the full
        face size (one per ``refresh_one``), dissolving the shared probes in view first. Returns
        how many were queued."""
        culled = outside_frustum_many(self.drawer.object_corners, view_projection)
        for group in list(self.groups):  # refinement converges to per-object cube maps
            if not all(culled[i] for i in group.members):
                self.dissolve_group(group.owner)
        queued = [
            obj.index
            for obj in self.objects
            if obj.cube is not None
            and obj.cube.face_size < self.bake.face_size
            and not culled[obj.index]
            and obj.index not in self.bake.upgrades
        ]
        self.bake.upgrades.extend(queued)
        return len(queued)

    # -- material edits -------------------------------------------------------------------------
    def material_edited(self, material_index: int) -> None:
        """After the analysis was made again for an edit of material ``material_index``: regroup
        as a fresh start on the edited scene would (what `shot --materials` renders), queue every
        other cube map as stale, and re-render now the edited objects' own cube maps whose size,
        group or need changed."""
        self.edited = True
        analysis, scene = self.drawer.analysis, self.drawer.scene
        regrouped = self.apply_groups(self.rule_groups())
        if self.pending is not None:
            # The exact build was for the old material: start it again for the edited scene
            # (the cube maps shown meanwhile stay; nothing of it is cached, the scene was edited).
            at_start, sizes, _ = self._start_plan()
            self._pend_exact_build(at_start, sizes, cache=False)
        # Everything else that reflects this object now sees an outdated appearance.
        self.bake.stale = [i for i in analysis.cube_mapped if scene.objects[i].material != material_index]
        for gpu_obj in self.objects:
            i = gpu_obj.index
            if i in regrouped and gpu_obj.probe_owner != i and gpu_obj.cube is not None:
                gpu_obj.cube.release()  # it reads its group's probe now
                gpu_obj.cube = None
                self.residency.evicted.discard(i)
            size = self.cube_size(i)
            # A shared probe is as fine as its narrowest member: an edited member may resize it.
            cube_size = gpu_obj.cube.face_size if gpu_obj.cube is not None else size
            resized_probe = self.group_of(i) is not None and cube_size != size
            if i not in regrouped and scene.objects[i].material != material_index and not resized_probe:
                continue
            needs = analysis.objects[i]
            on_demand = i not in analysis.cubes_at_start and gpu_obj.cube is None
            if (
                needs.needs_cube_map
                and not on_demand
                and gpu_obj.probe_owner == i
                and (i in regrouped or gpu_obj.cube is None or gpu_obj.cube.face_size != size)
            ):
                # A diffuse object that became glossy gets its cube map now (~0.1 s), one whose
                # lobes narrowed or widened gets it at the face size they need, and a probe whose
                # group changed is rendered for its new members.
                self.bake.build_one(self.objects, i, size, cached=False)

    def prefiltered_memory(self, index: int) -> dict[str, int]:
        """Bytes of each prefiltered map object ``index`` has built so far (empty: none)."""
        cube = self.objects[self.objects[index].probe_owner].cube
        maps = cube.built_prefiltered_maps if cube is not None else None
        return dict(maps.memory) if maps is not None else {}
