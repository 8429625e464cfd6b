"""GPU-driven drawing of the lobe-shaded objects (issue 42 item 1, second part): the objects a
pass shades with their lobes from their own cube map, under the real-time methods that read only
that cube (lobe-N with or without normalisation, fis-N), drawn by one multi-draw per group instead
of one draw call each.

- The cube maps lie in cube-map arrays, one per face size (viewer/cube_arrays.py), an object's
  layer in its record; the shader reads them through ``RADIANCE_LOD``.
- Each object's uniforms of the per-object program (material, lobes, patterns, bright-source
  lights, cube size, reflection proxy) become its record (viewer/object_records.py LOBE_RECORDS),
  packed from the very bytes the per-object path sends (viewer/interface.py DrawRecorder), so the
  frames are the same. Records depend on the method (patterns), so they are made per method,
  and per object again only when its material, textures or cube map changed.
- Normalised lobe-N's albedo tables (one small texture per material) lie in one 2D texture
  array (AlbedoTableArray), a record holding its layer: bound per group, they had split the
  mirror passes' lobe-3+norm into one group per material (10 on the 18-room apartment).
- lobe-N+norm+fit's blur stacks (materials/blur_stack.py, one per cube) are copied into shared 2D
  arrays of up to STACKS_PER_ARRAY stacks (StackArrays), a record holding its stack's first layer
  and whether it has one (objects without a fitted lobe, or whose stack a budgeted frame has not
  built yet, read their MIP chains).
- Groups: the same program variant (with or without a reflection proxy), cube-map array, stack
  array, texture bindings (lightmap, glTF maps) and face culling. The commands' instance counts
  come from the diffuse batches' frustum-culling compute pass (viewer/object_batches.py).
- Reflectors shaded from their mirror buffers (thesis 4.5, viewer/mirror_pass.py) form batches
  of their own (the MIRROR program variant, no cube-map array): a group per shared plane pass and
  side, its buffers bound once, so the floors of a whole apartment take one multi-draw.

Left to one draw per object (viewer/object_drawer.py): alphaMode BLEND, Rational materials,
objects whose method the panel overrides, the prefiltered methods (per-object prefiltered maps),
mc-N and the reference (per-object importance tables; on reflectors also the averaged tangent
planes), any object while a cube-map memory budget is set (the arrays would hold copies of cubes
the budget released), and everything where the direct GL calls are unavailable."""

from __future__ import annotations

import struct
from dataclasses import dataclass

import moderngl
import numpy as np

from lobeview.materials.blur_stack import STACK_FACE, STACK_LAYERS, STACK_PAD

from .cube_arrays import CubeMapArrays
from .interface import TEXTURE_UNITS, bind_storage
from .object_batches import binding_key, bound_texture
from .object_records import LOBE_RECORDS, OBJECT_RECORDS_BINDING

#: method kinds whose per-object state is the cube, the material and the lights (batchable)
BATCHED_METHOD_KINDS = ("lobe", "fis")
# methods whose records are kept (the camera pass's, its reflectors', the mirror passes', switches)
MAX_METHOD_BATCHES = 6
# Albedo-table layers before the array is started afresh (material edits each add a table; GL 4.5
# guarantees 2048 array layers, one table is 52 KB).
MAX_ALBEDO_LAYERS = 64


class AlbedoTableArray:
    """Normalised lobe-N's per-material albedo tables (viewer/shading.py, 2D float textures of one
    shape) copied into the layers of one 2D texture array, content-addressed: a table already
    there keeps its layer, so records made earlier stay valid until :meth:`clear`."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.texture: moderngl.TextureArray | None = None
        self._layers: dict[bytes, int] = {}  # a table's texels -> its layer
        self._known: dict[int, tuple[moderngl.Texture, int]] = {}  # id -> (texture held, its layer)
        self._tables: list[bytes] = []
        self._size: tuple[int, int] | None = None

    @property
    def full(self) -> bool:
        return len(self._tables) >= MAX_ALBEDO_LAYERS

    def layer_of(self, table: moderngl.Texture) -> int:
        """The layer holding ``table``'s texels (added when new; the array is made again). A
        texture seen before is not read back again (every object of a material shares its table,
        and records are made again on each cube update); held, so its id cannot alias."""
        known = self._known.get(id(table))
        if known is not None and known[0] is table:
            return known[1]
        if table.components != 3 or table.dtype != "f4":
            raise RuntimeError(f"albedo table of {table.components} x {table.dtype} texels, not 3 x f4")
        if self._size is not None and table.size != self._size:
            raise RuntimeError(f"albedo tables of two sizes: {self._size} and {table.size}")
        texels = table.read()
        layer = self._layers.get(texels)
        if layer is None:
            layer = self._layers[texels] = len(self._tables)
            self._tables.append(texels)
            self._size = table.size
            self._upload()
        self._known[id(table)] = (table, layer)
        return layer

    def _upload(self) -> None:
        if self.texture is not None:
            self.texture.release()
        width, height = self._size
        self.texture = self.ctx.texture_array((width, height, len(self._tables)), 3, b"".join(self._tables), dtype="f4")
        # As the per-object table (viewer/shading.py): linear between texel centres, clamped.
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False

    def bind(self, unit: int) -> None:
        if self.texture is not None:
            self.texture.use(location=unit)

    def clear(self) -> None:
        self.release()
        self._layers.clear()
        self._known.clear()
        self._tables.clear()
        self._size = None

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None


# Stacks per array: GL 4.5 guarantees 2048 layers, a stack takes 6 x STACK_LAYERS of them.
STACKS_PER_ARRAY = 2048 // (6 * STACK_LAYERS)
GL_TEXTURE_2D_ARRAY = 0x8C1A


class StackArrays:
    """lobe-N+norm+fit's blur stacks (materials/blur_stack.py; one 2D texture array of 6 x
    STACK_LAYERS layers per cube, viewer/blur_stack_gpu.py) copied into shared 2D arrays of up to
    STACKS_PER_ARRAY stacks each (glCopyImageSubData, on the GPU), so that a multi-draw reads every
    object's stack from one bound array: an object's record holds its stack's first layer. A slot
    keeps the stack texture it holds (identity: a rebuilt cube is a new texture, copied again)."""

    def __init__(self, ctx: moderngl.Context, gl):
        self.ctx = ctx
        self.gl = gl
        self.arrays: list[moderngl.TextureArray] = []
        self.slot_of: dict[int, tuple[int, int]] = {}  # owner (object index) -> (array, slot)
        self.held: list[list] = []  # array -> slot -> the stack texture copied there (or None)
        self.copies = 0

    def update(self, stacks: dict[int, moderngl.TextureArray], wanted: int = 0) -> dict[int, tuple[int, int]]:
        """``stacks``: owner -> its cube's stack; ``wanted``: how many owners will have one once
        every stack is built (a budgeted frame builds a few: a new array then has room for the
        rest, not one array per frame). Returns owner -> (array index, first layer)."""
        for owner in [o for o in self.slot_of if o not in stacks]:  # left: its slot is free again
            array, slot = self.slot_of.pop(owner)
            self.held[array][slot] = None
        missing = [owner for owner in stacks if owner not in self.slot_of]
        # every assigned slot holds its stack (set below): the empty ones are free
        free = [(a, k) for a, slots in enumerate(self.held) for k, held in enumerate(slots) if held is None]
        while len(free) < len(missing):
            room = sum(len(slots) for slots in self.held)
            free += self._allocate(min(max(len(missing) - len(free), wanted - room), STACKS_PER_ARRAY))
        for owner, place in zip(missing, free, strict=False):
            self.slot_of[owner] = place
        placed = {}
        for owner, stack in stacks.items():
            array, slot = self.slot_of[owner]
            if self.held[array][slot] is not stack:
                self._copy(stack, array, slot)
                self.held[array][slot] = stack
            placed[owner] = (array, slot * 6 * STACK_LAYERS)
        return placed

    def _allocate(self, capacity: int) -> list[tuple[int, int]]:
        side = STACK_FACE + 2 * STACK_PAD
        texture = self.ctx.texture_array((side, side, 6 * STACK_LAYERS * capacity), 4, dtype="f4")
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR)  # as each stack (blur_stack_gpu.py)
        texture.repeat_x = texture.repeat_y = False
        self.arrays.append(texture)
        self.held.append([None] * capacity)
        return [(len(self.arrays) - 1, k) for k in range(capacity)]

    def _copy(self, stack: moderngl.TextureArray, array: int, slot: int) -> None:
        gl = self.gl
        gl.clear_errors()
        side, _, layers = stack.size
        gl.glCopyImageSubData(
            stack.glo, GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0,
            self.arrays[array].glo, GL_TEXTURE_2D_ARRAY, 0, 0, 0, slot * layers,
            side, side, layers,
        )  # fmt: skip
        gl.check(f"copying a blur stack into slot {slot} of stack array {array}")
        self.copies += 1

    def bind(self, array: int | None, unit: int, empty: moderngl.TextureArray) -> None:
        """Bind stack array ``array`` (None: ``empty``, a group whose objects have no stack)."""
        (empty if array is None else self.arrays[array]).use(location=unit)

    def release(self) -> None:
        for texture in self.arrays:
            texture.release()
        self.arrays.clear()
        self.held.clear()
        self.slot_of.clear()


@dataclass
class LobeGroup:
    """Objects drawn by one multi-draw of the lobe-shaded program."""

    objects: np.ndarray  # object indices, in the commands' order
    first_command: int
    single_sided: bool
    parallax: bool  # the program variant with the reflection proxy
    face_size: int  # the cube-map array bound (0: none, reflectors drawn from mirror buffers)
    representative: object  # a GpuObject whose draw state binds the group's textures
    stack_array: int | None = None  # lobe-N+norm+fit: StackArrays array bound (None: no stacks)


@dataclass
class _ObjectRecord:
    key: tuple
    cube: object  # the RadianceCube it was made with (held: an identity that cannot alias)
    data: bytes
    group_key: tuple


@dataclass
class MethodBatch:
    """The multi-draws of one method: its records buffer, commands and groups."""

    key: tuple
    records: moderngl.Buffer
    commands: moderngl.Buffer
    command_count: int
    groups: list
    members: np.ndarray  # which objects the groups hold
    uses_stacks: bool = False  # lobe-N+norm+fit: each group binds its StackArrays array
    shares_key: tuple | None = None  # the mirror shares the groups were made for (reflectors)

    def release(self) -> None:
        self.records.release()
        self.commands.release()


class LobeBatches:
    """The records, groups and commands of the lobe-shaded objects, kept per method (the camera
    pass's and the mirror passes' methods differ, so one frame uses two; at most
    MAX_METHOD_BATCHES are kept). ``batches``: the drawer's ObjectBatches (command buffers,
    culling); ``gl``: viewer/cube_arrays.py DirectGL."""

    def __init__(self, ctx: moderngl.Context, batches, gl):
        self.ctx = ctx
        self.batches = batches
        self.arrays = CubeMapArrays(gl)
        self.albedo_tables = AlbedoTableArray(ctx)
        self.stacks = StackArrays(ctx, gl)
        self._no_stacks = None  # a 1-texel array bound for groups without stacks (made on first use)
        self._records: dict = {}  # method -> object index -> its record
        self._methods: dict = {}  # method -> MethodBatch, least recently prepared first
        self.current: MethodBatch | None = None  # the batch prepared last
        self.record_builds = 0  # object records made (tests: an unchanged object is not recorded again)

    def kept(self, method) -> MethodBatch | None:
        """The batch kept for ``method`` (the reflectors' batch of a method: ``(method, "mirror")``)."""
        return self._methods.get(method)

    @property
    def members(self) -> np.ndarray:
        """Which objects the last prepared batch holds."""
        return self.current.members if self.current is not None else np.zeros(0, dtype=bool)

    def prepare(
        self, method, key, objects: list, members, record_state, single_sided, stack_of=None, mirror_shares=None
    ) -> MethodBatch:
        """The batch of ``method``, made again when ``key`` changed; ``key[0]``: what every
        record depends on (material generation, texture evictions). ``members``: the objects to
        batch (each reads the cube map of ``objects[obj.probe_owner]``); ``record_state(obj)``
        records an object's per-object draw state: (DrawRecorder, parallax). ``stack_of(obj)``
        (lobe-N+norm+fit): (the blur stack the object reads, its owner's, or None; whether it
        reads one once built). An object's record is made again only when ``key[0]``, its cube,
        its layer or its stack's changed. ``mirror_shares`` (reflectors shaded from their mirror
        buffers): the members drawn this pass, object index -> what its draw binds beyond its
        record (the pass it shares, its plane's side), which splits the groups; the other members
        keep their records but join no group (a regroup costs the drawn reflectors, not all of
        them); no cube map is read (none placed in the arrays, the object may have none), and the
        batch does not become ``current``."""
        shares_key = None if mirror_shares is None else tuple(mirror_shares.items())
        batch = self._methods.pop(method, None)
        if batch is not None and batch.key == key:
            self._methods[method] = batch  # most recently used last
            if batch.shares_key != shares_key:  # the records stand; only the groups and commands change
                batch.commands.release()
                batch.groups, batch.commands, batch.command_count = self._group(
                    self._records[method], objects, batch.members, mirror_shares
                )
                batch.shares_key = shares_key
            if mirror_shares is None:
                self.current = batch
            return batch
        if batch is not None:
            batch.release()
        if self.albedo_tables.full:  # start afresh: every kept record names a layer
            self.albedo_tables.clear()
            self._records.clear()
            for other in self._methods.values():
                other.release()
            self._methods.clear()
        cubes = {objects[i].probe_owner: objects[objects[i].probe_owner].cube for i in np.flatnonzero(members)}
        if mirror_shares is None:
            placed = self.arrays.update({owner: cube.residual for owner, cube in cubes.items()})
        else:  # under MIRROR the cube is bound (per-object path: the object's or the sky's), never read
            placed = dict.fromkeys(cubes, (0, 0))
        # lobe-N+norm+fit: each object's stack (its owner's; None where it reads none, or where the
        # frame's budget left it unbuilt), the stacks copied into the shared arrays
        stacks_wanted = {int(i): stack_of(objects[i]) for i in np.flatnonzero(members)} if stack_of else {}
        object_stacks = {i: stack for i, (stack, _) in stacks_wanted.items()}
        owner_stacks = {objects[i].probe_owner: t for i, t in object_stacks.items() if t is not None}
        wanted = len({objects[i].probe_owner for i, (_, wants) in stacks_wanted.items() if wants})
        placed_stacks = self.stacks.update(owner_stacks, wanted) if stack_of else {}
        known = self._records.get(method, {})
        kept: dict[int, _ObjectRecord] = {}  # the method's records from now on: its members'
        records = bytearray(LOBE_RECORDS.size * max(len(objects), 1))
        radiance_unit, albedo_unit = TEXTURE_UNITS["u_radiance"], TEXTURE_UNITS["u_albedo"]
        stack_unit = TEXTURE_UNITS["u_blur_stack"]
        for index in np.flatnonzero(members).tolist():
            obj = objects[index]
            face_size, layer = placed[obj.probe_owner]
            cube = cubes[obj.probe_owner]
            stack_place = placed_stacks.get(obj.probe_owner) if object_stacks.get(index) is not None else None
            object_key = (key[0], face_size, layer, stack_place)
            entry = known.get(index)
            if entry is None or entry.key != object_key or entry.cube is not cube:
                recorder, parallax = record_state(obj)
                record = recorder.record()
                uniforms = {name: data for name, (_, data) in record.uniforms}
                uniforms["u_cube_layer"] = struct.pack("f", float(layer))
                table = bound_texture(record, albedo_unit)  # normalised lobe-N only
                albedo_layer = self.albedo_tables.layer_of(table) if table is not None else 0
                uniforms["u_albedo_layer"] = struct.pack("f", float(albedo_layer))
                uniforms["u_has_blur_stack"] = struct.pack("i", int(stack_place is not None))
                uniforms["u_stack_layer"] = struct.pack("f", float(stack_place[1] if stack_place else 0))
                # the cube, the albedo table and the blur stack come from their arrays
                binds = binding_key(record, skip_units=(radiance_unit, albedo_unit, stack_unit))
                stack_array = stack_place[0] if stack_place else None
                group_key = (parallax, face_size, stack_array, binds, bool(single_sided[index]))
                entry = _ObjectRecord(object_key, cube, LOBE_RECORDS.pack(uniforms), group_key)
                self.record_builds += 1
            kept[index] = entry
            records[index * LOBE_RECORDS.size : (index + 1) * LOBE_RECORDS.size] = entry.data
        self._records[method] = kept
        groups, commands, count = self._group(kept, objects, members, mirror_shares)
        batch = MethodBatch(
            key, self.ctx.buffer(bytes(records)), commands, count, groups, members.copy(), stack_of is not None,
            shares_key,
        )  # fmt: skip
        self._methods[method] = batch
        while len(self._methods) > MAX_METHOD_BATCHES:
            oldest = next(iter(self._methods))
            self._methods.pop(oldest).release()
            self._records.pop(oldest, None)
        if mirror_shares is None:
            self.current = batch
        return batch

    def _group(self, records: dict, objects: list, members: np.ndarray, mirror_shares) -> tuple[list, object, int]:
        """(groups, command buffer, command count) of ``members`` from their ``records``
        (index -> _ObjectRecord); where ``mirror_shares`` is given, of its objects (the drawn
        members), split further by their shares."""
        grouped: dict[tuple, list] = {}
        if mirror_shares is None:
            shared = [(index, None) for index in np.flatnonzero(members).tolist()]
        else:  # this pass's drawn reflectors, by the pass they share and their plane's side
            shared = sorted(mirror_shares.items())
        for index, share in shared:
            grouped.setdefault((*records[index].group_key, share), []).append(objects[index])
        groups, first = [], 0
        for (parallax, face_size, stack_array, _, one_sided, _), group in grouped.items():
            indices = np.array([obj.index for obj in group], dtype=np.int64)
            groups.append(LobeGroup(indices, first, one_sided, parallax, face_size, group[0], stack_array))
            first += len(indices)
        ordered = [group.objects for group in groups]
        commands, count = self.batches.command_buffer(np.concatenate(ordered) if ordered else [])
        return groups, commands, count

    def cull(self, batch: MethodBatch, enabled: np.ndarray, view_projection: np.ndarray, frustum_culling: bool) -> None:
        """Every command's instance count for this pass (the diffuse batches' compute pass)."""
        self.batches.cull_commands(batch.commands, batch.command_count, enabled, view_projection, frustum_culling)

    def draw_group(self, batch: MethodBatch, program, vao, group: LobeGroup) -> None:
        """One multi-draw of ``group``: its cube-map array and the records bound here, its other
        textures by the caller (a reflector's mirror buffers among them; no cube-map array)."""
        if group.face_size:
            self.arrays.bind(group.face_size, TEXTURE_UNITS["u_radiance_array"])
        self.albedo_tables.bind(TEXTURE_UNITS["u_albedo_array"])
        if batch.uses_stacks:
            if self._no_stacks is None:
                self._no_stacks = self.ctx.texture_array((1, 1, 1), 4, b"\0" * 16, dtype="f4")
            self.stacks.bind(group.stack_array, TEXTURE_UNITS["u_blur_stack"], self._no_stacks)
        bind_storage(program, batch.records, OBJECT_RECORDS_BINDING)
        vao.render_indirect(batch.commands, moderngl.TRIANGLES, count=len(group.objects), first=group.first_command)

    def release(self) -> None:
        for batch in self._methods.values():
            batch.release()
        self._methods.clear()
        self.current = None
        self.arrays.release()
        self.albedo_tables.release()
        self.stacks.release()
        if self._no_stacks is not None:
            self._no_stacks.release()
            self._no_stacks = None
        self._records.clear()
