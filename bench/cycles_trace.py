"""What lobeview's vertex horizons say at the pixels Cycles' light passes find self-occluded, and
what horizons traced at each pixel's own surface point would say (``python -m lobeview.bench.cycles
--passes --trace``; issue 40: the evidence for per-texel horizons).

For each white-sky case with passes, up to TRACE_PIXELS pixels are drawn (seeded) from two groups,
the hidden (Cycles' GlossDir below HIDDEN_BELOW) and the open (GlossDir at least OPEN_FROM) glossy
pixels. Each pixel's centre ray is cast into the scene as lobeview loads it (trimesh); at the point
it meets, with the interpolated vertex normal, the mirror direction of the view is tested three
ways, each the visible share of a point lookup (scenes/self_visibility.py horizon_visibility):
against the object's vertex horizons interpolated at the point (as lobeview shades an object
without a horizon map, scenes/horizon_maps.py), and against horizons traced at the point itself
(16 rays in each of a horizon map's MAP_HORIZON_SECTORS) with near-hit cuts of TRACE_CUTS of the
object's extent. Only the object the ray meets hides anything (what other objects hide is in its
cube map).
"""

from __future__ import annotations

import numpy as np

TRACE_PIXELS = 300
HIDDEN_BELOW = 0.3
OPEN_FROM = 0.9
TRACE_CUTS = (0.03, 0.01, 0.003)
RAYS_PER_SECTOR = 16
SEED = 5


def camera_rays(eye, target, fov_y: float, size, pixels: np.ndarray) -> np.ndarray:
    """Unit directions of the rays through the centres of ``pixels`` ((k, 2) rows and columns) of
    a ``size`` (width, height) image seen from ``eye`` toward ``target``, +y up, vertical field of
    view ``fov_y`` degrees (lobeview's camera and the bench's Cycles camera)."""
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    width, height = size
    half = np.tan(np.radians(fov_y) / 2.0)
    x = ((pixels[:, 1] + 0.5) / width * 2.0 - 1.0) * half * width / height
    y = (1.0 - (pixels[:, 0] + 0.5) / height * 2.0) * half
    rays = forward + x[:, None] * right + y[:, None] * up
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def mirror_visibility(scene, eye, rays: np.ndarray) -> dict:
    """For rays from ``eye`` into ``scene`` (scenes/scene.py, as loaded): the visible share of each
    hit point's mirror direction by its object's vertex horizons ("vertices") and by horizons
    traced at the point with each cut of TRACE_CUTS ("cut 3 %", ...), over the rays that hit."""
    import trimesh

    from lobeview.scenes.self_visibility import (
        MAP_HORIZON_SECTORS,
        NO_OCCLUSION,
        horizon_visibility,
        object_visibility_cones,
        traced_horizons,
    )

    meshes = [trimesh.Trimesh(obj.mesh.positions, np.asarray(obj.mesh.indices).reshape(-1, 3), process=False)
              for obj in scene.objects]  # fmt: skip
    merged = trimesh.util.concatenate(meshes)
    owner = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(meshes)])
    first_face = np.concatenate([[0], np.cumsum([len(m.faces) for m in meshes])[:-1]])
    eye = np.asarray(eye, dtype=np.float64)
    points, ray_index, faces = merged.ray.intersects_location(
        np.repeat(eye[None], len(rays), axis=0), rays, multiple_hits=False
    )
    results = {"vertices": []} | {f"cut {100 * cut:g} %": [] for cut in TRACE_CUTS}
    for index in np.unique(owner[faces]):
        mine = owner[faces] == index
        obj, mesh = scene.objects[index], meshes[index]
        local_faces = faces[mine] - first_face[index]
        point = points[mine]
        corners = mesh.faces[local_faces]
        bary = trimesh.triangles.points_to_barycentric(mesh.triangles[local_faces], point)
        normal = np.einsum("pk,pkc->pc", bary, np.asarray(obj.mesh.normals, dtype=np.float64)[corners])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        view = rays[ray_index[mine]]
        normal = np.where((np.sum(normal * view, axis=1) > 0.0)[:, None], -normal, normal)  # toward the eye
        mirror = view - 2.0 * np.sum(view * normal, axis=1, keepdims=True) * normal
        cones = np.einsum("pk,pkc->pc", bary, object_visibility_cones(obj).astype(np.float64)[corners])
        results["vertices"].append(horizon_visibility(mirror, cones, normal, below_hidden=True))
        extent = float(np.max(mesh.extents))
        for cut in TRACE_CUTS:
            traced = np.zeros((len(point), 4 + MAP_HORIZON_SECTORS))  # as a horizon map holds them
            traced[:, :3], traced[:, 3] = normal, NO_OCCLUSION + 1.0  # a cone: the horizons apply
            traced[:, 4:] = traced_horizons(
                mesh, point, normal, extent, RAYS_PER_SECTOR, near_hit=cut, sectors=MAP_HORIZON_SECTORS
            )
            results[f"cut {100 * cut:g} %"].append(horizon_visibility(mirror, traced, normal, below_hidden=True))
    return {key: np.concatenate(values) if values else np.zeros(0) for key, values in results.items()}


def trace_case(scene, eye, target, fov_y: float, size, layers: dict) -> dict:
    """Both groups of a case: {group: {"pixels", "cycles" (mean GlossDir), and the mean of each
    mirror_visibility entry}}."""
    from lobeview.bench.cycles_passes import MIN_GLOSSY_COLOUR, glossy_visibility

    visibility, colour = glossy_visibility(layers)
    glossy = colour > MIN_GLOSSY_COLOUR
    rng = np.random.default_rng(SEED)
    groups = {}
    for name, chosen in (
        ("hidden", glossy & (visibility < HIDDEN_BELOW)),
        ("open", glossy & (visibility >= OPEN_FROM)),
    ):
        pixels = np.argwhere(chosen)
        pixels = pixels[rng.permutation(len(pixels))[:TRACE_PIXELS]]
        if not len(pixels):
            continue
        found = mirror_visibility(scene, eye, camera_rays(eye, target, fov_y, size, pixels))
        groups[name] = {"pixels": int(len(found["vertices"])),
                        "cycles": float(visibility[pixels[:, 0], pixels[:, 1]].mean())}  # fmt: skip
        groups[name] |= {key: float(values.mean()) for key, values in found.items() if len(values)}
    return groups


def markdown_lines(rows: list) -> list:
    """The table of the rows' "trace" entries (trace_case per case)."""
    rows = [row for row in rows if row.get("trace")]
    if not rows:
        return []
    keys = ["vertices", *(f"cut {100 * cut:g} %" for cut in TRACE_CUTS)]
    lines = ["", f"The mirror direction at up to {TRACE_PIXELS} hidden (Cycles' GlossDir < {HIDDEN_BELOW}) and open "
             f"(>= {OPEN_FROM}) pixels (`--trace`): its mean visible share by the vertex horizons (lobeview's where an "
             f"object has no horizon map), and by horizons traced at each pixel's own point ({RAYS_PER_SECTOR} rays a "
             "sector) with the "
             "near-hit cut given (times the object's extent); Cycles' mean GlossDir beside.", "",
             "| case | pixels | n | Cycles | vertex horizons | "
             + " | ".join(f"per point, {k}" for k in keys[1:]) + " |",
             "|---|---|---|---|---|" + "---|" * (len(keys) - 1)]  # fmt: skip
    for row in rows:
        for group, found in row["trace"].items():
            cells = " | ".join(f"{found[k]:.2f}" if k in found else "-" for k in keys)
            lines.append(f"| {row['case']} | {group} | {found['pixels']} | {found['cycles']:.2f} | {cells} |")
    return lines
