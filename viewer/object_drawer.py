"""The scene's objects on the GPU and the loop that draws them (issue 38): vertex and index
buffers, vertex arrays, the shader variant of each object's method, frustum culling, draw order
(glTF alpha modes), the depth pre-pass and the reflectors' occlusion test. Every pass draws
through it: the camera pass, the mirror passes (viewer/mirror_pass.py) and the cube-map faces
(viewer/cube_bake.py); the shading binder (viewer/scene_shading.py) sets what each draw reads."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import moderngl
import numpy as np

from lobeview.core.methods import Method
from lobeview.materials.fitted_pattern import may_read_fitted
from lobeview.scenes.scene import Scene

from .camera import box_corners, outside_frustum_boxes
from .cube_arrays import direct_gl
from .cubemap import BLUR_STACK_BUILDS, RadianceCube
from .interface import DrawRecorder, method_defines, set_uniform, uses_blur_stack
from .lobe_batches import BATCHED_METHOD_KINDS, LobeBatches
from .material_gpu import PackedMaterial
from .mirror_pass import mirror_front
from .object_batches import ObjectBatches, SceneGeometry
from .occlusion import OcclusionTest
from .render_base import draw_environment
from .scene_shading import SceneShading, per_pixel_lobes
from .settings import RenderSettings


@dataclass
class PassCounts:
    drawn: int = 0
    culled: int = 0


class DrawCounts:
    """Objects drawn and culled (frustum) per kind of pass: 'camera' and 'mirror' for the last
    frame (new_frame resets them), 'cube map' since start-up (bake and refreshes)."""

    PER_FRAME = ("camera", "mirror", "depth pre-pass")

    def __init__(self):
        self.passes: dict[str, PassCounts] = {}

    def of(self, pass_kind: str) -> PassCounts:
        return self.passes.setdefault(pass_kind, PassCounts())

    def new_frame(self) -> None:
        for kind in self.PER_FRAME:
            self.passes[kind] = PassCounts()

    def report(self) -> list[str]:
        labels = {"camera": "camera pass", "mirror": "mirror passes", "cube map": "cube-map faces since start"}
        return [
            f"{labels.get(kind, kind)}: {c.drawn} object draws, {c.culled} culled (outside the frustum)"
            for kind, c in self.passes.items()
            if c.drawn or c.culled
        ]


@dataclass
class DrawCalls:
    """Draw calls made since start-up (a bench takes differences): per-object draws, multi-draws
    and the compute passes that build their commands (viewer/object_batches.py)."""

    single: int = 0
    multi: int = 0
    culls: int = 0

    def total(self) -> tuple[int, int, int]:
        return self.single, self.multi, self.culls


#: cube maps and probe owners assigned to any GpuObject since start-up (what the multi-draws know
#: of them is made again when this changes)
CUBE_ASSIGNMENTS = [0]


class GpuObject:
    """An object as the drawer keeps it: its index range in the scene's geometry buffers
    (viewer/object_batches.py SceneGeometry), material, bounds and cube map."""

    @property
    def cube(self) -> RadianceCube | None:
        return self._cube

    @cube.setter
    def cube(self, cube: RadianceCube | None) -> None:
        self._cube = cube
        CUBE_ASSIGNMENTS[0] += 1

    @property
    def probe_owner(self) -> int:
        return self._probe_owner

    @probe_owner.setter
    def probe_owner(self, owner: int) -> None:
        self._probe_owner = owner
        CUBE_ASSIGNMENTS[0] += 1

    def __init__(self, obj, material: PackedMaterial, index: int, first_index: int, index_count: int):
        m = obj.mesh
        self.first_index = int(first_index)
        self.index_count = int(index_count)
        self.material = material
        self.index = index
        self.name = obj.name
        lo, hi = m.positions.min(axis=0), m.positions.max(axis=0)
        self.centre = (lo + hi) / 2.0
        self.corners = box_corners(lo, hi)  # world space (meshes are stored transformed): frustum culling
        self.box = (lo, hi)
        self._cube: RadianceCube | None = None
        # Shared probes (scenes/probe_groups.py): the object whose cube map this one reads (itself
        # unless it shares a group's), and where its own cube map is rendered from and without whom.
        self._probe_owner = index
        self.probe_centre = self.centre
        self.probe_exclude = frozenset((index,))

    def release(self):
        if self.cube is not None:
            self.cube.release()


class ObjectDrawer:
    """Draws the scene's objects. ``settings``: the renderer's RenderSettings (frustum culling,
    plane averaging), replaced by SceneRenderer.configure; ``analysis``: what each object needs
    (scenes/analysis.py), replaced after a material edit; ``residency`` (viewer/cube_bake.py
    CubeResidency) hears of every cube map a draw reads; ``mirror_passes`` binds a reflector's
    buffers (set once the mirror passes exist: they draw through this drawer)."""

    def __init__(
        self,
        ctx: moderngl.Context,
        scene: Scene,
        materials: list[PackedMaterial],
        shading: SceneShading,
        environment,
        frame,
        settings: RenderSettings,
        analysis,
    ):
        self.ctx = ctx
        self.scene = scene
        self.shading = shading
        self.programs = shading.programs
        self.environment = environment  # bound where an object has no cube map (unread there)
        self.frame = frame
        self.settings = settings
        self.analysis = analysis
        self.geometry = SceneGeometry(ctx, scene.objects)
        self.objects = [
            GpuObject(obj, materials[i], i, self.geometry.first_index[i], self.geometry.index_count[i])
            for i, obj in enumerate(scene.objects)
        ]
        self.object_corners = np.array([obj.corners for obj in self.objects]).reshape(len(self.objects), 8, 3)
        self.object_boxes = np.array([obj.box for obj in self.objects], dtype=np.float64).reshape(-1, 2, 3)
        self.object_methods: dict[int, Method] = {}  # the panel's per-object real-time methods
        self.draw_counts = DrawCounts()
        self.draw_calls = DrawCalls()
        self.occlusion = OcclusionTest(ctx, self.programs, self.geometry, self.draw_calls, self.object_boxes)
        self.batches = ObjectBatches(ctx, self.programs, self.geometry, self.object_boxes)
        self.lobe_batches: LobeBatches | None = None  # made on the first lobe-shaded multi-draw
        self.lobe_batches_unavailable = ""  # why lobe-shaded objects are drawn one by one, if so
        self.residency = None
        self.mirror_passes = None
        self._vaos: dict = {}
        self._masks_key = self._order_key = self._owners_key = None  # what _batch_masks, draw_order, owner_cubes cached
        self._opaque_cache: dict = {}  # occluders only -> (analysis, material generation, opaque_objects)

    def material_of(self, index: int):
        """The scene material of object ``index``."""
        return self.scene.materials[self.scene.objects[index].material]

    def program(
        self,
        method: Method,
        specular: bool,
        parallax: bool = False,
        mirror: bool = False,
        rational: bool = False,
        records: bool = False,
        measured: bool = False,
    ):
        defines = {**method_defines(method), "SPECULAR": True} if specular else {"METHOD_LOBE": True}
        defines["HAS_RATIONAL"] = rational  # a Rational BRDF's functions (shaders/rational.glsl)
        defines["HAS_MEASURED"] = measured  # a measured BRDF's table (shaders/measured.glsl)
        if records:  # per-object uniforms from the records of a multi-draw (viewer/object_records.py)
            defines["OBJECT_RECORDS"] = True
        if specular and mirror:
            # Incident light from the mirror buffer; the cube's importance map does not apply, so
            # the reference samples the BSDF only (still unbiased for what the buffer holds).
            defines.update(MIRROR=True, ENV_SAMPLING=False, PLANE_AVERAGE=self.averages_planes(method))
        elif specular and parallax:
            # The cube's importance map samples directions seen from its centre, which the proxy
            # remaps: the reference then samples the BSDF only (still unbiased).
            defines.update(PARALLAX=True, ENV_SAMPLING=False)
        # lobe-N+norm+fit's coarse reads from the object's cube's blur stack (multi-draws: from the
        # group's array of stacks; not the mirror buffers)
        defines["BLUR_STACK"] = specular and not mirror and uses_blur_stack(method)
        return self.programs.program("scene.vert", "scene.frag", defines)

    def object_method(self, index: int, method: Method) -> Method:
        """The method object ``index`` is shaded with: the panel's per-object override of a
        real-time method, never of the reference."""
        return method if method.kind == "reference" else self.object_methods.get(index, method)

    def averages_planes(self, method: Method) -> bool:
        """Whether a reflector shaded with ``method`` averages its tangent planes (refinement)."""
        return self.settings.mirror_plane_average and method.kind in ("mc", "reference")

    def opaque_objects(self, occluders_only: bool) -> list:
        """(GPU object, single-sided) for the objects the camera pass draws opaquely (no alphaMode
        MASK or BLEND: their discarded or blended pixels hide nothing). ``occluders_only``: also
        without reflectors and transmissive objects (the reflectors' occlusion test:
        viewer/occlusion.py says why)."""
        cached = self._opaque_cache.get(occluders_only)
        if cached is not None and cached[0] is self.analysis and cached[1] == self.shading.record_generation:
            return cached[2]
        reflectors = self.analysis.reflectors
        found = []
        for obj in self.objects:
            mat = self.material_of(obj.index)
            if mat.alpha_mode.upper() != "OPAQUE":
                continue
            if occluders_only and (obj.index in reflectors or self.analysis.objects[obj.index].transmission_lobes):
                continue
            found.append((obj, not mat.double_sided))
        self._opaque_cache[occluders_only] = (self.analysis, self.shading.record_generation, found)
        return found

    def visible_samples(self, view_proj, size, indices: list, depth_fbo=None) -> dict[int, int]:
        """Pixels of a frame of ``size`` in which each reflector in ``indices`` is not hidden by an
        opaque object (viewer/occlusion.py); ``depth_fbo``: the camera pass's depth pre-pass,
        already drawn, to test against."""
        batches = self.batches if self.settings.indirect_draws else None
        queried = {index: self.objects[index] for index in indices}
        return self.occlusion.visible_samples(view_proj, size, self.opaque_objects(True), queried, batches, depth_fbo)

    def draw_depth(self, view_proj) -> tuple[int, int]:
        """The opaque objects' depth (the camera pass's pre-pass): (drawn, culled)."""
        batches = self.batches if self.settings.indirect_draws else None
        return self.occlusion.draw_depth(view_proj, self.opaque_objects(False), batches)

    def draw_background(self, cube, view_proj) -> None:
        """The environment ``cube`` behind everything (viewer/render_base.py draw_environment)."""
        draw_environment(self.ctx, self.programs, self._vaos, cube, view_proj)

    def _vao(self, program):
        """The vertex array of every object for ``program`` (one per program)."""
        key = ("objects", id(program))
        if key not in self._vaos:
            self._vaos[key] = self.geometry.vertex_array(self.ctx, program)
        return self._vaos[key]

    def draw(
        self,
        view_proj,
        eye,
        method: Method,
        specular: bool,
        exclude=None,
        lod_bias=None,
        sample_offset=0,
        seed=0,
        mirrors: dict | None = None,
        cull: bool = False,
        pass_kind: str = "camera",
        cull_view_projection=None,
    ):
        """Every object with its material whose bounding box reaches the frustum of
        ``view_proj`` (``RenderSettings.frustum_culling``; counted in ``draw_counts[pass_kind]``).
        ``cull``: skip the back faces of single-sided materials (the camera pass only: mirror
        and cube-map passes flip the winding). ``cull_view_projection``: the frustum to cull against when it is
        smaller than ``view_proj``'s (a scissored mirror pass)."""
        self.ctx.enable(moderngl.DEPTH_TEST)
        cull_view_projection = view_proj if cull_view_projection is None else cull_view_projection
        culled = None
        if self.settings.frustum_culling:
            culled = outside_frustum_boxes(self.object_boxes[:, 0], self.object_boxes[:, 1], cull_view_projection)
        mirrors = mirrors or {}
        counts = self.draw_counts.of(pass_kind)
        view_proj_values = tuple(view_proj.T.astype("f4").ravel())
        eye_values = tuple(float(x) for x in eye)
        excluded = exclude if isinstance(exclude, frozenset | set | tuple) else (exclude,)
        batched = None
        if self.settings.indirect_draws and self.objects:
            batched = self._draw_batched(
                view_proj_values, eye_values, cull_view_projection, method, specular, excluded, lod_bias,
                sample_offset, seed, mirrors, cull, culled, counts,
            )  # fmt: skip
            if specular and method.kind in BATCHED_METHOD_KINDS:
                batched = batched | self._draw_lobe_batched(
                    view_proj_values, eye_values, cull_view_projection, method, excluded, lod_bias,
                    sample_offset, seed, mirrors, cull, culled, counts,
                )  # fmt: skip
                if mirrors:
                    batched = batched | self._draw_mirror_batched(
                        view_proj_values, eye_values, eye, cull_view_projection, method, excluded, lod_bias,
                        sample_offset, seed, mirrors, cull, culled, counts,
                    )  # fmt: skip
        for obj, blended in self.draw_order(eye, batched):  # what the multi-draw did not draw
            if obj.index in excluded or (not specular and self.analysis.objects[obj.index].transmission_lobes):
                # Thin transmissive panes are see-through in the diffuse pass that fills cube
                # maps (as in the baker): a black pane would hide what lies behind it.
                continue
            if culled is not None and culled[obj.index]:
                counts.culled += 1
                continue
            counts.drawn += 1
            mat = self.material_of(obj.index)
            if blended:  # alphaMode BLEND: composited over what is drawn, depth tested, not written
                self.ctx.enable(moderngl.BLEND)
                self.ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
                self.ctx.fbo.depth_mask = False
            single_sided = cull and not mat.double_sided
            if single_sided:
                self.ctx.enable(moderngl.CULL_FACE)  # glTF doubleSided false: back faces are not drawn
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            # A reflector drawn from its mirror buffer needs no cube map (on demand: it may have none).
            mirror = mirrors.get(obj.index) if specular else None
            own_cube = self.objects[obj.probe_owner].cube  # its own, or its group's shared probe
            use_specular = specular and (own_cube is not None or mirror is not None)
            if use_specular and own_cube is not None and pass_kind != "cube map":
                self.residency.touch(obj.probe_owner)
            # Per-object real-time method (the panel's override); the reference ignores it.
            obj_method = self.object_method(obj.index, method)
            proxy = self.scene.objects[obj.index].reflection_proxy if use_specular and mirror is None else None
            program = self.program(
                obj_method, use_specular, proxy is not None, mirror is not None, obj.material.has_rational,
                measured=obj.material.has_measured,
            )  # fmt: skip
            set_uniform(program, "u_view_projection", view_proj_values)
            set_uniform(program, "u_camera_position", eye_values)
            self.shading.set_pass_state(program, obj_method, lod_bias, seed)
            set_uniform(program, "u_sample_offset", int(sample_offset))
            self.shading.object_state(
                program, obj, obj_method, mirror is not None, proxy, self.objects[obj.probe_owner].probe_centre
            )
            if use_specular:
                self.shading.bind_cube(program, self._cube_to_bind(obj), obj_method, obj.material, per_pixel_lobes(mat))
                if mirror is not None:
                    self.mirror_passes.bind(
                        program, self.analysis.objects[obj.index].reflector, mirror, eye, self.shading.white,
                        self.frame.previous_plane_states(),
                    )  # fmt: skip
            self._vao(program).render(moderngl.TRIANGLES, vertices=obj.index_count, first=obj.first_index)
            self.draw_calls.single += 1
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        self.ctx.fbo.depth_mask = True

    def _batch_masks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(batchable, transmissive, single-sided) per object: which objects the multi-draw may
        draw (opaque or masked, no Rational or measured BRDF: their buffers are bound per object),
        which a diffuse pass leaves out, which lose their back faces in the camera pass."""
        key = (id(self.analysis), self.shading.record_generation)
        if self._masks_key != key:
            n = len(self.objects)
            mats = [self.material_of(i) for i in range(n)]
            batchable = np.array(
                [
                    m.alpha_mode.upper() != "BLEND" and not o.material.draws_alone
                    for m, o in zip(mats, self.objects, strict=True)
                ],
                dtype=bool,
            )
            transmissive = np.array([bool(self.analysis.objects[i].transmission_lobes) for i in range(n)], dtype=bool)
            single_sided = np.array([not m.double_sided for m in mats], dtype=bool)
            self._masks, self._masks_key = (batchable, transmissive, single_sided), key
        return self._masks

    def owner_cubes(self) -> tuple[np.ndarray, np.ndarray]:
        """(probe owner, whether its cube map exists) per object, made again only after a cube
        map or an owner was assigned (a Python loop over the objects, not one per pass)."""
        if self._owners_key != CUBE_ASSIGNMENTS[0]:
            n = len(self.objects)
            owners = np.fromiter((obj.probe_owner for obj in self.objects), dtype=np.int64, count=n)
            has_cube = np.fromiter((obj.cube is not None for obj in self.objects), dtype=bool, count=n)
            self._owner_cubes, self._owners_key = (owners, has_cube), CUBE_ASSIGNMENTS[0]
        return self._owner_cubes

    def batch_program(self):
        """The diffuse scene program that reads per-object records (viewer/object_records.py)."""
        return self.programs.program(
            "scene.vert", "scene.frag", {"METHOD_LOBE": True, "HAS_RATIONAL": False, "OBJECT_RECORDS": True}
        )

    def _draw_batched(
        self, view_proj_values, eye_values, cull_view_projection, method, specular, excluded, lod_bias,
        sample_offset, seed, mirrors, cull, culled, counts,
    ) -> np.ndarray:  # fmt: skip
        """Draw this pass's diffuse-shaded objects by multi-draws (viewer/object_batches.py) and
        count them; returns which objects were handled here (the rest go through the loop)."""
        batchable, transmissive, single_sided = self._batch_masks()
        shading = self.shading
        key = (shading.record_generation, shading.textures.evictions, shading.material_textures.evictions)
        record_method = Method.parse("lobe-3")  # diffuse programs read no method state

        def record_state(recorder, obj):
            shading.set_object_state(recorder, obj, record_method, False, None, obj.probe_centre)

        self.batches.prepare(key, self.objects, batchable, record_state, single_sided)
        mask = batchable.copy()
        if specular:  # objects with a cube map or a mirror buffer are shaded with their lobes
            owners, has_cube = self.owner_cubes()
            mask &= ~has_cube[owners]
        else:
            mask &= ~transmissive
        visible = self._pass_objects(mask, mirrors, excluded, culled, counts)
        if not visible.any():
            return mask
        self.batches.cull(mask, cull_view_projection, self.settings.frustum_culling)
        self.draw_calls.culls += 1
        program = self.batch_program()
        set_uniform(program, "u_view_projection", view_proj_values)
        set_uniform(program, "u_camera_position", eye_values)
        shading.set_pass_state(program, method, lod_bias, seed)
        set_uniform(program, "u_sample_offset", int(sample_offset))
        vao = self._vao(program)
        for group in self.batches.groups:
            if not visible[group.objects].any():
                continue
            if cull and group.single_sided:
                self.ctx.enable(moderngl.CULL_FACE)  # glTF doubleSided false: back faces are not drawn
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            rep = group.representative
            shading.object_state(program, rep, method, False, None, rep.probe_centre)  # the group's textures
            self.batches.draw_group(program, vao, group)
            self.draw_calls.multi += 1
        return mask

    def _pass_objects(self, mask: np.ndarray, mirrors, excluded, culled, counts) -> np.ndarray:
        """Clear from ``mask`` (in place) the objects this pass shades from mirror buffers or
        leaves out; count the rest as drawn or culled; returns the drawn ones."""
        n = len(mask)
        if mirrors:
            mask[np.fromiter(mirrors, dtype=np.int64)] = False
        for index in excluded:
            if index is not None and 0 <= int(index) < n:
                mask[int(index)] = False
        visible = mask if culled is None else mask & ~culled
        drawn = int(np.count_nonzero(visible))
        counts.drawn += drawn
        counts.culled += int(np.count_nonzero(mask)) - drawn
        return visible

    def _lobe_batches(self) -> LobeBatches | None:
        """The lobe-shaded objects' multi-draws (viewer/lobe_batches.py), or None where they do
        not apply: a cube-map memory budget, or no direct GL calls (warned once)."""
        if self.residency is not None and self.residency.budget is not None:
            return None
        if self.lobe_batches is None and not self.lobe_batches_unavailable:
            gl, why = direct_gl(self.ctx)
            if gl is None:
                self._stop_lobe_batches(why)
                return None
            self.lobe_batches = LobeBatches(self.ctx, self.batches, gl)
        return self.lobe_batches

    def _stop_lobe_batches(self, why: str) -> None:
        """Draw lobe-shaded objects one by one from now on, and say why (once)."""
        if self.lobe_batches is not None:
            self.lobe_batches.release()
            self.lobe_batches = None
        self.lobe_batches_unavailable = why
        warnings.warn(
            f"lobe-shaded objects are drawn one by one (the same frames, more draw calls): {why}", stacklevel=3
        )

    def _cube_to_bind(self, obj):
        """The cube map ``obj``'s specular draw binds: its probe owner's, or the sky's for a
        reflector without one (drawn from its mirror buffers, whose MIRROR program never reads it)."""
        own = self.objects[obj.probe_owner].cube
        return own if own is not None else self.environment

    def _lobe_records_key(self) -> tuple:
        """What every lobe-shaded record depends on: material edits, texture evictions, the analysis."""
        shading = self.shading
        return (
            shading.record_generation,
            shading.textures.evictions,
            shading.material_textures.evictions,
            id(self.analysis),
        )

    def _drop_overridden(self, members: np.ndarray, method: Method) -> None:
        """Clear from ``members`` (in place) the objects the panel shades with another method."""
        for index, override in self.object_methods.items():
            if override != method:
                members[index] = False

    def _draw_lobe_batched(
        self, view_proj_values, eye_values, cull_view_projection, method, excluded, lod_bias, sample_offset, seed,
        mirrors, cull, culled, counts,
    ) -> np.ndarray:  # fmt: skip
        """Draw this pass's lobe-shaded objects (their own cube map, methods lobe-N and fis-N) by
        multi-draws (viewer/lobe_batches.py); returns which objects were handled here."""
        n = len(self.objects)
        handled = np.zeros(n, dtype=bool)
        batches = self._lobe_batches()
        if batches is None:
            return handled
        batchable, _, single_sided = self._batch_masks()
        owners, has_cube = self.owner_cubes()
        members = batchable & has_cube[owners]
        self._drop_overridden(members, method)
        shading = self.shading
        base_key = self._lobe_records_key()
        stacks = uses_blur_stack(method)
        # lobe-N+norm+fit: a stack built since (a budgeted frame left it out) changes the records
        key = (base_key, CUBE_ASSIGNMENTS[0], members.tobytes(), owners.tobytes(), stacks and BLUR_STACK_BUILDS[0])

        def record_state(obj):
            proxy = self.scene.objects[obj.index].reflection_proxy
            owner = self.objects[obj.probe_owner]
            recorder = DrawRecorder(self.program(method, True, proxy is not None))
            shading.set_object_state(recorder, obj, method, False, proxy, owner.probe_centre)
            shading.bind_cube(recorder, owner.cube, method, obj.material, per_pixel_lobes(self.material_of(obj.index)))
            return recorder, proxy is not None

        def stack_of(obj):
            owner = self.objects[obj.probe_owner]
            per_pixel = per_pixel_lobes(self.material_of(obj.index))
            wants = may_read_fitted(obj.material.lobe_components, per_pixel)
            return (shading.budgeted_blur_stack(owner.cube) if wants else None), wants

        try:
            batch = batches.prepare(
                method, key, self.objects, members, record_state, single_sided, stack_of if stacks else None
            )
        except RuntimeError as exc:  # a GL error of the cube-map arrays: the per-object path still works
            self._stop_lobe_batches(str(exc))
            return handled
        enabled = members.copy()
        visible = self._pass_objects(enabled, mirrors, excluded, culled, counts)
        if not visible.any():
            return enabled
        batches.cull(batch, enabled, cull_view_projection, self.settings.frustum_culling)
        self.draw_calls.culls += 1
        pass_values = (view_proj_values, eye_values, lod_bias, sample_offset, seed)
        self._draw_lobe_groups(batches, batch, visible, method, pass_values, cull)
        return enabled

    def _draw_lobe_groups(self, batches, batch, visible, method, pass_values, cull, mirrors=None, eye=None) -> None:
        """One multi-draw per group of ``batch`` with an object in ``visible``: the pass's
        uniforms, the face culling and the group's textures (its representative's, as its own
        draw binds them; ``mirrors``: the reflectors' buffers, seen from ``eye``)."""
        view_proj_values, eye_values, lod_bias, sample_offset, seed = pass_values
        shading = self.shading
        passed = set()  # programs given this pass's state: a program keeps its uniforms between groups
        for group in batch.groups:
            if not visible[group.objects].any():
                continue
            program = self.program(method, True, group.parallax, mirrors is not None, records=True)
            if id(program) not in passed:  # the groups' own state below never sets these
                passed.add(id(program))
                set_uniform(program, "u_view_projection", view_proj_values)
                set_uniform(program, "u_camera_position", eye_values)
                shading.set_pass_state(program, method, lod_bias, seed)
                set_uniform(program, "u_sample_offset", int(sample_offset))
            if cull and group.single_sided:
                self.ctx.enable(moderngl.CULL_FACE)  # glTF doubleSided false: back faces are not drawn
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            rep = group.representative
            owner = self.objects[rep.probe_owner]
            proxy = self.scene.objects[rep.index].reflection_proxy if mirrors is None else None
            # The group's textures (its cube comes from the array: viewer/lobe_batches.py).
            shading.object_state(program, rep, method, mirrors is not None, proxy, owner.probe_centre)
            per_pixel = per_pixel_lobes(self.material_of(rep.index))
            shading.bind_cube(program, self._cube_to_bind(rep), method, rep.material, per_pixel)
            if mirrors is not None:  # the group's shared buffers and plane side (its share key)
                self.mirror_passes.bind(
                    program, self.analysis.objects[rep.index].reflector, mirrors[rep.index], eye, shading.white, []
                )  # fmt: skip
            batches.draw_group(batch, program, self._vao(program), group)
            self.draw_calls.multi += 1

    def _draw_mirror_batched(
        self, view_proj_values, eye_values, eye, cull_view_projection, method, excluded, lod_bias, sample_offset,
        seed, mirrors, cull, culled, counts,
    ) -> np.ndarray:  # fmt: skip
        """Draw the reflectors this pass shades from their mirror buffers (methods lobe-N and
        fis-N) by one multi-draw per shared plane pass and side (viewer/lobe_batches.py): the
        floors of an apartment share a few passes, and a draw each cost more Python than the
        rest of the camera pass together (issue 42). Returns which objects were handled here."""
        handled = np.zeros(len(self.objects), dtype=bool)
        batches = self._lobe_batches()
        if batches is None or self.averages_planes(method):  # plane states: per reflector
            return handled
        batchable, _, single_sided = self._batch_masks()
        # Members: every batchable reflector (those without buffers this pass join no drawn group,
        # so their records outlive a frame in which they are hidden); groups: the drawn ones, by the
        # pass they share (named by its first member) and the plane's side.
        members = np.zeros(len(self.objects), dtype=bool)
        members[list(self.analysis.reflectors)] = True
        members &= batchable
        self._drop_overridden(members, method)
        shares, first_of_pass = {}, {}
        for index in sorted(mirrors):
            if members[index] and index not in excluded:
                first = first_of_pass.setdefault(tuple(id(t) for t in mirrors[index].values()), index)
                shares[index] = (first, mirror_front(self.analysis.objects[index].reflector, eye))
                handled[index] = True
        if not handled.any():
            return handled
        shading = self.shading
        base_key = self._lobe_records_key()
        key = (base_key, CUBE_ASSIGNMENTS[0], members.tobytes())  # the shares regroup, records stay

        def record_state(obj):
            owner = self.objects[obj.probe_owner]
            recorder = DrawRecorder(self.program(method, True, mirror=True))
            shading.set_object_state(recorder, obj, method, True, None, owner.probe_centre)
            per_pixel = per_pixel_lobes(self.material_of(obj.index))
            shading.bind_cube(recorder, self._cube_to_bind(obj), method, obj.material, per_pixel)
            return recorder, False

        try:
            batch = batches.prepare(
                (method, "mirror"), key, self.objects, members, record_state, single_sided, mirror_shares=shares
            )
        except RuntimeError as exc:  # a GL error of the shared arrays: the per-object path still works
            self._stop_lobe_batches(str(exc))
            return np.zeros(len(self.objects), dtype=bool)
        visible = handled if culled is None else handled & ~culled
        drawn = int(np.count_nonzero(visible))
        counts.drawn += drawn
        counts.culled += int(np.count_nonzero(handled)) - drawn
        if drawn:
            batches.cull(batch, handled, cull_view_projection, self.settings.frustum_culling)
            self.draw_calls.culls += 1
            pass_values = (view_proj_values, eye_values, lod_bias, sample_offset, seed)
            self._draw_lobe_groups(batches, batch, visible, method, pass_values, cull, mirrors, eye)
        return handled

    def draw_order(self, eye, skip: np.ndarray | None = None) -> list:
        """(object, blended): opaque and masked objects first, then the alphaMode BLEND ones
        from back to front by the distance of their bounding-box centre (glTF 3.9.4); without
        the objects ``skip`` marks (those the multi-draw drew), chosen without a Python loop
        over the others."""
        key = self.shading.record_generation  # a material edit may change an alpha mode
        if self._order_key != key:
            modes = [self.material_of(i).alpha_mode for i in range(len(self.objects))]
            self._opaque = np.array([i for i, mode in enumerate(modes) if mode != "BLEND"], dtype=np.int64)
            self._blended = [self.objects[i] for i, mode in enumerate(modes) if mode == "BLEND"]
            self._order_key = key
        opaque = self._opaque if skip is None else self._opaque[~skip[self._opaque]]
        eye = np.asarray(eye, dtype=np.float64)
        blended = sorted(self._blended, key=lambda o: -float(np.linalg.norm(o.centre - eye)))
        return [(self.objects[i], False) for i in opaque] + [(o, True) for o in blended]

    def release(self) -> None:
        self.occlusion.release()
        self.batches.release()
        if self.lobe_batches is not None:
            self.lobe_batches.release()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        for obj in self.objects:
            obj.release()
        self.geometry.release()
