"""Specular self-occlusion: per-vertex visibility cones of an object against its own surface
(issue 40).

An object's specular light comes from its cube map, rendered from the object's centre without
the object (viewer/cube_bake.py): what other objects hide is in the cube, what the object hides
from itself is not. Against Blender Cycles a baked DamagedHelmet came out 8 % too bright for that
reason alone (Cycles with the helmet invisible to its own rays matched lobeview's reference).

Each vertex gets a visibility cone, the usual approximation of what a point sees past its own
object (Oat and Sander 2007, "Ambient aperture lighting"; Jimenez et al. 2016, "Practical
real-time strategies for accurate indirect occlusion"): ``rays`` cosine-distributed directions
around the vertex normal are traced against the object's own triangles (embree through trimesh);
the bent normal is the mean of the directions that escape, and the cone's half angle ``a``
follows from the cosine-weighted visible fraction V: the cone around the bent normal holds V of
the cosine-weighted hemisphere (cos a = sqrt(1 - V) when the bent normal is the normal; wider as
it tilts, cone_cos_aperture). A vertex none of whose
rays hit the object (every vertex of a convex one) gets no cone (cos a = NO_OCCLUSION): nothing
changes there.

The cone says whether a vertex is occluded at all; which directions it hides is a horizon per
azimuth sector (HORIZON_SECTORS, Max 1988 "Horizon mapping"; Sloan and Cohen 2000): a circular
cone that holds the right visible fraction must cut every azimuth at one elevation, and hid the
studio's low softboxes from Suzanne's forehead, which only its brow shadows on one side
(docs/measurements.md). A lookup of the specular lobes (shaders/self_occlusion.glsl
self_occluded) averages the cube over a footprint about its direction d; its visible share is
the part of that footprint's cap above the horizon, the horizon averaged over the azimuths the
cap spans (horizon_visibility); the occluded part sees the object itself, whose radiance is
taken as the shading point's own (its diffuse and its specular reflectance lit by its
irradiance: "the occluder looks like me")."""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from lobeview.core.cache import read_cache_file, write_cache_file

from .baker import _frame

SELF_VISIBILITY_RAYS = 64  # rays per vertex
SMOOTHING_PASSES = 2  # neighbour averages of the per-vertex estimates
# Rays per object and pass (the cones', then the occluded vertices' horizons'): fewer a vertex beyond.
MAX_SELF_VISIBILITY_RAYS_TOTAL = 4_000_000
MIN_RAYS_PER_VERTEX = 8
NO_OCCLUSION = -2.0  # cos a of a vertex no ray of which hits its object: every direction visible
SOFT_EDGE = 0.1  # half width, in cosine, of the cone's soft edge (a 64-ray cone is not sharper)
ORIGIN_OFFSET = 1e-4  # ray origins off the surface, times the object's extent
NEAR_HIT_DISTANCE = 0.03  # hits nearer than this, times the object's extent, are ignored (see below)
SEED = 11
HORIZON_SECTORS = 8  # azimuth sectors of the horizon around each normal (traced_horizons)
# ... in a horizon map (scenes/horizon_maps.py): a point's own horizons, of which 8 sectors'
# (linear in azimuth between their centres) let a crease's narrow open azimuths through, 16 far
# less (DamagedHelmet's mirror directions Cycles finds hidden, traced per point: visible share
# 0.17 -> 0.13, exactly by ray 0.11; docs/measurements.md). Vertex horizons, interpolated over
# triangles, gain nothing comparable from more sectors and keep two vertex attributes.
MAP_HORIZON_SECTORS = 16
CONE_FLOATS = 4 + HORIZON_SECTORS  # per vertex: bent normal, cos of the cone's half angle, horizons
HORIZON_SOFT_EDGE = 0.08  # a point lookup's cap radius, in sin of elevation: the horizon's soft edge
# A lookup that averages the cube over a footprint (a filtered lobe-N or fis-N sample, a
# prefiltered lobe, a cap light) sees the horizon through it: taken as a spherical cap of the
# footprint's solid angle about the lookup direction, its visible share is the part of the cap above
# the horizon (a circle about the normal at the horizon's elevation) over its part above the surface
# (horizon_visibility, by cap_intersection_solid_angle). A point-sized lookup (the reference) gets a
# cap of HORIZON_SOFT_EDGE / cos e radians, the per-vertex horizon's own uncertainty (a sine).
HORIZON_MIN_COS = 1e-3  # cos e below which the soft edge's angle stops growing (at the zenith)
MAX_FOOTPRINT_RADIUS = 3.0  # radians: a footprint cap no wider (pi is the whole sphere)
# A split-sum lookup averages the whole lobe: a cap of radius k alpha, at most SPLIT_SUM_MAX_RADIUS,
# about its (leaned) lookup direction; k and the bound fitted against the lobe's BRDF-weighted share
# above horizons 0.4 rad below to above the mirror direction, alpha 0.05-1, views 15-80 degrees up
# (tests/test_self_visibility.py): GGX 2.75 (worst 0.21, mean 0.042 off), Beckmann 2.25 (0.13 /
# 0.036); the lookup direction's visibility alone was 0.88 / 0.23 off. Without the bound a rough
# lobe's cap covers the hemisphere evenly where the lobe weighs by cosine (mean 0.10 off at alpha
# 0.7-1 in that test).
SPLIT_SUM_RADIUS_PER_ALPHA_GGX = 2.75
SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN = 2.25
SPLIT_SUM_MAX_RADIUS = 1.3
# A reflection lobe whose normal a normal map tilts more than this (1 - cos) from the surface's
# takes a lookup's share over the part of its footprint above the lobe's own surface
# (horizon_visibility's lobe_normals): the part below the surface but above the lobe's horizon
# points into the object. Below it the surface's own normal (bit for bit as without a map).
SELF_LOBE_TILT_MIN = 1e-6
AZIMUTH_TAP = np.sqrt(0.5)  # horizon_visibility's taps across a cap: its centre and -+ this of its span
AZIMUTH_TAP_OFFSETS = (-AZIMUTH_TAP, 0.0, AZIMUTH_TAP)
AZIMUTH_TAP_WEIGHTS = (0.25, 0.5, 0.25)
# The horizon's azimuths are measured in a tangent frame from this axis (horizon_frame): continuous
# everywhere but at normals along +-axis, a direction no axis-aligned surface has.
HORIZON_AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
CACHE_VERSION = "cones-2"  # with the constants above and the mesh, the key of a cached file


def _unit_normals(normals: np.ndarray) -> np.ndarray:
    """Unit normals; a zero or non-finite one (degenerate input) becomes +z, which only decides
    which hemisphere that vertex's rays sample."""
    normals = np.asarray(normals, dtype=np.float64)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    ok = np.isfinite(length) & (length > 1e-12)
    return np.where(ok, normals / np.where(ok, length, 1.0), [[0.0, 0.0, 1.0]])


def cosine_directions(rays: int, seed: int = SEED) -> np.ndarray:
    """``rays`` cosine-distributed unit directions around +z (scrambled Sobol, Malley's method)."""
    u = qmc.Sobol(d=2, scramble=True, seed=seed).random(rays)
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - u[:, 0], 0.0))], axis=1)


def rays_per_vertex(vertex_count: int, rays: int = SELF_VISIBILITY_RAYS) -> int:
    """Rays per vertex for an object of ``vertex_count`` vertices: ``rays``, fewer (not below
    MIN_RAYS_PER_VERTEX) where the object would trace more than MAX_SELF_VISIBILITY_RAYS_TOTAL."""
    if vertex_count <= 0:
        return rays
    return int(max(min(rays, MAX_SELF_VISIBILITY_RAYS_TOTAL // vertex_count), MIN_RAYS_PER_VERTEX))


def vertex_visibility_cones(
    positions: np.ndarray,
    normals: np.ndarray,
    indices: np.ndarray,
    rays: int = SELF_VISIBILITY_RAYS,
    seed: int = SEED,
    smoothing_passes: int = SMOOTHING_PASSES,
) -> np.ndarray:
    """(V, 4 + HORIZON_SECTORS) float32: per vertex the bent normal (unit, the positions' space),
    the cosine of the visibility cone's half angle (NO_OCCLUSION where the object hides nothing
    from it) and the sine of the horizon's elevation in each azimuth sector (traced_horizons).
    ``indices``: the triangles (3 per face)."""
    import trimesh

    positions = np.asarray(positions, dtype=np.float64)
    count = len(positions)
    cones = np.zeros((count, CONE_FLOATS), dtype=np.float32)
    normals = _unit_normals(normals)
    cones[:, :3] = normals
    cones[:, 3] = NO_OCCLUSION
    faces = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    if count == 0 or len(faces) < 2:  # one triangle cannot hide anything from itself
        return cones
    mesh = trimesh.Trimesh(positions, faces, process=False)
    extent = float(np.max(positions.max(0) - positions.min(0)))
    n = rays_per_vertex(count, rays)
    local = cosine_directions(n, seed)
    # A per-vertex turn of the pattern about the normal: neighbouring vertices see different
    # directions (no shared aliasing), and the result stays deterministic.
    turn = np.random.default_rng(seed).random(count) * 2.0 * np.pi
    tangent, bitangent = _frame(normals)  # the baker's tangent frame per normal
    cos_t, sin_t = np.cos(turn)[:, None], np.sin(turn)[:, None]
    tangent, bitangent = cos_t * tangent + sin_t * bitangent, cos_t * bitangent - sin_t * tangent
    directions = (
        local[None, :, 0:1] * tangent[:, None, :]
        + local[None, :, 1:2] * bitangent[:, None, :]
        + local[None, :, 2:3] * normals[:, None, :]
    )  # (V, n, 3)
    hit = _own_hits(mesh, positions, normals, directions, extent).reshape(count, n)
    if not hit.any():
        return cones
    escaped = ~hit
    visible = escaped.mean(axis=1)
    bent = np.einsum("vn,vnk->vk", escaped.astype(np.float64), directions) / n  # V times the mean direction
    # A few dozen rays leave each vertex's estimate noisy (V to about +-0.09), which a near-mirror
    # shows as mottling: averaged with the neighbours that share a triangle, SMOOTHING_PASSES times.
    visible, bent = _smooth_over_neighbours(faces, count, visible, bent, passes=smoothing_passes)
    length = np.linalg.norm(bent, axis=1, keepdims=True)
    bent = np.where(length > 1e-12, bent / np.where(length > 1e-12, length, 1.0), normals)
    occluded = visible < 1.0 - 1e-6
    tilt = np.arccos(np.clip(np.sum(bent * normals, axis=1), -1.0, 1.0))
    cones[occluded, :3] = bent[occluded]
    cones[occluded, 3] = cone_cos_aperture(tilt[occluded], visible[occluded])
    if occluded.any():
        horizons = np.zeros((count, HORIZON_SECTORS))
        horizons[occluded] = traced_horizons(
            mesh, positions[occluded], normals[occluded], extent, max(n // HORIZON_SECTORS, 1), seed
        )
        (horizons,) = _smooth_over_neighbours(faces, count, horizons, passes=smoothing_passes)
        cones[occluded, 4:] = horizons[occluded]
    return cones


def _own_hits(
    mesh, positions: np.ndarray, normals: np.ndarray, directions: np.ndarray, extent: float, near_hit=NEAR_HIT_DISTANCE
) -> np.ndarray:
    """Whether each ray (``directions`` (V, n, 3) from each vertex) meets the object's own
    ``mesh`` (trimesh), flattened. Rays start ``near_hit`` (NEAR_HIT_DISTANCE) times the extent
    along themselves: a grazing ray from a vertex whose normal is averaged over a curved, faceted
    surface meets the neighbouring triangles at once, which hide nothing a finer mesh would (the
    occlusion texture holds detail at that scale)."""
    start = positions[:, None, :] + normals[:, None, :] * (ORIGIN_OFFSET * max(extent, 1e-12))
    start = start + directions * (near_hit * max(extent, 1e-12))
    return mesh.ray.intersects_any(start.reshape(-1, 3), directions.reshape(-1, 3))


def horizon_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent and bitangent about unit ``normals`` (..., 3) in which the horizon's azimuth is
    measured (shaders/self_occlusion.glsl horizon_frame): from HORIZON_AXIS, continuous but at
    normals along it (there from +x)."""
    normals = np.asarray(normals, dtype=np.float64)
    tangent = np.cross(HORIZON_AXIS, normals)
    length = np.linalg.norm(tangent, axis=-1, keepdims=True)
    fallback = np.cross([1.0, 0.0, 0.0], normals)
    tangent = np.where(length > 1e-6, tangent, fallback)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-12)
    return tangent, np.cross(normals, tangent)


def traced_horizons(
    mesh, positions, normals, extent, rays_per_sector, seed=SEED, near_hit=NEAR_HIT_DISTANCE, sectors=HORIZON_SECTORS
):
    """(V, ``sectors``): per vertex (or any surface point of ``mesh``: the horizon maps' texels,
    bench/cycles_trace.py's pixels) and azimuth sector, the sine of the horizon's elevation, rays cut
    ``near_hit`` times the extent from their origin (_own_hits),
    taken as the sector's hidden fraction of solid angle (its rays are uniform in solid angle:
    uniform in sin(elevation)), so that everything below the horizon is what the object hides.
    A circular cone must cut every azimuth at one elevation; a forehead that the brow hides
    toward one side only still sees low lights on the others (docs/measurements.md)."""
    count = len(positions)
    rng = np.random.default_rng(seed + 1)
    k = rays_per_sector
    jitter = rng.random((count, sectors, k, 2))
    # Latin hypercube in (sin of elevation, azimuth) within the sector: stratified in both.
    strata = rng.permuted(np.broadcast_to(np.arange(k), (count, sectors, k)), axis=2)
    sin_e = (np.arange(k)[None, None, :] + jitter[..., 0]) / k
    phi = (np.arange(sectors)[None, :, None] + (strata + jitter[..., 1]) / k) / sectors * 2.0 * np.pi
    cos_e = np.sqrt(np.maximum(1.0 - sin_e**2, 0.0))
    tangent, bitangent = horizon_frame(normals)
    directions = (
        (cos_e * np.cos(phi))[..., None] * tangent[:, None, None, :]
        + (cos_e * np.sin(phi))[..., None] * bitangent[:, None, None, :]
        + sin_e[..., None] * normals[:, None, None, :]
    ).reshape(count, -1, 3)
    hit = _own_hits(mesh, positions, normals, directions, extent, near_hit)
    return hit.reshape(count, sectors, k).mean(axis=2)


def cap_intersection_solid_angle(radius_a, radius_b, separation):
    """Solid angle of the intersection of two spherical caps of angular radii ``radius_a`` and
    ``radius_b`` (radians, up to pi) whose centres lie ``separation`` apart (Tovchigrechko and
    Vakser 2001, eq. 4; the shaders' cap_intersection_solid_angle)."""
    a, b, d = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (radius_a, radius_b, separation)))
    cos_a, cos_b, cos_d = np.cos(a), np.cos(b), np.cos(d)
    sin_a, sin_b, sin_d = (np.maximum(np.sin(x), 1e-12) for x in (a, b, d))
    with np.errstate(invalid="ignore"):
        t_d = np.arccos(np.clip((cos_d - cos_a * cos_b) / (sin_a * sin_b), -1.0, 1.0))
        t_a = np.arccos(np.clip((cos_b - cos_d * cos_a) / (sin_d * sin_a), -1.0, 1.0))
        t_b = np.arccos(np.clip((cos_a - cos_d * cos_b) / (sin_d * sin_b), -1.0, 1.0))
    partial = 2.0 * (np.pi - t_d - t_a * cos_a - t_b * cos_b)
    smaller = 2.0 * np.pi * (1.0 - np.maximum(cos_a, cos_b))
    contained = d <= np.abs(a - b)
    return np.where(d >= a + b, 0.0, np.where(contained, smaller, np.maximum(partial, 0.0)))


def footprint_radius(footprint, sin_e, soft_edge: float = HORIZON_SOFT_EDGE):
    """Angular radius of the cap a lookup averaging ``footprint`` sr about a direction of
    elevation sine ``sin_e`` is taken as: the footprint's own cap and the soft edge's (a sine,
    turned into angle by 1 / cos e) in quadrature, at most MAX_FOOTPRINT_RADIUS."""
    footprint = np.clip(np.asarray(footprint, dtype=np.float64), 0.0, 4.0 * np.pi)
    sin_e = np.asarray(sin_e, dtype=np.float64)
    own = np.arccos(np.clip(1.0 - footprint / (2.0 * np.pi), -1.0, 1.0))
    cos_e = np.maximum(np.sqrt(np.maximum(1.0 - sin_e * sin_e, 0.0)), HORIZON_MIN_COS)
    return np.minimum(np.sqrt(own * own + (soft_edge / cos_e) ** 2), MAX_FOOTPRINT_RADIUS)


def cap_footprint(radius):
    """The solid angle of a cap of angular ``radius``."""
    return 2.0 * np.pi * (1.0 - np.cos(np.minimum(np.asarray(radius, dtype=np.float64), np.pi)))


def split_sum_footprint(alpha, distribution: str = "ggx"):
    """The solid angle a split-sum lookup of roughness ``alpha`` averages, for its self-occlusion
    (shaders/self_occlusion.glsl split_sum_footprint)."""
    per_alpha = SPLIT_SUM_RADIUS_PER_ALPHA_GGX if distribution == "ggx" else SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN
    return cap_footprint(np.minimum(per_alpha * np.asarray(alpha, dtype=np.float64), SPLIT_SUM_MAX_RADIUS))


def _horizon_at(horizons: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """The horizon's sine at azimuth ``phi``: linear between the centres of the sectors
    ``horizons`` (..., sectors) holds (HORIZON_SECTORS at vertices, MAP_HORIZON_SECTORS in maps)."""
    sectors = horizons.shape[-1]
    x = np.mod(phi / (2.0 * np.pi) * sectors - 0.5, sectors)
    first = np.clip(np.nan_to_num(np.floor(x)).astype(int) % sectors, 0, sectors - 1)
    second = (first + 1) % sectors
    frac = x - np.floor(x)
    at_first = np.take_along_axis(horizons, first[..., None], -1)[..., 0]
    return (1.0 - frac) * at_first + frac * np.take_along_axis(horizons, second[..., None], -1)[..., 0]


def horizon_visibility(
    directions: np.ndarray,
    cones: np.ndarray,
    normals: np.ndarray,
    soft_edge: float = HORIZON_SOFT_EDGE,
    footprint=0.0,
    below_hidden=False,
    lobe_normals=None,
) -> np.ndarray:
    """How visible unit ``directions`` (..., 3) are above the horizons of ``cones`` (..., 4 +
    sectors: HORIZON_SECTORS at vertices, MAP_HORIZON_SECTORS in a horizon map) about unit
    ``normals`` (..., 3), in [0, 1]: the shaders' self_visibility
    (self_occlusion.glsl). The horizon's sine is linear in azimuth between the sectors' centres;
    the share of the lookup's cap (``footprint`` sr and the soft edge, footprint_radius) above it.
    Points without a cone pass. A direction below the surface passes for a transmission lobe and
    is hidden (0) for a reflection lobe's lookup (``below_hidden``, boolean or per direction): it
    points into the object (a rough lobe's tail, a normal map's tilt), whose own surface is what
    it sees, as a path tracer finds (DamagedHelmet against Cycles: docs/measurements.md).
    ``lobe_normals`` (..., 3): a reflection lobe's normal where a normal map tilts it; the share is
    then taken over the part of the footprint above the lobe's surface, the part below the
    surface but above the lobe's horizon counted hidden (the two hidden parts taken as nested:
    exact where only one of their edges crosses the footprint, an upper bound where both do)."""
    directions = np.asarray(directions, dtype=np.float64)
    cones = np.asarray(cones, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    tangent, bitangent = horizon_frame(normals)
    sin_e = np.sum(directions * normals, axis=-1)
    phi = np.arctan2(np.sum(directions * bitangent, axis=-1), np.sum(directions * tangent, axis=-1))
    horizons = cones[..., 4:]
    radius = footprint_radius(footprint, sin_e, soft_edge)
    from_normal = np.arccos(np.clip(sin_e, -1.0, 1.0))
    # The cap spans the azimuths phi -+ span about the normal (all of them once it holds the
    # normal); its horizon is the sectors' mean over them, weighed by the cap's width at each
    # (3-point Gauss-Chebyshev of the second kind: nodes 0, -+ span / sqrt 2, weights 1/2, 1/4).
    with np.errstate(invalid="ignore", divide="ignore"):
        span = np.where(
            radius >= from_normal,
            np.pi,
            np.arcsin(np.clip(np.sin(radius) / np.maximum(np.sin(from_normal), 1e-12), 0.0, 1.0)),
        )
    h = sum(
        weight * _horizon_at(horizons, phi + offset * span)
        for weight, offset in zip(AZIMUTH_TAP_WEIGHTS, AZIMUTH_TAP_OFFSETS, strict=True)
    )
    # the footprint's cap against the cap of directions above the horizon (about the normal, of
    # radius pi/2 - elevation), over its part above the surface (radius pi/2)
    above_horizon = np.arccos(np.clip(h, -1.0, 1.0))
    above = cap_intersection_solid_angle(above_horizon, radius, from_normal)
    above_surface = cap_intersection_solid_angle(0.5 * np.pi, radius, from_normal)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.clip(above / np.maximum(above_surface, 1e-12), 0.0, 1.0)
    if lobe_normals is not None:
        lobe_normals = np.asarray(lobe_normals, dtype=np.float64)
        # a point lookup (footprint 0: the reference's) is hidden by where it points; its cap is
        # only the horizon's soft edge, which across the surface would hide half of what clears it
        tilted = (
            np.asarray(below_hidden, dtype=bool)
            & (np.sum(lobe_normals * normals, axis=-1) < 1.0 - SELF_LOBE_TILT_MIN)
            & (np.asarray(footprint, dtype=np.float64) > 0.0)
        )
        from_lobe_normal = np.arccos(np.clip(np.sum(directions * lobe_normals, axis=-1), -1.0, 1.0))
        above_lobe = cap_intersection_solid_angle(0.5 * np.pi, radius, from_lobe_normal)
        with np.errstate(invalid="ignore", divide="ignore"):
            lobe_share = np.clip(np.minimum(above, above_lobe) / np.maximum(above_lobe, 1e-12), 0.0, 1.0)
        share = np.where(tilted, lobe_share, share)
    no_cone = cones[..., 3] <= NO_OCCLUSION + 1e-3
    below = np.asarray(below_hidden, dtype=bool) & (sin_e <= 0.0)  # a NaN normal is neither: it passes
    return np.where(no_cone, 1.0, np.where(below, 0.0, np.where(sin_e > 0.0, share, 1.0)))


APERTURE_TILTS = 46  # table of cone_cos_aperture: bent-normal tilts 0..90 degrees
APERTURE_VISIBLE = 101  # ... and visible fractions 0..1
_aperture_table_cache: list = []


def _aperture_table() -> np.ndarray:
    """(APERTURE_TILTS, APERTURE_VISIBLE): cos of the half angle of a cone around a bent normal
    tilted by each tilt that holds each cosine-weighted visible fraction of the hemisphere (the
    cone's part below the surface counts nothing), by Gauss-Legendre quadrature in cos theta and
    a uniform rule in phi."""
    if _aperture_table_cache:
        return _aperture_table_cache[0]
    x, w = np.polynomial.legendre.leggauss(128)
    cos_t, w_t = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(256) + 0.5) / 256 * 2.0 * np.pi
    sin_t = np.sqrt(1.0 - cos_t**2)
    directions = np.stack(
        [np.outer(sin_t, np.cos(phi)), np.outer(sin_t, np.sin(phi)), np.repeat(cos_t[:, None], phi.size, 1)], axis=-1
    ).reshape(-1, 3)
    weights = np.repeat(w_t * cos_t, phi.size) * (2.0 * np.pi / phi.size) / np.pi  # sums to 1
    table = np.zeros((APERTURE_TILTS, APERTURE_VISIBLE))
    fractions = np.linspace(0.0, 1.0, APERTURE_VISIBLE)
    for i, tilt in enumerate(np.linspace(0.0, np.pi / 2.0, APERTURE_TILTS)):
        cosines = directions @ np.array([np.sin(tilt), 0.0, np.cos(tilt)])
        order = np.argsort(-cosines)
        held = np.cumsum(weights[order])  # the fraction a cone reaching down to each cosine holds
        table[i] = np.interp(fractions, held, cosines[order])
    table[:, 0] = 1.0  # nothing visible: a closed cone
    _aperture_table_cache.append(table)
    return table


def cone_cos_aperture(tilt: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Cos of the half angle of the cone around a bent normal ``tilt`` radians off the normal
    that holds the cosine-weighted visible fraction ``visible`` (sqrt(1 - V) at tilt 0, wider as
    the cone leans toward the horizon, where it holds less; bilinear in the table)."""
    from scipy.interpolate import RegularGridInterpolator

    table = _aperture_table()
    interpolate = RegularGridInterpolator(
        (np.linspace(0.0, np.pi / 2.0, APERTURE_TILTS), np.linspace(0.0, 1.0, APERTURE_VISIBLE)), table
    )
    points = np.stack([np.clip(tilt, 0.0, np.pi / 2.0), np.clip(visible, 0.0, 1.0)], axis=-1)
    return interpolate(points)


def _smooth_over_neighbours(faces: np.ndarray, count: int, *values: np.ndarray, passes: int = 1):
    """Each of ``values`` (per vertex) replaced ``passes`` times by its mean over the vertex and
    the vertices it shares a triangle with."""
    from scipy.sparse import coo_matrix, identity

    rows = faces[:, [0, 0, 1, 1, 2, 2]].ravel()
    cols = faces[:, [1, 2, 0, 2, 0, 1]].ravel()
    adjacency = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(count, count)).tocsr()
    adjacency.data[:] = 1.0  # a shared edge counts once
    adjacency = adjacency + identity(count, format="csr")
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    out = []
    for value in values:
        for _ in range(passes):
            value = (adjacency @ value) / (degree if value.ndim == 1 else degree[:, None])
        out.append(value)
    return out


def cone_visibility(
    directions: np.ndarray, cones: np.ndarray, normals: np.ndarray | None = None, soft_edge: float = SOFT_EDGE
) -> np.ndarray:
    """How visible unit ``directions`` (..., 3) are through ``cones`` (..., 4), in [0, 1],
    smoothstep across the cone's edge; directions below the surface of ``normals`` pass. No
    shader reads the cone's aperture since the horizons (the shaders use only its flag,
    NO_OCCLUSION): this is the instrument of the aperture's tests."""
    directions = np.asarray(directions, dtype=np.float64)
    cones = np.asarray(cones, dtype=np.float64)
    cos_aperture = cones[..., 3]
    d = np.sum(directions * cones[..., :3], axis=-1)
    t = np.clip((d - (cos_aperture - soft_edge)) / (2.0 * soft_edge), 0.0, 1.0)
    passes = cos_aperture <= NO_OCCLUSION + 1e-3  # no cone (interpolated values near it too)
    if normals is not None:
        passes = passes | (np.sum(directions * np.asarray(normals, dtype=np.float64), axis=-1) <= 0.0)
    return np.where(passes, 1.0, t * t * (3.0 - 2.0 * t))


def self_occluded_incident(
    environment: np.ndarray,
    occluder: np.ndarray,
    directions: np.ndarray,
    cones: np.ndarray,
    normals: np.ndarray,
    footprint=0.0,
    below_hidden=False,
) -> np.ndarray:
    """Incident radiance with the object's self-occlusion (the shaders' self_occluded): the
    environment's where the direction clears the horizon, the occluder's radiance where it does
    not (RGB, (..., 3)), for lookups averaging ``footprint`` sr (``below_hidden``: a reflection
    lobe's, horizon_visibility)."""
    visibility = horizon_visibility(directions, cones, normals, footprint=footprint, below_hidden=below_hidden)
    visibility = visibility[..., None]
    return visibility * np.asarray(environment, dtype=np.float64) + (1.0 - visibility) * np.asarray(occluder)


# Cones traced in this process, by the same key as the disk cache: a scene loaded again (the
# first-use bake's swap, a reload, every test's renderer, which has no cache folder) is not
# traced again. Oldest first out beyond the bound (48 bytes a vertex: 1.4 million vertices).
MEMORY_CACHE_BYTES = 64 * 1024 * 1024
_traced_cones: OrderedDict[str, np.ndarray] = OrderedDict()


def forget_traced_cones() -> None:
    """Empty this process's cache of traced cones (the disk cache stays)."""
    _traced_cones.clear()


def _cones_key(mesh) -> str:
    constants = (
        CACHE_VERSION, SELF_VISIBILITY_RAYS, MAX_SELF_VISIBILITY_RAYS_TOTAL, MIN_RAYS_PER_VERTEX,
        SMOOTHING_PASSES, ORIGIN_OFFSET, NEAR_HIT_DISTANCE, SEED, APERTURE_TILTS, APERTURE_VISIBLE,
        HORIZON_SECTORS, tuple(HORIZON_AXIS),
    )  # fmt: skip
    digest = hashlib.sha256(repr(constants).encode())
    for array in (mesh.positions, mesh.normals, mesh.indices):
        data = np.ascontiguousarray(array)
        digest.update(f"{data.dtype.str}{data.shape}".encode())
        digest.update(data.tobytes())
    return digest.hexdigest()[:20]


def _remember(key: str, cones: np.ndarray) -> None:
    _traced_cones[key] = cones
    _traced_cones.move_to_end(key)
    while len(_traced_cones) > 1 and sum(c.nbytes for c in _traced_cones.values()) > MEMORY_CACHE_BYTES:
        _traced_cones.popitem(last=False)


def object_visibility_cones(obj, cache_folder: Path | None = None) -> np.ndarray:
    """The cones of a scene object (scenes/scene.py SceneObject), traced once and kept on it and
    in this process (by the mesh); with ``cache_folder``, kept on disk too (keyed by the mesh
    and the tracing's constants)."""
    known = getattr(obj, "self_visibility", None)  # any object with a mesh (tests pass stand-ins)
    if known is not None and len(known) == len(obj.mesh.positions):
        return known
    key = _cones_key(obj.mesh)
    count = len(obj.mesh.positions)
    cones = _traced_cones.get(key)
    if cones is not None:
        _traced_cones.move_to_end(key)
        obj.self_visibility = cones
        return cones
    path = None if cache_folder is None else Path(cache_folder) / f"cones-{key}.npy"

    def read(file: Path) -> np.ndarray:
        cones = np.load(file, allow_pickle=False)
        if cones.shape != (count, CONE_FLOATS) or cones.dtype != np.float32 or not np.all(np.isfinite(cones)):
            raise ValueError(f"cones of shape {cones.shape} ({cones.dtype}), expected ({count}, {CONE_FLOATS}) float32")
        return cones

    cones = read_cache_file(path, read, "visibility cones")
    if cones is None:
        cones = vertex_visibility_cones(obj.mesh.positions, obj.mesh.normals, obj.mesh.indices)
        if path is not None:
            write_cache_file(path, lambda handle: np.save(handle, cones, allow_pickle=False))
    cones.setflags(write=False)  # shared by every object of this mesh
    _remember(key, cones)
    obj.self_visibility = cones
    return cones
