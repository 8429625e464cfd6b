"""Mirror buffers at the resolution their lobes read (issue 42; scenes/planar_mirror.py
mirror_buffer_levels and reflector_max_view_angle, viewer/mirror_pass.py): the view-angle bound
against points sampled on a reflector, the finest lookup footprint of the coarse view grid against
random views below the bound, the level rule against the shaders' MIP level, and on the GPU a
rough floor whose halved buffers change the frame within a stated bound and not its error against
refinement, while a near-mirror keeps its full buffer."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.core.methods import Method
from lobeview.materials.lobe_spread import finest_sample_solid_angle
from lobeview.materials.patterns import lobe_sample_area, specular_lobes, wide_lobe_footprint_scale
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import build_bsdf
from lobeview.materials.vec import spherical_direction
from lobeview.scenes import planar_mirror
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.mirror_scene import mirror_floor_scene
from lobeview.viewer.camera import Camera


def _floor(lo=(-3.0, 0.0, -5.0), hi=(3.0, 0.0, 1.0)):
    return planar_mirror.PlanarReflector(np.array([0.0, 1.0, 0.0, 0.0]), np.array(lo), np.array(hi))


@pytest.mark.parametrize("eye", [(0.0, 1.6, 2.0), (2.5, 0.3, -4.0), (0.0, 8.0, -2.0), (10.0, 1.0, 10.0)])
def test_max_view_angle_bounds_every_point_of_the_reflector(eye):
    rng = np.random.default_rng(3)
    floor = _floor()
    bound = planar_mirror.reflector_max_view_angle(floor, eye)
    points = floor.box_min + rng.random((20000, 3)) * (floor.box_max - floor.box_min)
    to_eye = np.asarray(eye) - points
    angles = np.arccos(np.abs(to_eye[:, 1]) / np.linalg.norm(to_eye, axis=1))
    assert angles.max() <= bound + 1e-9
    # a flat box: its farthest corner lies on the plane, so the bound is the rounding step at most
    assert bound - angles.max() <= planar_mirror.MIRROR_VIEW_ANGLE_STEP + 1e-3 or bound == pytest.approx(
        planar_mirror.MIRROR_FOOTPRINT_MAX_VIEW_ANGLE
    )


@pytest.mark.parametrize("preset", ["plastic", "gold-ggx", "lacquer", "brushed-steel-beckmann"])
@pytest.mark.parametrize("n", [3, 7, 15])
@pytest.mark.parametrize("max_degrees", [60.0, 80.0, 89.0])
def test_finest_footprint_bounds_random_views(preset, n, max_degrees):
    """finest_sample_solid_angle looks at 6 view angles and 2 azimuths; no view below the bound,
    at any azimuth, has a smaller lookup (the buffer would be too coarse for it)."""
    rng = np.random.default_rng(n)
    lobes = specular_lobes(build_bsdf(PRESETS[preset]))
    max_angle = np.radians(max_degrees)
    finest = finest_sample_solid_angle(lobes, n, max_angle)
    for lobe in lobes:
        dist = lobe.distribution
        for _ in range(60):
            wo = spherical_direction(np.array(rng.uniform(0.0, max_angle)), np.array(rng.uniform(0.0, 2 * np.pi)))
            area = lobe_sample_area(dist, wo, n) / wide_lobe_footprint_scale(dist)
            assert area >= finest * (1.0 - 1e-6), (preset, n, max_degrees)


def test_levels_follow_the_shaders_mip_level():
    focal, bias = 800.0, -1.0
    assert planar_mirror.mirror_buffer_levels(None, focal, bias) == 0
    assert planar_mirror.mirror_buffer_levels(1e-7, focal, bias) == 0  # a near-mirror reads level 0
    assert planar_mirror.mirror_buffer_levels(1.0, focal, bias) == planar_mirror.MIRROR_MAX_COARSE_LEVELS
    margin = planar_mirror.MIRROR_CONTACT_MARGIN_LEVELS
    for omega in np.geomspace(1e-6, 1.0, 40):
        k = planar_mirror.mirror_buffer_levels(omega, focal, bias)
        # incident.glsl buffer_incident at an environment hit on the axis: the level the lookup
        # reads in a buffer halved k times (focal / 2^k) keeps the margin above level 0
        lod_halved = 0.5 * np.log2(omega * (focal / 2**k) ** 2) + bias
        assert k == 0 or lod_halved >= margin - 1e-9
        # and one more halving would break it (or k is at its cap)
        lod_more = 0.5 * np.log2(omega * (focal / 2 ** (k + 1)) ** 2) + bias
        assert lod_more < margin or k == planar_mirror.MIRROR_MAX_COARSE_LEVELS


SIZE = (640, 400)
CAMERA = Camera(position=(0.0, 2.0, 6.0), target=(0.0, 0.4, -1.0), up=(0.0, 1.0, 0.0), fov_y=40.0)


@pytest.fixture(scope="module")
def context():
    from lobeview.viewer.context import create_headless_context

    ctx = create_headless_context()
    yield ctx
    ctx.release()


def _frames(ctx, roughness: float):
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    sky = EnvironmentMap.from_function(
        lambda d: np.where(d[..., 1:2] > 0.3, np.array([4.0, 3.5, 3.0]), np.full(3, 0.5)), height=32, name="sky"
    )
    renderer = SceneRenderer(
        ctx, mirror_floor_scene(roughness), sky, size=SIZE, progress=False, settings=RenderSettings(cube_face_size=32)
    )
    frames, levels, reports = {}, {}, {}
    try:
        for sized in (True, False):
            renderer.configure(mirror_lobe_sizes=sized)
            renderer.invalidate_mirrors()
            result = renderer.render(CAMERA, Method.parse("lobe-7"))
            frames[sized] = result.radiance[..., :3].astype(np.float64)
            levels[sized] = dict(renderer.mirror_passes.coarse_levels)
            reports[sized] = list(renderer.mirror_report)
        floor = result.object_id == 0
        # the truth the halving is judged by: refinement (every buffer at full size)
        reference = renderer.render(CAMERA, Method.parse("reference"), spp=64, pixel_filter="point")
        frames["reference"] = reference.radiance[..., :3].astype(np.float64)
    finally:
        renderer.release()
    return frames, levels, reports, floor


def test_rough_floor_gets_a_smaller_buffer_and_the_same_frame(context):
    frames, levels, reports, floor = _frames(context, 0.3)
    assert max(levels[True].values()) >= 1, reports[True]
    assert set(levels[False].values()) == {0}
    assert any(f"mirror pass {SIZE[0] // 2}x{SIZE[1] // 2}" in line or f"{SIZE[0] // 4}x{SIZE[1] // 4}" in line
               for line in reports[True]), reports[True]  # fmt: skip
    sized, full = frames[True], frames[False]
    assert np.all(np.isfinite(sized))
    # The halved buffer differs at edges and contacts (its position and normal buffers are read
    # at the nearest texel; measured 1.5 % of the frame at 1/4 and at 1/2 size) ...
    rel_rmse = np.sqrt(np.mean((sized - full) ** 2)) / full.mean()
    assert 0.0 < rel_rmse < 0.03, rel_rmse
    # ... which is within lobe-7's own error on this floor (18 %): against refinement the floor
    # is as accurate with the small buffer as with the full one (measured 18.09 against 18.15 %).
    truth = frames["reference"][floor]

    def error(image):
        return np.sqrt(np.mean((image[floor] - truth) ** 2)) / truth.mean()

    assert error(sized) < error(full) + 0.005, (error(sized), error(full))


def test_near_mirror_floor_keeps_its_full_buffer(context):
    frames, levels, _, _ = _frames(context, 0.01)
    assert set(levels[True].values()) == {0}
    np.testing.assert_array_equal(frames[True], frames[False])


def test_view_angle_bounds_hold_every_bound_the_reflector_gives():
    """The mirror passes tabulate the footprint at mirror_view_angle_bounds: every bound that
    reflector_max_view_angle returns must be one of them (else a frame computes it anew)."""
    rng = np.random.default_rng(11)
    floor = _floor()
    bounds = {round(float(b), 6) for b in planar_mirror.mirror_view_angle_bounds()}
    eyes = rng.uniform(-12.0, 12.0, (400, 3))
    eyes[:, 1] = rng.uniform(0.001, 12.0, 400)
    for eye in eyes:
        assert round(planar_mirror.reflector_max_view_angle(floor, eye), 6) in bounds
    ascending = planar_mirror.mirror_view_angle_bounds()
    assert np.all(np.diff(ascending) > 0)
    assert ascending[-1] == pytest.approx(planar_mirror.MIRROR_FOOTPRINT_MAX_VIEW_ANGLE)


def test_mirror_passes_footprint_table_matches_one_bound_at_a_time(context):
    """viewer/mirror_pass.py tabulates a reflector's finest footprint over every bound in one
    numpy pass: each entry equals finest_sample_solid_angle of that bound alone, and a bound off
    the grid is computed as asked."""
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    sky = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=16, name="white")
    renderer = SceneRenderer(
        context, mirror_floor_scene(0.3), sky, size=(64, 40), progress=False,
        settings=RenderSettings(cube_face_size=16),
    )  # fmt: skip
    try:
        passes = renderer.mirror_passes
        reflectors = renderer.reflectors()
        assert reflectors
        for index in reflectors:
            lobes = specular_lobes(build_bsdf(renderer.drawer.material_of(index).desc))
            for n in (3, 7, 15):
                method = Method.parse(f"lobe-{n}")
                for bound in list(planar_mirror.mirror_view_angle_bounds()) + [0.7, 1.5]:
                    expected = finest_sample_solid_angle(lobes, n, bound)
                    assert passes.finest_footprint(index, method, bound) == pytest.approx(expected, rel=1e-12)
            assert passes.finest_footprint(index, Method.parse("fis-16"), 1.0) is None
    finally:
        renderer.release()


def test_a_planes_buffers_of_each_size_are_reused_and_the_frame_is_the_same(context):
    """Switching a pass between sizes (its lobes' level, the window's render scale) takes the
    buffers of the size it had before instead of allocating new ones (viewer/mirror_pass.py
    SPARE_SIZES), and a frame drawn in reused buffers is the frame drawn in new ones."""
    from lobeview.viewer.mirror_pass import SPARE_SIZES
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    sky = EnvironmentMap.from_function(lambda d: 0.5 + 3.0 * np.clip(d[..., 1:2], 0, 1) * np.ones(3), 32)
    renderer = SceneRenderer(context, mirror_floor_scene(0.3), sky, size=SIZE, progress=False,
                             settings=RenderSettings(cube_face_size=32))  # fmt: skip
    passes = renderer.mirror_passes
    try:

        def frame(sized: bool):
            renderer.configure(mirror_lobe_sizes=sized)
            renderer.invalidate_mirrors()
            image = renderer.render(CAMERA, Method.parse("lobe-7")).radiance.copy()
            return image, {key: (t, t.size) for key, t in passes.targets.items()}

        first, small = frame(True)
        _, full = frame(False)
        again, small_again = frame(True)
        assert small and all(small[key][1] != full[key][1] for key in small)  # the sizes did change
        assert all(small_again[key][0] is small[key][0] for key in small)  # the same buffers, not new ones
        np.testing.assert_array_equal(again, first)
        for scale in (0.9, 0.8, 0.7, 0.6, 0.5):  # a render scale's many sizes: the spares stay bounded
            renderer.configure(mirror_scale=scale)
            frame(True)
        assert all(len(spare) <= SPARE_SIZES for spare in passes._spare.values())
    finally:
        renderer.release()
    assert not passes.targets and not passes._spare
