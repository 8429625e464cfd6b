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

A lookup direction d of the specular lobes (shaders/incident.glsl self_occluded) is visible by
``smoothstep(cos a - SOFT_EDGE, cos a + SOFT_EDGE, dot(d, bent))``; the occluded part sees the
object itself, whose radiance is taken as the shading point's own (its diffuse and its
specular reflectance lit by its irradiance: "the occluder looks like me").
"""

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
MAX_SELF_VISIBILITY_RAYS_TOTAL = 4_000_000  # per object: fewer rays per vertex beyond (at least 8)
MIN_RAYS_PER_VERTEX = 8
NO_OCCLUSION = -2.0  # cos a of a vertex no ray of which hits its object: every direction visible
SOFT_EDGE = 0.1  # half width, in cosine, of the cone's soft edge (a 64-ray cone is not sharper)
ORIGIN_OFFSET = 1e-4  # ray origins off the surface, times the object's extent
NEAR_HIT_DISTANCE = 0.03  # hits nearer than this, times the object's extent, are ignored (see below)
SEED = 11
CACHE_VERSION = "cones-1"  # with the constants above and the mesh, the key of a cached file


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
    """(V, 4) float32: per vertex the bent normal (unit, the positions' space) and the cosine of
    the visibility cone's half angle, NO_OCCLUSION where the object hides nothing from it.
    ``indices``: the triangles (3 per face)."""
    import trimesh

    positions = np.asarray(positions, dtype=np.float64)
    count = len(positions)
    cones = np.zeros((count, 4), dtype=np.float32)
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
    # Rays start NEAR_HIT_DISTANCE along themselves: a grazing ray from a vertex whose normal is
    # averaged over a curved, faceted surface meets the neighbouring triangles at once, which
    # hide nothing a finer mesh would (the occlusion texture holds detail at that scale).
    start = positions[:, None, :] + normals[:, None, :] * (ORIGIN_OFFSET * max(extent, 1e-12))
    start = start + directions * (NEAR_HIT_DISTANCE * max(extent, 1e-12))
    hit = mesh.ray.intersects_any(start.reshape(-1, 3), directions.reshape(-1, 3)).reshape(count, n)
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
    return cones


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
    """How visible unit ``directions`` (..., 3) are through ``cones`` (..., 4), in [0, 1]: the
    shaders' self_visibility (incident.glsl), smoothstep across the cone's edge. Directions
    below the surface of ``normals`` (transmission) pass."""
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
    environment: np.ndarray, occluder: np.ndarray, directions: np.ndarray, cones: np.ndarray
) -> np.ndarray:
    """Incident radiance with the object's self-occlusion: the environment's where the cone
    lets the direction through, the occluder's radiance where it does not (RGB, (..., 3))."""
    visibility = cone_visibility(directions, cones)[..., None]
    return visibility * np.asarray(environment, dtype=np.float64) + (1.0 - visibility) * np.asarray(occluder)


# Cones traced in this process, by the same key as the disk cache: a scene loaded again (the
# first-use bake's swap, a reload, every test's renderer, which has no cache folder) is not
# traced again. Oldest first out beyond the bound (16 bytes a vertex: 4 million vertices).
MEMORY_CACHE_BYTES = 64 * 1024 * 1024
_traced_cones: OrderedDict[str, np.ndarray] = OrderedDict()


def forget_traced_cones() -> None:
    """Empty this process's cache of traced cones (the disk cache stays)."""
    _traced_cones.clear()


def _cones_key(mesh) -> str:
    constants = (
        CACHE_VERSION, SELF_VISIBILITY_RAYS, MAX_SELF_VISIBILITY_RAYS_TOTAL, MIN_RAYS_PER_VERTEX,
        SMOOTHING_PASSES, ORIGIN_OFFSET, NEAR_HIT_DISTANCE, SEED, APERTURE_TILTS, APERTURE_VISIBLE,
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
        if cones.shape != (count, 4) or cones.dtype != np.float32 or not np.all(np.isfinite(cones)):
            raise ValueError(f"cones of shape {cones.shape} ({cones.dtype}), expected ({count}, 4) float32")
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
