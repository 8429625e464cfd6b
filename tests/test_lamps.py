"""KHR_lights_punctual lamps: read from glTF, baked into lightmaps with exact shadows
(issue 16, item 4). Checked against closed forms for a lamp over an infinite-looking plane."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from lobeview.scenes.baker import bake_lightmap, lamp_irradiance, rasterize_uv
from lobeview.scenes.gltf_loader import load_gltf
from lobeview.scenes.meshes import Mesh
from lobeview.scenes.scene import PunctualLight, Scene, SceneMaterial, SceneObject

RES = 96
# The baker shades a texel at its surface point lifted by 1e-4 of the scene's extent (against
# self-shadowing): 4e-4 here, a relative change of up to 1e-3 in d^-3 at d = 2.
RTOL = 1e-3


def _plane(size: float, height: float, name: str, atlas: tuple[float, float, float, float]) -> SceneObject:
    """A square in the plane z = height facing +z, its TEXCOORD_1 in the atlas box (u0, v0, u1, v1)."""
    h = size / 2
    positions = np.array([[-h, -h, height], [h, -h, height], [h, h, height], [-h, h, height]], np.float32)
    normals = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
    tangents = np.tile(np.array([[1, 0, 0, 1]], np.float32), (4, 1))
    u0, v0, u1, v1 = atlas
    uv1 = np.array([[u0, v1], [u1, v1], [u1, v0], [u0, v0]], np.float32)
    mesh = Mesh(positions, normals, tangents, uv1.copy(), np.array([[0, 1, 2], [0, 2, 3]], np.uint32), name)
    return SceneObject(name, mesh, 0, uv1)


def _scene(lights, blocker: bool = False) -> Scene:
    material = SceneMaterial("grey", {"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 0.0,
                                      "roughness": 1.0})  # fmt: skip
    objects = [_plane(4.0, 0.0, "floor", (0.0, 0.0, 0.5, 0.5))]
    if blocker:  # a small square 1 unit above the floor's centre, facing up, casts the shadow
        objects.append(_plane(1.0, 1.0, "blocker", (0.5, 0.5, 1.0, 1.0)))
    from lobeview.materials.spec import validate

    material.desc = validate(material.desc)
    return Scene(objects, [material], lights=lights)


def _floor_texels(scene: Scene):
    floor = scene.objects[0]
    samples = rasterize_uv(floor.uv1.astype(np.float64), floor.mesh.positions.astype(np.float64),
                           floor.mesh.normals.astype(np.float64), floor.mesh.indices.reshape(-1, 3), RES)  # fmt: skip
    return samples.pixel, samples.position


def _bake(scene: Scene) -> np.ndarray:
    # No environment, no emitters: every texel's irradiance is the lamps' (one bounce of cosine
    # rays that find nothing adds zero).
    return bake_lightmap(scene, None, RES, rays=1, bounces=1, progress=False, light_samples=0)


def _lamp(kind: str, **kw) -> PunctualLight:
    defaults = dict(name=kind, type=kind, colour=np.array([1.0, 0.5, 0.25]), intensity=8.0,
                    position=np.array([0.3, -0.2, 2.0]), direction=np.array([0.0, 0.0, -1.0]))  # fmt: skip
    defaults.update(kw)
    return PunctualLight(**defaults)


def test_point_lamp_gives_the_inverse_square_cosine_law():
    lamp = _lamp("point")
    scene = _scene([lamp])
    pixel, position = _floor_texels(scene)
    baked = _bake(scene)[pixel[:, 0], pixel[:, 1]]
    # Closed form for a plane under a point source: E = I h / (r^2 + h^2)^(3/2).
    h = 2.0
    r2 = np.sum((position[:, :2] - lamp.position[:2]) ** 2, axis=1)
    expected = (8.0 * h / (r2 + h * h) ** 1.5)[:, None] * lamp.colour[None, :]
    np.testing.assert_allclose(baked, expected, rtol=RTOL)


def test_range_window_and_spot_cone():
    ranged = _lamp("point", range=2.5)
    pixel, position = _floor_texels(_scene([ranged]))
    d = np.linalg.norm(position - ranged.position, axis=1)
    baked = _bake(_scene([ranged]))[pixel[:, 0], pixel[:, 1], 0]
    assert np.all(baked[d >= 2.501] == 0) and np.all(baked[d < 2.4] > 0)
    window = np.clip(1 - (d / 2.5) ** 4, 0, 1)
    np.testing.assert_allclose(baked, 8.0 * 2.0 / d**3 * window, rtol=RTOL, atol=1e-3 * baked.max())

    spot = _lamp("spot", inner_cone=0.3, outer_cone=0.6)
    baked = _bake(_scene([spot]))[pixel[:, 0], pixel[:, 1], 0]
    point = _bake(_scene([_lamp("point")]))[pixel[:, 0], pixel[:, 1], 0]
    angle = np.arccos(np.clip((spot.position[2] - position[:, 2]) / np.linalg.norm(position - spot.position, axis=1),
                              -1, 1))  # fmt: skip
    inside, outside = angle < 0.3 - 1e-3, angle > 0.6 + 1e-3
    assert inside.sum() > 20 and outside.sum() > 20
    np.testing.assert_allclose(baked[inside], point[inside], rtol=RTOL)  # full intensity inside the inner cone
    assert np.all(baked[outside] == 0)
    ramp = ~inside & ~outside
    assert ramp.sum() > 10
    order = np.argsort(angle[ramp])  # the ramp falls with the angle, relative to the point lamp
    ratio = baked[ramp][order] / point[ramp][order]
    assert np.all(np.diff(ratio) <= 1e-6) and ratio[0] <= 1 and ratio[-1] >= 0


def test_lamps_cast_exact_shadows_only_from_geometry_between():
    sun = _lamp("directional", intensity=3.0, direction=np.array([0.0, 0.0, -1.0]))
    scene = _scene([sun], blocker=True)
    pixel, position = _floor_texels(scene)
    baked = _bake(scene)[pixel[:, 0], pixel[:, 1], 0]
    texel = 4.0 / (RES / 2)  # the floor's texel size
    under = np.all(np.abs(position[:, :2]) < 0.5 - 1.5 * texel, axis=1)
    clear = np.any(np.abs(position[:, :2]) > 0.5 + 1.5 * texel, axis=1)
    assert np.all(baked[under] == 0) and under.sum() > 4
    np.testing.assert_allclose(baked[clear], 3.0, rtol=1e-6)
    # A lamp between the floor and the blocker: nothing lies between it and the floor.
    low = _lamp("point", position=np.array([0.0, 0.0, 0.5]))
    lit = _bake(_scene([low], blocker=True))[pixel[:, 0], pixel[:, 1]]
    np.testing.assert_allclose(lit, _bake(_scene([low]))[pixel[:, 0], pixel[:, 1]], rtol=1e-6)


def test_unshadowed_irradiance_matches_the_extension_formula_at_random_points():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(200, 3))
    normals = rng.normal(size=(200, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    spot = _lamp("spot", inner_cone=0.2, outer_cone=0.9, range=3.0, direction=np.array([0.0, 0.6, -0.8]))
    e = lamp_irradiance(spot, points, normals)
    for p, n, value in zip(points, normals, e, strict=True):  # the extension's GLSL, written out per point
        light_vector = spot.position - p
        d = np.linalg.norm(light_vector)
        l = light_vector / d  # noqa: E741
        attenuation = max(min(1.0 - (d / 3.0) ** 4, 1.0), 0.0) / d**2
        scale = 1.0 / max(0.001, np.cos(0.2) - np.cos(0.9))
        offset = -np.cos(0.9) * scale
        cd = np.dot(spot.direction, -l)
        angular = min(max(cd * scale + offset, 0.0), 1.0) ** 2
        np.testing.assert_allclose(value, spot.colour * 8.0 * attenuation * angular * max(np.dot(n, l), 0), atol=1e-12)


def _lamp_gltf(tmp_path, lights, nodes_extra) -> str:
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], np.float32)
    blob = positions.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": lights}},
        "buffers": [
            {"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
        ],  # fmt: skip
        "bufferViews": [{"buffer": 0, "byteLength": len(blob)}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}
        ],  # fmt: skip
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}, *nodes_extra],
        "scenes": [{"nodes": list(range(1 + len(nodes_extra)))}],
    }
    path = tmp_path / "lamps.gltf"
    path.write_text(json.dumps(doc))
    return str(path)


def test_loader_places_lamps_on_their_nodes_and_warns_about_bad_ones(tmp_path):
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    path = _lamp_gltf(
        tmp_path,
        [
            {
                "type": "spot",
                "name": "desk",
                "intensity": 40,
                "color": [1, 0.9, 0.8],
                "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5},
                "range": 6,
            },
            {"type": "directional", "intensity": 2},
            {"type": "area"},
            {"type": "point", "intensity": -1},
        ],  # fmt: skip
        [
            # Quaternion (sin 45, 0, 0, cos 45): +90 degrees about x.
            {
                "name": "desk lamp",
                "translation": [1, 2, 3],
                "rotation": [s, 0, 0, c],
                "extensions": {"KHR_lights_punctual": {"light": 0}},
            },
            {"name": "sun", "extensions": {"KHR_lights_punctual": {"light": 1}}},
            {"name": "bad type", "extensions": {"KHR_lights_punctual": {"light": 2}}},
            {"name": "negative", "extensions": {"KHR_lights_punctual": {"light": 3}}},
            {"name": "missing", "extensions": {"KHR_lights_punctual": {"light": 9}}},
        ],  # fmt: skip
    )
    with pytest.warns(Warning):
        scene = load_gltf(path)
    assert [light.name for light in scene.lights] == ["desk", "light1"]
    desk, sun = scene.lights
    np.testing.assert_allclose(desk.position, [1, 2, 3])
    # A +90 degree turn about x takes -Z to +Y.
    np.testing.assert_allclose(desk.direction, [0, 1, 0], atol=1e-12)
    assert (desk.type, desk.intensity, desk.range, desk.inner_cone, desk.outer_cone) == ("spot", 40, 6, 0.1, 0.5)
    np.testing.assert_allclose(sun.direction, [0, 0, -1])
    text = "\n".join(scene.warnings)
    for expected in ("'light2'", "'light3'", "lamp 9", "bakes their light"):
        assert expected in text, expected


def test_environment_importance_sampling_tames_a_sun():
    """An open floor under builtin:sky (a 2e4 sun of 0.6 degrees): every texel's irradiance is
    the environment's, E = integral L cos (brute force over the map). Cosine rays alone leave
    most texels without the sun and a few with far too much; importance samples combined by MIS
    give every texel the sun, at the same ray count."""
    from lobeview.scenes.builtin_env import load_environment

    env = load_environment("builtin:sky")
    scene = _scene([])
    pixel, _ = _floor_texels(scene)
    # The floor faces +z; the sky's up is +y in envmap.py: turn the scene so the floor faces up.
    for obj in scene.objects:
        obj.mesh.positions = obj.mesh.positions[:, [0, 2, 1]] * np.array([1, 1, -1], np.float32)
        obj.mesh.normals = np.tile(np.array([[0, 1, 0]], np.float32), (len(obj.mesh.normals), 1))
    exact = env.irradiance(np.array([[0.0, 1.0, 0.0]]), source_height=512)[0]

    def bake(rays, env_samples):
        return bake_lightmap(scene, env, RES, rays=rays, bounces=1, progress=False, light_samples=0,
                             env_samples=env_samples)[pixel[:, 0], pixel[:, 1]]  # fmt: skip

    cosine_only = np.abs(bake(16, 0) / exact - 1).mean(axis=1)
    mis_baked = bake(8, 8)
    mis = np.abs(mis_baked / exact - 1).mean(axis=1)
    # Measured: cosine-only 16 rays median 55 % (the sun is most of the light, most texels miss
    # it); 8 + 8 with MIS median 3.8 %, 99th percentile 18 %; 32 + 32: 0.8 % and 5 %.
    assert np.median(cosine_only) > 0.5
    assert np.median(mis) < 0.1 and np.percentile(mis, 99) < 0.5, (np.median(mis), np.percentile(mis, 99))
    np.testing.assert_allclose(mis_baked.mean(axis=0), exact, rtol=0.02)  # unbiased


def test_alpha_masked_cutouts_let_light_through():
    """A MASK quad over the floor whose texture is transparent on its left half and opaque on its
    right: under a sun from straight above, only the right half's footprint is in shadow (the
    cut-out passes rays, AlphaTestedIntersector); an opaque material shadows the whole."""
    from lobeview.scenes.scene import TextureSlot

    sun = _lamp("directional", intensity=3.0, direction=np.array([0.0, 0.0, -1.0]))
    scene = _scene([sun], blocker=True)
    pixel, position = _floor_texels(scene)
    mask = np.zeros((4, 4, 4), np.uint8)
    mask[..., :3] = 200
    mask[:, 2:, 3] = 255  # u >= 0.5: opaque
    slot = TextureSlot(mask, srgb=True, mag_filter=9728, min_filter=9728)
    cutout = SceneMaterial("leaf", scene.materials[0].desc, alpha_mode="MASK", textures={"base_color": slot})
    scene.materials.append(cutout)
    blocker = scene.objects[1]
    blocker.material = 1
    # The blocker's TEXCOORD_0 runs u from 0 at x = -0.5 to 1 at x = +0.5.
    blocker.mesh.uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    baked = _bake(scene)[pixel[:, 0], pixel[:, 1], 0]
    texel = 4.0 / (RES / 2)
    inner_y = np.abs(position[:, 1]) < 0.5 - 1.5 * texel
    under_opaque = inner_y & (position[:, 0] > 1.5 * texel) & (position[:, 0] < 0.5 - 1.5 * texel)
    under_cutout = inner_y & (position[:, 0] < -1.5 * texel) & (position[:, 0] > -0.5 + 1.5 * texel)
    assert under_opaque.sum() > 4 and under_cutout.sum() > 4
    assert np.all(baked[under_opaque] == 0)
    np.testing.assert_allclose(baked[under_cutout], 3.0, rtol=1e-6)
    scene.materials[1].alpha_mode = "OPAQUE"
    opaque = _bake(scene)[pixel[:, 0], pixel[:, 1], 0]
    assert np.all(opaque[under_cutout] == 0)


def test_bounce_light_takes_the_colour_of_the_texel_it_hit():
    """A floor textured red on its left half and green on its right, lit by a sun; a white
    ceiling above it receives only bounced light. Over the red half the ceiling turns red, over
    the green half green: the bake's per-face albedo follows the texture (the texture's mean
    would give both halves the same olive)."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.meshes import quad
    from lobeview.scenes.scene import TextureSlot

    texture = np.zeros((2, 2, 4), np.uint8)
    texture[:, 0] = [255, 0, 0, 255]
    texture[:, 1] = [0, 255, 0, 255]
    floor_material = SceneMaterial(
        "floor", validate({"model": "gltf", "base_color": [1, 1, 1], "metallic": 0.0, "roughness": 1.0}),
        textures={"base_color": TextureSlot(texture, srgb=True, mag_filter=9728, min_filter=9728)},
    )  # fmt: skip
    white = SceneMaterial("white", validate({"model": "gltf", "base_color": [1, 1, 1], "metallic": 0.0,
                                             "roughness": 1.0}))  # fmt: skip
    # The floor is two quads (left, right) so faces do not straddle the colour edge.
    left = quad([-2.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 4.0, 0.0])
    right = quad([0.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 4.0, 0.0])
    left.uvs = np.array([[0.1, 0.5], [0.4, 0.5], [0.4, 0.5], [0.1, 0.5]], np.float32)
    right.uvs = np.array([[0.6, 0.5], [0.9, 0.5], [0.9, 0.5], [0.6, 0.5]], np.float32)
    ceiling = quad([-2.0, 2.0, 0.3], [4.0, 0.0, 0.0], [0.0, -4.0, 0.0])  # at z = 0.3, facing down
    objects = []
    parts = [("left", left, 0, (0.0, 0.0, 0.5, 0.5)), ("right", right, 0, (0.5, 0.0, 1.0, 0.5)),
             ("ceiling", ceiling, 1, (0.0, 0.5, 1.0, 1.0))]  # fmt: skip
    for name, mesh, material, box in parts:
        u0, v0, u1, v1 = box
        uv1 = np.array([[u0, v1], [u1, v1], [u1, v0], [u0, v0]], np.float32)
        objects.append(SceneObject(name, mesh, material, uv1))
    # A lamp between floor and ceiling lights both directly; the ceiling's bounce comes from the floor.
    lamp = _lamp("point", intensity=2.0, colour=np.array([1.0, 1.0, 1.0]), position=np.array([0.0, 0.0, 0.15]))
    scene = Scene(objects, [floor_material, white], lights=[lamp])
    baked = bake_lightmap(scene, None, 64, rays=64, bounces=2, progress=False, light_samples=0, env_samples=0)
    ceiling_obj = objects[2]
    mesh = ceiling_obj.mesh
    samples = rasterize_uv(ceiling_obj.uv1.astype(np.float64), mesh.positions.astype(np.float64),
                           mesh.normals.astype(np.float64), mesh.indices.reshape(-1, 3), 64)  # fmt: skip
    # Bounce 2 minus bounce 1 at the ceiling: what the floor sent up. Compare the two halves.
    direct = bake_lightmap(scene, None, 64, rays=64, bounces=1, progress=False, light_samples=0, env_samples=0)
    bounce = (baked - direct)[samples.pixel[:, 0], samples.pixel[:, 1]]
    x = samples.position[:, 0]
    over_red, over_green = bounce[x < -0.5].mean(axis=0), bounce[x > 0.5].mean(axis=0)
    assert over_red[0] > 2 * over_red[1] and over_green[1] > 2 * over_green[0], (over_red, over_green)
