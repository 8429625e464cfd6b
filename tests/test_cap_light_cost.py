"""What a light costs per pixel (materials/cap_lights.py, shaders/cap_lights.glsl): a cap below the
lobe's horizon and a Beckmann tail below e^-40 of its peak are skipped, and a cap far from a GGX
lobe's peak takes the Gauss rule its distance asks for, not its width; each against the
independent midpoint rule over the cap (the shaders follow the same choices: tests/test_cap_lights.py
test_light_term_matches_numpy_twin, per pixel)."""

from __future__ import annotations

import numpy as np
from test_cap_lights import GOLD, _microfacet

from lobeview.materials import cap_lights as cl
from lobeview.materials.cap_lights import CapLight, brute_force_cap_light, gauss_cap_integral, integrate_cap_light
from lobeview.materials.vec import reflect


def _view(theta_o: float) -> np.ndarray:
    return np.array([np.sin(np.radians(theta_o)), 0.0, np.cos(np.radians(theta_o))])


def _cap_off(direction: np.ndarray, off_degrees: float, phi: float, radius_degrees: float, inner=1.0) -> CapLight:
    """A cap of ``radius_degrees`` whose axis lies ``off_degrees`` from ``direction`` at azimuth ``phi``."""
    helper = np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t = np.cross(helper, direction)
    t /= np.linalg.norm(t)
    side = np.cos(phi) * t + np.sin(phi) * np.cross(direction, t)
    off = np.radians(off_degrees)
    axis = np.cos(off) * direction + np.sin(off) * side
    return CapLight(axis, np.cos(np.radians(radius_degrees)), np.ones(3), inner)


def _points(rule) -> int:
    return cl.NARROW_CAP_POINTS + cl.NARROW_LOBE_POINTS if rule is None else rule[0] * rule[1]


def test_caps_far_from_a_ggx_peak_take_the_rule_of_their_distance():
    """60 random caps of 0.3-25 degrees, wholly above the horizon, 0-110 degrees off the peak of GGX
    lobes of alpha 0.005-0.5 seen at 0-85 degrees, whose distance changes the rule: the chosen rule
    within 0.6 % of a 300 x 600 midpoint rule over the cap at the 95th percentile and 2 % at worst
    (relative to the cap's own value, where it is above 1e-6 of the cap's value on the peak;
    measured on 250 caps: 0.29 / 1 %), at under half the points the lobe's width alone asks for."""
    rng = np.random.default_rng(11)
    errors, points_width, points_distance = [], [], []
    while len(errors) < 60:
        lobe = _microfacet("ggx", float(np.exp(rng.uniform(np.log(0.005), np.log(0.5)))))
        wo = _view(rng.uniform(0.0, 85.0))
        mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
        radius = float(np.exp(rng.uniform(np.log(0.3), np.log(25.0))))
        light = _cap_off(mirror, rng.uniform(0.0, 110.0), rng.uniform(0.0, 2.0 * np.pi), radius,
                         inner=float(rng.choice([1.0, 0.6, 0.0])))  # fmt: skip
        distance = cl.cap_peak_distance(lobe, wo, light)
        by_width = cl.gauss_cap_rule(lobe, light, float(wo[2]))
        by_distance = cl.gauss_cap_rule(lobe, light, float(wo[2]), distance)
        if distance == 0.0 or by_distance is None or by_distance == by_width:
            continue
        truth = brute_force_cap_light(lobe, wo, light, rings=300)[0]
        on_peak = brute_force_cap_light(lobe, wo, CapLight(mirror, light.cos_radius, np.ones(3)), rings=300)[0]
        if not truth > 1e-6 * on_peak:
            continue
        got = integrate_cap_light(lobe, wo, light)[0]
        assert got == gauss_cap_integral(lobe, wo, light, *by_distance)[0]  # the rule it chose
        errors.append(abs(got - truth) / truth)
        points_width.append(_points(by_width))
        points_distance.append(_points(by_distance))
    assert np.percentile(errors, 95) < 0.006 and max(errors) < 0.02, np.sort(errors)[-5:]
    assert np.mean(points_distance) < 0.5 * np.mean(points_width), (np.mean(points_distance), np.mean(points_width))


def test_caps_below_the_horizon_cost_nothing():
    """A cap wholly below a reflection lobe's horizon (or above a transmission lobe's mirrored one)
    is skipped: its integral is 0 by the midpoint rule too; a cap crossing the horizon is not."""
    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf, load_material

    reflection, transmission = specular_lobes(build_bsdf(load_material("frosted-glass")))
    assert transmission.transmission and not reflection.transmission
    wo = _view(40.0)
    down = np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0])
    for lobe in (_microfacet("ggx", 0.5), _microfacet("beckmann", 0.3), reflection, transmission):
        for radius, elevation in ((5.0, -6.0), (20.0, -21.0), (20.0, -15.0), (5.0, 10.0)):
            e = np.radians(elevation)
            axis = np.array([np.cos(e), 0.0, np.sin(e)])
            if lobe.transmission:
                axis[2] = -axis[2]
            light = CapLight(axis, np.cos(np.radians(radius)), np.ones(3))
            below = cl.cap_below_horizon(lobe, light)
            assert below == (elevation < -radius), (lobe, radius, elevation)
            if below:
                assert np.all(integrate_cap_light(lobe, wo, light) == 0.0)
                assert np.all(brute_force_cap_light(lobe, wo, light, rings=100) == 0.0)
        assert not cl.cap_below_horizon(lobe, CapLight(down if lobe.transmission else -down, 0.9, np.ones(3)))


def test_a_beckmann_tail_is_skipped_only_where_it_holds_nothing():
    """cap_negligible on Beckmann lobes of alpha 0.005-0.4 (isotropic and 1:5) and caps of 0.3-20
    degrees at every distance from the peak: where it skips a cap, the midpoint rule's integral
    there is below 1e-14 of the cap's on the peak; caps at 0.8 of the skipping distance are kept
    and do hold light; GGX is never skipped."""
    rng = np.random.default_rng(5)
    skipped = kept = 0
    for _ in range(120):
        alpha = float(np.exp(rng.uniform(np.log(0.005), np.log(0.4))))
        lobe = _microfacet("beckmann", alpha)
        if rng.random() < 0.3:
            lobe = _anisotropic_beckmann(alpha, min(5.0 * alpha, 1.0))
        wo = _view(rng.uniform(0.0, 80.0))
        mirror = reflect(wo, np.array([0.0, 0.0, 1.0]))
        radius = float(np.exp(rng.uniform(np.log(0.3), np.log(20.0))))
        light = _cap_off(mirror, rng.uniform(0.0, 150.0), rng.uniform(0.0, 2.0 * np.pi), radius)
        on_peak = brute_force_cap_light(lobe, wo, CapLight(mirror, light.cos_radius, np.ones(3)), rings=200)[0]
        if cl.cap_negligible(lobe, wo, light):
            skipped += 1
            assert brute_force_cap_light(lobe, wo, light, rings=200)[0] <= 1e-14 * on_peak
            assert np.all(integrate_cap_light(lobe, wo, light) == 0.0)
        assert not cl.cap_negligible(_microfacet("ggx", alpha), wo, light)
    # the bound is not loose by orders: at the threshold's distance scaled by 0.8 the tail is there
    for alpha in (0.01, 0.05, 0.2):
        lobe = _microfacet("beckmann", alpha)
        wo = _view(0.0)
        threshold = 2.0 * np.degrees(np.arctan(np.sqrt(cl.BECKMANN_NEGLIGIBLE_EXPONENT) * alpha))
        light = _cap_off(np.array([0.0, 0.0, 1.0]), 0.8 * threshold + 0.5, 0.0, 0.5)
        kept += not cl.cap_negligible(lobe, wo, light)
        assert brute_force_cap_light(lobe, wo, light, rings=100)[0] > 0.0
    assert skipped >= 30 and kept == 3, (skipped, kept)


def _anisotropic_beckmann(alpha_x: float, alpha_y: float):
    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf, validate

    desc = {"model": "microfacet", "distribution": "beckmann", "alpha_u": alpha_x, "alpha_v": alpha_y, "fresnel": GOLD}
    return specular_lobes(build_bsdf(validate(desc)))[0]
