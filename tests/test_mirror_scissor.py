"""Scissored mirror passes (issue 18; scenes/planar_mirror.py mirror_scissor, materials/lobe_spread.py
lobe_spread): the screen rectangle of a reflector's box against projected points (also when it
reaches behind the eye), the lobes' spread against the lookups lobe_samples makes, and on the GPU a
frame whose passes are scissored equal to the frame without, with pixels actually saved, while a
scissor without the lookups' margin changes the frame (so the margin is what keeps it exact)."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.core.methods import Method
from lobeview.materials.lobe_spread import lobe_spread
from lobeview.materials.patterns import (
    choose_pattern,
    ggx_tail_lookups,
    lobe_directions,
    lobe_sample_area,
    lobe_samples,
    specular_lobes,
)
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import build_bsdf
from lobeview.materials.vec import spherical_direction
from lobeview.scenes import planar_mirror
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.mirror_scene import mirror_floor_scene
from lobeview.viewer.camera import Camera, look_at, perspective


@pytest.mark.parametrize("eye", [(0.0, 1.0, 8.0), (0.3, 0.5, 0.5)])  # whole box in front / box around the eye
def test_box_screen_rect_bounds_every_visible_point_of_the_box(eye):
    rng = np.random.default_rng(1)
    lo, hi = np.array([-2.0, 0.0, -3.0]), np.array([2.0, 0.05, 1.0])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    size = (320, 200)
    view_projection = perspective(60.0, 1.6, 0.05, 100.0) @ look_at(eye, (0.0, 0.0, -2.0), (0.0, 1.0, 0.0))
    rect = planar_mirror.box_screen_rect(corners, view_projection, size)
    assert rect is not None
    points = lo + rng.random((20000, 3)) * (hi - lo)
    clip = np.concatenate([points, np.ones((len(points), 1))], axis=1) @ view_projection.T
    front = clip[:, 3] > 1e-3
    xy = (clip[front, :2] / clip[front, 3:4] * 0.5 + 0.5) * np.array(size)
    x0, y0, x1, y1 = rect
    assert np.all(xy[:, 0] >= x0 - 1e-6) and np.all(xy[:, 0] <= x1 + 1e-6)
    assert np.all(xy[:, 1] >= y0 - 1e-6) and np.all(xy[:, 1] <= y1 + 1e-6)
    if eye[2] > 5.0:  # seen whole from afar: the rectangle is tight around the points
        assert xy[:, 0].min() - x0 < 2.0 and x1 - xy[:, 0].max() < 2.0


def test_box_rects_of_many_boxes_are_the_single_ones():
    """box_screen_rects (the shared passes' members at once) against box_screen_rect's pairwise
    edges: boxes in front, around and behind the eye, some flat in an axis."""
    from lobeview.viewer.camera import box_corners

    rng = np.random.default_rng(4)
    low = rng.uniform(-6.0, 6.0, (500, 3))
    high = low + rng.uniform(0.0, 4.0, (500, 3)) * (rng.uniform(size=(500, 3)) > 0.25)
    view_projection = perspective(60.0, 1.6, 0.05, 100.0) @ look_at((0.5, 1.0, 2.0), (0.0, 0.0, -2.0), (0, 1, 0))
    rects = planar_mirror.box_screen_rects(low, high, view_projection, (320, 200))
    behind = 0
    for a, b, rect in zip(low, high, rects, strict=True):
        single = planar_mirror.box_screen_rect(box_corners(a, b), view_projection, (320, 200))
        if single is None:
            behind += 1
            assert np.isnan(rect).all()
        else:
            np.testing.assert_allclose(rect, single, rtol=1e-9, atol=1e-9)  # 1e-11 apart near the eye
    assert 20 < behind < 480


@pytest.mark.parametrize("preset", ["lacquer", "plastic", "gold-ggx", "frosted-glass", "alanod-2000gs-2lobe"])
@pytest.mark.parametrize("n", [3, 7, 15])
def test_lobe_spread_covers_every_lookup(preset, n):
    """Every pattern direction (and GGX tail lookup) of lobe_samples at random views lies within
    the spread's angle of its lobe's centre direction, every footprint within its solid angle."""
    rng = np.random.default_rng(n)
    lobes = specular_lobes(build_bsdf(PRESETS[preset]))
    angle, solid_angle = lobe_spread(lobes, n, normalize=True)
    for lobe in lobes:
        for _ in range(40):
            wo = spherical_direction(np.array(rng.uniform(0.0, np.radians(89.0))), np.array(rng.uniform(0, 2 * np.pi)))
            centre, _ = lobe_directions(lobe, wo, np.array([[0.0, 0.0, 1.0]]))
            dist = lobe.distribution
            kind = choose_pattern(dist.alpha_x, dist.alpha_y, planar=True, n=n)  # a reflector's pattern
            samples = lobe_samples(lobe, wo, n, kind=kind)
            wi = samples.wi[samples.valid]
            if lobe.distribution.kind == "ggx":
                wi = np.concatenate([wi, ggx_tail_lookups(lobe, wo)[0]])
            if len(wi):
                assert np.degrees(np.arccos(np.clip(wi @ centre[0], -1, 1)).max()) <= np.degrees(angle) + 0.5
            assert lobe_sample_area(lobe.distribution, wo, n) <= solid_angle * (1 + 1e-9)


def test_spread_is_unbounded_for_sampled_patterns():
    from lobeview.materials.rational_brdf import RationalLobe

    class Sampled:  # stands in for a RationalLobe, whose lookups filter by 1 / (N p)
        sampled_pattern = RationalLobe.sampled_pattern

    assert Sampled.sampled_pattern and lobe_spread([Sampled()], 7, True) is None


GREY = 0.5
SIZE = (320, 200)
FAR = Camera(position=(0.0, 2.0, 16.0), target=(0.0, 0.4, -1.0), up=(0.0, 1.0, 0.0), fov_y=40.0)
FLOOR_ROUGHNESS = 0.01  # polished: a margin of ~20 px; the glossy wall (0.05) reaches further


@pytest.fixture(scope="module")
def far_floor():
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    ctx = create_headless_context()
    sky = EnvironmentMap.from_function(
        lambda d: np.where(d[..., 1:2] > 0.3, np.array([4.0, 3.5, 3.0]), np.full(3, GREY)), height=32, name="sky"
    )
    scene = mirror_floor_scene(FLOOR_ROUGHNESS, extra_reflector=True)
    renderer = SceneRenderer(ctx, scene, sky, size=SIZE, progress=False, settings=RenderSettings(cube_face_size=32))
    yield renderer
    renderer.release()
    ctx.release()


def _frame(renderer, method: str, scissor: bool):
    renderer.configure(mirror_scissor=scissor)
    renderer.invalidate_mirrors()
    result = renderer.render(FAR, Method.parse(method))
    return result.radiance, dict(renderer.mirror_passes.scissored_pixels), list(renderer.mirror_report)


@pytest.mark.parametrize("method", ["lobe-3+norm", "lobe-7+norm", "lobe-15+norm", "lobe-7+eq4.24"])
def test_scissored_passes_leave_the_frame_unchanged_and_save_pixels(far_floor, method):
    whole, saved_off, _ = _frame(far_floor, method, False)
    scissored, saved, report = _frame(far_floor, method, True)
    assert saved_off == {} or sum(saved_off.values()) == 0
    assert sum(saved.values()) > 0.5 * SIZE[0] * SIZE[1], report  # the far floor's pass: most pixels skipped
    assert any("scissored to" in line for line in report)
    np.testing.assert_array_equal(scissored, whole)


def test_scissor_without_the_lookups_margin_changes_the_frame(far_floor, monkeypatch):
    """The margin is what keeps the frame exact: the bare screen rectangle of each reflector
    changes pixels of the glossy floor (its lookups read the buffer beyond its own image)."""
    whole, _, _ = _frame(far_floor, "lobe-7+norm", False)

    def bare(reflectors, camera, spreads, lod_bias):  # mirror_scissors without the reach
        rects = []
        for reflector in reflectors:
            x0, y0, x1, y1 = planar_mirror.box_screen_rect(
                reflector.corners(), camera.plain_view_projection, camera.size
            )
            x0, y0 = max(int(x0), 0), max(int(y0), 0)
            rects.append(
                (
                    x0,
                    y0,
                    max(min(int(np.ceil(x1)), camera.size[0]) - x0, 1),
                    max(min(int(np.ceil(y1)), camera.size[1]) - y0, 1),
                )
            )
        return rects

    monkeypatch.setattr(planar_mirror, "mirror_scissors", bare)
    bare_frame, _, _ = _frame(far_floor, "lobe-7+norm", True)
    changed = np.abs(bare_frame - whole).max(axis=-1) > 1e-3 * np.maximum(whole.max(axis=-1), 1e-3)
    assert changed.sum() > 20


def test_unbounded_methods_draw_whole_passes(far_floor):
    for method in ("fis-8", "mc-4"):
        _, saved, report = _frame(far_floor, method, True)
        assert sum(saved.values()) == 0 and not any("scissored" in line for line in report)
