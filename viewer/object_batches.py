"""GPU-driven drawing of the scene's diffuse-shaded objects (issue 42, item 1, first part).

Every object's geometry lies in one vertex and one index buffer (:class:`SceneGeometry`), so an
object is a range of indices. The objects a pass shades with the diffuse scene program (no cube
map or mirror buffer read: walls, floors, everything in the diffuse cube-map bounce, the diffuse
objects of the mirror passes) are drawn by one ``glMultiDrawElementsIndirect`` per group of
objects that bind the same textures (lightmap, glTF maps and samplers) and the same face culling,
instead of one draw call each:

- the uniforms an object sets become its record in a storage buffer (viewer/object_records.py),
  made from the very bytes the per-object path sends, so the frames are the same;
- a compute pass (shaders/cull_commands.comp) writes each command's instance count: 1 where the
  pass enables the object (not excluded, not shaded another way this pass) and its bounding box
  reaches the frustum, 0 elsewhere. The CPU writes only the pass's enabled flags (one buffer of
  one integer per object, written when it changes).

Objects shaded with their lobes (cube map, mirror buffer), alphaMode BLEND (drawn back to front
after everything else) and Rational materials keep the per-object path
(viewer/object_drawer.py), as does everything with ``RenderSettings.indirect_draws`` off."""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from lobeview.scenes.self_visibility import object_visibility_cones

from .interface import DrawRecorder, bind_storage
from .object_records import OBJECT_RECORDS_BINDING, RECORD_UNIFORMS, pack_object_record

# Vertex layout of the scene's objects: position, normal, tangent (xyz, handedness), UV0, UV1,
# the visibility cone against the object itself (bent normal, cos of its half angle) and its
# horizon in 8 azimuth sectors (scenes/self_visibility.py).
VERTEX_FORMAT = "3f 3f 4f 2f 2f 4f 4f 4f"
VERTEX_ATTRIBUTES = (
    "in_position", "in_normal", "in_tangent", "in_uv0", "in_uv1", "in_visibility", "in_horizon0", "in_horizon1",
)  # fmt: skip
VERTEX_FLOATS = 26
POSITION_ONLY_FORMAT = f"3f {4 * (VERTEX_FLOATS - 3)}x"
COMMAND_WORDS = 5  # DrawElementsIndirectCommand: count, instanceCount, firstIndex, baseVertex, baseInstance
CULL_GROUP_SIZE = 64  # shaders/cull_commands.comp local_size_x
GL_COMMAND_BARRIER_BIT = 0x00000040  # indirect commands written by a shader are read after this
GL_SHADER_STORAGE_BARRIER_BIT = 0x00002000


class SceneGeometry:
    """The objects' vertices and indices in one buffer each. Indices are absolute (each object's
    offset by its first vertex), so every draw, per object or multi-draw, reads one vertex array
    per program: object ``i`` is ``index_count[i]`` indices from ``first_index[i]``."""

    def __init__(self, ctx: moderngl.Context, objects):
        vertices, indices = [], []
        self.first_index = np.zeros(len(objects), dtype=np.int64)
        self.index_count = np.zeros(len(objects), dtype=np.int64)
        base_vertex = first = 0
        for i, obj in enumerate(objects):
            m = obj.mesh
            uv1 = obj.uv1 if obj.uv1 is not None else np.zeros((len(m.positions), 2), np.float32)
            cones = object_visibility_cones(obj)
            vertices.append(
                np.concatenate([m.positions, m.normals, m.tangents, m.uvs, uv1, cones], axis=1).astype(np.float32)
            )
            object_indices = np.asarray(m.indices, dtype=np.int64).ravel() + base_vertex
            indices.append(object_indices)
            self.first_index[i], self.index_count[i] = first, object_indices.size
            base_vertex += len(m.positions)
            first += object_indices.size
        if base_vertex >= 2**32:
            raise ValueError(f"the scene has {base_vertex} vertices; 32-bit indices address at most 2^32")
        data = np.concatenate(vertices) if vertices else np.zeros((1, VERTEX_FLOATS), np.float32)
        index_data = np.concatenate(indices).astype(np.uint32) if indices else np.zeros(3, np.uint32)
        self.vertex_count = base_vertex
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(index_data).tobytes())
        # in_object of the multi-draw programs: a per-instance attribute read at baseInstance.
        self.object_slots = ctx.buffer(np.arange(max(len(objects), 1), dtype=np.uint32).tobytes())

    def vertex_array(self, ctx: moderngl.Context, program, position_only: bool = False) -> moderngl.VertexArray:
        """A vertex array of every object for ``program`` (the per-instance object index where
        the program reads it)."""
        if position_only:
            content = [(self.vbo, POSITION_ONLY_FORMAT, "in_position")]
        else:
            # An attribute a program does not read (the linker removes it: in_visibility where no
            # specular lobe is shaded) is skipped as padding.
            formats, names = [], []
            for part, name in zip(VERTEX_FORMAT.split(), VERTEX_ATTRIBUTES, strict=True):
                if program.get(name, None) is None:
                    formats.append(f"{4 * int(part[:-1])}x")
                else:
                    formats.append(part)
                    names.append(name)
            content = [(self.vbo, " ".join(formats), *names)]
        if program.get("in_object", None) is not None:
            content.append((self.object_slots, "1u/i", "in_object"))
        return ctx.vertex_array(program, content, self.ibo)

    def release(self) -> None:
        for buffer in (self.vbo, self.ibo, self.object_slots):
            buffer.release()


def binding_key(record, skip_units: tuple[int, ...] = ()) -> tuple:
    """What a recorded draw binds (textures, samplers, buffers and their units), as the key of
    the multi-draw group it joins; ``skip_units``: units left out (a lobe-shaded object's cube
    and albedo table, read from arrays instead)."""
    return tuple((id(bind.__self__), bind.__name__, target) for bind, target in record.uses if target not in skip_units)


def bound_texture(record, unit: int):
    """The texture a recorded draw binds to ``unit`` (None: nothing there)."""
    for bind, target in record.uses:
        if target == unit and isinstance(bind.__self__, moderngl.Texture):
            return bind.__self__
    return None


@dataclass
class DrawGroup:
    """Objects drawn by one multi-draw: the same texture bindings and face culling."""

    objects: np.ndarray  # object indices, in draw order (the commands' order)
    first_command: int
    single_sided: bool
    representative: object  # a GpuObject whose draw state binds the group's textures


class ObjectBatches:
    """The multi-draw of the diffuse-shaded objects (module docstring). ``geometry``: the
    drawer's SceneGeometry; ``boxes``: (n, 2, 3) world-space bounding boxes."""

    def __init__(self, ctx: moderngl.Context, programs, geometry: SceneGeometry, boxes: np.ndarray):
        self.ctx = ctx
        self.programs = programs
        self.geometry = geometry
        n = len(boxes)
        box_data = np.zeros((max(n, 1), 2, 4), dtype=np.float32)
        box_data[:n, :, :3] = boxes
        self.boxes = ctx.buffer(box_data.tobytes())
        self.enabled = ctx.buffer(reserve=4 * max(n, 1))
        self._enabled_bytes = b""
        self.commands = None
        self.records = None
        self.groups: list[DrawGroup] = []
        self._key = None  # what the records and groups were made from
        self.depth_commands = None  # every object, grouped by face culling (draw_depth)
        self.depth_command_count = 0
        self.depth_groups: list = []
        self._depth_key = None

    def prepare(self, key, objects: list, batchable: np.ndarray, record_state, single_sided: np.ndarray) -> None:
        """Make the records, groups and commands again when ``key`` (the shading's record
        generation and texture evictions) changed. ``record_state(recorder, obj)`` sets an
        object's draw state as the per-object path does; ``batchable``: the objects the
        multi-draw may draw at all (opaque, no Rational BRDF)."""
        if key == self._key:
            return
        plain = self.programs.program("scene.vert", "scene.frag", {"METHOD_LOBE": True, "HAS_RATIONAL": False})
        records, grouped = [], {}
        for obj in objects:
            recorder = DrawRecorder(plain)
            record_state(recorder, obj)
            record = recorder.record()
            records.append(pack_object_record({name: data for name, (_, data) in record.uniforms}))
            if batchable[obj.index]:
                grouped.setdefault((binding_key(record), bool(single_sided[obj.index])), []).append(obj)
        self.release_buffers()
        self.records = self.ctx.buffer(b"".join(records) if records else bytes(16))
        self.groups, first = [], 0
        for (_, one_sided), members in grouped.items():
            indices = np.array([obj.index for obj in members], dtype=np.int64)
            self.groups.append(DrawGroup(indices, first, one_sided, members[0]))
            first += len(indices)
        ordered = [group.objects for group in self.groups]
        self.commands, self.command_count = self.command_buffer(np.concatenate(ordered) if ordered else [])
        self._key = key

    def command_buffer(self, objects, instances: int = 0) -> tuple[moderngl.Buffer, int]:
        """(buffer, count): one draw command per object of ``objects``, in that order, its
        instance count ``instances`` (0: until a cull writes it), its baseInstance the object's
        index."""
        objects = np.asarray(objects, dtype=np.int64)
        data = np.zeros((len(objects), COMMAND_WORDS), dtype=np.uint32)
        data[:, 0] = self.geometry.index_count[objects]
        data[:, 1] = instances
        data[:, 2] = self.geometry.first_index[objects]
        data[:, 4] = objects
        return self.ctx.buffer(data.tobytes() if len(data) else bytes(4 * COMMAND_WORDS)), len(data)

    @staticmethod
    def unbatched_uniforms(recorded: set[str], samplers: set[str]) -> set[str]:
        """Per-object uniforms the records lack: what a program variant sets per object minus the
        record fields and the texture units (bound per group). Empty, or the multi-draw would
        draw a group with its first object's values."""
        return set(recorded) - RECORD_UNIFORMS - set(samplers)

    def cull(self, enabled: np.ndarray, view_projection: np.ndarray, frustum_culling: bool) -> None:
        """The compute pass that writes every command's instance count for this pass."""
        self.cull_commands(self.commands, self.command_count, enabled, view_projection, frustum_culling)

    def cull_commands(self, commands, command_count: int, enabled, view_projection, frustum_culling: bool) -> None:
        flags = np.ascontiguousarray(enabled, dtype=np.uint32).tobytes()
        if flags != self._enabled_bytes:
            self.enabled.write(flags)
            self._enabled_bytes = flags
        shader = self.programs.compute("cull_commands.comp")
        shader["u_cull_view_projection"].write(np.ascontiguousarray(view_projection.T, dtype=np.float32).tobytes())
        shader["u_command_count"].value = command_count
        shader["u_frustum_culling"].value = int(frustum_culling)
        commands.bind_to_storage_buffer(0)
        self.boxes.bind_to_storage_buffer(1)
        self.enabled.bind_to_storage_buffer(2)
        shader.run(group_x=(command_count + CULL_GROUP_SIZE - 1) // CULL_GROUP_SIZE)
        self.ctx.memory_barrier(GL_COMMAND_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT)

    def draw_depth(self, vao, enabled: np.ndarray, single_sided: np.ndarray, view_projection, frustum_culling) -> int:
        """Depth of the ``enabled`` objects (the depth pre-pass, the occluders of the reflectors'
        occlusion test) by one multi-draw per face-culling state, culled on the GPU; the caller
        set the program and depth state. Returns the multi-draws made."""
        key = np.ascontiguousarray(single_sided, dtype=bool).tobytes()
        if self._depth_key != key:
            if self.depth_commands is not None:
                self.depth_commands.release()
            self.depth_groups, first = [], 0
            for one_sided in (True, False):
                members = np.flatnonzero(single_sided == one_sided)
                if len(members):
                    self.depth_groups.append((first, members, one_sided))
                    first += len(members)
            ordered = [members for _, members, _ in self.depth_groups]
            self.depth_commands, self.depth_command_count = self.command_buffer(
                np.concatenate(ordered) if ordered else []
            )
            self._depth_key = key
        self.cull_commands(self.depth_commands, self.depth_command_count, enabled, view_projection, frustum_culling)
        draws = 0
        for first, members, one_sided in self.depth_groups:
            if not enabled[members].any():
                continue
            if one_sided:
                self.ctx.enable(moderngl.CULL_FACE)
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            vao.render_indirect(self.depth_commands, moderngl.TRIANGLES, count=len(members), first=first)
            draws += 1
        self.ctx.disable(moderngl.CULL_FACE)
        return draws

    def draw_group(self, program, vao, group: DrawGroup) -> None:
        """One multi-draw of ``group`` (its textures bound by the caller)."""
        bind_storage(program, self.records, OBJECT_RECORDS_BINDING)
        vao.render_indirect(self.commands, moderngl.TRIANGLES, count=len(group.objects), first=group.first_command)

    def read_instance_counts(self) -> np.ndarray:
        """(object index, instance count) of every command, as the last cull wrote them (tests)."""
        data = np.frombuffer(self.commands.read(), dtype=np.uint32).reshape(-1, COMMAND_WORDS)
        return data[: self.command_count, [4, 1]].astype(np.int64)

    def release_buffers(self) -> None:
        for buffer in (self.commands, self.records):
            if buffer is not None:
                buffer.release()
        self.commands = self.records = None

    def release(self) -> None:
        self.release_buffers()
        if self.depth_commands is not None:
            self.depth_commands.release()
        self.boxes.release()
        self.enabled.release()
