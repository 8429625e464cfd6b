"""Reflectors in one plane share its mirror pass (issue 42; scenes/planar_mirror.py
coplanar_groups, viewer/mirror_pass.py): an apartment's floors are one pass, not one per room.
Sharing changes no pixel of a floor split in two (its halves read the same buffer the whole floor
would), and it removes what a pass per reflector drew: each half's buffer showed the other half,
which lies in the pass's oblique near plane (a black band along the seam)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from lobeview.core.methods import Method
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import quad
from lobeview.scenes.mirror_scene import CAMERA, FLOOR_HALF, floor_material, mirror_floor_scene
from lobeview.scenes.planar_mirror import (
    PLANAR_TOLERANCE,
    PlanarReflector,
    coplanar_groups,
    reflector_max_view_angle,
    reflector_max_view_angles,
)
from lobeview.scenes.scene import SceneMaterial, SceneObject
from lobeview.viewer.camera import Camera

SIZE = (120, 80)


def _reflector(normal, offset, low, high, transmission=False) -> PlanarReflector:
    normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    return PlanarReflector(
        np.append(normal, offset), np.asarray(low, float), np.asarray(high, float), transmission=transmission
    )


def test_coplanar_groups_join_one_plane_seen_from_one_side_with_the_same_passes():
    floor = (0.0, 1.0, 0.0)
    reflectors = {
        3: _reflector(floor, 0.0, (0, 0, 0), (4, 0, 4)),  # room A's floor
        7: _reflector(floor, 0.0, (5, 0, 0), (9, 0, 4)),  # room B's floor, same plane
        8: _reflector(floor, -0.75, (1, 0.75, 1), (2, 0.75, 2)),  # a table top above it
        9: _reflector(floor, 0.5 * PLANAR_TOLERANCE * 20.0, (0, 0, 5), (4, 0, 9)),  # within the tolerance
        10: _reflector(floor, 3.0 * PLANAR_TOLERANCE * 20.0, (5, 0, 5), (9, 0, 9)),  # beyond it
        11: _reflector((0.0, -1.0, 0.0), 0.0, (0, 0, 10), (4, 0, 14)),  # the same plane seen from below
        12: _reflector((np.sin(2 * PLANAR_TOLERANCE), 1.0, 0.0), 0.0, (0, 0, 15), (4, 0, 19)),  # tilted
        13: _reflector(floor, 0.0, (5, 0, 10), (9, 0, 14), transmission=True),  # a pane: other passes
        2: _reflector((0.0, 0.0, 1.0), 4.0, (0, 0, -4), (4, 3, -4)),  # a wall
    }
    groups = coplanar_groups(reflectors, scene_diagonal=20.0)
    assert groups == [(2,), (3, 7, 9), (8,), (10,), (11,), (12,), (13,)]
    assert sorted(i for group in groups for i in group) == sorted(reflectors)
    assert coplanar_groups({}, 1.0) == []


def test_view_angle_bounds_of_many_reflectors_are_the_single_ones():
    rng = np.random.default_rng(5)
    reflectors = []
    for _ in range(40):
        normal = rng.normal(size=3)
        low = rng.uniform(-5, 5, 3)
        reflectors.append(_reflector(normal, rng.uniform(-2, 2), low, low + rng.uniform(0, 4, 3)))
    eye = rng.uniform(-6, 6, 3)
    many = reflector_max_view_angles(reflectors, eye)
    for reflector, angle in zip(reflectors, many, strict=True):
        # the definition: the farthest of the box's corners, one at a time
        height = abs(float(reflector.side(eye)))
        farthest = float(np.max(np.linalg.norm(reflector.corners() - eye, axis=1)))
        exact = np.arccos(np.clip(height / farthest, 0.0, 1.0))
        cap = np.radians(89.0)  # MIRROR_FOOTPRINT_MAX_VIEW_ANGLE; bounds rounded up to 2-degree steps
        assert min(exact, cap) <= angle + 1e-12 and angle <= min(exact + np.radians(2.0), cap) + 1e-9
        assert reflector_max_view_angle(reflector, eye) == pytest.approx(angle, abs=1e-12)
    assert reflector_max_view_angles([], eye).shape == (0,)


def _split_floor_scene(right_roughness: float | None = None, wall: bool = False):
    """mirror_floor_scene(0.05) with its floor cut into two halves along x = 0 (two reflectors
    in one plane); ``right_roughness``: the right half gets its own, polished material; ``wall``:
    with the glossy back wall (a reflector in another plane)."""
    scene = mirror_floor_scene(0.05, extra_reflector=wall)
    lightmap = scene.materials[0].lightmap
    left = quad([-FLOOR_HALF, 0.0, FLOOR_HALF], [FLOOR_HALF, 0.0, 0.0], [0.0, 0.0, -2 * FLOOR_HALF])
    right = quad([0.0, 0.0, FLOOR_HALF], [FLOOR_HALF, 0.0, 0.0], [0.0, 0.0, -2 * FLOOR_HALF])
    scene.objects[0] = SceneObject("left floor", left, 0, left.uvs.copy())
    material = 0
    if right_roughness is not None:
        scene.materials.append(SceneMaterial("polished floor", floor_material(right_roughness), lightmap=lightmap))
        material = len(scene.materials) - 1
    scene.objects.append(SceneObject("right floor", right, material, right.uvs.copy()))
    return scene


def _render(ctx, scene, share: bool):
    """(lobe-7 radiance, object ids, report, passes drawn, left half's mirror radiance buffer)."""
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    sky = EnvironmentMap.from_function(
        lambda d: np.where(d[..., 1:2] > 0.3, np.array([4.0, 3.5, 3.0]), np.full(3, 0.5)), height=32, name="sky"
    )
    settings = RenderSettings(cube_face_size=32, mirror_plane_sharing=share)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the floors' missing tangents and the like
        renderer = SceneRenderer(ctx, scene, sky, size=SIZE, progress=False, settings=settings)
    try:
        camera = Camera(tuple(CAMERA.position), tuple(CAMERA.target), tuple(CAMERA.up), CAMERA.fov_y)
        result = renderer.render(camera, Method.parse("lobe-7"))
        targets = renderer.mirror_passes.targets[(0, "mirror")]
        buffer = np.frombuffer(targets.radiance.read(), np.float32).reshape(targets.size[1], targets.size[0], 4)
        return (
            result.radiance[..., :3].astype(np.float64),
            result.object_id,
            list(renderer.mirror_report),
            renderer.mirror_passes.drawn_passes,
            buffer[..., :3].copy(),
        )
    finally:
        renderer.release()


def test_a_split_floor_shares_one_pass_and_renders_as_the_whole_floor(ctx):
    whole, whole_ids, _, whole_passes, _ = _render(ctx, mirror_floor_scene(0.05), True)
    split, split_ids, report, passes, _ = _render(ctx, _split_floor_scene(), True)
    assert whole_passes == 1 and passes == 1
    assert report == ["left floor: mirror pass 120x80", "right floor: mirror pass 120x80 (shared with left floor)"]
    floor = (whole_ids == 0) & np.isin(split_ids, (0, 4))
    assert floor.sum() > 0.3 * floor.size
    rel = np.sqrt(np.mean((split[floor] - whole[floor]) ** 2)) / whole[floor].mean()
    assert rel < 1e-4, rel  # measured 1e-6: the same buffer read by the same lookups
    _, _, unshared_report, unshared_passes, _ = _render(ctx, _split_floor_scene(), False)
    assert unshared_passes == 2 and not any("shared" in line for line in unshared_report)


def test_a_shared_pass_never_shows_its_own_plane(ctx):
    """Different materials on the halves, and the glossy wall: the left (rough) half's pixels are
    those of the whole rough floor, and its buffer holds no texel of the right half (kd 0 and no
    cube map: black). With a pass each, the right half lies in the left's oblique near plane,
    where rounding decides whether it is drawn: here (llvmpipe) it is, over the buffer's right
    half, and the left half's reflection goes dark along the seam."""
    whole, whole_ids, *_ = _render(ctx, mirror_floor_scene(0.05, extra_reflector=True), True)
    shared, ids, report, passes, buffer = _render(ctx, _split_floor_scene(right_roughness=0.01, wall=True), True)
    unshared, unshared_ids, _, unshared_passes, unshared_buffer = _render(
        ctx, _split_floor_scene(right_roughness=0.01, wall=True), False
    )
    assert passes == 2 and unshared_passes == 3  # the wall's own
    black = lambda image: np.all(image <= 1e-6, axis=-1).mean()  # noqa: E731
    assert black(buffer) == 0.0
    assert black(unshared_buffer) > 0.05  # measured: the right half of the buffer
    left = (whole_ids == 0) & (ids == 0) & (unshared_ids == 0)
    error = {
        name: np.sqrt(np.mean((image[left] - whole[left]) ** 2)) / whole[left].mean()
        for name, image in (("shared", shared), ("unshared", unshared))
    }
    assert error["shared"] < 1e-4 and error["unshared"] > 0.03, error  # measured 2e-6 / 0.09


def test_only_the_reflectors_given_a_pass_have_their_lookups_bounded(ctx, monkeypatch):
    """A frame finds the lobe-N lookups' reach (scissor) and finest footprint (buffer size) for
    the reflectors that get a pass, not for every reflector of the scene (a per-object Python
    loop in an otherwise per-pass frame, issue 42); the report still names the others and why."""
    from lobeview.viewer.mirror_pass import MirrorPasses
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    asked = []
    for name in ("lobe_spread", "finest_footprint"):
        original = getattr(MirrorPasses, name)

        def counted(self, index, *args, _original=original, _name=name):
            asked.append((_name, index))
            return _original(self, index, *args)

        monkeypatch.setattr(MirrorPasses, name, counted)
    scene = _split_floor_scene(right_roughness=0.01, wall=True)
    names = [obj.name for obj in scene.objects]
    left, right, wall = (names.index(name) for name in ("left floor", "right floor", "glossy wall"))
    sky = EnvironmentMap.from_function(lambda d: np.full(d.shape[:-1] + (3,), 0.5), height=16, name="grey")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(ctx, scene, sky, size=SIZE, progress=False, settings=RenderSettings(cube_face_size=16))
    try:
        down = Camera((0.0, 1.5, 3.0), (0.0, 0.0, 2.5), (0.0, 1.0, 0.0), CAMERA.fov_y)  # the wall out of view
        renderer.render(down, Method.parse("lobe-7"), spp=1)
        assert set(renderer.mirror_passes.drawn) == {left, right}
        assert {index for _, index in asked} == {left, right}
        assert {name for name, _ in asked} == {"lobe_spread", "finest_footprint"}
        assert renderer.mirror_passes.skipped == {wall: "outside the view"}
        assert "glossy wall: no mirror pass (outside the view)" in renderer.mirror_report
        assert renderer.mirror_report[0] == "left floor: mirror pass " + renderer.mirror_report[0].split(" pass ")[1]
    finally:
        renderer.release()
