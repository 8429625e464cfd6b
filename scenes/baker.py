"""Lightmap baking: irradiance per lightmap texel by Monte Carlo ray tracing on the CPU.

For every texel covered by a triangle in TEXCOORD_1 space, ``rays`` cosine-distributed
directions are traced from the texel's surface point (embree through trimesh/embreex). A ray
that leaves the scene returns the environment radiance, weighted by the balance heuristic
against ``env_samples`` importance samples of the environment (env_sampling.EquirectImportance:
its bright texels, a sun) traced as shadow rays, so a sun-bearing HDR does not leave a few
texels with most of the energy; a ray that hits a surface returns its
diffuse reflection kd E / pi of the previous bounce's irradiance (Eq. 4.1). Irradiance is
E = pi * mean(L_in) (cosine-weighted estimator of integral L cos d omega), iterated for
``bounces`` passes. Emissive surfaces are sampled directly (next-event estimation):
``light_samples`` points uniform over the emitters' area, each with a shadow ray, give
E_direct = A / S * sum L_e cos(theta_r) cos(theta_e) / d^2, so small lamps do not turn into
noise; cosine rays that hit an emitter count only its reflected light. Alpha-masked materials
(MASK, and BLEND at 0.5 coverage) let rays through their cut-outs (AlphaTestedIntersector). KHR_lights_punctual lamps
add their irradiance (:func:`lamp_irradiance`, the extension's falloff and spot cone) with one
exact shadow ray per texel and lamp, before the bounces, so their light is reflected too. Thin
transmissive objects (glass panes) are left out of the ray casting: they cast no shadow, a
documented simplification.

Directions come from a 2D Sobol sequence with a per-texel Cranley-Patterson rotation, so a bake
is deterministic. Islands are dilated by a few texels so bilinear lookups never read the black
background of the atlas.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

from lobeview.core.progress import report

from .env_sampling import EquirectImportance
from .envmap import EnvironmentMap
from .scene import Scene

try:  # trimesh picks embree (embreex) when it is installed
    import trimesh
except ImportError:  # pragma: no cover - trimesh is a hard dependency
    trimesh = None


@dataclass
class TexelSamples:
    """Surface points of the covered lightmap texels."""

    pixel: np.ndarray  # (M, 2) int (row, col)
    position: np.ndarray  # (M, 3)
    normal: np.ndarray  # (M, 3) interpolated shading normal
    geometric_normal: np.ndarray  # (M, 3)


def rasterize_uv(
    uv: np.ndarray, positions: np.ndarray, normals: np.ndarray, indices: np.ndarray, resolution: int
) -> TexelSamples:
    """Texel centres covered by triangles in ``uv`` space ([0,1]^2, v down = row) with their
    interpolated positions and normals. A texel belongs to the first triangle that covers its
    centre."""
    res = resolution
    rows, cols, pos, nrm, gnrm = [], [], [], [], []
    owner = np.full((res, res), False)
    p = uv * res - 0.5  # texel (i, j) centre at p = (j, i)
    for tri in indices:
        a, b, c = p[tri[0]], p[tri[1]], p[tri[2]]
        lo = np.floor(np.minimum(np.minimum(a, b), c)).astype(int)
        hi = np.ceil(np.maximum(np.maximum(a, b), c)).astype(int)
        lo = np.clip(lo, 0, res - 1)
        hi = np.clip(hi, 0, res - 1)
        if np.any(hi < lo):
            continue
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
        q = np.stack([xs.ravel(), ys.ravel()], -1).astype(np.float64)
        v0, v1 = b - a, c - a
        den = v0[0] * v1[1] - v1[0] * v0[1]
        if abs(den) < 1e-14:
            continue
        d = q - a
        w1 = (d[:, 0] * v1[1] - v1[0] * d[:, 1]) / den
        w2 = (v0[0] * d[:, 1] - d[:, 0] * v0[1]) / den
        w0 = 1.0 - w1 - w2
        eps = -1e-6
        inside = (w0 >= eps) & (w1 >= eps) & (w2 >= eps)
        if not np.any(inside):
            continue
        qi = q[inside].astype(int)
        free = ~owner[qi[:, 1], qi[:, 0]]
        if not np.any(free):
            continue
        qi = qi[free]
        bary = np.stack([w0[inside][free], w1[inside][free], w2[inside][free]], -1)
        owner[qi[:, 1], qi[:, 0]] = True
        rows.append(qi[:, 1])
        cols.append(qi[:, 0])
        pos.append(bary @ positions[tri])
        n = bary @ normals[tri]
        nrm.append(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))
        g = np.cross(positions[tri[1]] - positions[tri[0]], positions[tri[2]] - positions[tri[0]])
        gnrm.append(np.broadcast_to(g / max(np.linalg.norm(g), 1e-20), (len(qi), 3)))
    if not rows:
        empty = np.zeros((0, 3))
        return TexelSamples(np.zeros((0, 2), int), empty, empty, empty)
    return TexelSamples(
        np.stack([np.concatenate(rows), np.concatenate(cols)], -1),
        np.concatenate(pos),
        np.concatenate(nrm),
        np.concatenate(gnrm),
    )


def uv_triangle_areas(uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(T,) the areas of the triangles ``faces`` (T, 3) in the 2D coordinates ``uv`` (V, 2)."""
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def lightmap_uv_overlap(scene: Scene, resolution: int) -> float:
    """Fraction of the lightmap coordinates' texels claimed twice: by two objects (per-object
    lightmap UVs, each spanning [0, 1], or instances of one mesh), or by two triangles of one
    object (mirrored or stacked charts; measured as UV area beyond the texels covered). One
    shared atlas needs 0; a few per cent come from texel-centre sampling along chart edges."""
    return uv_overlap([(obj.uv1, obj.mesh) for obj in scene.objects if obj.uv1 is not None], resolution)


def uv_overlap(charts: list, resolution: int) -> float:
    """lightmap_uv_overlap of the (uv, mesh) pairs ``charts`` in one [0, 1]^2 atlas."""
    claimed, area_total = [], 0.0
    for uv, mesh in charts:
        tri = mesh.indices.reshape(-1, 3)
        area = uv_triangle_areas(uv.astype(np.float64) * resolution, tri)
        samples = rasterize_uv(uv.astype(np.float64), mesh.positions, mesh.normals, tri, resolution)
        claimed.append(samples.pixel[:, 0] * resolution + samples.pixel[:, 1])
        area_total += max(float(area.sum()), float(len(samples.pixel)))
    if not claimed or area_total == 0:
        return 0.0
    unique = len(np.unique(np.concatenate(claimed)))
    return max(0.0, 1.0 - unique / area_total)


def _frame(n: np.ndarray):
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def dilate(image: np.ndarray, covered: np.ndarray, steps: int = 4) -> np.ndarray:
    """Grow covered texels into their uncovered neighbours (mean of covered neighbours)."""
    img = image.copy()
    cov = covered.copy()
    for _ in range(steps):
        acc = np.zeros_like(img)
        cnt = np.zeros(cov.shape)
        for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)):
            shifted = np.roll(np.roll(img * cov[..., None], dy, 0), dx, 1)
            c = np.roll(np.roll(cov, dy, 0), dx, 1)
            acc += shifted
            cnt += c
        grow = ~cov & (cnt > 0)
        img[grow] = acc[grow] / cnt[grow][:, None]
        cov = cov | grow
    return img


def bake_lightmap(
    scene: Scene,
    environment: EnvironmentMap | None,
    resolution: int = 512,
    rays: int = 64,
    bounces: int = 3,
    progress: bool = True,
    seed: int = 7,
    light_samples: int = 32,
    env_samples: int = 32,
) -> np.ndarray:
    """Bake one shared atlas for all objects with TEXCOORD_1; returns (res, res, 3) irradiance."""
    from lobeview.materials.bsdf import diffuse_albedo
    from lobeview.materials.spec import build_bsdf

    t_start = time.perf_counter()
    objects = [o for o in scene.objects if o.uv1 is not None]
    if not objects:
        raise ValueError("no object has TEXCOORD_1 lightmap coordinates; unwrap the scene first")

    blockers, mesh, faces = ray_casting_geometry(scene)
    uv1_all = np.concatenate(
        [o.uv1 if o.uv1 is not None else np.full((len(o.mesh.positions), 2), -1.0) for o in blockers]
    )
    kd_face, emission_face = [], []
    for o in blockers:
        mat = scene.materials[o.material]
        kd, emission = _face_albedo_and_emission(o, mat, diffuse_albedo(build_bsdf(mat.desc)))
        kd_face.append(kd)
        emission_face.append(emission)
    kd_face = np.concatenate(kd_face)
    emission_face = np.concatenate(emission_face)
    intersector = AlphaTestedIntersector(mesh, faces, scene, blockers)

    texels = []
    for o in objects:
        s = rasterize_uv(
            o.uv1.astype(np.float64),
            o.mesh.positions.astype(np.float64),
            o.mesh.normals.astype(np.float64),
            o.mesh.indices,
            resolution,
        )
        texels.append(s)
    pixel = np.concatenate([s.pixel for s in texels])
    position = np.concatenate([s.position for s in texels])
    normal = np.concatenate([s.normal for s in texels])
    gnormal = np.concatenate([s.geometric_normal for s in texels])
    # Shading normals that point away from the geometric side are flipped to it.
    normal = np.where(np.sum(normal * gnormal, axis=1, keepdims=True) < 0, -normal, normal)
    covered = np.zeros((resolution, resolution), dtype=bool)
    covered[pixel[:, 0], pixel[:, 1]] = True
    if progress:
        print(
            f"[bake] {len(pixel)} texels of a {resolution}x{resolution} atlas, {rays} rays x {bounces} bounces",
            file=sys.stderr,
            flush=True,
        )

    extent = float(np.max(mesh.vertices.max(0) - mesh.vertices.min(0)))
    origin = position + gnormal * (1e-4 * extent)
    tangent, bitangent = _frame(normal)
    sobol = qmc.Sobol(d=2, scramble=True, seed=seed).random(rays)
    rng = np.random.default_rng(seed)
    rotation = rng.random((len(pixel), 2))

    direct = _direct_emission(mesh, intersector, faces, emission_face, origin, normal, light_samples, seed)
    importance = None
    if environment is not None and env_samples > 0:
        # Environment light by importance (its bright texels, a sun), combined with the cosine
        # rays' escapes by the balance heuristic: escapes below weigh n_cos p_cos / (n_cos p_cos
        # + n_env p_env), these samples the complement.
        t_env = time.perf_counter()
        report(f"lightmap bake: environment light, {env_samples} importance samples per texel")
        importance = EquirectImportance.from_environment(environment)
        direct = direct + _environment_light(
            environment, importance, intersector, origin, normal, rays, env_samples, seed
        )
        if progress:
            print(
                f"[bake] environment: {env_samples} importance samples per texel (MIS with the cosine rays): "
                f"{time.perf_counter() - t_env:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    if scene.lights:
        t_lamps = time.perf_counter()
        direct = direct + _lamp_light(scene.lights, mesh, intersector, origin, normal, extent)
        if progress:
            print(
                f"[bake] {len(scene.lights)} lamp(s) (KHR_lights_punctual): {time.perf_counter() - t_lamps:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    lightmap = np.zeros((resolution, resolution, 3))
    hit_tri = None
    hit_uv = None
    # What the rays that escape bring is the same in every bounce: summed once in bounce 0.
    escape_total = np.zeros((len(pixel), 3))
    for bounce in range(bounces):
        t0 = time.perf_counter()
        total = np.zeros((len(pixel), 3)) if bounce == 0 else escape_total.copy()
        for r in range(rays):
            report(f"lightmap bake: bounce {bounce + 1} of {bounces}, ray {r + 1} of {rays}",
                   (bounce * rays + r) / (bounces * rays))  # fmt: skip
            u = (sobol[r][None, :] + rotation) % 1.0
            # cosine-weighted hemisphere (Malley)
            radius = np.sqrt(u[:, 0])
            phi = 2 * np.pi * u[:, 1]
            local = np.stack(
                [radius * np.cos(phi), radius * np.sin(phi), np.sqrt(np.clip(1 - u[:, 0], 0, 1))],
                -1,
            )
            direction = local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:3] * normal
            if bounce == 0:
                tri = intersector.intersects_first(origin, direction)
                escape = tri < 0
                radiance = np.zeros((len(pixel), 3))
                if environment is not None and np.any(escape):
                    radiance[escape] = environment.lookup_nearest(direction[escape])
                    if importance is not None:
                        weight = balance_heuristic(rays, local[escape, 2] / np.pi, env_samples,
                                                   importance.pdf(direction[escape]))  # fmt: skip
                        radiance[escape] *= weight[:, None]
                hit = ~escape
                # Remember the hit point in uv1 for later bounces.
                uv_hit = np.full((len(pixel), 2), -1.0)
                if np.any(hit):
                    locs = _hit_points(mesh, origin[hit], direction[hit], tri[hit])
                    uv_hit[hit] = _at_hits(mesh, faces, uv1_all, tri[hit], locs)
                if r == 0:
                    # 12 bytes per ray and texel kept for the later bounces (the face hit and
                    # where in the atlas, int32/float32): a 200k-texel atlas at 128 rays holds
                    # 0.3 GB; the escapes' radiance is kept summed per texel (escape_total).
                    hit_tri = np.empty((rays, len(pixel)), dtype=np.int32)
                    hit_uv = np.empty((rays, len(pixel), 2), dtype=np.float32)
                hit_tri[r] = tri
                hit_uv[r] = uv_hit
                escape_total += radiance
                total += radiance
            else:
                tri = hit_tri[r]
                hit = (tri >= 0) & (hit_uv[r, :, 0] >= 0)
                if np.any(hit):
                    e = _bilinear(lightmap, hit_uv[r][hit].astype(np.float64))
                    total[hit] += kd_face[tri[hit]] / np.pi * e
        new_map = np.zeros_like(lightmap)
        new_map[pixel[:, 0], pixel[:, 1]] = np.pi * total / rays + direct
        lightmap = dilate(new_map, covered)
        if progress:
            print(
                f"[bake] bounce {bounce + 1}/{bounces}: {time.perf_counter() - t0:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    if progress:
        print(f"[bake] done in {time.perf_counter() - t_start:.1f} s", file=sys.stderr, flush=True)
    return lightmap.astype(np.float32)


# Barycentric points at which a face's textures are averaged (a 4 x 4 stratified set folded
# into the triangle), for the bake's per-face diffuse albedo and emission.
_FACE_POINTS = np.array([((i + 0.5) / 4, (j + 0.5) / 4) for i in range(4) for j in range(4)])
_FACE_BARY = np.stack(
    [
        1 - np.sqrt(_FACE_POINTS[:, 0]),
        np.sqrt(_FACE_POINTS[:, 0]) * (1 - _FACE_POINTS[:, 1]),
        np.sqrt(_FACE_POINTS[:, 0]) * _FACE_POINTS[:, 1],
    ],
    axis=1,
)


def _face_albedo_and_emission(obj, material, kd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) diffuse albedo and emitted radiance per face of ``obj``: the material's kd and
    emission, with its textures (base colour, metallic, transmission, emissive) averaged over each face at 16
    stratified points (shaders/scene.frag's per-pixel inputs, scenes/texturing.py), so a bounce
    off a textured floor carries the colour of the part it hit, not the texture's mean."""
    faces = obj.mesh.indices.reshape(-1, 3)
    count = len(faces)
    if not any(material.texture(slot) for slot in ("base_color", "metallic_roughness", "emissive", "transmission")):
        return np.broadcast_to(kd, (count, 3)), np.broadcast_to(material.emission, (count, 3))
    from .texturing import texel_material

    def at_points(values):  # (V, 2) vertex values -> (F * 16, 2) at the face points
        v = np.asarray(values, dtype=np.float64)[faces]  # (F, 3, 2)
        return np.einsum("pk,fkc->fpc", _FACE_BARY, v).reshape(-1, 2)

    uv1 = None if obj.uv1 is None else at_points(obj.uv1)
    inputs = texel_material(material, at_points(obj.mesh.uvs), uv1)
    points = len(_FACE_BARY)
    if inputs["gltf_model"]:
        # kd = (1 - metallic)(1 - transmission) baseColor (materials/gltf.py GltfDiffuse), per point.
        transmission = inputs["extensions"].get("transmission", 0.0)
        point_kd = ((1.0 - inputs["metallic"]) * (1.0 - transmission))[:, None] * inputs["base_color"]
    else:
        point_kd = np.asarray(kd) * inputs["base_texel"]
    kd_face = point_kd.reshape(count, points, 3).mean(axis=1)
    emission_face = inputs["emission"].reshape(count, points, 3).mean(axis=1)
    return kd_face, emission_face


def ray_casting_geometry(scene: Scene) -> tuple[list, trimesh.Trimesh, np.ndarray]:
    """(blockers, mesh, faces): what shadows and bounce rays hit, every object that is not a thin
    transmissive pane, as one triangle mesh (faces index its vertices, objects in order)."""

    def transmissive(obj):
        desc = scene.materials[obj.material].desc
        return bool(desc.get("transmission_lobes")) or desc.get("transmission", 0.0) > 0

    blockers = [o for o in scene.objects if not transmissive(o)]
    offsets = np.cumsum([0] + [len(o.mesh.positions) for o in blockers])
    vertices = np.concatenate([o.mesh.positions for o in blockers]).astype(np.float64) if blockers else np.zeros((0, 3))
    faces = (
        np.concatenate(
            [o.mesh.indices.astype(np.int64) + off for o, off in zip(blockers, offsets[:-1], strict=True)]
        ).reshape(-1, 3)
        if blockers
        else np.zeros((0, 3), np.int64)
    )
    return blockers, trimesh.Trimesh(vertices, faces, process=False), faces


def scene_intersector(scene: Scene) -> AlphaTestedIntersector:
    """The bake's ray caster over ``scene`` (ray_casting_geometry), seeing through alpha cut-outs."""
    blockers, mesh, faces = ray_casting_geometry(scene)
    return AlphaTestedIntersector(mesh, faces, scene, blockers)


class AlphaTestedIntersector:
    """Embree's first hit, seeing through the cut-outs of alpha-masked materials: a ray that
    hits a MASK (or BLEND) triangle where the base colour's alpha (factor x texture at the hit's
    TEXCOORD_0) is below the cutoff (BLEND: 0.5) goes on from just past the hit, up to
    ``MAX_LAYERS`` times. Opaque scenes cost one cast, as before."""

    MAX_LAYERS = 16

    def __init__(self, mesh, faces: np.ndarray, scene: Scene, blockers: list):
        self.mesh = mesh
        self.faces = faces
        self.ray = mesh.ray
        counts = [len(o.mesh.indices) for o in blockers]
        self.face_object = np.repeat(np.arange(len(blockers)), counts)
        self.blockers = blockers
        self.materials = [scene.materials[o.material] for o in blockers]
        # TEXCOORD_0 and _1 of the ray-casting mesh's vertices (objects without a TEXCOORD_1
        # sample their masks through TEXCOORD_0, as texturing.transformed_uv does).
        self.uv0 = np.concatenate([o.mesh.uvs for o in blockers]) if blockers else np.zeros((0, 2))
        self.uv1 = np.concatenate([o.mesh.uvs if o.uv1 is None else o.uv1 for o in blockers]) if blockers else None
        masked = [m.alpha_mode in ("MASK", "BLEND") for m in self.materials]
        self.masked_face = np.repeat(np.asarray(masked, dtype=bool), counts) if counts else np.zeros(0, bool)
        self.extent = float(np.max(mesh.vertices.max(0) - mesh.vertices.min(0))) if len(mesh.vertices) else 1.0

    def _alpha(self, tri: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Coverage at hit points on masked triangles (as shaders/scene.frag computes it)."""
        from .texturing import sample_slot

        out = np.ones(len(tri))
        objects = self.face_object[tri]
        for index in np.unique(objects):
            sel = objects == index
            material = self.materials[index]
            slot = material.texture("base_color")
            alpha = np.full(int(sel.sum()), float(material.base_alpha))
            if slot is not None:
                uv0 = _at_hits(self.mesh, self.faces, self.uv0, tri[sel], points[sel])
                uv1 = _at_hits(self.mesh, self.faces, self.uv1, tri[sel], points[sel])
                alpha = alpha * sample_slot(slot, uv0, uv1)[:, 3]
            cutoff = material.alpha_cutoff if material.alpha_mode == "MASK" else 0.5
            out[sel] = np.where(alpha < cutoff, 0.0, 1.0)
        return out

    def hit_points(self, origins: np.ndarray, directions: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """Exact hit points of rays known to hit triangles ``tris`` (intersects_first's answer)."""
        return _hit_points(self.mesh, origins, directions, tris)

    def intersects_first(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        origins = np.asarray(origins, dtype=np.float64)
        directions = np.ascontiguousarray(directions, dtype=np.float64)
        tri = self.ray.intersects_first(origins, directions)
        if not np.any(self.masked_face):
            return tri
        pending = np.flatnonzero(tri >= 0)
        pending = pending[self.masked_face[tri[pending]]]
        start = origins.copy()
        for _ in range(self.MAX_LAYERS):
            if len(pending) == 0:
                break
            points = _hit_points(self.mesh, start[pending], directions[pending], tri[pending])
            see_through = self._alpha(tri[pending], points) == 0.0
            pending = pending[see_through]
            if len(pending) == 0:
                break
            # Go on from just past the cut-out (relative to the scene, as the texel lift is).
            start[pending] = points[see_through] + directions[pending] * (1e-5 * self.extent)
            tri[pending] = self.ray.intersects_first(start[pending], directions[pending])
            pending = pending[tri[pending] >= 0]
            pending = pending[self.masked_face[tri[pending]]]
        return tri


def balance_heuristic(count: int, pdf: np.ndarray, other_count: int, other_pdf: np.ndarray) -> np.ndarray:
    """Veach's balance heuristic: the weight n p / (n p + m q) of a sample of one strategy
    (``count`` samples of density ``pdf``) against another (``other_count`` of ``other_pdf``)."""
    return count * pdf / (count * pdf + other_count * other_pdf)


def _environment_light(environment, importance, intersector, origin, normal, rays: int, samples: int, seed: int):
    """The environment's irradiance by importance samples with shadow rays, each weighted by
    the balance heuristic against the ``rays`` cosine rays: sum w_env L cos / p_env / samples,
    w_env = samples p_env / (rays p_cos + samples p_env), p_cos = cos / pi."""
    out = np.zeros((len(origin), 3))
    points = qmc.Sobol(d=2, scramble=True, seed=seed + 3).random(samples)
    rotation = np.random.default_rng(seed + 4).random((len(origin), 2))
    for s in range(samples):
        u = (points[s][None, :] + rotation) % 1.0
        direction = importance.sample(u[:, 0], u[:, 1])
        cos = np.sum(normal * direction, axis=1)
        idx = np.flatnonzero(cos > 0)
        if len(idx) == 0:
            continue
        first = intersector.intersects_first(origin[idx], np.ascontiguousarray(direction[idx]))
        free = idx[first < 0]
        p_env = importance.pdf(direction[free])
        weight = balance_heuristic(samples, p_env, rays, cos[free] / np.pi)
        out[free] += environment.lookup_nearest(direction[free]) * (weight * cos[free] / p_env)[:, None]
    return out / samples


EMITTER_UNIFORM_SHARE = 0.2  # defensive share of area sampling in the emitter choice (see below)
EMITTER_CHUNK = 32768  # texels per block of the per-texel emitter weights


def emitter_choice_weights(origin, normal, tri, tri_normal, area, radiance) -> np.ndarray:
    """(texels, emitters) probabilities of choosing each emissive triangle for each texel: the
    triangle's unoccluded irradiance at the texel estimated from its centroid (L area cos_r
    cos_e / d^2, d^2 kept above the triangle's area so a nearby emitter does not take every
    sample), mixed with EMITTER_UNIFORM_SHARE of plain area sampling so that every triangle that
    can contribute keeps a non-zero probability (the estimator stays unbiased where the centroid
    guess is wrong, e.g. a light whose centre is behind the receiver's horizon but whose edge is
    not). A texel in one room of a walkthrough then spends its samples on its own lamp instead of
    the lamps of every other room in proportion to their area."""
    centroid = tri.mean(axis=1)
    d = centroid[None, :, :] - origin[:, None, :]
    dist2 = np.maximum(np.sum(d * d, axis=2), area[None, :])
    cos_r = np.clip(np.einsum("tk,tek->te", normal, d), 0.0, None) / np.sqrt(dist2)
    cos_e = np.clip(-np.einsum("ek,tek->te", tri_normal, d), 0.0, None) / np.sqrt(dist2)
    guess = radiance[None, :] * area[None, :] * cos_r * cos_e / dist2
    total = guess.sum(axis=1, keepdims=True)
    uniform = area / area.sum()
    share = np.where(total > 0, 1.0 - EMITTER_UNIFORM_SHARE, 0.0)
    return share * guess / np.where(total > 0, total, 1.0) + (1.0 - share) * uniform[None, :]


def _direct_emission(mesh, intersector, faces, emission_face, origin, normal, samples, seed):
    """Irradiance from emissive triangles by area sampling with shadow rays, per texel: each
    sample picks a triangle with the texel's own probabilities (emitter_choice_weights), then a
    uniform point on it; E = mean of L_e cos_r cos_e / d^2 / (p_k / A_k)."""
    emitters = np.flatnonzero(np.max(emission_face, axis=1) > 0)
    out = np.zeros((len(origin), 3))
    if len(emitters) == 0 or samples <= 0:
        return out
    tri = mesh.triangles[emitters]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    tri_normal = cross / np.maximum(2.0 * area[:, None], 1e-30)
    radiance = emission_face[emitters] @ np.array([0.2126, 0.7152, 0.0722])
    points = qmc.Sobol(d=3, scramble=True, seed=seed + 1).random(samples)
    rotation = np.random.default_rng(seed + 2).random((len(origin), 3))
    for lo in range(0, len(origin), EMITTER_CHUNK):
        block = slice(lo, min(lo + EMITTER_CHUNK, len(origin)))
        o, n = origin[block], normal[block]
        probability = emitter_choice_weights(o, n, tri, tri_normal, area, radiance)
        cdf = np.cumsum(probability, axis=1)
        cdf[:, -1] = 1.0
        for s in range(samples):
            u = (points[s][None, :] + rotation[block]) % 1.0
            k = np.minimum((cdf < u[:, :1]).sum(axis=1), len(area) - 1)
            su = np.sqrt(u[:, 1])
            b0, b1 = 1.0 - su, u[:, 2] * su  # uniform point on the triangle
            p = tri[k, 0] * b0[:, None] + tri[k, 1] * b1[:, None] + tri[k, 2] * (1.0 - b0 - b1)[:, None]
            d = p - o
            dist2 = np.sum(d * d, axis=1)
            direction = d / np.sqrt(np.maximum(dist2, 1e-30))[:, None]
            cos_r = np.sum(n * direction, axis=1)
            cos_e = -np.sum(tri_normal[k] * direction, axis=1)
            candidate = (cos_r > 0) & (cos_e > 0)
            if not np.any(candidate):
                continue
            idx = np.flatnonzero(candidate)
            first = intersector.intersects_first(o[idx], direction[idx])
            idx = idx[np.isin(first, emitters)]
            g = cos_r[idx] * cos_e[idx] / np.maximum(dist2[idx], 1e-12)
            weight = area[k[idx]] / probability[idx, k[idx]]  # 1 / (p_k / A_k)
            out[lo + idx] += emission_face[emitters[k[idx]]] * (g * weight)[:, None]
    return out / samples


def spot_ramp(light) -> tuple[float, float]:
    """(cos_outer, 1 / (cos_inner - cos_outer)) of a spot lamp's cone: its factor is the squared
    linear ramp clamp((cos - cos_outer) x scale, 0, 1)^2 (the difference floored at 1e-3: equal
    cones). The one definition the bake, the live lamps (scenes/lamps.py) and their shader
    uniforms (viewer/scene_shading.py lamp_uniforms) share."""
    cos_outer, cos_inner = float(np.cos(light.outer_cone)), float(np.cos(light.inner_cone))
    return cos_outer, 1.0 / max(1e-3, cos_inner - cos_outer)


def range_window(light, distance: np.ndarray) -> np.ndarray:
    """KHR_lights_punctual's recommended range falloff clamp(1 - (d / range)^4, 0, 1) (1 without a
    range)."""
    distance = np.asarray(distance, dtype=np.float64)
    if light.range is None:
        return np.ones_like(distance)
    return np.clip(1.0 - (distance / light.range) ** 4, 0.0, 1.0)


def spot_factor(light, cos_axis: np.ndarray) -> np.ndarray:
    """A spot lamp's cone (:func:`spot_ramp`); 1 for point and directional lamps. ``cos_axis``:
    cosine between the lamp's direction and the direction from the lamp to the shading point."""
    cos_axis = np.asarray(cos_axis, dtype=np.float64)
    if light.type != "spot":
        return np.ones_like(cos_axis)
    cos_outer, scale = spot_ramp(light)
    return np.clip((cos_axis - cos_outer) * scale, 0.0, 1.0) ** 2


def lamp_irradiance(light, position: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Unshadowed irradiance (M, 3) from one KHR_lights_punctual lamp at surface points with
    unit normals, as the extension defines it: E = I cos(theta) / d^2 for point and spot lamps,
    windowed by the recommended range falloff clamp(1 - (d / range)^4, 0, 1) and, for spot lamps,
    the squared linear ramp between the cones' cosines; E = I cos(theta) for directional ones."""
    colour = np.asarray(light.colour, np.float64) * float(light.intensity)
    if light.type == "directional":
        cos_theta = np.clip(-(normal @ np.asarray(light.direction, np.float64)), 0.0, None)
        return cos_theta[:, None] * colour[None, :]
    to_lamp = np.asarray(light.position, np.float64)[None, :] - position
    dist2 = np.maximum(np.sum(to_lamp * to_lamp, axis=1), 1e-30)
    dist = np.sqrt(dist2)
    cos_theta = np.clip(np.sum(normal * to_lamp, axis=1) / dist, 0.0, None)
    cos_axis = -np.sum(to_lamp * np.asarray(light.direction, np.float64)[None, :], axis=1) / dist
    falloff = 1.0 / dist2 * range_window(light, dist) * spot_factor(light, cos_axis)  # the order of before: same bits
    return (cos_theta * falloff)[:, None] * colour[None, :]


def _lamp_light(lights, mesh, intersector, origin, normal, extent: float) -> np.ndarray:
    """Irradiance from the scene's lamps at the texels, one shadow ray per texel and lamp (a
    punctual lamp has no area: the shadow is hard and exact, no noise)."""
    out = np.zeros((len(origin), 3))
    for light in lights:
        e = lamp_irradiance(light, origin, normal)
        lit = np.flatnonzero(np.max(e, axis=1) > 0)
        if len(lit) == 0:
            continue
        if light.type == "directional":
            direction = np.broadcast_to(-np.asarray(light.direction, np.float64), (len(lit), 3))
            dist = np.full(len(lit), np.inf)
        else:
            to_lamp = np.asarray(light.position, np.float64)[None, :] - origin[lit]
            dist = np.linalg.norm(to_lamp, axis=1)
            direction = to_lamp / np.maximum(dist, 1e-30)[:, None]
        direction = np.ascontiguousarray(direction)
        first = intersector.intersects_first(origin[lit], direction)
        blocked = first >= 0
        if np.any(blocked):
            hits = _hit_points(mesh, origin[lit][blocked], direction[blocked], first[blocked])
            # Only geometry between the texel and the lamp shadows it (a lamp may hang below a ceiling).
            hit_dist = np.linalg.norm(hits - origin[lit][blocked], axis=1)
            blocked[np.flatnonzero(blocked)] = hit_dist < dist[blocked] - 1e-6 * extent
        out[lit[~blocked]] += e[lit[~blocked]]
    return out


def _at_hits(mesh, faces: np.ndarray, values: np.ndarray, tris: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per-vertex ``values`` (V, C) interpolated at hit ``points`` on triangles ``tris`` of the
    ray-casting mesh (barycentric coordinates of the points in their triangles)."""
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tris], points)
    return np.einsum("ij,ijk->ik", bary, np.asarray(values, dtype=np.float64)[faces[tris]])


def _hit_points(mesh, origins, directions, tris):
    """Exact ray-triangle intersection points for rays known to hit triangle ``tris``."""
    tri = mesh.triangles[tris]
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    n = np.cross(e1, e2)
    denom = np.sum(n * directions, axis=1)
    t = np.sum(n * (tri[:, 0] - origins), axis=1) / np.where(np.abs(denom) > 1e-20, denom, 1e-20)
    return origins + directions * t[:, None]


def _bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1)
    y = np.clip(uv[:, 1] * h - 0.5, 0, h - 1)
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    return (image[y0, x0] * (1 - fx) + image[y0, x1] * fx) * (1 - fy) + (
        image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    ) * fy
