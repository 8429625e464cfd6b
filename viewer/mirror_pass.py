"""The planar mirror pass (thesis 4.5; numpy reference scenes/planar_mirror.py): per visible
reflector per frame, the scene drawn from the camera mirrored about its plane (and, for panes,
from the camera itself behind the plane: the see-through pass) with Lengyel's oblique near plane
into a buffer of radiance (MIP chain), world position and normal; reused while nothing changes.
The pass draws through the scene's object drawer (viewer/object_drawer.py), so it holds no shading
code of its own."""

from __future__ import annotations

import time

import moderngl
import numpy as np

from lobeview.core.methods import Method
from lobeview.materials.lobe_spread import finest_sample_solid_angle, finest_sample_solid_angles, lobe_spread
from lobeview.materials.patterns import specular_lobes
from lobeview.materials.spec import build_bsdf
from lobeview.scenes.planar_mirror import mirror_view_angle_bounds, reflector_arrays

from .camera import Camera, outside_frustum_boxes, perspective
from .frame import begin_pass, new_framebuffer
from .interface import TEXTURE_UNITS, bind_sampler, has_uniform, set_uniform
from .mip_chain import DEFAULT_MIP_FILTER, build_mip_chain
from .scene_shading import per_pixel_lobes

MIRROR_BOUNCE_METHOD = Method("lobe", 3, normalize=True)  # glossy objects inside mirror buffers (cheap)
# Sampler-uniform prefixes of the mirror and see-through buffers (units: interface.TEXTURE_UNITS).
BUFFER_PREFIXES = {"mirror": "u_mirror", "see-through": "u_through"}


def mirror_front(reflector, eye) -> tuple[float, float, float]:
    """The reflector's plane normal on the side of ``eye`` (u_mirror_front): the reflectors of a
    shared pass with the same value draw as one multi-draw (viewer/object_drawer.py)."""
    plane = reflector.plane
    front = plane[:3] if float(np.dot(plane[:3], eye) + plane[3]) >= 0.0 else -plane[:3]
    return tuple(float(x) for x in front)


# Mirror buffers of other sizes a plane keeps for reuse (its levels 1/2 and 1/4, a render scale).
SPARE_SIZES = 3


class MirrorTargets:
    """One reflector's mirror buffer (thesis 4.5.1): radiance with a MIP chain, world position
    (w = 1 geometry, 0 environment), normal, depth."""

    def __init__(self, ctx, size):
        self.size = size
        self.radiance = ctx.texture(size, 4, dtype="f4")
        self.radiance.build_mipmaps()  # allocates the levels; each pass filters them again
        self.radiance.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.radiance.repeat_x = self.radiance.repeat_y = False
        self.position = ctx.texture(size, 4, dtype="f4")
        self.normal = ctx.texture(size, 4, dtype="f4")
        for tex in (self.position, self.normal):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_renderbuffer(size)
        self.fbo = new_framebuffer(ctx, [self.radiance, self.position, self.normal], self.depth)
        self.camera = None  # scenes.planar_mirror.MirrorCamera of the last pass
        self._uniforms = (None, {})  # (camera, its uniform values), made once a pass, bound per reflector

    def camera_uniforms(self) -> dict:
        """The last pass's camera as the shaders' mirror uniforms (name suffix -> value), converted
        once per pass: every reflector of a shared plane binds the same values."""
        camera, values = self._uniforms
        if camera is not self.camera:
            camera = self.camera
            values = {
                "_view": tuple(camera.view.T.astype("f4").ravel()),
                "_view_projection": tuple(camera.plain_view_projection.T.astype("f4").ravel()),
                "_eye": tuple(float(x) for x in camera.position),
                "_focal_px": float(camera.focal_pixels),
            }
            self._uniforms = (camera, values)
        return values

    def release(self):
        for item in (self.fbo, self.radiance, self.position, self.normal, self.depth):
            item.release()


class ReflectorLayout:
    """The reflectors' arrays for the frame's tests in one numpy pass (planes, boxes, which
    transmit), and their plane groups: made when the reflectors change, not every frame (a
    frame's per-reflector Python loops grew with the scene, issue 42)."""

    def __init__(self, reflectors: dict, groups: list[tuple] | None = None):
        items = list(reflectors.values())
        self.indices = np.fromiter(reflectors, dtype=np.int64, count=len(items))
        self.planes, self.low, self.high = reflector_arrays(items)
        self.transmits = np.array([r.transmission for r in items], dtype=bool)
        self.groups = groups if groups is not None else [(index,) for index in reflectors]
        self.group_of = {index: order for order, group in enumerate(self.groups) for index in group}

    def tests(self, camera: Camera, view_proj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(seen from behind, outside the view) per reflector, in the layout's order."""
        if not len(self.indices):
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        eye = np.asarray(camera.position, dtype=np.float64)
        behind = (self.planes[:, :3] @ eye + self.planes[:, 3] <= 1e-6) & ~self.transmits
        return behind, outside_frustum_boxes(self.low, self.high, view_proj)


class PassOutcome:
    """What the last frame's passes did: the reflectors drawn and, built only when asked (the
    panel, the benches), why each other one got none and the report's lines."""

    def __init__(self, order: list, names: list, reasons: dict | None = None, lines: dict | None = None,
                 tests=None, skip_format: str = "{name}: no mirror pass ({reason})"):  # fmt: skip
        self.order, self.names = order, names
        self._reasons = reasons or {}  # index -> reason, where the tests' arrays do not say
        self._lines = lines or {}  # index -> its pass lines (drawn reflectors)
        self._tests = tests  # (indices, behind, outside) of the frame's tests, or None
        self._skip_format = skip_format

    @property
    def skipped(self) -> dict[int, str]:
        reasons = {}
        if self._tests is not None:
            indices, behind, outside = self._tests
            for index, back, out in zip(indices.tolist(), behind.tolist(), outside.tolist(), strict=True):
                if back or out:
                    reasons[index] = "seen from behind" if back else "outside the view"
        reasons.update(self._reasons)
        return {index: reasons[index] for index in self.order if index in reasons and index not in self._lines}

    @property
    def report(self) -> list[str]:
        skipped = self.skipped
        lines = []
        for index in self.order:
            if index in self._lines:
                lines += self._lines[index]
            elif index in skipped:
                lines.append(self._skip_format.format(name=self.names[index], reason=skipped[index]))
        return lines


def sub_rect_projection(rect, size) -> np.ndarray:
    """Clip-space transform that maps the pixel rectangle ``rect`` (x, y, width, height) of a
    ``size`` buffer onto the whole clip square: its frustum is the scissored pass's (culling)."""
    x, y, w, h = rect
    width, height = size
    centre = ((x + w / 2.0) / width * 2.0 - 1.0, (y + h / 2.0) / height * 2.0 - 1.0)
    half = (w / width, h / height)
    m = np.eye(4)
    m[0, 0], m[0, 3] = 1.0 / half[0], -centre[0] / half[0]
    m[1, 1], m[1, 3] = 1.0 / half[1], -centre[1] / half[1]
    return m


def buffer_size(frame_size, scale: float) -> tuple[int, int]:
    width, height = frame_size
    return max(1, round(width * scale)), max(1, round(height * scale))


HIDDEN = "hidden behind other objects"
SCISSOR_NOTE = ", scissored to"  # how a report line says its pass was scissored
SHARED_NOTE = "shared with"  # how a report line says its reflector reads another's pass (its plane's)


def union_rect(rects: list) -> tuple[int, int, int, int] | None:
    """The smallest pixel rectangle (x, y, width, height) holding every one of ``rects``; None
    (the whole buffer) if any of them is None."""
    if not rects or any(rect is None for rect in rects):
        return None
    x0 = min(rect[0] for rect in rects)
    y0 = min(rect[1] for rect in rects)
    x1 = max(rect[0] + rect[2] for rect in rects)
    y1 = max(rect[1] + rect[3] for rect in rects)
    return x0, y0, x1 - x0, y1 - y0


def unscissored(report: list[str]) -> list[str]:
    """The report's lines without their scissor notes (which passes were drawn, at what size)."""
    return [line.split(SCISSOR_NOTE)[0] for line in report]


class MirrorPasses:
    """Draws through ``drawer`` (viewer/object_drawer.py ObjectDrawer: its environment,
    background, draw loop and the reflectors' occlusion test); ``probes`` (viewer/cube_probes.py
    CubeProbes) restores the evicted cube maps a pass will read before it binds its buffers."""

    def __init__(self, ctx: moderngl.Context, drawer, probes=None, mip_filter: str = DEFAULT_MIP_FILTER):
        self.ctx = ctx
        self.mip_filter = mip_filter  # of the radiance buffers' MIP chains (viewer/mip_chain.py)
        self.drawer = drawer
        self.probes = probes
        self.environment = drawer.environment
        self._spreads: dict = {}  # (reflector, N, normalize, pattern) -> materials.lobe_spread.lobe_spread
        self._footprints: dict = {}  # (reflector, N) -> {view-angle bound: finest lookup solid angle or None} or None
        self.targets: dict[tuple[int, str], MirrorTargets] = {}  # (index, 'mirror' | 'see-through')
        # Buffers of other sizes kept for reuse, most recent last: a plane's pass changes size with
        # its lobes' level (1/2, 1/4) and the window's render scale as the camera moves, and
        # allocating four textures and a framebuffer each time cost ~0.4 ms a frame in the
        # apartment (18 rooms, llvmpipe). SPARE_SIZES per (index, kind); the oldest is released.
        self._spare: dict[tuple[int, str], list[MirrorTargets]] = {}
        self._key = None
        self._active: dict = {}  # index -> {kind: targets} drawn for _key
        self.generation = 0  # bumped when what the buffers show changes (material edits)
        self.outcome = PassOutcome([], [])  # the last frame's passes: report, skipped
        self.drawn: list[int] = []  # reflectors that got their passes in the last frame
        self.occlusion_seconds = 0.0  # the last drawn frame's occlusion test (0: not run)
        self.scissored_pixels: dict[int, int] = {}  # reflector -> pixels the scissor saved, last frame
        self.coarse_levels: dict[int, int] = {}  # reflector -> times its buffers were halved, last frame
        self._layout_key = None
        self._layout = ReflectorLayout({})  # of _layout_key's reflectors, with their plane groups

    def invalidate(self) -> None:
        """Draw the buffers again on the next frame even if nothing changed (benchmarks)."""
        self._key = None

    def materials_changed(self) -> None:
        """What the buffers show and a reflector's lobes may have changed (a material edit)."""
        self.generation += 1
        self._spreads.clear()
        self._footprints.clear()

    @property
    def report(self) -> list[str]:
        """What the last frame's passes did, one line per pass or skipped reflector."""
        return self.outcome.report

    @property
    def skipped(self) -> dict[int, str]:
        """Reflector -> why it got no pass in the last frame."""
        return self.outcome.skipped

    def layout(self, reflectors: dict, share_planes: bool = True) -> ReflectorLayout:
        """The reflectors' arrays and the groups that share a pass (scenes/planar_mirror.py
        coplanar_groups; each alone without ``share_planes``), made again only when the
        reflectors change."""
        from lobeview.scenes.planar_mirror import coplanar_groups

        key = (tuple(reflectors), tuple(map(id, reflectors.values())), share_planes)
        if key != self._layout_key:
            groups = None
            if share_planes:  # the scene diagonal the analysis found the reflectors flat against
                low, high = self.drawer.scene.bounds
                groups = coplanar_groups(reflectors, float(np.linalg.norm(high - low)))
            self._layout = ReflectorLayout(dict(sorted(reflectors.items())), groups)
            self._layout_key = key
        return self._layout

    def lobe_spread(self, index: int, method: Method) -> tuple[float, float] | None:
        """How far the lobe-N lookups of reflector ``index`` reach (None: not lobe-N, unbounded)."""
        mat = self.drawer.material_of(index)
        if method.kind != "lobe" or per_pixel_lobes(mat):  # textures vary the lobes: no bound here
            return None
        key = (index, method.samples, method.normalize, method.pattern)
        if key not in self._spreads:
            lobes = specular_lobes(build_bsdf(mat.desc))
            self._spreads[key] = lobe_spread(lobes, method.samples, method.normalize) if lobes else None
        return self._spreads[key]

    def finest_footprint(self, index: int, method: Method, max_view_angle: float) -> float | None:
        """The smallest solid angle one lobe-N lookup of reflector ``index`` reads from views up to
        ``max_view_angle`` (radians; scenes/planar_mirror.py reflector_max_view_angle); None: not
        lobe-N, or lobes that textures vary (no bound here)."""
        mat = self.drawer.material_of(index)
        if method.kind != "lobe" or per_pixel_lobes(mat):
            return None
        key = (index, method.samples)
        if key not in self._footprints:
            # Every bound reflector_max_view_angle gives, in one numpy pass: computed one bound at
            # a time as the camera reached it, the walkthrough's frames spent milliseconds here.
            lobes = specular_lobes(build_bsdf(mat.desc))
            bounds = mirror_view_angle_bounds()
            finest = finest_sample_solid_angles(lobes, method.samples, bounds) if lobes else None
            self._footprints[key] = None
            if finest is not None:
                self._footprints[key] = {
                    round(float(b), 6): (float(f) if np.isfinite(f) else None)
                    for b, f in zip(bounds, finest, strict=True)
                }
        table = self._footprints[key]
        if table is None:
            return None
        bound = round(float(max_view_angle), 6)
        if bound not in table:  # a bound off the grid (not from reflector_max_view_angle)
            lobes = specular_lobes(build_bsdf(mat.desc))
            table[bound] = finest_sample_solid_angle(lobes, method.samples, max_view_angle)
        return table[bound]

    def render(
        self,
        camera: Camera,
        frame_size,
        reflectors: dict,
        names: list,
        scale: float,
        specular: bool,
        occlusion: bool = True,
        scissor_for: Method | None = None,
        lod_bias: float = 0.0,
        sizes_for: Method | None = None,
        share_planes: bool = True,
        camera_depth=None,
    ) -> dict:
        """The buffers of the reflectors that need them for ``camera`` (index -> {'mirror' and/or
        'see-through': targets}); reused while the camera, the size, the options and the materials
        stay the same (refinement passes). ``specular``: glossy objects seen in a mirror are shaded
        from their cube maps (lobe-3) instead of the thesis' diffuse-only mirror pass.
        ``occlusion``: a reflector that opaque objects hide at every pixel centre gets no pass.
        ``scissor_for``: the frame's method; each pass is scissored to the region that its
        reflectors' lookups in that method (or their override) can read, with the lookups'
        ``lod_bias`` (lobe_spread, scenes/planar_mirror.py mirror_scissor; None: every pass whole).
        ``sizes_for``: the frame's method; each pass's buffers are halved as often as its
        reflectors' lookups in it allow (finest_footprint, scenes/planar_mirror.py
        mirror_buffer_levels; None: full size). Both are found for the reflectors that get a pass
        only. ``share_planes``: reflectors in one plane
        share its passes (scenes/planar_mirror.py coplanar_groups); False: a pass per reflector.
        ``camera_depth``: a framebuffer of ``frame_size`` holding the camera pass's depth pre-pass
        for ``camera``, which the occlusion test reads instead of drawing its own (None: it does)."""
        from lobeview.scenes.planar_mirror import (
            mirror_buffer_levels,
            mirror_camera,
            mirror_scissors,
            reflector_max_view_angles,
        )

        width, height = frame_size
        view_proj = camera.view_projection(width / height)
        key = (
            tuple(camera.position), tuple(camera.target), tuple(camera.up), camera.fov_y, camera.near, camera.far,
            tuple(frame_size), scale, specular, tuple(sorted(reflectors)), self.generation, occlusion,
            scissor_for, lod_bias, sizes_for, share_planes,
            tuple(sorted(self.drawer.object_methods.items())) if scissor_for or sizes_for else (),
        )  # fmt: skip
        if key == self._key:
            return self._active
        active, scissored, coarse = {}, {}, {}
        full_size = buffer_size(frame_size, scale)
        full_focal = full_size[1] / 2.0 / np.tan(np.radians(camera.fov_y) / 2.0)
        projection = perspective(camera.fov_y, width / height, camera.near, camera.far)
        layout = self.layout(reflectors, share_planes)
        behind, outside = layout.tests(camera, view_proj)
        candidates = layout.indices[~(behind | outside)].tolist()
        reasons = {}
        self.occlusion_seconds = 0.0
        if occlusion and candidates:
            t0 = time.perf_counter()
            # reading the queries waits for the GPU
            samples = self.drawer.visible_samples(view_proj, frame_size, candidates, camera_depth)
            self.occlusion_seconds = time.perf_counter() - t0
            reasons = {index: HIDDEN for index in candidates if samples[index] == 0}
        passing = [index for index in candidates if index not in reasons]
        # Only the groups with a member to draw are visited: the rest of the scene's reflectors
        # cost nothing here (their reasons are the tests' arrays, read when a report is asked for).
        lines: dict[int, list[str]] = {index: [] for index in passing}
        for order in sorted({layout.group_of[index] for index in passing}):
            group = layout.groups[order]
            drawn = [index for index in group if index in lines]
            # One pass for the group's plane: at the finest size any of its drawn members' lookups
            # need, scissored to the union of their regions, without any of its members (they lie
            # in the pass's oblique near plane: nothing of them is in front of it). The buffers
            # are the group's, kept under its first index whichever members are drawn.
            first, owner = drawn[0], group[0]
            spreads = [None] * len(drawn)
            if scissor_for is not None:
                spreads = [self.lobe_spread(i, self.drawer.object_method(i, scissor_for)) for i in drawn]
            level = 0
            if sizes_for is not None:
                angles = reflector_max_view_angles([reflectors[i] for i in drawn], camera.position)
                level = min(
                    mirror_buffer_levels(
                        self.finest_footprint(i, self.drawer.object_method(i, sizes_for), angle), full_focal, lod_bias
                    )
                    for i, angle in zip(drawn, angles, strict=True)
                )
            size = buffer_size(frame_size, scale / 2.0**level)
            buffers = {}
            for kind in reflectors[owner].passes:
                targets = self._targets_of((owner, kind), size)
                buffer_camera = mirror_camera(
                    camera.view(), projection, reflectors[owner], size, see_through=kind != "mirror"
                )
                rect = union_rect(
                    mirror_scissors([reflectors[index] for index in drawn], buffer_camera, spreads, lod_bias)
                )
                if rect is not None and rect[2] * rect[3] >= size[0] * size[1]:
                    rect = None  # the members' regions cover the whole buffer
                cull_view_projection = None
                if rect is not None:
                    cull_view_projection = sub_rect_projection(rect, size) @ buffer_camera.view_projection
                if self.probes is not None:
                    self.probes.restore(
                        buffer_camera.view_projection if cull_view_projection is None else cull_view_projection,
                        frozenset(group),
                    )
                begin_pass(self.ctx, targets.fbo, size)
                self.drawer.draw_background(self.environment, buffer_camera.plain_view_projection)
                if rect is not None:  # the scene only where the reflectors' lookups read
                    self.ctx.scissor = rect
                self.drawer.draw(
                    buffer_camera.view_projection, buffer_camera.position, MIRROR_BOUNCE_METHOD, specular,
                    frozenset(group), pass_kind="mirror", cull_view_projection=cull_view_projection,
                )  # fmt: skip
                self.ctx.scissor = None
                build_mip_chain(self.ctx, targets.radiance, self.mip_filter, allocated=True)
                targets.camera = buffer_camera
                buffers[kind] = targets
                pixels = size[0] * size[1] if rect is None else rect[2] * rect[3]
                scissored[first] = scissored.get(first, 0) + size[0] * size[1] - pixels
                where = "" if rect is None else f"{SCISSOR_NOTE} {rect[2]}x{rect[3]} at ({rect[0]}, {rect[1]})"
                lines[first].append(f"{names[first]}: {kind} pass {size[0]}x{size[1]}{where}")
                for index in drawn[1:]:
                    lines[index].append(
                        f"{names[index]}: {kind} pass {size[0]}x{size[1]} ({SHARED_NOTE} {names[first]})"
                    )
            for index in drawn:
                active[index] = buffers
                coarse[index] = level
        self.ctx.viewport = (0, 0, width, height)
        self._key, self._active = key, active
        self.outcome = PassOutcome(list(reflectors), names, reasons, lines, (layout.indices, behind, outside))
        self.drawn = list(active)
        self.scissored_pixels = scissored  # reflector -> buffer pixels its passes did not shade
        self.coarse_levels = coarse
        return active

    @property
    def drawn_pixels(self) -> int:
        """Buffer pixels of the last frame's passes (each at its own size, scissor not counted)."""
        return sum(t.size[0] * t.size[1] for t in self._drawn_targets())

    @property
    def drawn_passes(self) -> int:
        """Mirror and see-through passes of the last frame (a pass its plane's reflectors share
        counted once)."""
        return len(self._drawn_targets())

    def _drawn_targets(self) -> list:
        if not self.drawn:
            return []
        unique = {id(t): t for kinds in self._active.values() for t in kinds.values()}
        return list(unique.values())

    def skip_all(self, reflectors, names: list, reason: str) -> None:
        """No pass for any reflector this frame (the prefiltered method reads cube maps); the
        next render draws the buffers again rather than trusting ones kept from before."""
        self.outcome = PassOutcome(
            list(reflectors), names, dict.fromkeys(reflectors, reason), None, None, "{name}: {reason}"
        )
        self.drawn = []
        self.scissored_pixels = {}
        self._key = None

    def bind(self, program, reflector, buffers: dict, eye, dummy, previous_plane_states: list) -> None:
        """The reflector's buffers (``dummy`` for a kind it does not have, flagged off in
        u_mirror_sides), its plane's normal on the camera's side and the previous pass's
        plane-state targets (averaged tangent planes)."""
        set_uniform(program, "u_mirror_front", mirror_front(reflector, eye))
        set_uniform(program, "u_mirror_sides", int("mirror" in buffers) | 2 * int("see-through" in buffers))
        for kind, prefix in BUFFER_PREFIXES.items():
            targets = buffers.get(kind)
            textures = (targets.radiance, targets.position, targets.normal) if targets else (dummy,) * 3
            for name, tex in zip(("radiance", "position", "normal"), textures, strict=True):
                bind_sampler(program, f"{prefix}_{name}", tex)
            if targets is None:
                continue
            for suffix, value in targets.camera_uniforms().items():
                set_uniform(program, prefix + suffix, value)
        if has_uniform(program, "u_plane_point_state"):
            # Points (mirror, see-through), then normals: the order of the state attachments.
            for k, tex in enumerate(previous_plane_states):
                bind_sampler(program, ("u_plane_point_state", "u_plane_normal_state")[k // 2], tex, index=k % 2)
            for name in ("u_plane_point_state", "u_plane_normal_state"):
                set_uniform(program, name, list(TEXTURE_UNITS[name]))

    def _targets_of(self, key: tuple[int, str], size: tuple[int, int]) -> MirrorTargets:
        """The buffers of ``key`` at ``size``: the current ones, a spare of that size, or new; the
        current ones of another size become a spare."""
        current = self.targets.get(key)
        if current is not None and current.size == size:
            return current
        spare = self._spare.setdefault(key, [])
        if current is not None:
            spare.append(current)
        reuse = next((t for t in spare if t.size == size), None)
        if reuse is not None:
            spare.remove(reuse)
        while len(spare) > SPARE_SIZES:
            spare.pop(0).release()
        self.targets[key] = reuse if reuse is not None else MirrorTargets(self.ctx, size)
        return self.targets[key]

    def release(self) -> None:
        for targets in [*self.targets.values(), *(t for spare in self._spare.values() for t in spare)]:
            targets.release()
        self.targets.clear()
        self._spare.clear()
