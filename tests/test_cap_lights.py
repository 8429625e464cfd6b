"""Bright-source separation and cap lights (issue 39, steps 1-2): materials/cap_lights.py against
independent integrals, scenes/bright_sources.py's conservation and choices, and the shaders'
light term (shaders/cap_lights.glsl) against its numpy twin through the real pipeline."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import SHARED_ASSETS
from test_render_vs_numpy import CAMERA, SIZE, _frame, _pixels, smooth_sky

from lobeview.core.cube_layout import face_directions
from lobeview.materials.cap_lights import CapLight, brute_force_cap_light, integrate_cap_light
from lobeview.materials.patterns import specular_lobes
from lobeview.materials.spec import build_bsdf, load_material, validate
from lobeview.materials.vec import reflect
from lobeview.scenes import bright_sources as bs
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import uv_sphere

GOLD = {"type": "conductor", "eta": [0.143, 0.374, 1.442], "k": [3.983, 2.385, 1.603]}


def _microfacet(kind: str, alpha: float):
    desc = {"model": "microfacet", "distribution": kind, "alpha_u": alpha, "alpha_v": alpha, "fresnel": GOLD}
    return specular_lobes(build_bsdf(validate(desc)))[0]


def _lobes():
    yield "ggx 0.01", _microfacet("ggx", 0.01)
    yield "ggx 0.1", _microfacet("ggx", 0.1)
    yield "ggx 0.5", _microfacet("ggx", 0.5)
    yield "beckmann 0.3", _microfacet("beckmann", 0.3)
    yield "thesis", specular_lobes(build_bsdf(load_material("frosted-glass")))[0]
    gltf = {"model": "gltf", "base_color": [0.9, 0.6, 0.3], "metallic": 0.3, "roughness": 0.4, "clearcoat": 1.0,
            "clearcoat_roughness": 0.05}  # fmt: skip
    for lobe in specular_lobes(build_bsdf(validate(gltf))):
        yield f"glTF {type(lobe).__name__}", lobe


def _monte_carlo(lobe, wo, light, n=200_000, seed=0):
    """The cap integral by random two-strategy MIS (an independent estimator: random points, not
    the lattice, uniform over the cap whatever its edge profile; unbiased for any lobe, resolved
    where the dense grid is not)."""
    rng = np.random.default_rng(seed)
    total = np.zeros(3)
    wi_cap = light.points(rng.random(n), rng.random(n))
    wi_lobe = lobe.sample_wi(rng.random(n), rng.random(n), np.broadcast_to(wo, (n, 3)))
    for wi, inside in ((wi_cap, np.ones(n, bool)), (wi_lobe, light.contains(wi_lobe))):
        wo_b = np.broadcast_to(wo, wi.shape)
        f, p = lobe.eval(wi, wo_b), lobe.pdf(wi, wo_b)
        denominator = n / light.solid_angle + n * p
        h = np.where(inside, light.profile(wi), 0.0) * np.abs(wi[:, 2])
        weight = np.where(inside & (denominator > 0), h / np.where(denominator > 0, denominator, 1), 0)
        total += np.sum(f * weight[:, None], axis=0)
    return total * light.radiance


@pytest.mark.parametrize(("name", "lobe"), list(_lobes()), ids=[name for name, _ in _lobes()])
def test_cap_light_integral_against_independent_estimates(name, lobe):
    """integrate_cap_light for caps of 0.1-30 degrees at and 10 degrees off the mirror direction,
    views at 0 / 45 / 75 degrees: with 32 + 32 points within 6 % of a 200 000-sample random MIS
    estimate (which itself agrees with a 300 x 600 midpoint rule over the cap where that rule
    resolves the lobe), and with the shaders' 8 + 8 within 15 % (measured worst 11.5 %)."""
    for theta_o in (0.0, 45.0, 75.0):
        wo = np.array([np.sin(np.radians(theta_o)), 0.0, np.cos(np.radians(theta_o))])
        mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
        if getattr(lobe, "transmission", False):
            mirror = np.array([-wo[0], -wo[1], -wo[2]])
        for off in (0.0, 10.0):
            axis = np.cos(np.radians(off)) * mirror + np.sin(np.radians(off)) * np.array([0.0, 1.0, 0.0])
            for radius in (0.1, 1.0, 5.0, 30.0):
                light = CapLight(axis, np.cos(np.radians(radius)), np.array([1.0, 2.0, 3.0]))
                truth = _monte_carlo(lobe, wo, light)
                if truth[0] < 1e-6 * light.solid_angle:
                    continue  # the cap is outside the lobe: nothing to compare
                fine = integrate_cap_light(lobe, wo, light, cap_points=32, lobe_points=32)
                coarse = integrate_cap_light(lobe, wo, light)
                case = (name, theta_o, off, radius, fine / truth, coarse / truth)
                assert np.allclose(fine, truth, rtol=0.06), case
                assert np.allclose(coarse, truth, rtol=0.15), case


def _random_cap_errors(q_range, count, seed):
    """(error, case) of integrate_cap_light on ``count`` random caps whose q (cap radius / lobe
    width, materials/cap_lights.py cap_width_ratio) lies in ``q_range``: caps of 0.2-25 degrees,
    uniform or soft-edged, anywhere from the lobe's peak to beyond its edge, on GGX / Beckmann lobes
    of alpha 0.01-0.5 seen at 0-80 degrees; the error against a 100 000-sample random MIS
    estimate, relative to the value with the cap on the lobe's peak (the highlight's scale)."""
    from lobeview.materials.cap_lights import cap_width_ratio

    rng = np.random.default_rng(seed)
    errors = []
    while len(errors) < count:
        kind = "ggx" if rng.random() < 0.7 else "beckmann"
        lobe = _microfacet(kind, float(np.exp(rng.uniform(np.log(0.01), np.log(0.5)))))
        theta_o = rng.uniform(0.0, 80.0)
        wo = np.array([np.sin(np.radians(theta_o)), 0.0, np.cos(np.radians(theta_o))])
        mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
        radius = float(np.exp(rng.uniform(np.log(0.2), np.log(25.0))))
        inner = 1.0 if rng.random() < 0.7 else 0.6
        peak = CapLight(mirror, np.cos(np.radians(radius)), np.ones(3), inner)
        ratio = cap_width_ratio(lobe, peak, float(wo[2]))
        if not q_range[0] <= ratio < q_range[1]:
            continue
        width = np.degrees(peak.radius / ratio)  # the lobe's width at this view
        off = np.radians(rng.uniform(0.0, 1.5) * (radius + width))
        phi = rng.uniform(0.0, 2.0 * np.pi)
        side = np.sin(phi) * np.array([0.0, 1.0, 0.0]) + np.cos(phi) * np.cross(mirror, [0.0, 1.0, 0.0])
        light = CapLight(np.cos(off) * mirror + np.sin(off) * side, peak.cos_radius, np.ones(3), inner)
        truth = _monte_carlo(lobe, wo, light, n=100_000)[0]
        scale = max(_monte_carlo(lobe, wo, peak, n=100_000)[0], truth)
        if scale <= 0.0:
            continue
        got = integrate_cap_light(lobe, wo, light)[0]
        errors.append((abs(got - truth) / scale, lobe.distribution, theta_o, radius, np.degrees(off), ratio))
    return errors


def test_caps_about_as_wide_as_the_lobe_against_random_mis():
    """Caps up to as wide as the lobe (q < GAUSS_BELOW; _random_cap_errors): integrate_cap_light
    (the product Gauss rule there) within 1.5 % on 40 random caps. The two-strategy lattice sum it
    replaced was 9.7 % off at the 95th percentile for q in 0.2-0.35 (a lobe's lattice points
    landing in the cap or not), 12 % at worst."""
    from lobeview.materials.cap_lights import GAUSS_BELOW

    worst = max(_random_cap_errors((0.0, GAUSS_BELOW), 40, seed=7), key=lambda e: e[0])
    assert worst[0] < 0.015, worst


def test_caps_one_to_two_lobe_widths_against_random_mis():
    """Caps one to two lobe widths wide (q in 1-2), where the two-strategy sum stays: 8 cap and 16
    lobe points by the power heuristic, as for narrower lobes, within 6 % at the 95th percentile
    (the 8 + 8 points by the balance heuristic that this band had: 7.9 % on 150 caps, 3.8 % with
    these) and 12 % at worst."""
    errors = np.array([e[0] for e in _random_cap_errors((1.0, 2.0), 40, seed=3)])
    assert np.percentile(errors, 95) < 0.06 and errors.max() < 0.12, np.sort(errors)[-5:]


@pytest.mark.parametrize("inner_fraction", [0.0, 0.6])
def test_soft_edged_caps_against_independent_estimates(inner_fraction):
    """A cap whose radiance falls linearly (in cos) to its rim, as a soft box: integrate_cap_light
    (cap points drawn from the profile) against the uniform-cap random MIS and the midpoint rule,
    caps of 1-20 degrees on and off the mirror direction of GGX 0.05 / 0.4 and Beckmann 0.3; the
    shaders' 8 + 8 within 15 %, 32 + 32 within 6 %."""
    for lobe in (_microfacet("ggx", 0.05), _microfacet("ggx", 0.4), _microfacet("beckmann", 0.3)):
        for theta_o in (0.0, 60.0):
            wo = np.array([np.sin(np.radians(theta_o)), 0.0, np.cos(np.radians(theta_o))])
            mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
            for off, radius in ((0.0, 1.0), (0.0, 12.0), (8.0, 12.0), (0.0, 20.0), (30.0, 12.0)):
                axis = np.cos(np.radians(off)) * mirror + np.sin(np.radians(off)) * np.array([0.0, 1.0, 0.0])
                light = CapLight(axis, np.cos(np.radians(radius)), np.array([3.0, 2.0, 1.0]), inner_fraction)
                truth = _monte_carlo(lobe, wo, light)
                if truth[0] < 1e-4 * light.solid_angle:
                    continue
                case = (lobe.distribution, theta_o, off, radius)
                fine = integrate_cap_light(lobe, wo, light, cap_points=32, lobe_points=32)
                assert np.allclose(fine, truth, rtol=0.06), (*case, fine / truth)
                assert np.allclose(integrate_cap_light(lobe, wo, light), truth, rtol=0.15), case
                if radius >= 12.0:  # the midpoint grid resolves these lobes over wide caps
                    assert np.allclose(brute_force_cap_light(lobe, wo, light, rings=300), truth, rtol=0.02), case


def test_a_soft_caps_profile_power_and_point_density():
    """The edge profile is linear in cos from the core to the rim; the light's power is its
    integral (against a fine quadrature in the angle); profile_area_fraction is the inverse of the
    profile's CDF: its points' histogram passes a chi-square test against the profile."""
    from scipy import stats

    from lobeview.materials.cap_lights import edge_profile, profile_area_fraction

    light = CapLight(np.array([0.0, 0.0, 1.0]), np.cos(np.radians(16.0)), np.ones(3), inner_fraction=0.7)
    theta = np.radians(np.linspace(0.0, 16.0, 200_001))
    d = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=1)
    # builtin:studio's disc: clip((cos - cos 16) / softness, 0, 1) with softness 0.3 (1 - cos 16)
    expected = np.clip((d[:, 2] - light.cos_radius) / (0.3 * (1.0 - light.cos_radius)), 0.0, 1.0)
    assert np.allclose(light.profile(d), expected, atol=1e-9)
    power = 2.0 * np.pi * np.trapezoid(light.profile(d) * np.sin(theta), theta)
    assert light.power[0] == pytest.approx(power, rel=1e-6)
    assert CapLight(light.direction, light.cos_radius, np.ones(3)).power[0] == pytest.approx(light.solid_angle)
    for f in (0.0, 0.35, 1.0):
        u = profile_area_fraction(np.random.default_rng(3).random(40_000), f)
        edges = np.linspace(0.0, 1.0, 21)
        counts, _ = np.histogram(u, edges)
        fine = np.linspace(0.0, 1.0, 20 * 400 + 1)
        mass = np.add.reduceat(edge_profile(0.5 * (fine[1:] + fine[:-1]), f), np.arange(0, 8000, 400))
        expected_counts = mass / mass.sum() * len(u)
        keep = expected_counts > 5
        chi2 = np.sum((counts[keep] - expected_counts[keep]) ** 2 / expected_counts[keep])
        assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-3, (f, counts, expected_counts)
    assert np.allclose(profile_area_fraction(np.array([0.0, 0.5, 1.0]), 1.0), [0.0, 0.5, 1.0])


def test_random_estimate_agrees_with_the_midpoint_rule():
    """The test's own reference: where the lobe is wide against the grid cells both agree."""
    lobe = _microfacet("ggx", 0.3)
    wo = np.array([0.5, 0.0, np.sqrt(0.75)])
    for radius in (2.0, 20.0):
        light = CapLight(reflect(wo, np.array([0.0, 0.0, 1.0])), np.cos(np.radians(radius)), np.ones(3))
        assert np.allclose(_monte_carlo(lobe, wo, light), brute_force_cap_light(lobe, wo, light, rings=200), rtol=0.01)


def test_sub_pixel_sun_on_a_near_mirror_keeps_its_energy():
    """A sun of 0.27 degrees reflected by GGX alpha 0.001 (its core narrower than the sun, 85 % of
    its energy inside it: GGX's tail): the shaders' 8 + 8 points keep the reflected energy within
    5 % (lobe-7 kept 3 % of it, prefiltered 5 %: issue 39)."""
    lobe = _microfacet("ggx", 0.001)
    wo = np.array([np.sin(0.6), 0.0, np.cos(0.6)])
    light = CapLight(reflect(wo, np.array([0.0, 0.0, 1.0])), np.cos(np.radians(0.27)), np.full(3, 7.9e4))
    truth = _monte_carlo(lobe, wo, light)
    albedo = _monte_carlo(lobe, wo, CapLight(light.direction, np.cos(np.radians(5.0)), np.ones(3)))
    assert 0.8 < truth[0] / (albedo[0] * light.radiance[0]) < 0.9  # the part of the lobe inside the sun
    assert np.allclose(integrate_cap_light(lobe, wo, light), truth, rtol=0.05)


def test_caps_at_grazing_views_of_a_narrow_lobe():
    """Below MIN_VIEW_COSINE the Gauss rule's azimuths double (GRAZING_AZIMUTH_FACTOR): a 1-degree cap
    anywhere within the GGX 0.05 lobe seen at cos theta_o 0.05 (the sun low on a sphere's rim) is
    integrated within 4 % of the largest of their integrals (3 x 8 points: 14 %), the integral by a
    dense quadrature over the cap."""
    from lobeview.materials.cap_lights import gauss_cap_rule

    lobe = _microfacet("ggx", 0.05)
    cos_o = 0.05
    wo = np.array([np.sqrt(1.0 - cos_o**2), 0.0, cos_o])
    mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
    rng = np.random.default_rng(1)
    fast, exact = [], []
    for k in range(12):
        centre = mirror + (rng.normal(size=3) * 0.06 if k else 0.0)
        centre[2] = abs(centre[2]) + 0.02
        light = CapLight(centre / np.linalg.norm(centre), float(np.cos(np.radians(1.03))), np.ones(3))
        assert gauss_cap_rule(lobe, light, cos_o) == (3, 16)
        fast.append(integrate_cap_light(lobe, wo, light)[0])
        exact.append(brute_force_cap_light(lobe, wo, light)[0])
    fast, exact = np.array(fast), np.array(exact)
    assert np.max(np.abs(fast - exact)) < 0.04 * exact.max()


def test_cap_light_validates_its_parameters():
    with pytest.raises(ValueError, match="direction"):
        CapLight(np.array([np.nan, 0.0, 1.0]), 0.9, np.ones(3))
    with pytest.raises(ValueError, match="cos"):
        CapLight(np.array([0.0, 0.0, 1.0]), 1.0, np.ones(3))
    with pytest.raises(ValueError, match="radiance"):
        CapLight(np.array([0.0, 0.0, 1.0]), 0.9, np.array([1.0, -1.0, 0.0]))
    light = CapLight(np.array([0.0, 0.0, 2.0]), 0.5, np.ones(3))
    assert np.allclose(light.direction, [0.0, 0.0, 1.0]) and light.solid_angle == pytest.approx(np.pi)
    points = light.points(*np.random.default_rng(0).random((2, 1000)))
    assert np.all(light.contains(points * (1 - 1e-9))) and np.allclose(np.linalg.norm(points, axis=1), 1.0)


# -- separation -------------------------------------------------------------------------------------
SUN = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)  # a cube corner: the sun falls on three faces
SUN_VIEW = (SUN + np.array([0.0, -0.3, 1.0])) / np.linalg.norm(SUN + np.array([0.0, -0.3, 1.0]))  # sees its glint


def _sky_with_sun(d, sun_radius=1.0, sun_radiance=5e3):
    return smooth_sky(d) + sun_radiance * (np.sum(d * SUN, -1) > np.cos(np.radians(sun_radius)))[..., None]


def _cube_faces(fn, size=128):
    return np.stack([fn(face_directions(face, size, 2)).mean(axis=2) for face in range(6)]).astype(np.float32)


def _power(faces):
    _, solid = bs.cube_texels(faces)
    return np.sum(faces * solid[..., None], axis=(0, 1, 2))


def test_separation_conserves_energy_and_finds_a_sun_across_cube_faces():
    """The residual cube plus the lights' power is the cube (to 1e-4), a 1-degree sun at a cube
    corner is one light at its direction (within 0.5 degrees) with the power the cube holds in it
    (within 3 %),
    and nothing of the smooth sky is taken."""
    faces = _cube_faces(_sky_with_sun)
    separation = bs.separate_cube(faces)
    assert len(separation.lights) == 1
    (light,) = separation.lights
    assert np.degrees(np.arccos(np.clip(light.direction @ SUN, -1, 1))) < 0.5
    sun_power = _power(faces) - _power(_cube_faces(smooth_sky))  # the sun as the cube holds it
    assert np.allclose(light.power, sun_power, rtol=0.03), (light.power, sun_power)
    assert np.allclose(light.power, 5e3 * 2 * np.pi * (1 - np.cos(np.radians(1.0))), rtol=0.06)  # the disc
    total = _power(faces)
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, total, rtol=1e-4)
    assert np.allclose(_power(separation.without_sources) + separation.light_power, total, rtol=1e-4)
    assert separation.without_sources.max() < 10.0  # smooth_sky peaks near 8: no sun left in the cube
    # a 1-degree sun in 0.9-degree texels: no shape the cube resolves, the residual is the sky
    assert bs.SHAPE_FROM_TEXELS * 2.0 / faces.shape[1] > np.radians(1.0)
    assert np.array_equal(separation.residual, separation.without_sources)
    assert not bs.separate_cube(_cube_faces(smooth_sky)).lights


def _wall(d):
    """A bright region of 20 degrees whose radiance varies across it (a sunlit wall: 100-900)."""
    inside = np.sum(d * SUN, -1) > np.cos(np.radians(20.0))
    return smooth_sky(d) + (inside * (500.0 + 400.0 * np.sin(12.0 * d[..., 0]) * np.cos(9.0 * d[..., 2])))[..., None]


def test_separation_leaves_wide_or_low_contrast_regions_in_the_map():
    """A bright region of 20 degrees with structure (a sunlit wall, a sky) keeps it in the map,
    and so does a region only 20 times brighter than its surroundings."""
    assert not bs.separate_cube(_cube_faces(_wall)).lights
    faint = _cube_faces(lambda d: 0.5 + 10.0 * (np.sum(d * SUN, -1) > np.cos(np.radians(2.0)))[..., None] * np.ones(3))
    assert not bs.separate_cube(faint).lights


def _patch_between_walls(level: float):
    """A sky of radiance 1 (the map's median), dark walls (0.005) over a 30-degree region and inside
    them a 5-degree patch of sky at ``level`` with structure (not uniform: no soft-edged cap): what
    courtyard.exr and forest.exr hold between their buildings and trees."""

    def radiance(d):
        cos_to_centre = np.sum(d * SUN, -1)
        walls = cos_to_centre > np.cos(np.radians(30.0))
        patch = cos_to_centre > np.cos(np.radians(5.0))
        structure = 1.0 + 0.6 * np.sin(40.0 * d[..., 0]) * np.cos(30.0 * d[..., 1])
        value = np.where(patch, level * structure, np.where(walls, 0.005, 1.0))
        return value[..., None] * np.ones(3)

    return _cube_faces(radiance, size=128)


def test_a_bright_patch_of_sky_between_walls_stays_in_the_map():
    """A patch 150x the map's median, 3e4x its dark surroundings (it passes MIN_CONTRAST), keeps its
    shape in the map (bs.MIN_SOURCE_FACTOR: under courtyard.exr and forest.exr such caps cost lobe-7
    on metals up to 12 points, docs/measurements.md); ten times brighter it is a source and becomes a light.
    Energy is conserved either way."""
    patch, source = _patch_between_walls(150.0), _patch_between_walls(1500.0)
    kept = bs.separate_cube(patch)
    assert not kept.lights and np.array_equal(kept.residual, patch)
    taken = bs.separate_cube(source)
    assert len(taken.lights) == 2 and np.degrees(taken.lights[0].radius) < 5.5  # its core, and a cone
    assert taken.lights[0].inner_fraction == 1.0  # a hard cap: the rule it tests applies to those
    assert taken.lights[1].inner_fraction == 0.0  # of what the patch holds beyond the core
    assert np.allclose(_power(taken.residual) + taken.residual_light_power, _power(source), rtol=1e-4)


def _band_or_disc(elongated: bool):
    """A dim sky with one bright region of the same solid angle (about 0.012 sr) near the
    horizon: a band 24 x 1.7 degrees (elongated) or a disc of 3.6 degrees radius, with a
    brightness gradient along it so that it is not uniform (no soft-edged cap)."""

    def radiance(d):
        azimuth = np.degrees(np.arctan2(d[..., 0], -d[..., 2]))
        elevation = np.degrees(np.arcsin(np.clip(d[..., 1], -1.0, 1.0)))
        if elongated:
            inside = (np.abs(azimuth) < 12.0) & (np.abs(elevation - 5.0) < 0.85)
        else:
            inside = np.hypot(azimuth, elevation - 5.0) < 3.6
        level = 400.0 * (1.0 + 0.05 * azimuth)
        return 0.5 + (inside * level)[..., None] * np.ones(3)

    return _cube_faces(radiance, size=128)


def test_an_elongated_region_stays_in_the_map():
    """A band (a horizon's city lights, night.exr: elongation 4.8) would become a round cap that a
    mirror shows as a disc: it stays in the map; a disc of the same solid angle and brightness
    becomes a light. Both maps' energy is conserved."""
    band, disc = _band_or_disc(True), _band_or_disc(False)
    assert not bs.separate_cube(band).lights
    separation = bs.separate_cube(disc)
    assert len(separation.lights) == 1
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, _power(disc), rtol=1e-4)


def test_soft_cap_shape_inverts_the_profiles_energy_and_moment():
    """soft_cap_shape against the moments of the edge profile by quadrature (not the closed form
    it inverts): rim and inner fraction back for cones, soft boxes and uniform caps."""
    from lobeview.materials.cap_lights import edge_profile

    for rim_degrees in (2.0, 11.0, 24.0):
        b = 1.0 - np.cos(np.radians(rim_degrees))
        u = (np.arange(200_000) + 0.5) / 200_000 * b  # u = 1 - cos, uniform in solid angle
        for f in (0.0, 0.3, 0.78, 1.0):
            radiance = 7.0 * edge_profile(u / b, f)
            energy = 2.0 * np.pi * np.sum(radiance) * b / len(u)
            moment = 2.0 * np.pi * np.sum(radiance * u) * b / len(u)
            one_minus_cos, inner = bs.soft_cap_shape(energy, moment, 7.0)
            assert one_minus_cos == pytest.approx(b, rel=1e-3) and inner == pytest.approx(f, abs=2e-3), (rim_degrees, f)


@pytest.mark.parametrize("face_size", [64, 128])
def test_a_uniform_soft_box_becomes_a_soft_edged_cap(face_size):
    """builtin:studio's key and fill soft boxes (11 and 16 degrees, radiance 30 and 10, a ramp
    linear in cos over their outer 22 and 26 % of area): the key was wider than a hard cap may be
    and the fill's contrast was measured against its own ramp, so both stayed in the cube, in a
    glossy floor's GGX tail (1.55x too bright below). Now each is one soft-edged cap, its rim
    within a texel of the box's, its inner fraction within 0.1, the map's energy conserved and
    no ramp left in the cube; the rim light (4 degrees, mostly ramp) and the strip stay."""
    from lobeview.scenes.builtin_env import studio

    faces = _cube_faces(studio, size=face_size)
    separation = bs.separate_cube(faces)
    assert np.allclose(_power(separation.residual) + separation.residual_light_power, _power(faces), rtol=1e-4)
    texel = np.degrees(2.0 / face_size)
    boxes = [
        ([0.55, 0.6, 0.58], 11.0, 0.004, 30.0 * np.array([1.0, 0.97, 0.92])),
        ([-0.6, 0.45, 0.66], 16.0, 0.01, 10.0 * np.array([0.9, 0.95, 1.0])),
    ]
    directions = bs.cube_texels(faces)[0].reshape(-1, 3)
    for axis, radius, softness, radiance in boxes:
        axis = np.asarray(axis) / np.linalg.norm(axis)
        light = max(separation.lights, key=lambda light: float(light.direction @ axis))
        assert np.degrees(np.arccos(min(float(light.direction @ axis), 1.0))) < 0.5 * texel
        assert abs(np.degrees(light.radius) - radius) < texel, (radius, np.degrees(light.radius))
        inner = softness / (1.0 - np.cos(np.radians(radius)))
        assert abs(light.inner_fraction - (1.0 - inner)) < 0.1, (radius, light.inner_fraction)
        assert np.allclose(light.radiance, radiance, rtol=0.06), (radius, light.radiance)
        inside = directions @ axis > np.cos(np.radians(radius + texel))
        assert separation.residual.reshape(-1, 3)[inside].max() < 0.5  # the backdrop's level: no ramp left
    assert all(np.degrees(light.radius) > 10.0 for light in separation.lights if light.inner_fraction < 1.0)


@pytest.fixture(scope="module")
def glossy_floor(tmp_path_factory):
    """A roughness-0.4 metal quad under builtin:studio, seen so that its mirror direction lies on
    the studio floor and the key and fill soft boxes 47-75 degrees off it, in the GGX tail; and
    its reference mean over the quad's pixels."""
    from test_textures import _textured_gltf

    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    material = {"pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1.0], "metallicFactor": 1.0,
                                         "roughnessFactor": 0.4}}  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(_textured_gltf(tmp_path_factory.mktemp("floor"), material, []))
        ctx = create_headless_context()
        renderer = SceneRenderer(ctx, scene, load_environment("builtin:studio"), size=(48, 48), progress=False,
                                 settings=RenderSettings(cube_face_size=64, mirrors=False))  # fmt: skip
    camera = Camera(position=(0.6, 1.2, 1.6), target=(0.5, 0.5, 0.0), fov_y=40.0)
    reference = renderer.render(camera, "reference", spp=256)
    yield renderer, camera, float(reference.radiance[reference.mask].mean())
    renderer.release()
    ctx.release()


@pytest.mark.parametrize("method", ["lobe-7+norm", "lobe-15+norm", "fis-16", "prefiltered", "prefiltered-rsibr"])
def test_a_glossy_floor_under_the_studio_keeps_its_brightness(glossy_floor, method):
    """Every real-time method within 6 % of the reference on the glossy floor. While the key and
    fill soft boxes stayed in the cube, lobe-7+norm and lobe-15+norm were 1.55x (their four GGX
    tail lookups read the boxes 2.5x too bright) and prefiltered 0.85x; they are soft-edged cap
    lights now (test_a_uniform_soft_box_becomes_a_soft_edged_cap)."""
    renderer, camera, truth = glossy_floor
    result = renderer.render(camera, method)
    got = float(result.radiance[result.mask].mean())
    assert abs(got / truth - 1.0) < 0.06, (method, got, truth)


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
@pytest.mark.parametrize("name", ["polyhaven_1k/chinese_garden_1k.hdr", "blender_studiolights_1k/studio.exr"])
def test_separation_of_real_captures_conserves_energy(name):
    """A sun of 7.9e4 (a light of about the sun's size and a cone of its glow) and a studio's
    softboxes: the residual plus the lights is the map, on the equirectangular map and on its cube."""
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.viewer.cubemap import equirect_to_cube_faces

    env = load_environment(str(SHARED_ASSETS / "env" / name))
    separation = bs.separate_equirect(env.image)
    _, solid = bs.equirect_texels(env.image.shape[0])
    total = np.sum(env.image.astype(np.float64) * solid[..., None], axis=(0, 1))
    residual = np.sum(separation.residual.astype(np.float64) * solid[..., None], axis=(0, 1))
    assert np.allclose(residual + separation.residual_light_power, total, rtol=1e-4)
    without = np.sum(separation.without_sources.astype(np.float64) * solid[..., None], axis=(0, 1))
    assert np.allclose(without + separation.light_power, total, rtol=1e-4)
    assert separation.lights  # hard caps up to 10 degrees, cones (a source's glow) and soft caps up to 25
    assert all(light.radius < np.radians(10.0 if light.inner_fraction == 1.0 else 25.0) for light in separation.lights)
    if "garden" in name:  # the sun's core and a cone of its glow
        assert len(separation.lights) == 2 and np.degrees(separation.lights[0].radius) < 1.0
        assert separation.lights[1].inner_fraction == 0.0
    faces = equirect_to_cube_faces(env, 64)
    cube = bs.separate_cube(faces)
    assert np.allclose(_power(cube.residual) + cube.residual_light_power, _power(faces), rtol=1e-4)
    assert np.allclose(_power(cube.without_sources) + cube.light_power, _power(faces), rtol=1e-4)


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
def test_bright_sky_between_buildings_and_trees_stays_in_real_captures():
    """courtyard.exr's two patches of sky (4-5 degrees, 90-130x the map's median) and forest.exr's
    7-degree one (140x) keep their shape in the map; forest's sun (1.2 degrees, 3000x) is a light
    (and its glow a cone)."""
    from lobeview.scenes.builtin_env import load_environment

    folder = SHARED_ASSETS / "env" / "blender_studiolights_1k"
    assert not bs.separate_equirect(load_environment(str(folder / "courtyard.exr")).image).lights
    sun, glow = bs.separate_equirect(load_environment(str(folder / "forest.exr")).image).lights
    assert np.degrees(sun.radius) < 1.5 and glow.inner_fraction == 0.0


def test_separation_rejects_bad_maps():
    with pytest.raises(ValueError, match="shape"):
        bs.separate_cube(np.zeros((5, 8, 8, 3)))
    with pytest.raises(ValueError, match="finite"):
        bs.separate_cube(np.full((6, 8, 8, 3), np.nan))


# -- the shaders' light term ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sun_renderer():
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(_sky_with_sun, height=256, name="sky-with-sun")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=SIZE, face_size=64,
                                   bright_sources=True)  # fmt: skip
    yield renderer
    renderer.release()
    ctx.release()


@pytest.mark.parametrize("method", ["lobe-7+norm", "fis-8", "prefiltered"])
@pytest.mark.parametrize("material", ["gold-ggx", "frosted-glass", "miro5-2lobe"])
def test_light_term_matches_numpy_twin(sun_renderer, method, material):
    """The frame with the lights minus the frame without them (same residual cube) is, per pixel,
    integrate_cap_light summed over the material's lobes and the cube's lights."""
    renderer = sun_renderer
    lights = renderer.cubes.lights
    assert len(lights) == 1
    bsdf = build_bsdf(load_material(material))
    # At the pixel centre's lobe, as the twin integrates (the footprint: tests/test_footprint_lights.py).
    # Both frames read the cube without sources (>= 0): the signed residual's reads alone may sum
    # below zero, which the shaders clamp, and the difference would then not be the light term.
    residual = renderer.cubes.residual
    renderer.cubes.residual = renderer.cubes.without_sources
    try:
        with_lights = renderer.render(CAMERA, bsdf, method, background=False, footprint_lights=False)
        renderer.cubes.lights = []
        without = renderer.render(CAMERA, bsdf, method, background=False, footprint_lights=False)
    finally:
        renderer.cubes.lights = lights
        renderer.cubes.residual = residual
    difference = with_lights.radiance - without.radiance
    assert difference.max() > 0.3  # the sun is on the sphere
    for y, x in _pixels(with_lights, count=40):
        frame, wo = _frame(with_lights, y, x)
        expected = sum(integrate_cap_light(lobe, wo, light, frame) for lobe in specular_lobes(bsdf) for light in lights)
        assert np.allclose(difference[y, x], expected, rtol=0.02, atol=2e-3), (y, x, difference[y, x], expected)


@pytest.mark.parametrize("material", ["gold-ggx", "frosted-glass", "chrome"])
def test_a_soft_edged_light_matches_its_numpy_twin(sun_renderer, material):
    """A 14-degree soft box (radiance falling to its rim over the outer 60 % of its area) in place
    of the sun: the shaders' light term per pixel against integrate_cap_light (chrome: a lobe
    narrow against the cap, 8 + 16 points by the power heuristic)."""
    renderer = sun_renderer
    lights = renderer.cubes.lights
    soft = CapLight(SUN_VIEW, np.cos(np.radians(14.0)), np.array([40.0, 30.0, 20.0]), inner_fraction=0.4)
    bsdf = build_bsdf(load_material(material))
    try:
        renderer.cubes.lights = [soft]
        with_light = renderer.render(CAMERA, bsdf, "lobe-7+norm", background=False, footprint_lights=False)
        renderer.cubes.lights = []
        without = renderer.render(CAMERA, bsdf, "lobe-7+norm", background=False, footprint_lights=False)
    finally:
        renderer.cubes.lights = lights
    difference = with_light.radiance - without.radiance
    assert difference.max() > 0.3
    for y, x in _pixels(with_light, count=40):
        frame, wo = _frame(with_light, y, x)
        expected = sum(integrate_cap_light(lobe, wo, soft, frame) for lobe in specular_lobes(bsdf))
        assert np.allclose(difference[y, x], expected, rtol=0.02, atol=2e-3), (y, x, difference[y, x], expected)


def test_a_separated_cube_counts_both_of_its_textures(sun_renderer):
    """The cube budget (viewer/cube_bake.py cube_gpu_bytes) sees the residual cube too."""
    from lobeview.viewer.cube_bake import cube_gpu_bytes
    from lobeview.viewer.cubemap import RadianceCube

    faces = _cube_faces(_sky_with_sun, size=32)
    plain = RadianceCube(sun_renderer.ctx, faces)
    separated = RadianceCube(sun_renderer.ctx, faces, bright_sources=True)
    try:
        assert separated.lights and separated.residual is not separated.radiance
        assert not plain.lights and plain.residual is plain.radiance
        assert cube_gpu_bytes(separated) == 2 * cube_gpu_bytes(plain)
    finally:
        plain.release()
        separated.release()


@pytest.mark.parametrize(
    "desc",
    [
        {"model": "gltf", "base_color": [1.0, 0.78, 0.34], "metallic": 1.0, "roughness": 0.4},
        "gold-ggx",  # a material whose lobes no texture changes: prefiltered-rsibr bakes it
    ],
    ids=["gltf-gold", "gold-ggx"],
)
def test_scene_objects_get_the_lights_too(desc):
    """A scene's objects (shaders/scene.frag, its own lobe loop) add the cube's lights like the
    preview does: a gold sphere under a sky with a 5e3 sun keeps the reference's brightness in
    every real-time method (Blender Cycles found them at 0.05-0.37 of it, the sun missing)."""
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    material = validate(desc) if isinstance(desc, dict) else load_material(desc)
    scene = Scene([SceneObject("sphere", uv_sphere(rings=64, segments=128), 0)], [SceneMaterial("gold", material)])
    scene.objects[0].planar_reflector = False
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(_sky_with_sun, height=256, name="sky-with-sun")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(ctx, scene, env, size=(64, 64), progress=False,
                                 settings=RenderSettings(cube_face_size=64))  # fmt: skip
    try:
        assert renderer.objects[0].cube.lights, "the sun is separated from the sphere's cube"
        camera = Camera(position=tuple(3.2 * SUN_VIEW), target=(0.0, 0.0, 0.0), fov_y=40.0)
        reference = renderer.render(camera, "reference", spp=256)
        mask = reference.object_id == 0
        truth = reference.radiance[mask].mean()
        methods = ["lobe-7+norm", "fis-16", "prefiltered"] + (["prefiltered-rsibr"] if isinstance(desc, str) else [])
        for method in methods:
            got = renderer.render(camera, method).radiance[mask].mean()
            assert abs(got / truth - 1.0) < 0.1, (method, got, truth)
    finally:
        renderer.release()
        ctx.release()
