"""Multi-draws of lobe-shaded objects (issue 42 item 1, viewer/lobe_batches.py): cube maps in
cube-map arrays read exactly like the cube maps themselves, the records hold every per-object
value of the lobe program, the frames equal the per-object path's within rounding, and an
object's record is made again only when what it depends on changed."""

from __future__ import annotations

import warnings

import moderngl
import numpy as np
import pytest
from test_frames_unchanged import _apartment_scene, _demo_scene, _renderer, _scene_camera
from test_indirect_draws import _frames, assert_within_rounding

from lobeview.core.methods import Method
from lobeview.viewer.cube_arrays import CubeMapArrays, direct_gl
from lobeview.viewer.cubemap import RadianceCube
from lobeview.viewer.interface import TEXTURE_UNITS, DrawRecorder
from lobeview.viewer.mip_chain import upload_cube
from lobeview.viewer.object_records import LOBE_RECORDS, RECORD_SIZE
from lobeview.viewer.scene_shading import per_pixel_lobes


def _sampling_shader(single: str, array: str, query: str, lookup: str, layered: str) -> str:
    """A compute shader that reads each query from a texture (uniform u_single, unit 0) and from
    the same texels' layer of an array (unit 5), side by side."""
    return f"""#version 450 core
layout(local_size_x = 64) in;
uniform {single} u_single;
layout(binding = 5) uniform {array} u_array;
uniform float u_layer;
layout(std430, binding = 0) writeonly buffer Out {{ vec4 samples[]; }};
layout(std430, binding = 1) readonly buffer Queries {{ {query} queries[]; }};
void main() {{
    uint i = gl_GlobalInvocationID.x;
    samples[2u * i] = {lookup};
    samples[2u * i + 1u] = {layered};
}}
"""


# q = (direction, LOD)
SAMPLE_CUBES = _sampling_shader(
    "samplerCube", "samplerCubeArray", "vec4",
    "textureLod(u_single, queries[i].xyz, queries[i].w)",
    "textureLod(u_array, vec4(queries[i].xyz, u_layer), queries[i].w)",
)  # fmt: skip


def _gl(ctx):
    gl, why = direct_gl(ctx)
    if gl is None:
        pytest.skip(f"no direct GL calls here: {why}")
    return gl


def test_cube_map_arrays_read_like_cube_maps(ctx):
    """Random cubes of two face sizes in their arrays: every level and layer gives the cube
    map's own texels bit for bit (seamless filtering, random directions and LODs); replacing one
    object's cube copies that cube only."""
    rng = np.random.default_rng(3)
    arrays = CubeMapArrays(_gl(ctx))
    cubes = {i: upload_cube(ctx, rng.random((6, size, size, 3)).astype(np.float32)) for i, size in
             enumerate((16, 8, 16, 16, 8))}  # fmt: skip
    shader = ctx.compute_shader(SAMPLE_CUBES)
    n = 64 * 32
    queries = rng.normal(size=(n, 4)).astype(np.float32)
    queries[:, 3] = rng.uniform(0.0, 5.0, size=n)
    query_buffer, out = ctx.buffer(queries.tobytes()), ctx.buffer(reserve=n * 32)
    try:
        placed = arrays.update({i: cube for i, cube in cubes.items()})
        assert arrays.copies == 5 and sorted(arrays.classes) == [8, 16]
        assert arrays.gpu_bytes == sum(6 * 16 * sum((s >> k) ** 2 for k in range(s.bit_length())) * c
                                       for s, c in ((16, 3), (8, 2)))  # fmt: skip
        shader["u_single"] = 0
        for index, cube in cubes.items():
            size, layer = placed[index]
            assert size == cube.size[0]
            cube.use(0)
            arrays.bind(size, 5)
            shader["u_layer"] = float(layer)
            out.bind_to_storage_buffer(0)
            query_buffer.bind_to_storage_buffer(1)
            shader.run(n // 64)
            samples = np.frombuffer(out.read(), np.float32).reshape(n, 2, 4)
            assert samples[:, 0, :3].max() > 0.5  # the cube was read, not a black unit
            np.testing.assert_array_equal(samples[:, 1], samples[:, 0])
        # One object's cube replaced: one copy; an object gone frees its layer's texture.
        replacement = upload_cube(ctx, rng.random((6, 16, 16, 3)).astype(np.float32))
        cubes_after = {**cubes, 2: replacement}
        del cubes_after[4]
        arrays.update(cubes_after)
        assert arrays.copies == 6
        assert 4 not in arrays.classes[8].layer_of
    finally:
        arrays.release()
        for cube in cubes.values():
            cube.release()
        shader.release()
        query_buffer.release()
        out.release()


SAMPLE_TABLES = _sampling_shader(
    "sampler2D", "sampler2DArray", "vec2",
    "textureLod(u_single, queries[i], 0.0)", "textureLod(u_array, vec3(queries[i], u_layer), 0.0)",
)  # fmt: skip


def test_albedo_table_array_reads_like_the_tables(ctx):
    """Each albedo table's layer gives the table's own linear-filtered texels bit for bit; a
    table already there (same texels, another texture) keeps its layer; a full array starts afresh."""
    from lobeview.viewer.lobe_batches import MAX_ALBEDO_LAYERS, AlbedoTableArray

    rng = np.random.default_rng(5)
    tables = [ctx.texture((32, 136), 3, rng.random((136, 32, 3)).astype(np.float32).tobytes(), dtype="f4")
              for _ in range(3)]  # fmt: skip
    for table in tables:
        table.filter = (moderngl.LINEAR, moderngl.LINEAR)
        table.repeat_x = table.repeat_y = False
    array = AlbedoTableArray(ctx)
    shader = ctx.compute_shader(SAMPLE_TABLES)
    n = 64 * 16
    queries = rng.uniform(-0.1, 1.1, size=(n, 2)).astype(np.float32)  # clamped edges too
    query_buffer, out = ctx.buffer(queries.tobytes()), ctx.buffer(reserve=n * 32)
    try:
        layers = [array.layer_of(table) for table in tables]
        assert layers == [0, 1, 2] and array.texture.size == (32, 136, 3)
        copy = ctx.texture((32, 136), 3, tables[1].read(), dtype="f4")
        assert array.layer_of(copy) == 1 and array.texture.size[2] == 3  # content-addressed
        reads = []
        original_read = type(tables[0]).read
        type(tables[0]).read = lambda self, *a, **k: reads.append(self) or original_read(self, *a, **k)
        try:
            assert [array.layer_of(table) for table in tables] == [0, 1, 2] and reads == []  # known: no read-back
        finally:
            type(tables[0]).read = original_read
        copy.release()
        shader["u_single"] = 0
        for table, layer in zip(tables, layers, strict=True):
            table.use(0)
            array.bind(5)
            shader["u_layer"] = float(layer)
            out.bind_to_storage_buffer(0)
            query_buffer.bind_to_storage_buffer(1)
            shader.run(n // 64)
            samples = np.frombuffer(out.read(), np.float32).reshape(n, 2, 4)
            assert samples[:, 0, :3].max() > 0.5
            np.testing.assert_array_equal(samples[:, 1], samples[:, 0])
        with pytest.raises(RuntimeError, match="two sizes"):
            other = ctx.texture((16, 136), 3, bytes(16 * 136 * 12), dtype="f4")
            try:
                array.layer_of(other)
            finally:
                other.release()
        assert not array.full
        array._tables += [b""] * (MAX_ALBEDO_LAYERS - 3)
        assert array.full
        array.clear()
        assert not array.full and array.texture is None and array.layer_of(tables[2]) == 0
    finally:
        array.release()
        for resource in (*tables, shader, query_buffer, out):
            resource.release()


@pytest.mark.parametrize("method", ["lobe-7", "lobe-11+norm", "fis-8"])
def test_demo_lobe_shaded_objects_are_multi_drawn(ctx, method):
    """The demo's lobe-shaded objects go through multi-draws: per-object draws are left only for
    what the batches exclude (alphaMode BLEND, reflectors drawn from mirror buffers), the frame
    equals the per-object path's within rounding."""
    _gl(ctx)
    scene = _demo_scene()
    renderer = _renderer(ctx, scene)
    try:
        frames = _frames(renderer, _scene_camera(scene, "overview"), method)
        (single, calls_single), (multi, calls_multi) = frames[False], frames[True]
        assert_within_rounding(multi, single, method)
        drawer = renderer.drawer
        batched = int(np.count_nonzero(drawer.lobe_batches.members))
        assert batched >= 5  # the demo's glossy objects
        assert calls_multi[0] <= calls_single[0] - batched  # their per-object draws are gone
        for index in np.flatnonzero(drawer.lobe_batches.members):  # BLEND stays per object (sorted)
            assert drawer.material_of(index).alpha_mode.upper() != "BLEND"
        if method.endswith("+norm"):  # albedo tables from one array: materials do not split the groups
            layers = drawer.lobe_batches.albedo_tables.texture.size[2]
            assert layers >= 5 and len(drawer.lobe_batches.current.groups) < layers
    finally:
        renderer.release()


def test_apartment_lobe_shaded_frames_and_cube_faces(ctx):
    """The one-room apartment under normalised lobe-N, and its cube-map faces (later bounces draw
    lobe-shaded objects from the previous bounce's cubes): equal within rounding."""
    _gl(ctx)
    scene = _apartment_scene()
    renderer = _renderer(ctx, scene)
    try:
        camera = _scene_camera(scene)
        frames = _frames(renderer, camera, "lobe-7+norm")
        assert_within_rounding(frames[True][0], frames[False][0], "apartment-1 lobe-7+norm")
        assert frames[True][1][1] > frames[False][1][1]
    finally:
        renderer.release()


def test_fitted_reads_multi_draw_with_the_stacks_in_arrays(ctx):
    """lobe-N+norm+fit in the multi-draws: each object's blur stack copied into a shared array
    (StackArrays), its first layer in the record: the frame equals the per-object path's within
    rounding with the spheres' draws gone, and the stacks matter in it (the MIP chain's reads
    give another frame); the anisotropic sphere's record names no stack."""
    from test_blur_stack import spheres_in_a_scene

    from lobeview.bench.lobe_kernel import sunless_sky
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.camera import Camera

    _gl(ctx)
    env = EnvironmentMap.from_function(sunless_sky, height=64, name="sunless-sky")
    # GGX 0.3 and Beckmann 0.5 read fitted (wide enough for the stack), the anisotropic one not
    renderer = spheres_in_a_scene(ctx, ["ggx:0.3", "beckmann:0.5", "ggx:0.05x0.3"], env, (120, 48), rings=24)
    try:
        camera = Camera(position=(0.0, 0.0, 7.5), target=(0.0, 0.0, 0.0), fov_y=40.0)
        frames = _frames(renderer, camera, "lobe-7+norm+fit")
        (single, calls_single), (multi, calls_multi) = frames[False], frames[True]
        assert_within_rounding(multi, single, "spheres lobe-7+norm+fit")
        batches = renderer.drawer.lobe_batches
        assert int(np.count_nonzero(batches.members)) == 3 and calls_multi[0] <= calls_single[0] - 3
        assert batches.current.uses_stacks and batches.stacks.copies == 2  # not the anisotropic one
        assert sorted(len(g.objects) for g in batches.current.groups if g.stack_array is not None) == [2]
        # the stacks matter: the per-object frame without them (u_has_blur_stack 0: the chain)
        renderer.configure(indirect_draws=False)
        renderer.shading.stack_budget(0.0)
        for obj in renderer.objects:  # as if not built yet: this frame builds one, reads one chain
            if obj.cube.has_blur_stack:
                obj.cube._blur_stack.release()
                obj.cube._blur_stack = None
        chain = renderer.render(camera, "lobe-7+norm+fit", spp=1).radiance
        renderer.shading.stack_budget(None)
        assert np.abs(chain - single).max() > 0.01 * np.abs(single).max()
    finally:
        renderer.release()


def test_lobe_records_hold_every_per_object_value(ctx):
    """Every uniform a lobe-shaded object's draw sets (material, lights, cube size, proxy) is a
    record field or a texture unit: a missed one would shade a group with one object's value."""
    _gl(ctx)
    samplers = set(TEXTURE_UNITS)
    for scene in (_demo_scene(), _apartment_scene()):
        renderer = _renderer(ctx, scene)
        try:
            drawer = renderer.drawer
            checked = 0
            methods = ("lobe-7", "lobe-11+norm", "fis-8", "lobe-7+norm+fit")
            for method in (Method.parse(m) for m in methods):
                for obj in drawer.objects:
                    owner = drawer.objects[obj.probe_owner]
                    if owner.cube is None:
                        continue
                    proxy = scene.objects[obj.index].reflection_proxy
                    recorder = DrawRecorder(drawer.program(method, True, proxy is not None))
                    renderer.shading.set_object_state(recorder, obj, method, False, proxy, owner.probe_centre)
                    mat = drawer.material_of(obj.index)
                    renderer.shading.bind_cube(recorder, owner.cube, method, obj.material, per_pixel_lobes(mat))
                    names = {name for name, _ in recorder.record().uniforms}
                    assert names - LOBE_RECORDS.uniforms - samplers == set(), (obj.name, method)
                    checked += 1
            assert checked > 0
        finally:
            renderer.release()


def test_records_are_made_again_only_for_what_changed(ctx):
    """A second frame records nothing; a new cube for one object records that object only (its
    record and layer); the diffuse fields keep their offsets in the lobe layout."""
    _gl(ctx)
    assert LOBE_RECORDS.size > RECORD_SIZE and LOBE_RECORDS.size % 16 == 0
    scene = _demo_scene()
    renderer = _renderer(ctx, scene)
    try:
        camera = _scene_camera(scene, "overview")
        renderer.render(camera, "lobe-7", spp=1)
        batches = renderer.drawer.lobe_batches
        builds = batches.record_builds
        renderer.render(camera, "lobe-7", spp=1)
        assert batches.record_builds == builds
        index = int(np.flatnonzero(batches.members)[0])
        owner = renderer.drawer.objects[renderer.drawer.objects[index].probe_owner]
        copies = batches.arrays.copies
        owner.cube = owner.cube  # the same cube assigned again: the key changes, nothing is re-recorded
        renderer.render(camera, "lobe-7", spp=1)
        assert batches.record_builds == builds and batches.arrays.copies == copies
        old = owner.cube
        owner.cube = RadianceCube(ctx, old.faces)  # a new cube for one owner: its readers only
        objects = renderer.drawer.objects
        readers = sum(1 for i in np.flatnonzero(batches.members) if objects[i].probe_owner == owner.index)
        try:
            renderer.render(camera, "lobe-7", spp=1)
            assert batches.record_builds == builds + readers and batches.arrays.copies == copies + 1
        finally:
            old.release()
    finally:
        renderer.release()


def _assert_per_object_fallback(renderer, camera, why: str) -> None:
    """With the lobe batches off for ``why``: a warning saying it, and lobe-7's frame with
    multi-draws on equal bit for bit to the frame with them off."""
    renderer.configure(indirect_draws=False)
    single = renderer.render(camera, "lobe-7", spp=1).radiance
    renderer.configure(indirect_draws=True)
    renderer.invalidate_mirrors()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        multi = renderer.render(camera, "lobe-7", spp=1).radiance
    assert any(why in str(w.message) for w in caught)
    assert renderer.drawer.lobe_batches is None
    np.testing.assert_array_equal(multi, single)


def test_without_direct_gl_the_objects_are_drawn_one_by_one(ctx, monkeypatch):
    """Where the GL library cannot be reached, a warning says so and the frame is the per-object
    path's, bit for bit."""
    import lobeview.viewer.object_drawer as object_drawer

    monkeypatch.setattr(object_drawer, "direct_gl", lambda ctx: (None, "no GL library (test)"))
    scene = _demo_scene()
    renderer = _renderer(ctx, scene)
    try:
        assert renderer.drawer.lobe_batches_unavailable == "no GL library (test)"  # found at start-up (cube bake)
        renderer.drawer.lobe_batches_unavailable = ""  # asked again: warned again
        _assert_per_object_fallback(renderer, _scene_camera(scene, "overview"), "no GL library (test)")
    finally:
        renderer.release()


def test_a_failing_array_falls_back_to_one_draw_per_object(ctx, monkeypatch):
    """A GL error while the cube-map arrays are made (a driver without them, memory) stops the
    lobe batches with a warning; the frame is the per-object path's, bit for bit."""
    from lobeview.viewer.lobe_batches import LobeBatches

    _gl(ctx)

    def failing_prepare(*args, **kwargs):
        raise RuntimeError("a cube-map array of 9 x 6 faces of 64^2: GL error 0x0505 (test)")

    scene = _demo_scene()
    renderer = _renderer(ctx, scene)
    try:
        monkeypatch.setattr(LobeBatches, "prepare", failing_prepare)
        if renderer.drawer.lobe_batches is not None:  # made again on the next frame, then failing
            renderer.drawer.lobe_batches.release()
            renderer.drawer.lobe_batches = None
        _assert_per_object_fallback(renderer, _scene_camera(scene, "overview"), "GL error 0x0505 (test)")
    finally:
        renderer.release()


@pytest.mark.parametrize("method", ["lobe-7", "lobe-7+norm+fit", "fis-8"])
def test_reflectors_multi_draw_one_group_per_shared_pass(ctx, method):
    """Reflectors shaded from their mirror buffers: the split floor's halves (two
    materials, one shared pass) take one multi-draw and the glossy wall (its own plane) another;
    the frame equals the per-object path's within rounding, without their per-object draws. A
    frame in which the wall has no pass (out of view) regroups the batch without recording
    anything again."""
    from test_mirror_sharing import _split_floor_scene

    from lobeview.scenes.mirror_scene import CAMERA
    from lobeview.viewer.camera import Camera

    _gl(ctx)
    scene = _split_floor_scene(right_roughness=0.01, wall=True)
    names = [obj.name for obj in scene.objects]
    left, right, wall = (names.index(name) for name in ("left floor", "right floor", "glossy wall"))
    renderer = _renderer(ctx, scene)
    try:
        camera = Camera(tuple(CAMERA.position), tuple(CAMERA.target), tuple(CAMERA.up), CAMERA.fov_y)
        frames = _frames(renderer, camera, method)
        (single, calls_single), (multi, calls_multi) = frames[False], frames[True]
        assert_within_rounding(multi, single, f"split floor and wall, {method}")
        assert calls_multi[0] <= calls_single[0] - 3  # the reflectors' own draws are gone
        counts = renderer.draw_counts.of("camera")  # each object counted once, drawn or culled
        assert counts.drawn + counts.culled == len(scene.objects) and counts.drawn >= 3
        assert any("shared with left floor" in line for line in renderer.mirror_report)
        batches = renderer.drawer.lobe_batches
        batch = batches.kept((Method.parse(method), "mirror"))
        groups = sorted(sorted(int(i) for i in group.objects) for group in batch.groups)
        assert groups == sorted([sorted([left, right]), [wall]])
        assert batches.current is not batch  # the camera's own lobe batch stays the current one
        # Looking down at the floor: the wall is out of view, gets no pass, and leaves the drawn groups.
        builds, shares = batches.record_builds, batch.shares_key
        down = Camera((0.0, 1.5, 3.0), (0.0, 0.0, 2.5), (0.0, 1.0, 0.0), CAMERA.fov_y)
        renderer.render(down, method, spp=1)
        assert wall in renderer.mirror_passes.skipped and left not in renderer.mirror_passes.skipped
        assert batches.kept((Method.parse(method), "mirror")) is batch and batch.shares_key != shares
        assert batches.record_builds == builds
        counts = renderer.draw_counts.of("camera")
        assert counts.drawn + counts.culled == len(scene.objects)
        drawn = [sorted(int(i) for i in g.objects) for g in batch.groups if wall not in g.objects]
        assert drawn == [sorted([left, right])]
    finally:
        renderer.release()
