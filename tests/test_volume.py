"""Thick transmission (KHR_materials_volume, issue 40 item 4; materials/volume.py and
shaders/volume.glsl): the path model against ray tracing a real glass ball and a real slab with
Snell's law, the GLSL twin against numpy, the loader, and a glass ball rendered through the
pipeline against a numpy ray tracer of the same ball."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from conftest import run_compute_probe

from lobeview.materials.volume import (
    attenuation,
    bend_rotation,
    exit_transmittance,
    slab_gains,
    sphere_weight,
    volume_factors,
    volume_of,
    volume_path,
)


def _refract(incident, normal, eta):
    """Snell's law in vector form for a unit ``incident`` direction and a unit ``normal`` on the
    side it comes from (normal . incident < 0), ``eta`` = n_from / n_to; None for total internal
    reflection. Written from the tangential components (independently of materials/volume.py)."""
    cos_in = -np.dot(normal, incident)
    tangential = incident + cos_in * normal  # the component along the surface
    tangential_out = eta * tangential
    sin2 = np.dot(tangential_out, tangential_out)
    if sin2 > 1.0:
        return None
    return tangential_out - np.sqrt(1.0 - sin2) * normal


def _sphere_exit(origin, direction, centre, radius):
    """The far intersection of a ray starting on the sphere with it (the larger root)."""
    oc = origin - centre
    b = np.dot(oc, direction)
    c = np.dot(oc, oc) - radius * radius
    return origin + (-b + np.sqrt(max(b * b - c, 0.0))) * direction


def _random_views(rng, count, normal):
    """Unit views in the hemisphere of ``normal`` (incidence up to 85 degrees)."""
    out = []
    while len(out) < count:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if np.dot(v, normal) > np.cos(np.radians(85)):
            out.append(v)
    return np.array(out)


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.4])
def test_the_sphere_model_is_exact_for_a_glass_ball(ior):
    """A ball whose thickness is its diameter: exit point and direction as a ray tracer finds them
    (two refractions through the real sphere), at any incidence."""
    rng = np.random.default_rng(4)
    centre, radius = np.array([0.3, -0.2, 1.0]), 0.7
    for _ in range(40):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        entry = centre + radius * normal
        view = _random_views(rng, 1, normal)[0]
        inside = _refract(-view, normal, 1.0 / ior)
        exit_point = _sphere_exit(entry, inside, centre, radius)
        exit_normal = (exit_point - centre) / radius
        out = _refract(inside, -exit_normal, ior)
        assert out is not None  # a ball never reflects totally at the exit
        path = volume_path(view, normal, ior, 2 * radius, extent=2 * radius)
        np.testing.assert_allclose(path.exit_direction, out, atol=1e-9)
        np.testing.assert_allclose(entry + path.exit_offset, exit_point, atol=1e-9)
        assert path.length == pytest.approx(np.linalg.norm(exit_point - entry), abs=1e-9)


def test_the_slab_model_is_exact_for_a_plate():
    """A thin plate (thickness 0.01 of its width): the ray leaves parallel to the view ray, through
    the far face where Snell's law puts it."""
    rng = np.random.default_rng(5)
    normal = np.array([0.0, 0.0, 1.0])
    for view in _random_views(rng, 30, normal):
        inside = _refract(-view, normal, 1.0 / 1.5)
        far = inside * (0.01 / -inside[2])  # from z = 0 to the face z = -0.01
        out = _refract(inside, normal, 1.5)  # the far face's normal faces the ray: +z
        path = volume_path(view, normal, 1.5, 0.01, extent=1.0)
        np.testing.assert_allclose(path.exit_direction, -view, atol=1e-12)
        np.testing.assert_allclose(out, -view, atol=1e-12)
        np.testing.assert_allclose(path.exit_offset, far, atol=1e-12)


def test_the_models_blend_continuously_and_bend_nothing_without_refraction():
    ratios = np.linspace(0.0, 1.5, 301)
    w = sphere_weight(ratios, 1.0)
    assert w[0] == 0 and w[-1] == 1 and np.all(np.diff(w) >= 0) and np.max(np.abs(np.diff(w))) < 0.02
    assert sphere_weight(0.25, 1.0) == 0 and sphere_weight(0.75, 1.0) == 1
    view = np.array([0.3, 0.1, 0.9]) / np.linalg.norm([0.3, 0.1, 0.9])
    for ior in (1.0, 0.0):  # no refraction (0: the extensions' infinite index transmits nothing anyway)
        path = volume_path(view, [0, 0, 1], ior, 1.0, 1.0)
        np.testing.assert_allclose(path.exit_direction, -view, atol=1e-12)


def test_bend_rotation_and_attenuation():
    rng = np.random.default_rng(6)
    a, b = rng.normal(size=(2, 50, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    r = bend_rotation(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r, a), b, atol=1e-9)
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", r, r), np.broadcast_to(np.eye(3), (50, 3, 3)), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-9)
    np.testing.assert_allclose(bend_rotation(a[0], a[0]), np.eye(3), atol=1e-12)
    # attenuationColor is reached at attenuationDistance, its square at twice that.
    colour = [0.9, 0.5, 0.2]
    np.testing.assert_allclose(attenuation(2.0, colour, 2.0), colour)
    np.testing.assert_allclose(attenuation(4.0, colour, 2.0), np.square(colour))
    np.testing.assert_allclose(attenuation(4.0, colour, None), 1.0)
    assert exit_transmittance(1.0, [0.04] * 3, 1.0) == pytest.approx(0.96)


def test_slab_gains_sum_the_bounces_between_the_faces():
    """Against the bounces summed one by one: a plate reflects F, then (1 - F)^2 a^(2k) F^(2k - 1)
    after k round trips inside; it transmits (1 - F)^2 a (F a)^(2k)."""
    for f, a in ((0.04, 1.0), (0.3, 0.8), (0.9, 0.5), (0.04, 0.0)):
        reflected = f + sum((1 - f) ** 2 * a ** (2 * k) * f ** (2 * k - 1) for k in range(1, 400))
        transmitted = sum((1 - f) ** 2 * a * (f * a) ** (2 * k) for k in range(400))
        reflection_gain, transmission_gain = slab_gains(f, np.full(3, a))
        np.testing.assert_allclose(f * reflection_gain, reflected, rtol=1e-12)
        np.testing.assert_allclose((1 - f) ** 2 * a * transmission_gain, transmitted, rtol=1e-12, atol=1e-300)


def test_glsl_volume_path_equals_numpy():
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.shaders import ProgramCache

    rng = np.random.default_rng(7)
    n = 256
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    views = np.array([_random_views(rng, 1, m)[0] for m in normals])
    thickness = rng.uniform(0.01, 1.0, n)
    extent = rng.uniform(0.2, 1.5, n)
    ior = rng.choice([1.0, 1.33, 1.5, 2.4], n)
    given = rng.uniform(0.0, 3.0, n)
    probe = np.zeros((n, 3, 4), np.float32)
    probe[:, 0, :3], probe[:, 0, 3] = views, thickness
    probe[:, 1, :3], probe[:, 1, 3] = normals, extent
    probe[:, 2, 0], probe[:, 2, 1] = ior, given
    # u_volume: (thickness, middle extent, ior, 1 / attenuation distance) of volume_shading's runs:
    # none (the path's pieces are per item), a plate, between plate and ball, a ball.
    volumes = [
        (0.0, 1.0, 1.5, 1.0 / 0.7),
        (0.05, 1.0, 1.5, 1.0 / 0.7),
        (0.5, 1.0, 1.33, 1.0 / 0.7),
        (1.0, 1.0, 2.4, 0.0),
    ]
    ctx = create_headless_context()
    try:
        program = ProgramCache(ctx).compute("volume_probe.comp")
        program["u_volume_attenuation"] = (0.9, 0.5, 0.2)
        runs = []
        for volume in volumes:
            program["u_volume"] = volume
            runs.append(run_compute_probe(ctx, program, probe, 8))
    finally:
        ctx.release()
    out = runs[0]
    cos_view = np.sum(views * normals, axis=1)
    # volume_shading: the combination of the pieces, against materials/volume.py volume_factors.
    assert np.all(out[:, 6, 3] == 0) and np.all(out[:, 6:8, :3] == 1)  # no volume: factors 1
    for (thick, side, index, inverse_distance), run in zip(volumes[1:], runs[1:], strict=True):
        assert np.all(run[:, 6, 3] == 1)
        distance = 1.0 / inverse_distance if inverse_distance else None
        transmitted, reflected = volume_factors(volume_path(views, normals, index, thick, side), cos_view,
                                                [0.04, 0.05, 0.03], 0.9, [0.9, 0.5, 0.2], distance)  # fmt: skip
        np.testing.assert_allclose(run[:, 6, :3], transmitted, rtol=2e-4)
        np.testing.assert_allclose(run[:, 7, :3], reflected, rtol=2e-4)
    path = volume_path(views, normals, ior, thickness, extent)
    np.testing.assert_allclose(out[:, 2, 3], path.slab_weight, atol=1e-5)
    np.testing.assert_allclose(out[:, 3, 3], path.slab_length, rtol=1e-4)
    exit_t = np.array([exit_transmittance(c, [0.04, 0.05, 0.03], 0.9) for c in np.sum(views * normals, axis=1)])
    reflection_gain, transmission_gain = slab_gains(1 - exit_t, attenuation(path.slab_length, [0.9, 0.5, 0.2], 0.7))
    np.testing.assert_allclose(out[:, 4, :3], reflection_gain, rtol=1e-4)
    np.testing.assert_allclose(out[:, 5, :3], transmission_gain, rtol=1e-4)
    np.testing.assert_allclose(out[:, 0, :3], path.exit_direction, atol=2e-5)
    np.testing.assert_allclose(out[:, 0, 3], path.length, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(out[:, 1, :3], path.exit_offset, atol=2e-5)
    np.testing.assert_allclose(out[:, 1, 3], [exit_transmittance(c, [0.04, 0.05, 0.03], 0.9) for c in cos_view],
                               atol=1e-5)  # fmt: skip
    bends = bend_rotation(-views, path.exit_direction)
    np.testing.assert_allclose(out[:, 2, :3], np.einsum("nij,nj->ni", bends, normals), atol=5e-5)
    np.testing.assert_allclose(out[:, 3, :3], attenuation(given, [0.9, 0.5, 0.2], 0.7), rtol=1e-4)


def _volume_gltf(tmp_path, volume: dict, scale=2.0):
    from pathlib import Path

    from test_textures import _textured_gltf

    tmp_path.mkdir(parents=True, exist_ok=True)
    material = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.1},
                "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                               "KHR_materials_volume": volume}}  # fmt: skip
    path = Path(_textured_gltf(tmp_path, material, []))
    doc = json.loads(path.read_text())
    doc["extensionsUsed"] += ["KHR_materials_transmission", "KHR_materials_volume"]
    doc["nodes"][0]["scale"] = [scale] * 3
    path.write_text(json.dumps(doc))
    return path


def _load_with_warnings(path):
    from lobeview.scenes.gltf_loader import load_gltf

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_gltf(path)
    return scene, "\n".join(str(w.message) for w in caught)


def test_the_loader_reads_the_volume(tmp_path):
    volume = {"thicknessFactor": 0.5, "attenuationColor": [0.9, 0.8, 0.7], "attenuationDistance": 2.0}
    scene, messages = _load_with_warnings(_volume_gltf(tmp_path / "a", volume))
    desc = scene.materials[0].desc
    assert desc["thickness"] == 0.5 and desc["attenuation_color"] == [0.9, 0.8, 0.7]
    assert desc["attenuation_distance"] == 2.0 and desc["transmission"] == 1.0
    assert scene.objects[0].volume_scale == pytest.approx(2.0)
    assert "thin-walled" not in messages
    # A negative distance: warned, no attenuation; thickness 0: thin-walled, nothing kept.
    scene, messages = _load_with_warnings(_volume_gltf(tmp_path / "b", {"thicknessFactor": 0.5,
                                                                        "attenuationDistance": -1}))  # fmt: skip
    assert "attenuation_distance" not in scene.materials[0].desc and "attenuationDistance" in messages
    scene, _ = _load_with_warnings(_volume_gltf(tmp_path / "c", {"thicknessFactor": 0}))
    assert "thickness" not in scene.materials[0].desc
    # The uniforms: thickness in world units (x the node's scale), the middle extent (the quad's 2 x 2).
    from lobeview.viewer.shading import volume_uniforms

    scene, _ = _load_with_warnings(_volume_gltf(tmp_path / "d", volume))
    obj = scene.objects[0]
    (thickness, extent, ior, inverse_distance), colour = volume_uniforms(
        volume_of(scene.materials[0].desc), obj.mesh.positions, obj.volume_scale
    )
    assert (thickness, extent, ior, inverse_distance) == pytest.approx((1.0, 2.0, 1.5, 0.5))
    assert colour == pytest.approx((0.9, 0.8, 0.7))


def _smooth_sky(d):
    """Radiance varying smoothly over the sphere (every direction distinct in colour), so that
    an inverted or shifted image behind the ball shows as an error."""
    d = np.asarray(d, dtype=np.float64)
    return (0.6 + 0.35 * d[..., 1:2] * np.array([1.0, 0.8, 0.5]) + 0.25 * d[..., 0:1] * np.array([0.2, 0.6, 1.0])
            + 0.15 * d[..., 2:3] * np.array([0.9, 0.3, 0.4]))  # fmt: skip


def _glass_ball_scene(folder, thickness: float):
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.scenes.scene import Scene, SceneCamera, SceneMaterial, SceneObject

    glass = {"model": "gltf", "base_color": [1, 1, 1], "metallic": 0, "roughness": 0.0, "transmission": 1.0,
             "ior": 1.5}  # fmt: skip
    if thickness > 0:
        glass["thickness"] = thickness
    scene = Scene(
        objects=[SceneObject("ball", uv_sphere(0.5, 96, 192), 0)],
        materials=[SceneMaterial("glass", validate(glass))],
        cameras=[SceneCamera("front", np.array(BALL_CAMERA[0]), np.zeros(3), np.array([0, 1.0, 0]), BALL_CAMERA[1])],
    )
    return write_glb(scene, folder / f"ball-{thickness}.glb")


BALL_CAMERA = ((0.3, 0.4, 2.6), 30.0)  # position, vertical field of view (degrees); looking at the origin


def _traced_ball(size: int, sky, camera=BALL_CAMERA, radius: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A glass ball (``radius``, ior 1.5, at the origin) ray traced in numpy from ``camera``
    (position, vertical fov; looking at the origin): Schlick reflection (f0 0.04) plus the ray
    refracted in and out of the real sphere, (1 - F)^2 of it; and the pixels well inside the
    silhouette (the mask)."""
    eye = np.array(camera[0], dtype=np.float64)
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    half = np.tan(np.radians(camera[1]) / 2)
    image, mask = np.zeros((size, size, 3)), np.zeros((size, size), bool)
    for row in range(size):
        for col in range(size):
            x, y = (2 * (col + 0.5) / size - 1) * half, (1 - 2 * (row + 0.5) / size) * half
            d = forward + x * right + y * up
            d /= np.linalg.norm(d)
            b = np.dot(eye, d)
            disc = b * b - (np.dot(eye, eye) - radius * radius)
            if disc <= 0:
                continue
            p = eye + (-b - np.sqrt(disc)) * d
            n = p / radius
            cos_i = -np.dot(d, n)
            mask[row, col] = cos_i > 0.35  # leave the rim, where a pixel spans much of the ball
            fresnel = 0.04 + 0.96 * (1 - cos_i) ** 5
            reflected = d + 2 * cos_i * n
            inside = _refract(d, n, 1 / 1.5)
            q = _sphere_exit(p, inside, np.zeros(3), radius)
            out = _refract(inside, -q / radius, 1.5)
            image[row, col] = fresnel * sky(reflected) + (1 - fresnel) ** 2 * sky(out)
    return image, mask


@pytest.mark.parametrize("method", ["lobe-7", "fis-8", "prefiltered", "reference"])
def test_a_glass_ball_renders_as_a_ray_tracer_sees_it(tmp_path, method):
    """Through the pipeline (cube map, lobes, the volume path): the ball's image against the numpy
    ray tracer within 2 % relative RMSE; the thin-walled rendering of the same ball is far off
    (the image behind a ball is inverted, a thin wall shows it upright)."""
    from lobeview.app.cli import main
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.hdrio import write_hdr_image

    size = 48
    env = EnvironmentMap.from_function(_smooth_sky, height=256)
    write_hdr_image(tmp_path / "sky.exr", env.image)
    truth, mask = _traced_ball(size, env.lookup)
    errors = {}
    for thickness in (1.0, 0.0):
        out = tmp_path / f"ball-{thickness}.npy"
        argv = ["shot", str(_glass_ball_scene(tmp_path, thickness)), "--env", str(tmp_path / "sky.exr"),
                "--size", f"{size}x{size}", "--method", method, "--out", str(out), "--face-size", "128",
                "--cache", str(tmp_path / "cache")]  # fmt: skip
        if method == "reference":
            argv += ["--spp", "32"]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # no lightmap: the irradiance fallback is warned
            assert main(argv) == 0
        image = np.load(out)[..., :3]
        errors[thickness] = np.sqrt(np.mean((image[mask] - truth[mask]) ** 2)) / np.sqrt(np.mean(truth[mask] ** 2))
    assert errors[1.0] < 0.02, errors
    assert errors[0.0] > 3 * errors[1.0], errors


def test_a_thickness_beyond_the_object_is_its_diagonal(tmp_path):
    from lobeview.viewer.shading import volume_uniforms

    scene, _ = _load_with_warnings(_volume_gltf(tmp_path, {"thicknessFactor": 1e6}, scale=1.0))
    obj = scene.objects[0]
    (thickness, extent, _, _), _ = volume_uniforms(volume_of(scene.materials[0].desc), obj.mesh.positions)
    assert thickness == pytest.approx(np.sqrt(2.0)) and extent == pytest.approx(1.0)  # the unit quad


def test_the_object_preview_renders_the_volume_too():
    """`shot --object sphere --material` with a thickness: the preview's unit sphere as a glass
    ball (thickness 2, its diameter) against the numpy ray tracer, and thin-walled without it."""
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    size, camera = 40, ((0.0, 0.5, 4.0), 35.0)
    env = EnvironmentMap.from_function(_smooth_sky, height=256)
    truth, mask = _traced_ball(size, env.lookup, camera, radius=1.0)
    glass = {"model": "gltf", "base_color": [1, 1, 1], "metallic": 0, "roughness": 0.0, "transmission": 1.0}
    ctx = create_headless_context()
    errors = {}
    try:
        renderer = PreviewRenderer(ctx, env, uv_sphere(rings=96, segments=192), size=(size, size), face_size=128)
        view = Camera(camera[0], (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), camera[1])
        for thickness in (2.0, 0.0):
            desc = validate({**glass, "thickness": thickness} if thickness else glass)
            image = renderer.render(view, build_bsdf(desc), "lobe-7").radiance
            errors[thickness] = np.sqrt(np.mean((image[mask] - truth[mask]) ** 2)) / np.sqrt(np.mean(truth[mask] ** 2))
        renderer.release()
    finally:
        ctx.release()
    assert errors[2.0] < 0.02 and errors[0.0] > 3 * errors[2.0], errors
