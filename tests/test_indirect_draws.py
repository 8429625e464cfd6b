"""GPU-driven drawing (issue 42, viewer/object_batches.py): the multi-draw path renders the same
frames as one draw per object, its GPU culling never drops what the CPU's frustum test keeps,
and the per-object records hold every value a diffuse draw sets. (tests/test_frames_unchanged.py
holds the default, multi-draw path against frames stored before it existed.)"""

from __future__ import annotations

import numpy as np
import pytest
from test_frames_unchanged import _demo_scene, _model, _model_camera, _renderer, _scene_camera
from test_textures import _textured_quad_scene

from lobeview.core.methods import Method
from lobeview.viewer.camera import Camera, outside_frustum_many, perspective
from lobeview.viewer.interface import TEXTURE_UNITS, DrawRecorder
from lobeview.viewer.object_batches import ObjectBatches, SceneGeometry
from lobeview.viewer.object_records import RECORD_OFFSETS, RECORD_SIZE, pack_object_record

# Bound of the multi-drawn lobe-shaded frames against one draw per object: the same values reach
# the same GLSL, but llvmpipe compiles record reads (storage buffer) and uniform reads into
# differently scheduled code, so a few pixels differ in their last bits (measured:
# 4-13 of 4000 pixels on the demo, 66 on WaterBottle under fis-8; at most 2.3e-7 relative).
RELATIVE_BOUND = 1e-6
DIFFERING_PIXELS_BOUND = 0.05


def assert_within_rounding(multi: np.ndarray, single: np.ndarray, what: str) -> None:
    """Frames equal within RELATIVE_BOUND of the frame's peak, on at most DIFFERING_PIXELS_BOUND of the pixels."""
    assert np.all(np.isfinite(multi)) and multi.max() > 0.01, what
    scale = max(float(np.abs(single).max()), 1e-6)
    difference = np.abs(multi - single)
    assert float(difference.max()) <= RELATIVE_BOUND * scale, what
    assert np.count_nonzero(np.any(difference > 0, axis=-1)) <= DIFFERING_PIXELS_BOUND * difference[..., 0].size, what


def _frames(renderer, camera, method: str) -> dict:
    """Radiance of one frame and the draw calls it took, per path."""
    out = {}
    for indirect in (False, True):
        renderer.configure(indirect_draws=indirect)
        renderer.invalidate_mirrors()
        before = renderer.drawer.draw_calls.total()
        frame = renderer.render(camera, method, spp=3 if method == "reference" else 1).radiance
        out[indirect] = (frame, np.subtract(renderer.drawer.draw_calls.total(), before))
    return out


@pytest.mark.parametrize("method", ["lobe-7", "reference", "prefiltered"])
def test_demo_frames_are_bit_identical_with_fewer_draws(ctx, method):
    scene = _demo_scene()
    renderer = _renderer(ctx, scene)
    try:
        frames = _frames(renderer, _scene_camera(scene, "overview"), method)
        (single, calls_single), (multi, calls_multi) = frames[False], frames[True]
        if method == "prefiltered":
            np.testing.assert_array_equal(multi, single)
        else:  # lobe-shaded objects multi-drawn too: equal within rounding (tests/test_lobe_batches.py);
            # the reference's program variants round the self-occlusion horizons' arithmetic apart
            # (1 ulp on 2 of 4000 pixels on llvmpipe)
            assert_within_rounding(multi, single, method)
        assert calls_single[1] == 0 and calls_multi[1] > 0  # the switch switches
        assert calls_multi[0] < calls_single[0]  # fewer draw calls: the diffuse objects are batched
        assert renderer.frame_draw_calls[1] > 0 and "multi-draws" in renderer.draw_report[-1]  # the panel's line
        # The cube-map faces (the diffuse bounce draws everything but transmissive panes batched).
        eye = np.array(_scene_camera(scene, "overview").position)
        faces = {}
        for indirect in (False, True):
            renderer.configure(indirect_draws=indirect)
            faces[indirect] = renderer.render_cube_faces(eye, None, False, 16)
        np.testing.assert_array_equal(faces[True], faces[False])
    finally:
        renderer.release()


def test_textured_models_render_the_same_frames(ctx):
    """glTF textures (sampled with derivatives taken from the UV sets under OBJECT_RECORDS) and a
    model whose materials share textures: equal within rounding of the texture-transform chain."""
    from conftest import SHARED_ASSETS

    cases = [(_textured_quad_scene(), Camera((0.0, 1.2, 1.4), (0, 0, 0), (0, 1, 0), 50.0))]
    if SHARED_ASSETS.exists():
        scene = _model("CornellBox")
        cases.append((scene, _model_camera(scene)))
    for scene, camera in cases:
        renderer = _renderer(ctx, scene)
        try:
            frames = _frames(renderer, camera, "lobe-7+norm")
            single, multi = frames[False][0], frames[True][0]
            assert np.all(np.isfinite(multi)) and multi.max() > 0.01
            scale = max(float(np.abs(single).max()), 1e-6)
            assert float(np.abs(multi - single).max()) <= 1e-5 * scale
        finally:
            renderer.release()


def test_gpu_culling_never_drops_what_the_frustum_test_keeps(ctx):
    """3000 random boxes, many at the frustum's edges, 20 random cameras: every box the float64
    test keeps gets instance count 1; the GPU keeps at most a handful more (its margin)."""
    from lobeview.viewer.shaders import ProgramCache

    rng = np.random.default_rng(7)
    n = 3000
    centres = rng.uniform(-20, 20, size=(n, 3))
    halves = rng.uniform(0.01, 2.0, size=(n, 3))
    boxes = np.stack([centres - halves, centres + halves], axis=1)

    class _Object:
        def __init__(self):
            from types import SimpleNamespace

            tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
            self.mesh = SimpleNamespace(
                positions=tri, normals=np.zeros_like(tri), tangents=np.zeros((3, 4), np.float32),
                uvs=np.zeros((3, 2), np.float32), indices=np.array([[0, 1, 2]]),
            )  # fmt: skip
            self.uv1 = None

    geometry = SceneGeometry(ctx, [_Object() for _ in range(n)])
    batches = ObjectBatches(ctx, ProgramCache(ctx), geometry, boxes)
    commands = np.array([(3, 0, 3 * i, 0, i) for i in range(n)], dtype=np.uint32)
    batches.commands = ctx.buffer(commands.tobytes())
    batches.command_count = n
    enabled = rng.random(n) < 0.9
    extra = 0
    try:
        for _ in range(20):
            eye = rng.uniform(-10, 10, size=3)
            target = eye + rng.normal(size=3)
            camera = Camera(tuple(eye), tuple(target), (0.0, 1.0, 0.0), float(rng.uniform(20, 90)))
            view_projection = perspective(camera.fov_y, 1.6, 0.1, 60.0) @ camera.view()
            corners = np.array(
                [[[b[i >> 0 & 1][0], b[i >> 1 & 1][1], b[i >> 2 & 1][2]] for i in range(8)] for b in boxes]
            )
            kept = enabled & ~outside_frustum_many(corners, view_projection)
            batches.cull(enabled, view_projection, True)
            counts = batches.read_instance_counts()
            drawn = np.zeros(n, dtype=bool)
            drawn[counts[:, 0]] = counts[:, 1] == 1
            assert np.all(drawn[kept]), "the GPU culled a box the frustum test keeps"
            assert not np.any(drawn & ~enabled)
            extra += int(np.count_nonzero(drawn & ~kept))
            assert 0 < kept.sum() < n  # the cameras see some boxes and not all
        assert extra <= 20  # the margin keeps a few boxes at the planes, not a different test
        # Culling off: every enabled command is drawn.
        batches.cull(enabled, np.eye(4), False)
        counts = batches.read_instance_counts()
        assert np.array_equal(counts[:, 1] == 1, enabled[counts[:, 0]])
    finally:
        batches.release()
        geometry.release()


def test_records_hold_every_per_object_value(ctx):
    """Every uniform a diffuse object's draw sets on the multi-draw program is a texture unit: all
    other values come from the record (a missed one would draw a group with one object's value)."""
    from conftest import SHARED_ASSETS

    scenes = [_demo_scene(), _textured_quad_scene()]
    if SHARED_ASSETS.exists():
        scenes.append(_model("WaterBottle"))
    samplers = set(TEXTURE_UNITS)
    for scene in scenes:
        renderer = _renderer(ctx, scene)
        try:
            drawer = renderer.drawer
            program = drawer.batch_program()
            for obj in drawer.objects:
                recorder = DrawRecorder(program)
                renderer.shading.set_object_state(recorder, obj, Method.parse("lobe-7"), False, None, obj.probe_centre)
                names = {name for name, _ in recorder.record().uniforms}
                assert ObjectBatches.unbatched_uniforms(names, samplers) == set(), obj.name
        finally:
            renderer.release()


def test_record_packing():
    """Fields land at their std430 offsets; mat3 columns are padded to vec4."""
    transform = np.arange(9 * 11, dtype=np.float32)
    data = pack_object_record(
        {"u_kd": np.array([1, 2, 3], np.float32).tobytes(), "u_map_transform": transform.tobytes(), "u_other": b"x"}
    )
    assert len(data) == RECORD_SIZE and RECORD_SIZE % 16 == 0
    floats = np.frombuffer(data, dtype=np.float32)
    kd = RECORD_OFFSETS["u_kd"][0] // 4
    assert floats[kd : kd + 3].tolist() == [1, 2, 3]
    start = RECORD_OFFSETS["u_map_transform"][0] // 4
    columns = floats[start : start + 11 * 12].reshape(33, 4)
    np.testing.assert_array_equal(columns[:, :3].ravel(), transform)
    assert np.all(columns[:, 3] == 0)
    with pytest.raises(ValueError, match="u_kd"):
        pack_object_record({"u_kd": bytes(8)})


def test_materials_sharing_a_lightmap_share_one_image():
    """A lightmap image several materials use is decoded and sanitised once (issue 43), so their
    objects bind one texture and share a multi-draw."""
    scene = _demo_scene()
    images = {id(m.lightmap.image) for m in scene.materials if m.lightmap is not None}
    assert sum(m.lightmap is not None for m in scene.materials) > 3
    assert len(images) == 1


def test_counted_occlusion_test_equals_one_query_per_reflector(ctx):
    """The multi-drawn occlusion test (viewer/occlusion.py: one draw, each passing fragment adding
    to its object's count) gives every reflector of the 4-room apartment exactly the samples a
    samples-passed query per reflector counts, along the recorded path, against its own depth
    pass and against the camera pass's depth pre-pass; some are hidden, some seen."""
    from lobeview.scenes.apartment import apartment_geometry, apartment_path

    scene = apartment_geometry(4)
    renderer = _renderer(ctx, scene)
    drawer = renderer.drawer
    size = (96, 60)
    path = apartment_path(4)
    seen = hidden = 0
    try:
        candidates = sorted(renderer.reflectors())
        assert len(candidates) >= 6
        for t in path.frame_times(6):
            camera = Camera.from_scene_camera(path.camera_at(float(t)))
            view_proj = camera.view_projection(size[0] / size[1])
            counted = {}
            for indirect in (False, True):
                renderer.configure(indirect_draws=indirect)
                own = drawer.visible_samples(view_proj, size, candidates)
                drawer.occlusion._targets(size)  # a pre-pass of the camera's opaque objects to read
                fbo = drawer.occlusion.fbo
                fbo.use()
                ctx.viewport = (0, 0, *size)
                fbo.clear(depth=1.0)
                drawer.draw_depth(view_proj)
                counted[indirect] = (own, drawer.visible_samples(view_proj, size, candidates, fbo))
            assert counted[True] == counted[False], t
            seen += sum(1 for n in counted[True][0].values() if n > 0)
            hidden += sum(1 for n in counted[True][0].values() if n == 0)
        assert seen > 0 and hidden > 0
    finally:
        renderer.release()
