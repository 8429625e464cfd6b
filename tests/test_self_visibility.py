"""Specular self-occlusion (issue 40; scenes/self_visibility.py, shaders/incident.glsl): the
visibility cones against closed forms (a point at the bottom of a cylindrical well sees a cone of
half angle atan(r / h), cosine-weighted fraction r^2 / (r^2 + h^2); a convex object hides
nothing), the soft cone against quadrature, bad input, and the shaders against the numpy twin
on a floor beside a wall."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_compute_probe

from lobeview.scenes.self_visibility import (
    CONE_FLOATS,
    HORIZON_SECTORS,
    MAP_HORIZON_SECTORS,
    MIN_RAYS_PER_VERTEX,
    NO_OCCLUSION,
    cone_visibility,
    horizon_visibility,
    rays_per_vertex,
    self_occluded_incident,
    split_sum_footprint,
    vertex_visibility_cones,
)
from lobeview.viewer.camera import Camera


def _well(radius: float, depth: float, segments: int = 96):
    """A cylindrical well: its bottom disc (a fan around the centre vertex 0) and its wall, open
    at the top."""
    angle = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros_like(angle)], axis=1)
    positions = np.concatenate([[[0.0, 0.0, 0.0]], ring, ring + [0.0, 0.0, depth]])
    normals = np.concatenate([[[0.0, 0.0, 1.0]], np.tile([0.0, 0.0, 1.0], (segments, 1)), -ring / radius])
    faces = []
    for i in range(segments):
        j = (i + 1) % segments
        faces += [(0, 1 + i, 1 + j), (1 + i, 1 + segments + i, 1 + j), (1 + j, 1 + segments + i, 1 + segments + j)]
    return positions, normals, np.array(faces)


@pytest.mark.parametrize("depth", [0.5, 1.0, 2.0])
def test_bottom_of_a_well_sees_the_opening_as_its_cone(depth):
    positions, normals, faces = _well(1.0, depth)
    cones = vertex_visibility_cones(positions, normals, faces, rays=4096, smoothing_passes=0)
    visible = 1.0 / (1.0 + depth**2)  # sin^2 of the opening's half angle atan(1 / depth)
    sigma = np.sqrt(visible * (1.0 - visible) / 4096)
    cos_expected = depth / np.hypot(1.0, depth)
    # cos a = sqrt(1 - V): dcos = dV / (2 cos a); four standard deviations
    assert abs(cones[0, 3] - cos_expected) < 4.0 * sigma / (2.0 * cos_expected) + 1e-3
    np.testing.assert_allclose(cones[0, :3], [0.0, 0.0, 1.0], atol=0.01)  # bent along the axis
    assert np.all(cones[:, 3] > NO_OCCLUSION)  # every vertex of the well sees some of it


def test_convex_object_hides_nothing():
    import trimesh

    sphere = trimesh.creation.icosphere(3)
    cones = vertex_visibility_cones(sphere.vertices, sphere.vertex_normals, sphere.faces)
    assert np.all(cones[:, 3] == NO_OCCLUSION)
    np.testing.assert_allclose(cones[:, :3], sphere.vertex_normals, atol=1e-6)


def test_degenerate_input_gives_finite_cones():
    positions, normals, faces = _well(1.0, 1.0, segments=16)
    normals[0] = 0.0
    normals[5] = np.nan
    cones = vertex_visibility_cones(positions, normals, faces, rays=64)
    assert np.isfinite(cones).all()
    np.testing.assert_allclose(np.linalg.norm(cones[:, :3], axis=1), 1.0, atol=1e-5)
    one = vertex_visibility_cones(positions[:3], normals[:3], np.array([[0, 1, 2]]))
    assert np.all(one[:, 3] == NO_OCCLUSION)
    empty = vertex_visibility_cones(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), int))
    assert empty.shape == (0, CONE_FLOATS)


def test_smoothing_averages_over_triangle_neighbours():
    from lobeview.scenes.self_visibility import _smooth_over_neighbours

    faces = np.array([[0, 1, 2], [1, 3, 2]])
    values = np.array([0.0, 4.0, 8.0, 12.0])
    (once,) = _smooth_over_neighbours(faces, 4, values, passes=1)
    np.testing.assert_allclose(once, [4.0, 6.0, 6.0, 8.0])  # vertex 1: (0 + 4 + 8 + 12) / 4
    (constant,) = _smooth_over_neighbours(faces, 4, np.full((4, 3), 2.5), passes=3)
    np.testing.assert_allclose(constant, 2.5)


@pytest.mark.parametrize("tilt_degrees", [0.0, 25.0, 50.0, 75.0])
@pytest.mark.parametrize("visible", [0.15, 0.5, 0.85])
def test_tilted_cone_holds_the_visible_fraction(tilt_degrees, visible):
    """cone_cos_aperture against Monte Carlo: of cosine-distributed directions, the share inside
    the cone (around a bent normal tilted off the normal) is the visible fraction; at tilt 0 the
    closed form sqrt(1 - V)."""
    from lobeview.scenes.self_visibility import cone_cos_aperture, cosine_directions

    tilt = np.radians(tilt_degrees)
    cos_aperture = float(cone_cos_aperture(np.array([tilt]), np.array([visible]))[0])
    directions = cosine_directions(1 << 16, seed=3)
    held = np.mean(directions @ np.array([np.sin(tilt), 0.0, np.cos(tilt)]) > cos_aperture)
    assert held == pytest.approx(visible, abs=0.01)
    if tilt_degrees == 0.0:
        assert cos_aperture == pytest.approx(np.sqrt(1.0 - visible), abs=0.01)


def test_ray_budget_of_large_objects():
    assert rays_per_vertex(1000) == 64
    assert rays_per_vertex(10**6) == MIN_RAYS_PER_VERTEX
    assert MIN_RAYS_PER_VERTEX <= rays_per_vertex(200_000) < 64


@pytest.mark.parametrize("visible", [0.1, 0.5, 0.9])
def test_soft_cone_keeps_the_visible_fraction(visible):
    """A cone around the normal with cos a = sqrt(1 - V), its edge softened symmetrically, lets
    through about V of the cosine-weighted hemisphere (quadrature over the hemisphere)."""
    x, w = np.polynomial.legendre.leggauss(400)
    cos_t = 0.5 * (x + 1.0)
    weights = 0.5 * w * 2.0 * cos_t  # cosine-weighted, normalised: integral of 2 cos over [0, 1]
    directions = np.stack([np.sqrt(1.0 - cos_t**2), np.zeros_like(cos_t), cos_t], axis=1)
    cone = np.array([0.0, 0.0, 1.0, np.sqrt(1.0 - visible)])
    passed = np.sum(weights * cone_visibility(directions, np.broadcast_to(cone, (len(cos_t), 4))))
    assert passed == pytest.approx(visible, abs=0.02)


def test_visibility_and_mix():
    cone = np.array([0.0, 0.0, 1.0, 0.8])
    inside, edge, outside = np.array([0.0, 0.0, 1.0]), np.array([0.6, 0.0, 0.8]), np.array([1.0, 0.0, 0.0])
    assert cone_visibility(inside, cone) == 1.0
    assert cone_visibility(edge, cone) == pytest.approx(0.5)
    assert cone_visibility(outside, cone) == 0.0
    assert cone_visibility(outside, np.array([0.0, 0.0, 1.0, NO_OCCLUSION])) == 1.0
    # horizons: sine 0.6 all round (about +z); a direction at that elevation is half visible
    normal = np.array([0.0, 0.0, 1.0])
    horizons = np.concatenate([cone, np.full(HORIZON_SECTORS, 0.6)])
    at_horizon, above, below = np.array([0.8, 0.0, 0.6]), np.array([0.0, 0.6, 0.8]), np.array([0.0, -0.95, 0.3122])
    # at the horizon a little less than half: the horizon is a circle about the normal, curving
    # away from the lookup's cap (0.08 / 0.8 rad of soft edge)
    assert horizon_visibility(at_horizon, horizons, normal) == pytest.approx(0.492, abs=1e-3)
    assert horizon_visibility(above, horizons, normal) == 1.0
    assert horizon_visibility(below / np.linalg.norm(below), horizons, normal) == 0.0
    assert horizon_visibility(-normal, horizons, normal) == 1.0  # below the surface: transmission
    grazing_below = np.array([0.0, 0.999, -0.0447])
    assert horizon_visibility(grazing_below, horizons, normal, below_hidden=True) == 0.0  # a reflection's
    assert horizon_visibility(-normal, horizons, normal, below_hidden=True) == 0.0
    assert horizon_visibility(above, horizons, normal, below_hidden=True) == 1.0
    with np.errstate(invalid="ignore"):
        assert horizon_visibility(above, horizons, np.full(3, np.nan)) == 1.0  # a degenerate normal
        assert horizon_visibility(above, horizons, np.full(3, np.nan), below_hidden=True) == 1.0
    no_cone = horizons.copy()
    no_cone[3] = NO_OCCLUSION
    assert horizon_visibility(below / np.linalg.norm(below), no_cone, normal) == 1.0
    assert horizon_visibility(-normal, no_cone, normal, below_hidden=True) == 1.0  # nothing hidden: no stand-in
    mixed = self_occluded_incident(np.array([4.0, 4.0, 4.0]), np.array([1.0, 2.0, 3.0]), at_horizon, horizons, normal)
    share = float(horizon_visibility(at_horizon, horizons, normal))
    np.testing.assert_allclose(mixed, share * 4.0 + (1.0 - share) * np.array([1.0, 2.0, 3.0]))


def test_horizon_is_linear_in_azimuth_between_sector_centres():
    """The horizon's sine at an azimuth between two sectors' centres is their linear mix, in the
    frame horizon_frame gives (the shaders measure azimuth the same way)."""
    from lobeview.scenes.self_visibility import horizon_frame

    normal = np.array([0.0, 1.0, 0.0])
    tangent, bitangent = horizon_frame(normal)
    assert abs(tangent @ normal) < 1e-12 and abs(bitangent @ normal) < 1e-12 and abs(tangent @ bitangent) < 1e-12
    cones = np.concatenate([[0.0, 1.0, 0.0, 0.5], np.linspace(0.1, 0.8, HORIZON_SECTORS)])
    for sector in range(HORIZON_SECTORS - 1):
        phi = (sector + 1.0) / HORIZON_SECTORS * 2.0 * np.pi  # half way between centres k and k+1
        h = 0.5 * (cones[4 + sector] + cones[5 + sector])
        direction = np.sqrt(1.0 - h**2) * (np.cos(phi) * tangent + np.sin(phi) * bitangent) + h * normal
        level = np.concatenate([cones[:4], np.full(HORIZON_SECTORS, h)])  # that horizon all round
        assert horizon_visibility(direction, cones, normal) == pytest.approx(
            horizon_visibility(direction, level, normal), abs=1e-9
        )


def _cap_directions(axis: np.ndarray, solid_angle: float, count: int, rng) -> np.ndarray:
    """Uniform directions on the spherical cap of ``solid_angle`` about unit ``axis``."""
    cos_radius = 1.0 - solid_angle / (2.0 * np.pi)
    cos_t = 1.0 - rng.random(count) * (1.0 - cos_radius)
    phi = rng.random(count) * 2.0 * np.pi
    sin_t = np.sqrt(1.0 - cos_t**2)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return (sin_t * np.cos(phi))[:, None] * u + (sin_t * np.sin(phi))[:, None] * v + cos_t[:, None] * axis


def test_cap_intersection_against_monte_carlo():
    """The solid angle two spherical caps share (the closed form the horizon's visibility rests
    on) against the fraction of 400k uniform directions in both, over overlap, containment and
    disjoint cases."""
    from lobeview.scenes.self_visibility import cap_intersection_solid_angle

    rng = np.random.default_rng(1)
    directions = rng.normal(size=(400_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for a, b, d in [(0.5, 0.3, 0.6), (1.2, 0.4, 1.0), (1.5, 1.0, 0.3), (0.3, 0.3, 0.1), (np.pi / 2, 0.8, 1.2),
                    (0.4, 0.2, 0.1), (0.2, 0.4, 0.1), (0.3, 0.2, 0.6), (2.8, 0.5, 2.0)]:  # fmt: skip
        centre_b = np.array([np.sin(d), 0.0, np.cos(d)])
        inside = (directions[:, 2] > np.cos(a)) & (directions @ centre_b > np.cos(b))
        expected = inside.mean() * 4.0 * np.pi
        assert cap_intersection_solid_angle(a, b, d) == pytest.approx(expected, abs=0.02 + 0.02 * expected), (a, b, d)


def test_a_footprints_visible_share_is_its_caps_share_above_the_horizon():
    """A lookup averaging a cap of directions sees the horizon through the cap: its visibility
    (horizon_visibility with that footprint, the fixed soft edge off) against the fraction of
    the cap's directions above the surface that lie above a horizon of sine h all round (Monte
    Carlo, 40k directions; the part below the surface is no lookup the horizon can hide), for
    caps of 0.002-0.3 sr at elevations from 10 to 70 degrees, centres from below to above h."""
    from lobeview.scenes.self_visibility import footprint_radius

    rng = np.random.default_rng(5)
    normal = np.array([0.0, 0.0, 1.0])
    worst = 0.0
    for solid_angle in (0.002, 0.02, 0.1, 0.3):
        radius = np.sqrt(solid_angle / np.pi)
        for elevation in np.radians([10.0, 30.0, 50.0, 70.0]):
            axis = np.array([np.cos(elevation), 0.0, np.sin(elevation)])
            directions = _cap_directions(axis, solid_angle, 40_000, rng)
            for offset in np.linspace(-1.2, 1.2, 9):  # the horizon's elevation, in cap radii off the centre
                h = np.sin(np.clip(elevation + offset * radius, 0.01, 1.5))
                cones = np.concatenate([[0.0, 0.0, 1.0, 0.5], np.full(HORIZON_SECTORS, h)])
                exact = np.mean(directions[:, 2] > h) / np.mean(directions[:, 2] > 0.0)
                modelled = horizon_visibility(axis, cones, normal, soft_edge=1e-9, footprint=solid_angle)
                worst = max(worst, abs(modelled - exact))
    assert worst < 0.015, worst  # Monte Carlo noise: the cap is the model
    # no footprint: the fixed soft edge alone (a sine, so wider in angle toward the zenith); the cap
    # widens with the footprint, never narrows
    assert footprint_radius(0.0, 0.6) == pytest.approx(0.08 / 0.8)
    radii = footprint_radius(np.array([0.0, 0.01, 0.1, 1.0]), 0.3)
    assert np.all(np.diff(radii) > 0.0)


def test_a_tilted_lobes_footprint_counts_what_lies_below_the_surface_as_hidden():
    """A normal map tilts a reflection lobe so that part of a read's footprint lies below the
    surface but above the lobe's horizon: those directions point into the object. The share
    (horizon_visibility with ``lobe_normals``) against the fraction of the cap's directions above
    the lobe's surface that also clear a horizon of sine h all round (Monte Carlo, 40k
    directions), caps of 0.02-0.6 sr 5-50 degrees up at five azimuths, lobes tilted 20-60 degrees.
    Measured: 0.004 worst where one of the two edges crosses the cap (the model is exact there),
    0.035 mean / 0.24 worst where both do (taken as nested: an upper bound); without the lobe's
    normal 0.041 mean, 0.57 worst (ClearCoatTest's ribbed rows, issue 40)."""
    rng = np.random.default_rng(7)
    normal = np.array([0.0, 0.0, 1.0])
    errors, untilted_errors, one_edge = [], [], []
    for solid_angle in (0.02, 0.1, 0.3, 0.6):
        for elevation in np.radians([5.0, 15.0, 30.0, 50.0]):
            for azimuth in np.radians([0.0, 45.0, 90.0, 135.0, 180.0]):
                axis = np.array(
                    [np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)]
                )
                directions = _cap_directions(axis, solid_angle, 40_000, rng)
                for tilt in np.radians([20.0, 40.0, 60.0]):
                    lobe_normal = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
                    in_lobe = directions @ lobe_normal > 0.0
                    if in_lobe.mean() < 0.05:
                        continue  # the read carries next to nothing of the lobe
                    for h in (0.0, 0.2):
                        cones = np.concatenate([[0.0, 0.0, 1.0, 0.5], np.full(HORIZON_SECTORS, h)])
                        clears = directions[:, 2] > h
                        exact = np.mean(clears & in_lobe) / np.mean(in_lobe)
                        shares = [
                            float(
                                horizon_visibility(
                                    axis,
                                    cones,
                                    normal,
                                    soft_edge=1e-9,
                                    footprint=solid_angle,
                                    below_hidden=True,
                                    lobe_normals=lobe,
                                )
                            )
                            for lobe in (lobe_normal, None)
                        ]
                        errors.append(abs(shares[0] - exact))
                        untilted_errors.append(abs(shares[1] - exact))
                        one_edge.append(clears.all() or not clears.any() or in_lobe.all())
    errors, untilted_errors, one_edge = np.array(errors), np.array(untilted_errors), np.array(one_edge)
    assert one_edge.sum() > 100 and (~one_edge).sum() > 30
    assert errors[one_edge].max() < 0.015, errors[one_edge].max()
    assert errors[~one_edge].mean() < 0.05 and errors.mean() < 0.01, (errors[~one_edge].mean(), errors.mean())
    assert untilted_errors.mean() > 4.0 * errors.mean()
    # a point lookup (the reference's) is hidden by where it points, tilted lobe or not
    cones = np.concatenate([[0.0, 0.0, 1.0, 0.5], np.full(HORIZON_SECTORS, 0.0)])
    low = np.array([np.cos(0.05), 0.0, np.sin(0.05)])
    tilted = np.array([np.sin(1.0), 0.0, np.cos(1.0)])
    assert horizon_visibility(low, cones, normal, below_hidden=True, lobe_normals=tilted) == horizon_visibility(
        low, cones, normal, below_hidden=True
    )


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_split_sum_footprint_matches_the_lobes_share_above_the_horizon(kind):
    """A split-sum lookup averages the whole lobe: the visibility of its lookup direction (the
    mirror direction leaned toward the normal, materials/prefilter.py split_sum_lean) with
    split_sum_footprint(alpha) against the BRDF-weighted share of the lobe's reflected
    directions above a horizon of sine h all round (importance sampling of the microfacet
    normals, weight G (wo.wm) / (cos_o cos_m): the lobe f cos without Fresnel), alpha 0.05-1,
    views 15-80 degrees up, the horizon from 0.4 rad below to 0.4 rad above the mirror direction."""
    from lobeview.materials.microfacet import MicrofacetDistribution
    from lobeview.materials.prefilter import split_sum_lean

    rng = np.random.default_rng(9)
    normal = np.array([0.0, 0.0, 1.0])
    errors, point_errors = [], []
    for alpha in (0.05, 0.15, 0.3, 0.5, 0.7, 1.0):
        dist = MicrofacetDistribution(kind, alpha, alpha)
        wm = dist.half_vector_from_xi(rng.random(100_000), rng.random(100_000))
        for elevation in np.radians([15.0, 25.0, 45.0, 65.0, 80.0]):
            wo = np.array([-np.cos(elevation), 0.0, np.sin(elevation)])
            wo_m = wm @ wo
            wi = 2.0 * wo_m[:, None] * wm - wo
            weight = np.where((wo_m > 0.0) & (wi[:, 2] > 0.0), dist.G(wi, np.broadcast_to(wo, wi.shape), wm), 0.0)
            weight *= np.maximum(wo_m, 0.0) / (wo[2] * wm[:, 2])
            mirror = np.array([np.cos(elevation), 0.0, np.sin(elevation)])
            lookup = normal + split_sum_lean(alpha) * (mirror - normal)
            lookup /= np.linalg.norm(lookup)
            for offset in np.linspace(-0.4, 0.4, 9):
                h = np.sin(np.clip(elevation + offset, 0.01, 1.5))
                cones = np.concatenate([[0.0, 0.0, 1.0, 0.5], np.full(HORIZON_SECTORS, h)])
                exact = np.sum(weight * (wi[:, 2] > h)) / np.sum(weight)
                footprint = split_sum_footprint(alpha, kind)
                modelled = horizon_visibility(lookup, cones, normal, soft_edge=1e-9, footprint=footprint)
                errors.append(abs(modelled - exact))
                point_errors.append(abs(horizon_visibility(lookup, cones, normal) - exact))
    errors, point_errors = np.array(errors), np.array(point_errors)
    # measured: GGX worst 0.21 / mean 0.042, Beckmann 0.13 / 0.036; the lookup direction alone
    # (with the fixed soft edge, as before the footprint) 0.88 / 0.23
    worst, mean = (0.25, 0.05) if kind == "ggx" else (0.16, 0.045)
    assert errors.max() < worst and errors.mean() < mean, (errors.max(), errors.mean())
    assert point_errors.mean() > 3.0 * errors.mean()


def test_floor_beside_a_wall_gets_the_walls_horizon_per_azimuth():
    """A point on a floor 1 in front of a wall 1 high and 3 wide (from x = -1.5 to 1.5): toward
    azimuth phi off the wall's direction the wall's top stands at sin e = cos phi / sqrt(1 +
    cos^2 phi) while |tan phi| <= 1.5, else nothing; each sector's traced horizon is the mean
    of that over the sector (quadrature), which a circular cone cannot hold."""
    from lobeview.scenes.meshes import merge_meshes
    from lobeview.scenes.self_visibility import horizon_frame

    floor = _grid((-1.5, 0.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, -2.0), 30)
    wall = _grid((-1.5, 0.0, -1.0), (3.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30)
    mesh = merge_meshes([floor, wall], "corner")
    cones = vertex_visibility_cones(mesh.positions, mesh.normals, mesh.indices, rays=1024, smoothing_passes=0)
    centre = int(np.argmin(np.linalg.norm(mesh.positions[: len(floor.positions)] - [0.0, 0.0, 0.0], axis=1)))
    assert np.allclose(mesh.positions[centre], 0.0)
    tangent, bitangent = horizon_frame(np.array([0.0, 1.0, 0.0]))
    phi = (np.arange(HORIZON_SECTORS * 400) + 0.5) / (HORIZON_SECTORS * 400) * 2.0 * np.pi
    toward = np.cos(phi)[:, None] * tangent + np.sin(phi)[:, None] * bitangent
    cos_to_wall = -toward[:, 2]  # the wall lies toward -z
    lateral = np.abs(toward[:, 0]) / np.maximum(cos_to_wall, 1e-12)
    hit = (cos_to_wall > 0.0) & (lateral <= 1.5)
    sin_top = np.where(hit, cos_to_wall / np.sqrt(1.0 + cos_to_wall**2), 0.0)
    expected = sin_top.reshape(HORIZON_SECTORS, -1).mean(axis=1)
    assert expected.max() > 0.5 and expected.min() == 0.0  # the wall's side and the open side
    np.testing.assert_allclose(cones[centre, 4:], expected, atol=0.03)  # 128 rays a sector


# -- the shaders against the numpy twin --------------------------------------------------------


def _grid(corner, edge_u, edge_v, steps: int):
    from lobeview.scenes.meshes import Mesh

    s, t = np.meshgrid(np.linspace(0.0, 1.0, steps + 1), np.linspace(0.0, 1.0, steps + 1), indexing="ij")
    corner, edge_u, edge_v = (np.asarray(v, dtype=np.float64) for v in (corner, edge_u, edge_v))
    positions = corner + s[..., None] * edge_u + t[..., None] * edge_v
    normal = np.cross(edge_u, edge_v)
    normal /= np.linalg.norm(normal)
    faces = []
    for i in range(steps):
        for j in range(steps):
            a, b = i * (steps + 1) + j, (i + 1) * (steps + 1) + j
            faces += [(a, b, b + 1), (a, b + 1, a + 1)]
    count = (steps + 1) ** 2
    tangent = np.concatenate([edge_u / np.linalg.norm(edge_u), [1.0]])
    return Mesh(
        positions.reshape(-1, 3).astype(np.float32),
        np.tile(normal, (count, 1)).astype(np.float32),
        np.tile(tangent, (count, 1)).astype(np.float32),
        np.stack([s.ravel(), t.ravel()], axis=1).astype(np.float32),
        np.array(faces, dtype=np.uint32),
    )


FLOOR_CAMERA = Camera(position=(0.0, 0.9, 2.6), target=(0.0, 0.0, -0.3), fov_y=45.0)


def floor_occlusion_ratios(scene, method: str, inspect=None):
    """The floor scene of the tests below under a uniform white sky, rendered by ``method`` with
    self-occlusion and without: the ratio of the two at every floor pixel (normal +y, in front of
    the wall), those pixels' positions, and ``inspect(renderer)`` before it is released."""
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=32, name="white")
    ctx = create_headless_context()
    renderer = SceneRenderer(
        ctx, scene, env, size=(128, 96), progress=False, settings=RenderSettings(cube_face_size=16)
    )
    try:
        inspected = inspect(renderer) if inspect is not None else None
        frames = {}
        for occlusion in (True, False):
            renderer.configure(self_occlusion=occlusion)
            frames[occlusion] = renderer.render(FLOOR_CAMERA, method)
        on, off = frames[True], frames[False]
    finally:
        renderer.release()
        ctx.release()
    assert not on.invalid.any() and not off.invalid.any()
    # the floor by position (a normal map tilts the G-buffer's normal), in front of the wall
    floor_pixels = (on.object_id == 0) & (np.abs(on.position[..., 1]) < 1e-3) & (on.position[..., 2] > -0.95)
    assert floor_pixels.sum() > 2000
    ratio = on.radiance[floor_pixels].mean(axis=-1) / off.radiance[floor_pixels].mean(axis=-1)
    return ratio, on.position[floor_pixels].astype(np.float64), inspected


def assert_floor_ratios_follow(
    ratio, points, cones, footprint, shading_normal=(0.0, 1.0, 0.0), both_regimes: bool = True
) -> None:
    """The floor's self-occluded / unoccluded ratios equal 0.5 + 0.5 vis (the hidden part sees
    the point itself: F0 0.5 lit by E = pi), vis the numpy horizons ``cones`` about the floor's
    normal +y at the pixels ``points`` toward their mirror direction about ``shading_normal`` (a
    normal map's) through a lookup of ``footprint`` sr, a reflection's (hidden below the floor):
    99 % within 0.03, mean within 0.01, with both regimes (mostly hidden, open) among the pixels
    unless ``both_regimes`` is False."""
    view = FLOOR_CAMERA.position - points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    normal = np.asarray(shading_normal, dtype=np.float64) / np.linalg.norm(shading_normal)
    mirror = 2.0 * (view @ normal)[:, None] * normal - view
    floor_normal = np.array([0.0, 1.0, 0.0])
    visible = horizon_visibility(mirror, cones, floor_normal, footprint=footprint, below_hidden=True)
    expected = 0.5 + 0.5 * visible
    assert (expected < 0.6).sum() > 100 and ((expected > 0.95).sum() > 100 or not both_regimes)
    error = np.abs(ratio - expected)
    assert np.quantile(error, 0.99) < 0.03, np.quantile(error, [0.5, 0.9, 0.99, 1.0])
    assert np.mean(error) < 0.01


@pytest.mark.parametrize("method", ["lobe-7", "prefiltered-rsibr"])
def test_shaders_follow_the_numpy_horizons_on_a_floor_beside_a_wall(method):
    """A near-mirror metal floor (base colour 0.5) with a wall at its back, one object, under a
    uniform sky: its cube map holds only the sky (the object is not in its own cube), so with
    self-occlusion a floor pixel shows F (vis L + (1 - vis) 0.5 L), the hidden part seeing the
    object as the point itself (F0 0.5 lit by E = pi L), and without it F L. The ratio of the two
    frames is 0.5 + 0.5 vis at every floor pixel, vis from the numpy horizons interpolated at the
    pixel's position and its mirror direction (measured: 99 % within 5e-4, the worst 1.4e-3).
    prefiltered-rsibr's maps hold the lobe over the surroundings alone too: its hidden share is
    its split-sum footprint's (rsibr.glsl), the same ratio (before, 1 at every pixel)."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.meshes import merge_meshes
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject
    from lobeview.scenes.self_visibility import object_visibility_cones

    floor = _grid((-1.5, 0.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, -2.0), 30)  # normal +y
    wall = _grid((-1.5, 0.0, -1.0), (3.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30)  # normal +z, toward the floor
    mesh = merge_meshes([floor, wall], "corner")
    metal = validate({"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 1.0, "roughness": 0.05})
    scene = Scene([SceneObject("corner", mesh, 0)], [SceneMaterial("metal", metal)])
    scene.objects[0].planar_reflector = False  # its cube map, not a mirror pass
    cones = object_visibility_cones(scene.objects[0])
    floor_cones = cones[: len(floor.positions)]
    assert (floor_cones[:, 3] > NO_OCCLUSION).mean() > 0.5  # the wall hides part of the floor's sky

    with pytest.warns(UserWarning, match="no usable lightmap"):
        ratio, points, _ = floor_occlusion_ratios(scene, method)
    # numpy: the cone and horizons at each pixel's position, the mirror direction of the view about +y
    assert_floor_ratios_follow(
        ratio,
        points,
        _floor_cones_at(points, floor, floor_cones),
        split_sum_footprint(0.05**2) if method == "prefiltered-rsibr" else 0.0,
    )


def _floor_cones_at(points: np.ndarray, floor, floor_cones: np.ndarray, steps: int = 30) -> np.ndarray:
    """The cones and horizons of the floor's vertices (``_grid`` of ``steps`` cells a side over
    x in [-1.5, 1.5], z in [1, -1]) at floor ``points``, barycentric on its triangles as the
    rasteriser interpolates."""
    import trimesh

    cell_i = np.clip(np.floor((points[:, 0] + 1.5) / 3.0 * steps), 0, steps - 1).astype(int)
    cell_j = np.clip(np.floor((1.0 - points[:, 2]) / 2.0 * steps), 0, steps - 1).astype(int)
    first = 2 * (cell_i * steps + cell_j)  # the cell's two triangles: first, first + 1
    floor_positions = floor.positions.astype(np.float64)
    bary_first = trimesh.triangles.points_to_barycentric(floor_positions[floor.indices[first]], points)
    in_first = np.all(bary_first >= -1e-6, axis=1)
    triangle = np.where(in_first, first, first + 1)
    bary = trimesh.triangles.points_to_barycentric(floor_positions[floor.indices[triangle]], points)
    return np.einsum("pk,pkc->pc", bary, floor_cones[floor.indices[triangle]].astype(np.float64))


def test_a_reflection_below_the_surface_sees_the_object_itself():
    """The floor beside a wall again, its shading normal tilted 10 degrees away from the camera
    by a uniform normal map: at the floor's far half the mirror direction about that normal lies
    below the floor (a normal map takes reflections there), which a reflection lobe's lookups
    take as hidden, seeing the object (the stand-in radiance, F0 0.5 lit by E = pi: ratio 0.5);
    nearer, 0.5 + 0.5 vis by the horizons as before. Before, every direction below the surface
    passed (ratio 1 on the far half)."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.meshes import merge_meshes
    from lobeview.scenes.scene import NEAREST, Scene, SceneMaterial, SceneObject, TextureSlot
    from lobeview.scenes.self_visibility import object_visibility_cones

    floor = _grid((-1.5, 0.0, 1.0), (3.0, 0.0, 0.0), (0.0, 0.0, -2.0), 30)  # normal +y, tangent +x
    wall = _grid((-1.5, 0.0, -1.0), (3.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30)
    mesh = merge_meshes([floor, wall], "corner")
    tilt = np.radians(10.0)
    # tangent space (0, sin, cos): toward the bitangent n x t = -z, away from the camera at +z
    texel = np.round((np.array([0.0, np.sin(tilt), np.cos(tilt)]) * 0.5 + 0.5) * 255)
    normal_map = np.tile(np.append(texel, 255).astype(np.uint8), (4, 4, 1))
    metal = validate({"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 1.0, "roughness": 0.05})
    textures = {"normal": TextureSlot(normal_map, mag_filter=NEAREST, min_filter=NEAREST)}
    scene = Scene([SceneObject("corner", mesh, 0)], [SceneMaterial("metal", metal, textures=textures)])
    scene.objects[0].planar_reflector = False
    floor_cones = object_visibility_cones(scene.objects[0])[: len(floor.positions)]

    with pytest.warns(UserWarning, match="no usable lightmap"):
        ratio, points, _ = floor_occlusion_ratios(scene, "lobe-7")
    decoded = texel[:3] / 255.0 * 2.0 - 1.0  # the texel as the shader reads it: (0, sin, cos) in tangent space
    shading_normal = decoded[0] * np.array([1.0, 0.0, 0.0]) + decoded[1] * np.array([0.0, 0.0, -1.0])
    shading_normal = shading_normal + decoded[2] * np.array([0.0, 1.0, 0.0])
    view = FLOOR_CAMERA.position - points
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    normal = shading_normal / np.linalg.norm(shading_normal)
    below = (2.0 * (view @ normal)[:, None] * normal - view)[:, 1] < -0.02
    assert below.sum() > 300 and (~below).sum() > 300
    np.testing.assert_allclose(np.median(ratio[below]), 0.5, atol=0.01)
    cones = _floor_cones_at(points, floor, floor_cones)
    # above the floor the tilted mirror leans toward the wall: partly hidden, none fully open
    assert_floor_ratios_follow(ratio, points, cones, 0.0, shading_normal, both_regimes=False)


def test_cones_are_cached_by_mesh_and_a_damaged_file_is_traced_again(tmp_path, monkeypatch):
    from lobeview.scenes import self_visibility
    from lobeview.scenes.meshes import Mesh
    from lobeview.scenes.scene import SceneObject

    positions, normals, faces = _well(1.0, 1.0, segments=16)
    mesh = Mesh(positions.astype(np.float32), normals.astype(np.float32), np.zeros((len(positions), 4), np.float32),
                np.zeros((len(positions), 2), np.float32), faces.astype(np.uint32))  # fmt: skip
    self_visibility.forget_traced_cones()
    first = self_visibility.object_visibility_cones(SceneObject("well", mesh, 0), tmp_path)
    files = list(tmp_path.glob("cones-*.npy"))
    assert len(files) == 1

    def no_tracing(*args, **kwargs):
        raise AssertionError("traced again although the cache holds the cones")

    with monkeypatch.context() as patch:
        patch.setattr(self_visibility, "vertex_visibility_cones", no_tracing)
        again = self_visibility.object_visibility_cones(SceneObject("well", mesh, 0), tmp_path)
        self_visibility.forget_traced_cones()  # now from the disk
        from_disk = self_visibility.object_visibility_cones(SceneObject("well", mesh, 0), tmp_path)
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(first, from_disk)
    self_visibility.forget_traced_cones()
    files[0].write_bytes(b"not a numpy file")
    with pytest.warns(UserWarning, match="unusable cached visibility cones"):
        traced = self_visibility.object_visibility_cones(SceneObject("well", mesh, 0), tmp_path)
    np.testing.assert_array_equal(first, traced)
    moved = Mesh(mesh.positions + 1.0, mesh.normals, mesh.tangents, mesh.uvs, mesh.indices)
    self_visibility.object_visibility_cones(SceneObject("moved", moved, 0), tmp_path)
    assert len(list(tmp_path.glob("cones-*.npy"))) == 2  # another mesh, another key


def test_a_mesh_loaded_again_is_not_traced_again_without_a_cache_folder(monkeypatch):
    """The process keeps what it traced (every test's renderer, the first-use bake's swap): the
    same mesh in a new object is not traced again, another mesh is, and the memory is bounded."""
    from lobeview.scenes import self_visibility
    from lobeview.scenes.meshes import Mesh
    from lobeview.scenes.scene import SceneObject

    positions, normals, faces = _well(1.0, 1.0, segments=16)
    mesh = Mesh(positions.astype(np.float32), normals.astype(np.float32), np.zeros((len(positions), 4), np.float32),
                np.zeros((len(positions), 2), np.float32), faces.astype(np.uint32))  # fmt: skip
    self_visibility.forget_traced_cones()
    traced = []
    real = self_visibility.vertex_visibility_cones
    monkeypatch.setattr(self_visibility, "vertex_visibility_cones", lambda *a, **k: traced.append(1) or real(*a, **k))
    first = self_visibility.object_visibility_cones(SceneObject("well", mesh, 0))
    again = self_visibility.object_visibility_cones(SceneObject("well again", mesh, 0))
    assert len(traced) == 1 and again is first and not first.flags.writeable
    deeper = Mesh(mesh.positions * [1.0, 2.0, 1.0], mesh.normals, mesh.tangents, mesh.uvs, mesh.indices)
    other = self_visibility.object_visibility_cones(SceneObject("deeper", deeper, 0))
    assert len(traced) == 2 and not np.array_equal(other, first)
    monkeypatch.setattr(self_visibility, "MEMORY_CACHE_BYTES", first.nbytes)  # room for one
    wider = Mesh(mesh.positions * [2.0, 1.0, 2.0], mesh.normals, mesh.tangents, mesh.uvs, mesh.indices)
    newest = self_visibility.object_visibility_cones(SceneObject("wider", wider, 0))
    assert list(self_visibility._traced_cones.values()) == [newest]  # the older two went
    self_visibility.forget_traced_cones()


@pytest.mark.parametrize("sectors", [HORIZON_SECTORS, MAP_HORIZON_SECTORS])
def test_glsl_self_visibility_and_split_sum_footprint_equal_numpy(sectors):
    """self_occlusion.glsl's self_visibility (the cap of a lookup's footprint against per-sector
    horizons, as many sectors as vertices or a horizon map hold) and split_sum_footprint through a
    compute probe, against the numpy twin, for random normals, directions above and below them
    (below: hidden for a reflection lobe, passing for a transmission lobe), horizons, footprints
    0-2 sr, lobes tilted from the normal by up to 60 degrees and both distributions."""
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.interface import DISTRIBUTIONS
    from lobeview.viewer.shaders import ProgramCache

    rng = np.random.default_rng(3)
    n = 2048
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    directions = rng.normal(size=(n, 3)) + 1.5 * normals  # mostly above the surface
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    footprints = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(0.0, 2.0, n) ** 2)
    horizons = rng.uniform(-0.1, 0.9, (n, sectors))
    kinds = rng.choice(["ggx", "beckmann"], n)
    alphas = rng.uniform(0.002, 1.0, n)
    horizon_rows = MAP_HORIZON_SECTORS // 4
    probe = np.zeros((n, 4 + horizon_rows, 4), np.float32)
    probe[:, 0, :3], probe[:, 0, 3] = directions, footprints
    probe[:, 1, :3], probe[:, 1, 3] = normals, sectors
    probe[:, 2 : 2 + horizon_rows] = np.pad(horizons, ((0, 0), (0, MAP_HORIZON_SECTORS - sectors))).reshape(n, -1, 4)
    reflects = rng.random(n) < 0.5
    probe[:, -2, 0] = [DISTRIBUTIONS[k] for k in kinds]
    probe[:, -2, 1] = alphas
    probe[:, -2, 2] = reflects
    # half the lobes tilted from the surface's normal by up to 60 degrees (a normal map)
    tilt_axis = np.cross(normals, rng.normal(size=(n, 3)))
    tilt_axis /= np.linalg.norm(tilt_axis, axis=1, keepdims=True)
    tilt = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.0, np.radians(60.0), n))[:, None]
    lobe_normals = np.cos(tilt) * normals + np.sin(tilt) * tilt_axis
    probe[:, -1, :3] = lobe_normals
    ctx = create_headless_context()
    try:
        program = ProgramCache(ctx).compute("self_visibility_probe.comp")
        out = run_compute_probe(ctx, program, probe, 1)[:, 0]
    finally:
        ctx.release()
    cones = np.concatenate([np.tile([0.0, 0.0, 1.0, 0.5], (n, 1)), horizons], axis=1)
    expected = horizon_visibility(probe[:, 0, :3].astype(np.float64), cones, probe[:, 1, :3].astype(np.float64),
                                  footprint=probe[:, 0, 3].astype(np.float64), below_hidden=reflects,
                                  lobe_normals=probe[:, -1, :3].astype(np.float64))  # fmt: skip
    untilted = horizon_visibility(probe[:, 0, :3].astype(np.float64), cones, probe[:, 1, :3].astype(np.float64),
                                  footprint=probe[:, 0, 3].astype(np.float64), below_hidden=reflects)  # fmt: skip
    assert np.mean(np.abs(expected - untilted) > 0.02) > 0.05  # the tilted lobes' shares differ
    below = np.sum(probe[:, 0, :3] * probe[:, 1, :3], axis=1) <= 0.0
    assert (below & reflects).sum() > 20 and np.all(expected[below & reflects] == 0.0)
    assert np.all(expected[below & ~reflects] == 1.0)
    assert 0.1 < np.mean((expected > 0.02) & (expected < 0.98)) < 0.9  # partial shares covered
    # float32: acos near +-1 in the cap formula loses up to 0.005 of share on the smallest caps
    # (the soft edge's alone, 0.1-0.2 rad); 99 % of items within 2e-3
    np.testing.assert_allclose(out[:, 0], expected, atol=8e-3)
    assert np.quantile(np.abs(out[:, 0] - expected), 0.99) < 2e-3
    footprint = np.array(
        [split_sum_footprint(a, k) for a, k in zip(probe[:, -2, 1].astype(np.float64), kinds, strict=True)]
    )
    np.testing.assert_allclose(out[:, 1], footprint, rtol=1e-4, atol=1e-6)
