"""A test scene for planar mirror passes (thesis 4.5): boxes on a reflective floor, lit by a
constant lightmap (E = pi, so a diffuse surface's radiance is its albedo times its texture), so
a ray tracer can compute exactly what the floor should reflect. Shared by tests/test_planar_mirror.py,
the bench's mirror-pass timing and the convergence image pair (bench/mirror_figure.py)."""

from __future__ import annotations

import numpy as np

from lobeview.materials.spec import validate

from .meshes import box_mesh, quad
from .scene import Lightmap, Scene, SceneCamera, SceneMaterial, SceneObject

FLOOR_HALF = 4.0
TILE_TEXELS = 16  # checker tiles: 2 x 2 per box face (uv 0..1 per face)
#: (centre, size, albedo): a cube on the floor, a tall pillar, and a box floating 0.6 m above the
#: floor (its reflection blurs more on a glossy floor: the lobe widens with distance, Fig. 4.32)
BOXES = (
    ((-0.8, 0.25, -0.4), (0.5, 0.5, 0.5), (0.85, 0.65, 0.15)),
    ((0.7, 0.75, -1.1), (0.3, 1.5, 0.3), (0.2, 0.45, 0.85)),
    ((-0.1, 0.9, -2.2), (0.7, 0.6, 0.5), (0.8, 0.2, 0.2)),
)
CAMERA = SceneCamera(
    "mirror floor", np.array([0.0, 1.1, 2.2]), np.array([0.0, 0.35, -0.9]), np.array([0, 1.0, 0]), 50.0
)


def checker(albedo) -> np.ndarray:
    """A 2 x 2 checker between the albedo and 35 % of it (texture: multiplies kd = 1)."""
    n = 2 * TILE_TEXELS
    parity = (np.arange(n)[:, None] // TILE_TEXELS + np.arange(n)[None] // TILE_TEXELS) % 2
    bright = np.asarray(albedo, np.float32)
    return np.where(parity[..., None] == 1, bright, 0.35 * bright).astype(np.float32)


def floor_material(roughness: float, r0: float = 1.0, roughness_y: float | None = None) -> dict:
    """The floor: one thesis lobe (ks = 1, kd = 0) of Beckmann roughness ``roughness`` (along
    the tangent; ``roughness_y`` along the bitangent for an anisotropic floor)."""
    my = roughness if roughness_y is None else roughness_y
    lobe = {"ks": 1.0, "mx": roughness, "my": my, "r0": r0, "alpha": 0.0}
    return validate({"model": "thesis", "kd": 0.0, "lobes": [lobe]})


def mirror_floor_scene(
    roughness: float = 0.002, extra_reflector: bool = False, roughness_y: float | None = None
) -> Scene:
    """Boxes on a floor of the given roughness (a planar reflector by automatic detection;
    ``roughness_y``: anisotropic, see floor_material).
    ``extra_reflector`` adds a glossy back wall as a second reflector (the bench's 2-reflector
    case)."""
    lightmap = Lightmap(np.full((4, 4, 3), np.pi, np.float32))
    floor = quad([-FLOOR_HALF, 0.0, FLOOR_HALF], [2 * FLOOR_HALF, 0.0, 0.0], [0.0, 0.0, -2 * FLOOR_HALF])
    materials = [SceneMaterial("floor", floor_material(roughness, roughness_y=roughness_y), lightmap=lightmap)]
    objects = [SceneObject("floor", floor, 0, floor.uvs.copy())]
    for k, (centre, size, albedo) in enumerate(BOXES):
        mesh = box_mesh(centre, size)
        diffuse = validate({"model": "thesis", "kd": 1.0, "lobes": []})
        materials.append(SceneMaterial(f"box {k}", diffuse, checker(albedo), lightmap=lightmap))
        objects.append(SceneObject(f"box {k}", mesh, len(materials) - 1, mesh.uvs.copy()))
    if extra_reflector:
        wall = quad([-FLOOR_HALF, 0.0, -3.0], [2 * FLOOR_HALF, 0.0, 0.0], [0.0, 3.0, 0.0])
        glossy = validate(
            {"model": "thesis", "kd": 0.3, "lobes": [{"ks": 0.5, "mx": 0.05, "my": 0.05, "r0": 0.05, "alpha": 0.0}]}
        )
        materials.append(SceneMaterial("glossy wall", glossy, lightmap=lightmap))
        objects.append(SceneObject("glossy wall", wall, len(materials) - 1, wall.uvs.copy()))
    return Scene(objects, materials, [CAMERA], "mirror floor")


PANE_Z = 0.6  # the glass pane of pane_scene: a vertical quad between the camera and the boxes


def pane_material(roughness: float, r0: float = 0.0, reflection: bool = False) -> dict:
    """A thin pane: one thesis transmission lobe (kt = 1) of Beckmann roughness ``roughness``,
    optionally with the matching reflection lobe."""
    lobe = {"mx": roughness, "my": roughness, "r0": r0, "alpha": 0.0}
    desc = {"model": "thesis", "kd": 0.0, "lobes": [], "transmission_lobes": [{"kt": 1.0, **lobe}]}
    if reflection:
        desc["lobes"] = [{"ks": 1.0, **lobe}]
    return validate(desc)


def pane_scene(roughness: float = 0.002, reflection: bool = False) -> Scene:
    """The boxes on a diffuse floor behind a vertical glass pane (3 m x 2 m at z = PANE_Z, a
    planar reflector with a see-through pass by automatic detection)."""
    scene = mirror_floor_scene()
    scene.materials[0].desc = validate({"model": "thesis", "kd": 0.6, "lobes": []})
    pane = quad([-1.5, 0.0, PANE_Z], [3.0, 0.0, 0.0], [0.0, 2.0, 0.0])
    lightmap = scene.materials[0].lightmap
    scene.materials.append(SceneMaterial("pane", pane_material(roughness, reflection=reflection), lightmap=lightmap,
                                         double_sided=True))  # fmt: skip
    scene.objects.append(SceneObject("pane", pane, len(scene.materials) - 1, pane.uvs.copy()))
    scene.name = "glass pane"
    return scene


class BoxTracer:
    """Ray casting against the scene's boxes (trimesh, Embree where installed) with their
    light-mapped radiance (kd 1 x checker texel, E = pi): the ground truth of the mirror tests and
    of the refinement bench. The floor itself is not traced (rays leave it upward)."""

    def __init__(self):
        import trimesh

        meshes = [box_mesh(c, s) for c, s, _ in BOXES]
        offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
        self.mesh = trimesh.Trimesh(
            np.concatenate([m.positions for m in meshes]),
            np.concatenate([m.indices.reshape(-1, 3) + o for m, o in zip(meshes, offsets, strict=True)]),
            process=False,
        )
        self._uvs = np.concatenate([m.uvs for m in meshes])
        self._faces_per_box = len(meshes[0].indices.reshape(-1, 3))
        self._images = np.stack([checker(albedo) for _, _, albedo in BOXES])

    def hits(self, origins: np.ndarray, directions: np.ndarray):
        """First hits: (ray index (H,), box index (H,), texture texel coordinates (H, 2))."""
        import trimesh

        locations, index_ray, index_tri = self.mesh.ray.intersects_location(origins, directions, multiple_hits=False)
        corners = self.mesh.faces[index_tri]
        bary = trimesh.triangles.points_to_barycentric(self.mesh.vertices[corners], locations)
        texels = np.einsum("ki,kij->kj", bary, self._uvs[corners]) * 2 * TILE_TEXELS
        return index_ray, index_tri // self._faces_per_box, texels

    def radiance(self, origins: np.ndarray, directions: np.ndarray, background: float) -> np.ndarray:
        """Radiance (K, 3) along the rays: the box face hit (nearest texel), ``background`` where
        they miss."""
        radiance = np.full((len(origins), 3), float(background))
        index_ray, box, texels = self.hits(origins, directions)
        col, row = np.clip(texels.astype(int), 0, 2 * TILE_TEXELS - 1).T
        radiance[index_ray] = self._images[box, row, col]
        return radiance


def traced_floor_reflection(points, eye, lobe, samples: int, background: float, seed: int = 0) -> np.ndarray:
    """The exact reflected radiance of floor points (K, 3) toward ``eye`` for an isotropic floor
    ``lobe`` (materials.patterns.specular_lobes), by importance sampling the lobe with ``samples``
    random directions per point and ray tracing the boxes: the ground truth the mirror-pass
    refinement converges to where the mirror buffer sees what the rays hit."""
    rng = np.random.default_rng(seed)
    tracer = BoxTracer()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    frame = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]).T  # t, b, n (n = +y)
    result = np.zeros((len(points), 3))
    chunk = max(1, 200_000 // samples)  # points per batch of rays
    for start in range(0, len(points), chunk):
        p = points[start : start + chunk]
        v = np.asarray(eye, dtype=np.float64) - p
        wo = (v / np.linalg.norm(v, axis=1, keepdims=True)) @ frame
        wo = np.repeat(wo, samples, axis=0)
        u = rng.random((len(wo), 2))
        wi = lobe.sample_wi(u[:, 0], u[:, 1], wo)
        pdf = lobe.pdf(wi, wo)
        ok = pdf > 0.0
        weight = np.zeros((len(wo), 3))
        weight[ok] = lobe.eval(wi[ok], wo[ok]) * (np.abs(wi[ok, 2]) / pdf[ok])[:, None]
        origins = np.repeat(p, samples, axis=0)
        radiance = np.zeros((len(wo), 3))
        radiance[ok] = tracer.radiance(origins[ok] + 1e-5 * frame[:, 2], wi[ok] @ frame.T, background)
        result[start : start + len(p)] = (radiance * weight).reshape(len(p), samples, 3).mean(axis=1)
    return result
