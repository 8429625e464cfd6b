"""Reflection-space image-based rendering (Cabral, Olano and Nemec 1999; seed 004), numpy reference.

A *radiance environment map* (REM) holds, for one fixed viewing direction v_j, the light a surface
of the material sends towards v_j, as a function of the surface's orientation, for a distant
environment (seed section 2). RSIBR precomputes REMs at a set of view directions (the vertices of
an icosahedron, section 3.1), and reconstructs the map of any other view by warping the three
maps of the spherical triangle that holds it to that view and blending them with spherical
barycentric weights (sections 3.2-3.4).

lobeview's form of it (the seed's future work, section 6: the warp per pixel):

* **The mirror warp** (section 3.3) is built into the parameterisation: map j is indexed by the
  reflection direction r, and its texel r holds the radiance of the normal that reflects v_j into
  r, n_j = normalize(v_j + r) (:func:`warped_normal`). A pixel seen from v with normal n reflects
  into r = reflect(-v, n) and reads every map at that same r, so "warping" a map to the pixel's
  view is a lookup at r; at v = v_j it is exact (n_j = n).
* **Spherical barycentric weights** (section 3.4): the ratio of the spherical triangle opposite
  each vertex to the whole triangle, areas from the spherical excess (:func:`triangle_area`, the
  closed form of Van Oosterom and Strackee 1983; the seed's dihedral-angle form is the test's
  independent check).
* **Confidence near the singularity** (section 3.3): texel r = -v_j of map j is the grazing limit
  (n_j perpendicular to v_j), where the map is pinched; the weight of map j fades with
  n_j . v_j below RSIBR_FADE and the weights are renormalised (:func:`blend_weights`).
* **Anisotropic materials** (beyond the seed, which assumes a BRDF fixed relative to n and v): the
  radiance also depends on the tangent's angle about n. Map j then has RSIBR_SLICES slices: slice
  k holds the radiance with the tangent at angle k pi / K from the map's own tangent field
  t0_j(n) (:func:`map_tangent`: smooth over the map's warped normals; pi-periodic because a
  microfacet lobe is symmetric under t -> -t); a pixel carries its tangent to map j's warped
  normal n_j (:func:`transported_tangent`) and reads the two slices around its angle there.
* **Elevation correction** (beyond the seed): map j at r was integrated at n_j . v_j = |v_j + r| / 2,
  the pixel sees its surface at n . v; the mirror warp keeps the lobe's direction but not its
  strength, which Fresnel and shadowing change fastest at grazing angles (an edge-on pane read
  from maps of views 30 degrees away came out at a tenth of its grazing reflection). Each map's
  value is scaled by E(n . v) / E(n_j . v_j), E the baked lobes' directional albedo (azimuth-
  averaged for anisotropic lobes): the energy rescaling Kautz and McCool (seed 000, 3.1) apply to
  their fitted lobes, here across views. At a view (n_j = n) the factor is 1.
* Only the reflection lobes with a microfacet distribution are in the maps: a thin transmission
  lobe is centred on -v, which the mirror warp cannot follow between views (three views would
  show three displaced images), so transmission lobes and lobes without a distribution are
  looked up as in the automatic prefiltered mode.

Maps are equirectangular in r (scenes/envmap.py's convention), 2H x H texels, the layers of one
texture array: tile (j, k) = j K + k (:func:`tile_lookup`, the GL twin).
"""

from __future__ import annotations

import numpy as np

from lobeview.core.cube_layout import direction_to_equirect

#: fade of a map's weight as n_j . v_j goes to 0 (its singular, grazing texels)
RSIBR_FADE = 0.25
#: tangent-angle slices of an anisotropic material's maps over [0, pi)
RSIBR_SLICES = 8
RSIBR_MAX_ROWS = 128  # isotropic maps: 256 x 128 x 42 views, 22 MB
RSIBR_MAX_ROWS_ANISOTROPIC = 64  # 128 x 64 x 42 views x 8 slices, 44 MB
RSIBR_MIN_ROWS = 16
#: geodesic subdivisions of the view sphere: 0 is the seed's icosahedron (12 views, 20 faces),
#: 1 the once-subdivided one (42 views, 80 faces; the largest the shaders hold). Measured on the
#: preview sphere (smooth sky, relative RMSE against the reference): gold-ggx 0.095 -> 0.041,
#: brushed-steel-beckmann 0.111 -> 0.047, frosted-glass 0.069 -> 0.065 from 12 to 42 views.
RSIBR_SUBDIVISIONS = 1
RSIBR_MAX_VIEWS = 42
RSIBR_MAX_FACES = 80
#: entries of the baked lobes' directional albedo E(n.v), at n.v = (i / (size - 1))^2
RSIBR_ALBEDO_SIZE = 32
RSIBR_ALBEDO_AZIMUTHS = 8  # view azimuths in [0, pi/2] averaged for anisotropic lobes
RSIBR_MAX_ALBEDO_RATIO = 32.0
#: the fallback axis of the canonical tangent field where the normal is (anti)parallel to +Z
_TANGENT_AXIS = np.array([0.0, 0.0, 1.0])
_TANGENT_FALLBACK = np.array([1.0, 0.0, 0.0])


def _normalize(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def geodesic_sphere(subdivisions: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3), faces (F, 3)) of an icosahedron (subdivisions 0: 12 views, 20 faces) or
    its geodesic subdivision (1: 42 views, 80 faces); faces counter-clockwise seen from outside."""
    phi = (1.0 + np.sqrt(5.0)) / 2.0
    vertices = [
        (-1, phi, 0), (1, phi, 0), (-1, -phi, 0), (1, -phi, 0),
        (0, -1, phi), (0, 1, phi), (0, -1, -phi), (0, 1, -phi),
        (phi, 0, -1), (phi, 0, 1), (-phi, 0, -1), (-phi, 0, 1),
    ]  # fmt: skip
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]  # fmt: skip
    verts = [tuple(v) for v in _normalize(np.array(vertices, dtype=np.float64))]
    index = {v: i for i, v in enumerate(verts)}

    def midpoint(a: int, b: int) -> int:  # the new vertex on edge ab, shared by both its faces
        m = tuple(_normalize(np.add(verts[a], verts[b])))
        if m not in index:
            index[m] = len(verts)
            verts.append(m)
        return index[m]

    for _ in range(subdivisions):
        refined = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            refined += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = refined
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def triangle_area(a, b, c) -> np.ndarray:
    """Area (spherical excess) of the spherical triangle of unit vectors a, b, c:
    tan(E / 2) = |a . (b x c)| / (1 + a.b + b.c + c.a) (Van Oosterom and Strackee 1983)."""
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (a, b, c))
    triple = np.abs(np.sum(a * np.cross(b, c), axis=-1))
    denominator = 1.0 + np.sum(a * b, axis=-1) + np.sum(b * c, axis=-1) + np.sum(c * a, axis=-1)
    return 2.0 * np.arctan2(triple, denominator)


def containing_face(v, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Index of the face whose spherical triangle holds each direction v (..., 3): the face that
    maximises the smallest of v's three signed distances to its edge planes (ties on an edge go
    to either face; both give the same weights)."""
    v = _normalize(v)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    edge_normals = np.stack([np.cross(a, b), np.cross(b, c), np.cross(c, a)], axis=1)  # (F, 3, 3)
    edge_normals /= np.linalg.norm(edge_normals, axis=-1, keepdims=True)
    distances = np.einsum("...k,fek->...fe", v, edge_normals)  # (..., F, 3)
    return np.argmax(distances.min(axis=-1), axis=-1)


def view_weights(v, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(views (..., 3), weights (..., 3)): the vertices of the triangle holding v and their
    spherical barycentric weights, weight_i = area(v, opposite edge of i) / area of the triangle
    (seed 3.4), renormalised to sum to 1."""
    v = _normalize(v)
    views = faces[containing_face(v, vertices, faces)]
    a, b, c = (vertices[views[..., i]] for i in range(3))
    areas = np.stack([triangle_area(v, b, c), triangle_area(a, v, c), triangle_area(a, b, v)], axis=-1)
    return views, areas / areas.sum(axis=-1, keepdims=True)


def reflect(view, normal) -> np.ndarray:
    """The mirror direction r of the direction towards the viewer ``view`` about ``normal``."""
    view, normal = np.asarray(view, dtype=np.float64), np.asarray(normal, dtype=np.float64)
    return 2.0 * np.sum(view * normal, axis=-1, keepdims=True) * normal - view


def warped_normal(r, view) -> np.ndarray:
    """The mirror warp: the normal that reflects ``view`` into r (singular at r = -view)."""
    h = np.asarray(view, dtype=np.float64) + np.asarray(r, dtype=np.float64)
    length = np.linalg.norm(h, axis=-1, keepdims=True)
    return h / np.maximum(length, 1e-12)


def confidence(r, view) -> np.ndarray:
    """Weight of map ``view`` at its texel r: smoothstep(0, RSIBR_FADE, n_j . v_j), where
    n_j . v_j = |v_j + r| / 2 (no normalisation, so the singular texel r = -v_j gives 0, not NaN)."""
    x = np.clip(0.5 * np.linalg.norm(np.asarray(view) + np.asarray(r), axis=-1) / RSIBR_FADE, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def blend_weights(barycentric, confidences) -> np.ndarray:
    """Barycentric weights times each map's confidence, renormalised; where all three maps are
    at their singular texels (never, for distinct views) the barycentric weights alone."""
    product = np.asarray(barycentric) * np.asarray(confidences)
    total = product.sum(axis=-1, keepdims=True)
    return np.where(total > 1e-6, product / np.maximum(total, 1e-30), barycentric)


def canonical_tangent(normal) -> np.ndarray:
    """t0(n) = normalize(Z x n), or normalize(X x n) within 1e-3 of the poles n = +-Z: a field
    on the whole sphere, singular at its poles (any continuous one is somewhere); each map's own
    field (:func:`map_tangent`) starts from it at the map's view."""
    n = _normalize(normal)
    t = np.cross(_TANGENT_AXIS, n)
    near_pole = np.linalg.norm(t, axis=-1, keepdims=True) < 1e-3
    t = np.where(near_pole, np.cross(_TANGENT_FALLBACK, n), t)
    return _normalize(t)


def map_tangent(normal, view) -> np.ndarray:
    """Map ``view``'s tangent field t0_j(n): canonical_tangent(v_j) carried from v_j to n by the
    smallest rotation (:func:`transported_tangent`). Smooth over the hemisphere n . v_j > -1 that
    the map's warped normals cover, singular only at n = -v_j. The one global field
    (canonical_tangent) has its poles at +-Z, and around a pole its tangents turn fast from texel
    to texel: a quad facing +Z read its anisotropic maps 1.4-2.9x too bright, and the preview
    sphere showed a swirl where its normal faced the camera (issue 45's anisotropic lobe against
    Mitsuba 9.6 -> 6.7 % with per-map fields, bench/results/mitsuba-20261127-215024.md)."""
    view = _normalize(view)
    return transported_tangent(canonical_tangent(view), view, normal)


def slice_frame(normal, angle, view=None) -> np.ndarray:
    """(..., 3, 3) frame with columns (t, b, n): t = t0(n) turned by ``angle`` about n; t0 the
    field of map ``view`` (:func:`map_tangent`), or the canonical one when ``view`` is None."""
    n = _normalize(normal)
    t0 = canonical_tangent(n) if view is None else map_tangent(n, view)
    b0 = np.cross(n, t0)
    angle = np.asarray(angle, dtype=np.float64)[..., None]
    t = np.cos(angle) * t0 + np.sin(angle) * b0
    return np.stack([t, np.cross(n, t), n], axis=-1)


def transported_tangent(tangent, normal, target) -> np.ndarray:
    """``tangent`` (perpendicular to ``normal``) turned by the smallest rotation that takes
    ``normal`` to ``target``: t - (t . n') / (1 + n . n') (n + n'). A map's texel holds the slices
    of its own warped normal n_j, which differs from the pixel's n by up to half the angle between
    the pixel's view and the map's: the pixel's tangent is carried to n_j before its slice angle is
    measured there, so lookup and bake agree on which physical tangent a slice holds."""
    t = np.asarray(tangent, dtype=np.float64)
    n, m = _normalize(normal), _normalize(target)
    denominator = np.maximum(1.0 + np.sum(n * m, axis=-1, keepdims=True), 1e-6)
    return _normalize(t - np.sum(t * m, axis=-1, keepdims=True) / denominator * (n + m))


def tangent_angle(tangent, normal, view=None) -> np.ndarray:
    """Angle in [0, pi) of ``tangent`` about ``normal`` from t0(normal) (map ``view``'s field, or
    the canonical one when ``view`` is None)."""
    n = _normalize(normal)
    t0 = canonical_tangent(n) if view is None else map_tangent(n, view)
    b0 = np.cross(n, t0)
    return np.mod(np.arctan2(np.sum(tangent * b0, axis=-1), np.sum(tangent * t0, axis=-1)), np.pi)


def tile_lookup(maps: np.ndarray, tile, r) -> np.ndarray:
    """Twin of the shader's read of one layer (GL_LINEAR, repeat in x, clamp to edge in y):
    ``maps`` (tiles, H, 2H, C)."""
    height, width = maps.shape[1], maps.shape[2]
    u, v = direction_to_equirect(r)
    x = u * width - 0.5
    y = np.clip(v * height - 0.5, 0.0, height - 1.0)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0 %= width
    x1 = (x0 + 1) % width
    y1 = np.minimum(y0 + 1, height - 1)
    tile = np.broadcast_to(np.asarray(tile), x0.shape)
    return (
        maps[tile, y0, x0] * (1 - fx) * (1 - fy)
        + maps[tile, y0, x1] * fx * (1 - fy)
        + maps[tile, y1, x0] * (1 - fx) * fy
        + maps[tile, y1, x1] * fx * fy
    )


def albedo_cosines(size: int = RSIBR_ALBEDO_SIZE) -> np.ndarray:
    """n.v of the albedo table's entries: (i / (size - 1))^2, dense at grazing angles where
    Fresnel changes fastest; the first entry is evaluated at 1e-3 (the shader clamps n.v)."""
    return np.maximum((np.arange(size) / (size - 1)) ** 2, 1e-3)


def albedo_table(components: list, size: int = RSIBR_ALBEDO_SIZE, order: int = 64) -> np.ndarray:
    """(size, 3) directional albedo of the summed ``components`` at :func:`albedo_cosines`,
    averaged over RSIBR_ALBEDO_AZIMUTHS view azimuths in [0, pi/2] (the tangent angle a map
    slice does not record; microfacet lobes are symmetric about both tangent axes)."""
    from .bsdf import BSDF

    mu = albedo_cosines(size)
    phi = (np.arange(RSIBR_ALBEDO_AZIMUTHS) + 0.5) / RSIBR_ALBEDO_AZIMUTHS * 0.5 * np.pi
    sin = np.sqrt(1.0 - mu * mu)[:, None]
    wos = np.stack([sin * np.cos(phi), sin * np.sin(phi), np.broadcast_to(mu[:, None], (size, len(phi)))], axis=-1)
    reflection, _ = BSDF(list(components), "rsibr lobes").albedo_many(wos.reshape(-1, 3), order)
    return reflection.reshape(size, len(phi), 3).mean(axis=1)


def albedo_at(table: np.ndarray, cos_view) -> np.ndarray:
    """Linear interpolation of :func:`albedo_table` in sqrt(n.v) (the shader's rsibr_albedo)."""
    x = np.sqrt(np.clip(np.asarray(cos_view, dtype=np.float64), 0.0, 1.0)) * (len(table) - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), len(table) - 2)
    f = (x - i0)[..., None]
    return (1 - f) * table[i0] + f * table[i0 + 1]


def albedo_ratio(table: np.ndarray, cos_pixel, cos_map) -> np.ndarray:
    """E(n.v) / E(n_j.v_j) per channel, at most RSIBR_MAX_ALBEDO_RATIO (0 where E(n_j.v_j) is 0)."""
    pixel, source = albedo_at(table, cos_pixel), albedo_at(table, cos_map)
    ratio = np.where(source > 1e-6, pixel / np.maximum(source, 1e-6), 0.0)
    return np.minimum(ratio, RSIBR_MAX_ALBEDO_RATIO)


def rsibr_radiance(
    maps: np.ndarray, slices: int, vertices: np.ndarray, faces: np.ndarray, view, frame, albedo=None
) -> np.ndarray:
    """The shader's RSIBR lookup (shaders/rsibr.glsl rsibr_radiance) on ``maps`` (tiles, H, 2H, C),
    for world directions towards the viewer ``view`` (..., 3) and shading frames ``frame``
    (..., 3, 3; columns t, b, n); ``albedo``: the :func:`albedo_table` of the elevation correction
    (None: no correction)."""
    view = _normalize(view)
    frame = np.asarray(frame, dtype=np.float64)
    t, n = frame[..., 0], frame[..., 2]
    r = reflect(view, n)
    views, barycentric = view_weights(view, vertices, faces)
    confidences = np.stack([confidence(r, vertices[views[..., i]]) for i in range(3)], axis=-1)
    weights = blend_weights(barycentric, confidences)
    cos_pixel = np.sum(view * n, axis=-1)
    result = np.zeros(view.shape[:-1] + (maps.shape[-1],))
    for i in range(3):
        source = vertices[views[..., i]]
        base = views[..., i] * slices
        if slices > 1:
            # map i's slices are about its own warped normal, in its own tangent field
            map_normal = warped_normal(r, source)
            s = tangent_angle(transported_tangent(t, n, map_normal), map_normal, source) / np.pi * slices
            k0 = np.floor(s).astype(np.int64) % slices
            f = (s - np.floor(s))[..., None]
            k1 = (k0 + 1) % slices
            value = (1 - f) * tile_lookup(maps, base + k0, r) + f * tile_lookup(maps, base + k1, r)
        else:
            value = tile_lookup(maps, base, r)
        if albedo is not None:
            value = value * albedo_ratio(albedo, cos_pixel, 0.5 * np.linalg.norm(source + r, axis=-1))
        result += weights[..., i : i + 1] * value
    return result


def median_reflection_angle(distribution) -> float:
    """Median angle between the reflected direction and the mirror direction of a microfacet
    lobe at normal incidence along its narrower axis: twice the half-vector median, tan = alpha
    (GGX: P(tan^2 < x) = x / (alpha^2 + x)) or alpha sqrt(ln 2) (Beckmann: 1 - exp(-x / alpha^2))."""
    alpha = min(distribution.alpha_x, distribution.alpha_y)
    scale = 1.0 if distribution.kind == "ggx" else np.sqrt(np.log(2.0))
    return float(2.0 * np.arctan(alpha * scale))


def map_rows(distributions: list, anisotropic: bool) -> int:
    """Rows of every tile: two texels across the narrowest lobe's median angle, a multiple of 8
    between RSIBR_MIN_ROWS and the cap (anisotropic materials have K slices per view)."""
    most = RSIBR_MAX_ROWS_ANISOTROPIC if anisotropic else RSIBR_MAX_ROWS
    angle = min((median_reflection_angle(d) for d in distributions), default=np.pi / 8)
    rows = int(np.ceil(2.0 * np.pi / max(angle, 1e-6)))
    return int(np.clip(-(-rows // 8) * 8, RSIBR_MIN_ROWS, most))
