"""The residual keeps a resolved bright source's shape beyond its cap (issue 39,
scenes/bright_sources.py Separation): the cap as drawn into the texels, the signed residual it
leaves, and a glossy sphere reading it through the real pipeline."""

from __future__ import annotations

import warnings

import numpy as np
from test_cap_lights import SUN, SUN_VIEW, _cube_faces, _power
from test_render_vs_numpy import smooth_sky

from lobeview.materials.cap_lights import edge_profile
from lobeview.materials.lobe_fit import LUMINANCE
from lobeview.scenes import bright_sources as bs
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import uv_sphere


def _sky_with_soft_box(d, scale=1.0):
    """smooth_sky and a 4 x 2.5-degree box of 2e3 around SUN with a 1-degree hot spot of 2e4 in
    one corner (angles times ``scale``): a source the cube resolves, far from a uniform disc."""
    helper = np.cross(SUN, [0.0, 0.0, 1.0])
    u, v = helper / np.linalg.norm(helper), np.cross(SUN, helper / np.linalg.norm(helper))
    x, y = np.degrees(np.sum(d * u, -1)) / scale, np.degrees(np.sum(d * v, -1)) / scale
    facing = np.sum(d * SUN, -1) > 0.0
    box = facing & (np.abs(x) < 2.0) & (np.abs(y) < 1.25)
    spot = facing & ((x - 1.2) ** 2 + (y - 0.6) ** 2 < 0.5**2)
    return smooth_sky(d) + (2e3 * box + 2e4 * spot)[..., None]


def test_the_residual_keeps_a_resolved_sources_shape_beyond_its_cap():
    """A box with a hot spot, 5.6 texels in radius on 256^2 faces: two lights, its core (the cap of
    its energy's median spread) and a cone holding the corners beyond it. The residual is the cube
    minus the core's cap as drawn into its texels, signed (the hot spot above the cap's level, the
    cap's parts beyond the box below zero), local (the cube unchanged beyond the cap), and keeps the
    corners (the cone is no light of it): a read wider than the source sees them as the cone (a
    5-degree Gaussian at the source: within 3 % of the source's power). The cube without sources
    keeps the sky's level there (>= 0). Each conserves with its lights."""
    faces = _cube_faces(_sky_with_soft_box, size=256)
    sky = _cube_faces(smooth_sky, size=256)
    separation = bs.separate_cube(faces)
    light, corners = separation.lights
    assert light.radius >= bs.SHAPE_FROM_TEXELS * 2.0 / 256 and light.inner_fraction == 1.0
    assert corners.inner_fraction == 0.0 and corners.radius > light.radius
    assert separation.kept_whole == [1] and separation.residual_lights == [light]
    total = _power(faces)
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, total, rtol=1e-4)
    assert np.allclose(_power(separation.without_sources) + separation.light_power, total, rtol=1e-4)
    assert separation.without_sources.min() >= 0.0 and separation.without_sources.max() < 10.0
    directions, solid = bs.cube_texels(faces)
    angle = np.arccos(np.clip(directions @ light.direction, -1.0, 1.0))
    detail = (separation.residual - sky).astype(np.float64)
    outside = angle > light.radius + 2.0 * 2.0 / 256  # beyond the drawn cap the cube is as it was
    assert np.array_equal(separation.residual[outside], faces[outside])
    level = float(light.radiance @ LUMINANCE)
    luminance = detail @ LUMINANCE
    assert luminance.max() > 3.0 * level  # the hot spot (2e4 + sky) stays, far above the cap's level
    assert luminance.min() < -0.5 * level  # the cap where the box is not: signed
    dirs, omega = directions.reshape(-1, 3), solid.reshape(-1)
    drawn, cone = bs.rasterised_cap(
        dirs, omega, corners.direction, corners.cos_radius, corners.power, 2.0 / 256, corners.inner_fraction
    )
    without_corners = detail.reshape(-1, 3)
    without_corners[drawn] -= cone
    wide = np.exp(-0.5 * (angle / np.radians(5.0)) ** 2).reshape(-1, 1) * omega[:, None]
    seen = np.sum(without_corners * wide, axis=0)
    source = np.sum((faces - sky).astype(np.float64).reshape(-1, 3) * wide, axis=0)
    assert np.all(np.abs(seen) < 0.03 * source), (seen, source)


def _sky_with_sun_in_glow(d):
    """smooth_sky, a 1.5-degree sun of 1e5 around SUN and a Gaussian glow about it (sigma 4 degrees,
    peak 500): the sun holds 93 % of the excess, the glow the rest, spread far out."""
    angle = np.degrees(np.arccos(np.clip(np.sum(d * SUN, -1), -1.0, 1.0)))
    return smooth_sky(d) + (1e5 * (angle < 1.5) + 500.0 * np.exp(-0.5 * (angle / 4.0) ** 2))[..., None]


def test_a_sun_in_its_glow_is_a_cap_of_the_suns_size_and_a_cone_of_its_glow():
    """A sun in its glow is two lights: a cap of the sun's 1.5 degrees (within a texel of a 256^2
    cube; the energy-weighted mean of 1 - cos, which weighs the glow by its angle squared, gave one
    cap of 2.5 degrees) holding the sun's power (within 2 %), and a cone (inner fraction 0) about
    the same axis holding the glow, wider; together they hold the source's excess over the sky but
    for the glow's tail below the threshold (> 98 %). Both cubes conserve to 1e-4; the residual
    keeps the glow's shape beyond the cone, signed."""
    faces = _cube_faces(_sky_with_sun_in_glow, size=256)
    sky = _cube_faces(smooth_sky, size=256)
    separation = bs.separate_cube(faces)
    sun_light, glow = separation.lights
    texel = 2.0 / 256
    assert abs(sun_light.radius - np.radians(1.5)) < texel, np.degrees(sun_light.radius)
    assert glow.inner_fraction == 0.0 and glow.radius > np.radians(3.0)
    assert np.allclose(glow.direction, sun_light.direction)
    directions, solid = bs.cube_texels(faces)
    angle = np.arccos(np.clip(directions @ sun_light.direction, -1.0, 1.0))
    sun = np.sum(1e5 * solid[angle < np.radians(1.5)])
    assert abs(float(sun_light.power @ LUMINANCE) / sun - 1.0) < 0.02
    source = float(_power(faces - sky) @ LUMINANCE)
    assert 0.98 < float(separation.light_power @ LUMINANCE) / source <= 1.0 + 1e-6
    total = _power(faces)
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, total, rtol=1e-4)
    assert np.allclose(_power(separation.without_sources) + separation.light_power, total, rtol=1e-4)
    # the residual loses both as drawn (the cone lies over its glow: no texel far darker than it),
    # so it keeps the glow's shape: at 3 degrees the residual plus the cone is the glow (to 0.1 %),
    # and reads wider than the sun see about nothing of it (< 1.5 % of the source's excess)
    assert separation.kept_whole == [] and separation.shapes_kept == 2
    detail = (separation.residual - sky).astype(np.float64)
    ring = (angle > np.radians(2.9)) & (angle < np.radians(3.1))
    cone = glow.radiance[0] * edge_profile((1.0 - np.cos(angle[ring])) / (1.0 - glow.cos_radius), 0.0)
    glow_excess = (faces - sky)[ring][:, 0].astype(np.float64)
    assert abs(float(np.mean(detail[ring][:, 0] + cone)) / float(np.mean(glow_excess)) - 1.0) < 1e-3
    for width in (2.0, 5.0, 10.0):
        wide = np.exp(-0.5 * (angle / np.radians(width)) ** 2)[..., None] * solid[..., None]
        seen = np.sum(detail * wide, axis=(0, 1, 2))
        assert np.all(np.abs(seen) < 0.015 * np.sum((faces - sky) * wide, axis=(0, 1, 2))), width


def test_a_rasterised_cap_carries_its_power_over_the_caps_solid_angle():
    """rasterised_cap on a 128^2 cube: a 3-degree cap across a cube edge carries exactly its power,
    at a uniform level inside (within 1 %, the texels wholly covered) that is the cap's radiance
    within 3 % (the ramp over the rim texels is the only approximation), and nothing beyond
    the rim's ramp."""
    directions, solid = bs.cube_texels(np.zeros((6, 128, 128, 3)))
    dirs, omega = directions.reshape(-1, 3), solid.reshape(-1)
    centre = np.array([1.0, 0.02, 1.0]) / np.linalg.norm([1.0, 0.02, 1.0])
    cos_radius, power = np.cos(np.radians(3.0)), np.array([3.0, 2.0, 1.0])
    texel = 2.0 / 128
    touched, radiance = bs.rasterised_cap(dirs, omega, centre, cos_radius, power, texel)
    assert np.allclose(np.sum(radiance * omega[touched, None], axis=0), power, rtol=1e-9)
    angle = np.arccos(np.clip(dirs[touched] @ centre, -1.0, 1.0))
    assert angle.max() <= np.radians(3.0) + 0.5 * texel + 1e-9
    inside = angle < np.radians(3.0) - 0.5 * texel
    cap_radiance = power / (2.0 * np.pi * (1.0 - cos_radius))
    assert np.ptp(radiance[inside, 0]) < 0.01 * radiance[inside, 0].max()
    assert np.allclose(radiance[inside].mean(axis=0), cap_radiance, rtol=0.03)
    # a cone (inner fraction 0, a glow's light) follows its profile: 1 - u of its peak, which is
    # twice its mean radiance (edge_profile), and carries its power exactly
    touched, radiance = bs.rasterised_cap(dirs, omega, centre, cos_radius, power, texel, 0.0)
    assert np.allclose(np.sum(radiance * omega[touched, None], axis=0), power, rtol=1e-9)
    u = (1.0 - dirs[touched] @ centre) / (1.0 - cos_radius)
    middle = u < 0.55  # texels wholly inside (the rim's ramp is one texel wide: 0.9 degrees)
    assert np.allclose(radiance[middle, 0], 2.0 * cap_radiance[0] * (1.0 - u[middle]), rtol=0.03)


def test_a_glossy_sphere_reads_a_soft_boxs_shape_from_the_residual():
    """Through the real pipeline: a GGX 0.05 sphere under an 8 x 5-degree box with a hot spot
    (5.6 texels of a 128^2 cube; its core and a cone of the rest), lobe-7+norm+fit with the signed
    residual against the same with the cube without sources (the caps alone: a disc and a cone),
    both against the reference; supersampled 2 x 2 (the reference's box footprints). No pixel
    negative or NaN."""
    from lobeview.bench.mitsuba import relative_rmse
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(lambda d: _sky_with_soft_box(d, 2.0), height=512, name="soft-box")
    from lobeview.bench.light import build_material
    from lobeview.viewer.camera import Camera

    bsdf = build_material("ggx:0.05")
    camera = Camera(position=tuple(3.2 * SUN_VIEW), target=(0.0, 0.0, 0.0), fov_y=40.0)  # sees the glint
    size = 48
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=(size, size), face_size=128)
        fine = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=(2 * size, 2 * size),
                               face_size=128, bright_sources=True)  # fmt: skip
    try:
        assert len(fine.cubes.lights) == 2 and fine.cubes.residual is not fine.cubes.without_sources
        reference = plain.render(camera, bsdf, "reference", spp=1024, background=False)
        luminance = reference.radiance @ LUMINANCE
        highlight = reference.mask & (luminance > 0.02 * luminance.max())
        assert highlight.sum() > 20
        errors = {}
        for label in ("residual", "without_sources"):
            keep = fine.cubes.residual
            fine.cubes.residual = getattr(fine.cubes, label)
            try:
                frame = fine.render(camera, bsdf, "lobe-7+norm+fit", background=False).radiance
            finally:
                fine.cubes.residual = keep
            assert np.all(np.isfinite(frame)) and frame.min() >= 0.0
            image = frame.reshape(size, 2, size, 2, 3).mean(axis=(1, 3))
            # over the box's highlight (the sky's reflection is the same in both)
            errors[label] = relative_rmse(image, reference.radiance, highlight)
        assert errors["residual"] < 0.9 * errors["without_sources"], errors  # measured 3.9 against 4.7 %
    finally:
        plain.release()
        fine.release()
        ctx.release()


def _sky_with_strip(d):
    """smooth_sky and a 9 x 3-degree strip of 2e3 around SUN: elongation 3 (under MAX_ELONGATION),
    so a 3.9-degree cap whose disc lies half over the sky beside the strip."""
    helper = np.cross(SUN, [0.0, 0.0, 1.0])
    u, v = helper / np.linalg.norm(helper), np.cross(SUN, helper / np.linalg.norm(helper))
    x, y = np.degrees(np.sum(d * u, -1)), np.degrees(np.sum(d * v, -1))
    strip = (np.sum(d * SUN, -1) > 0.0) & (np.abs(x) < 4.5) & (np.abs(y) < 1.5)
    return smooth_sky(d) + (2e3 * strip)[..., None]


def test_unbacked_share_is_the_caps_share_over_dark_texels():
    """A 5-degree cap over a map bright on one side of a great circle through its axis and 1000x
    darker on the other: half its solid angle is unbacked (within 3 %: the cut runs along texel
    rows of a 256^2 cube), none where the dark side is only 10x darker, all where the whole map
    is dark."""
    directions, solid = bs.cube_texels(np.zeros((6, 256, 256, 3)))
    dirs, omega = directions.reshape(-1, 3), solid.reshape(-1)
    centre = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    side = np.cross(centre, [0.0, 1.0, 0.0])
    bright = dirs @ side > 0.0
    cos_radius, radiance = np.cos(np.radians(5.0)), np.full(3, 1e3)
    for dark_level, expected in ((1.0, 0.5), (100.0, 0.0)):
        luminance = np.where(bright, 1e3, dark_level)
        share = bs.unbacked_share(dirs, omega, luminance, centre, cos_radius, radiance)
        assert abs(share - expected) < 0.03, (dark_level, share)
    assert bs.unbacked_share(dirs, omega, np.ones(len(dirs)), centre, cos_radius, radiance) == 1.0


def test_a_strip_light_stays_whole_in_the_residual_and_is_a_light_of_the_cube_without_sources():
    """A strip the cube resolves (its core's cap 6.7 texels in radius at 256^2) whose cap lies half
    over the sky (> MAX_UNBACKED_SHARE) is one source (its core and a cone of its ends: two lights),
    kept whole: the residual is the cube as it was (no signed disc for a near-mirror's reads and
    cap integral to cancel), the cube without sources loses it; each plus its lights conserves.
    The box with a hot spot (a disc's shape) keeps only its corners' cone whole."""
    faces = _cube_faces(_sky_with_strip, size=256)
    separation = bs.separate_cube(faces)
    light, ends = separation.lights  # the strip's core and a cone holding its ends
    assert light.radius >= bs.SHAPE_FROM_TEXELS * 2.0 / 256 and ends.inner_fraction == 0.0
    assert separation.kept_whole == [0, 1] and separation.residual_lights == [] and separation.shapes_kept == 0
    assert np.array_equal(separation.residual, faces)
    assert separation.without_sources.max() < 10.0
    total = _power(faces)
    assert np.allclose(_power(separation.without_sources) + separation.light_power, total, rtol=1e-4)
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, total, rtol=1e-4)
    box = bs.separate_cube(_cube_faces(_sky_with_soft_box, size=256))
    assert box.kept_whole == [1] and len(box.residual_lights) == 1 and box.shapes_kept == 1


def test_a_near_mirror_under_a_strip_light_has_no_clamped_pixel():
    """Through the real pipeline, a GGX 0.01 sphere (200 px, one point per pixel) under the strip:
    lobe-7+norm+fit reads it from the residual, whole, and no pixel has a channel at 0 (the strip
    as a signed disc in the residual left 5 there: the cap integral and the reads did not cancel
    over the sky beside the strip); prefiltered binds the strip as its light. Both within 3 % of
    the reference's mean over the sphere (96 px; nothing counted twice or lost)."""
    from lobeview.bench.light import build_material
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(_sky_with_strip, height=512, name="strip")
    camera = Camera(position=tuple(3.2 * SUN_VIEW), target=(0.0, 0.0, 0.0), fov_y=40.0)  # sees the strip
    bsdf = build_material("ggx:0.01")
    renderers = {}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for size, lights in ((200, True), (96, True), (96, False)):
                renderers[size, lights] = PreviewRenderer(
                    ctx, env, uv_sphere(rings=64, segments=128), size=(size, size), face_size=256, bright_sources=lights
                )
        cubes = renderers[200, True].cubes
        assert len(cubes.lights) == 2 and cubes.residual_lights == [] and cubes.residual is cubes.radiance
        sharp = renderers[200, True].render(camera, bsdf, "lobe-7+norm+fit", background=False)
        assert sharp.mask.sum() > 20000
        assert not (sharp.radiance[sharp.mask] <= 0.0).any()
        reference = renderers[96, False].render(camera, bsdf, "reference", spp=512, background=False)
        mean = (reference.radiance[reference.mask] @ LUMINANCE).mean()
        for method in ("lobe-7+norm+fit", "prefiltered"):
            frame = renderers[96, True].render(camera, bsdf, method, background=False)
            assert np.all(np.isfinite(frame.radiance)) and frame.radiance.min() >= 0.0
            ratio = (frame.radiance[frame.mask] @ LUMINANCE).mean() / mean
            assert abs(ratio - 1.0) < 0.03, (method, ratio)
    finally:
        for renderer in renderers.values():
            renderer.release()
        ctx.release()
