"""The blur stack (materials/blur_stack.py, viewer/blur_stack_gpu.py, shaders/blur_stack.*): its
exact blur against the von Mises-Fisher closed form, its layout and reads in numpy, the GPU's
build against the exact blur of the cube's own texels. The shader's reads against the numpy
twin: tests/test_render_vs_numpy.py (lobe-N+norm+fit in the preview)."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.bench import blur_stack as bench_blur_stack
from lobeview.core.cube_layout import direction_to_face, face_directions, face_point_directions, texel_solid_angles
from lobeview.core.methods import Method
from lobeview.materials import blur_stack as bs


def _sphere_quadrature(height: int = 128):
    theta = np.pi * (np.arange(height) + 0.5) / height
    phi = 2.0 * np.pi * (np.arange(2 * height) + 0.5) / (2 * height)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    solid = (np.sin(t) * (np.pi / height) ** 2).reshape(-1)
    return dirs, solid


@pytest.mark.parametrize("degrees", [6.0, 20.0, 60.0])
def test_vmf_blur_of_a_linear_environment_is_the_mean_resultant(degrees):
    # For the vMF density exp(kappa mu.x) on the sphere E[x] = (coth kappa - 1 / kappa) mu: the blur
    # of L(d) = a.d around an axis is that factor times a.axis.
    dirs, solid = _sphere_quadrature()
    a = np.array([0.3, -0.5, 0.8])
    radiance = (dirs @ a)[:, None]
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    sigma = np.radians(degrees)
    kappa = 1.0 / sigma**2
    factor = 1.0 / np.tanh(kappa) - 1.0 / kappa
    blurred = bs.vmf_blur(axes, np.full(20, sigma), dirs, solid, radiance)[:, 0]
    np.testing.assert_allclose(blurred, factor * (axes @ a), atol=2e-3)


def test_stack_layers_are_sqrt2_apart_from_their_first_sigma():
    sigmas = bs.stack_sigmas()
    assert np.degrees(sigmas[0]) == pytest.approx(bs.SIGMA0_TEXELS * 90.0 / bs.STACK_FACE)
    np.testing.assert_allclose(sigmas[1:] / sigmas[:-1], np.sqrt(2.0))
    assert np.degrees(sigmas[-1]) > 60.0  # wider than any lobe's widest read


def test_the_face_of_a_read_inverts_the_cube_layout():
    # read_layer's face and face coordinates (core/cube_layout.py direction_to_face)
    rng = np.random.default_rng(5)
    for face in range(6):
        sc, tc = rng.uniform(-0.999, 0.999, size=(2, 200))
        got_face, got_sc, got_tc = direction_to_face(face_point_directions(face, sc, tc))
        assert np.all(got_face == face)
        np.testing.assert_allclose(got_sc, sc, atol=1e-12)
        np.testing.assert_allclose(got_tc, tc, atol=1e-12)


def test_a_read_at_a_texel_centre_is_the_texel_and_layers_blend_in_variance():
    rng = np.random.default_rng(7)
    size = bs.STACK_FACE + 2 * bs.STACK_PAD
    stack = rng.uniform(0.5, 2.0, size=(bs.STACK_LAYERS, 6, size, size, 3))
    for face in (0, 3, 5):
        centres = bs.padded_face_directions(face)[bs.STACK_PAD : -bs.STACK_PAD, bs.STACK_PAD : -bs.STACK_PAD]
        got = bs.read_layer(stack, 4, centres.reshape(-1, 3)).reshape(bs.STACK_FACE, bs.STACK_FACE, 3)
        inner = stack[4, face, bs.STACK_PAD : -bs.STACK_PAD, bs.STACK_PAD : -bs.STACK_PAD]
        np.testing.assert_allclose(got, inner, rtol=1e-9)
    sigmas = bs.stack_sigmas()
    axis = np.array([[0.3, 0.4, 0.866]])
    halfway = np.sqrt(0.5 * (sigmas[2] ** 2 + sigmas[3] ** 2))
    expected = 0.5 * (bs.read_layer(stack, 2, axis) + bs.read_layer(stack, 3, axis))
    np.testing.assert_allclose(bs.read_stack(stack, axis, halfway), expected, rtol=1e-12)
    np.testing.assert_allclose(bs.read_stack(stack, axis, 10.0), bs.read_layer(stack, bs.STACK_LAYERS - 1, axis))
    np.testing.assert_allclose(bs.read_stack(stack, axis, 1e-3), bs.read_layer(stack, 0, axis))


def test_a_layer_of_a_constant_environment_stays_constant():
    dirs, solid = _sphere_quadrature(32)
    stack = bs.exact_stack(dirs, solid, np.full((len(dirs), 3), 2.5), layers=2)
    np.testing.assert_allclose(stack, 2.5, rtol=1e-6)


def test_the_gpu_build_matches_the_exact_blur_of_the_cubes_texels():
    from lobeview.bench.lobe_kernel import sunless_sky
    from lobeview.viewer.blur_stack_gpu import read_blur_stack
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.cubemap import RadianceCube

    face = 48
    faces = np.stack([sunless_sky(face_directions(f, face, 2)).mean(axis=2) for f in range(6)])
    ctx = create_headless_context()
    try:
        cube = RadianceCube(ctx, faces)
        gpu = read_blur_stack(cube.blur_stack())
        assert cube.blur_stack() is cube.blur_stack()  # built once
        width, height, layers = cube.blur_stack().size
        assert width * height * layers * 16 == bs.STACK_BYTES  # what the benches' memory column counts
        cube.release()
    finally:
        ctx.release()
    dirs = np.concatenate([face_directions(f, face).reshape(-1, 3) for f in range(6)])
    solid = np.tile(texel_solid_angles(face).reshape(-1), 6)
    radiance = faces.reshape(-1, 3).astype(np.float64)
    sigmas = bs.stack_sigmas()
    for layer in (0, 3, 6, 9):
        exact = np.stack(
            [
                bs.vmf_blur(axes := bs.padded_face_directions(f).reshape(-1, 3), bs.texel_blur(sigmas[layer], axes),
                            dirs, solid, radiance).reshape(gpu.shape[2:])
                for f in range(6)
            ]
        )  # fmt: skip
        error = np.sqrt(np.mean((gpu[layer] - exact) ** 2) / np.mean(exact**2))
        assert error < 0.015, (layer, error)  # 128^2 faces: 0.3-1.0 % (shaders/blur_stack.comp)


def test_the_bench_reads_the_same_stack_as_the_renderer():
    # bench/blur_stack.py measures the layout and reads the renderer uses, not a copy of them
    assert bench_blur_stack.stack_sigmas is bs.stack_sigmas and bench_blur_stack.vmf_blur is bs.vmf_blur


def spheres_in_a_scene(ctx, cases, env, size, face_size=32, rings=32, spacing=2.2):
    """A SceneRenderer of one unit sphere per Mitsuba-bench case (bench/mitsuba.py material:
    'ggx:0.3', 'ggx:0.05x0.3', ...) side by side along x, ``spacing`` apart, no reflectors, no
    lightmap (the unbaked path), each with its own cube of ``face_size``."""
    import warnings

    from lobeview.bench.mitsuba import material
    from lobeview.materials.spec import validate
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    objects, materials = [], []
    for k, case in enumerate(cases):
        mesh = uv_sphere(rings=rings, segments=2 * rings)
        offset = spacing * (k - (len(cases) - 1) / 2.0)
        mesh.positions = mesh.positions + np.array([offset, 0.0, 0.0], dtype=mesh.positions.dtype)
        materials.append(SceneMaterial(case, validate(material(case))))
        objects.append(SceneObject(f"sphere {case} {k}", mesh, k))
        objects[-1].planar_reflector = False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no lightmap: the unbaked path
        return SceneRenderer(ctx, Scene(objects, materials), env, size=size, progress=False,
                             settings=RenderSettings(cube_face_size=face_size))  # fmt: skip


@pytest.fixture(scope="module")
def rough_sphere_in_a_scene():
    """A GGX 0.3 sphere under issue 45's sunless sky, in a scene (its own cube) and in the preview."""
    from lobeview.bench.lobe_kernel import sunless_sky
    from lobeview.bench.mitsuba import material
    from lobeview.materials.spec import validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    desc = validate(material("ggx:0.3"))
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(sunless_sky, height=128, name="sunless-sky")
    in_scene = spheres_in_a_scene(ctx, ["ggx:0.3"], env, (64, 64), face_size=64, rings=64)
    preview = PreviewRenderer(ctx, env, uv_sphere(rings=64, segments=128), size=(64, 64), face_size=64)
    yield in_scene, preview, desc
    in_scene.release()
    preview.release()
    ctx.release()


CAMERA = ((0.0, 0.0, 4.0), (0.0, 0.0, 0.0))


def _relative_rms(got, expected):
    return float(np.sqrt(np.mean((got - expected) ** 2) / np.mean(expected**2)))


def test_a_scene_object_reads_its_cubes_stack_as_the_preview_reads_the_environments(rough_sphere_in_a_scene):
    # The preview's lobe-N+norm+fit is the numpy twin's (tests/test_render_vs_numpy.py); a sphere in
    # a scene, its own cube of the same sky, drawn one by one with its cube's stack, must render the
    # same (0.3 % here; the chain's reads are ~6 % from the stack's on this sky: bench/blur_stack.py).
    from lobeview.materials.spec import build_bsdf
    from lobeview.viewer.camera import Camera

    in_scene, preview, desc = rough_sphere_in_a_scene
    in_scene.set_reflection_proxy(0, None)
    camera = Camera(position=CAMERA[0], target=CAMERA[1], fov_y=40.0)
    scene_frame = in_scene.render(camera, "lobe-7+norm+fit")
    preview_frame = preview.render(camera, build_bsdf(desc), "lobe-7+norm+fit", background=False)
    assert in_scene.objects[0].cube._blur_stack is not None  # built for the object's own cube
    mask = (scene_frame.object_id == 0) & preview_frame.mask
    assert _relative_rms(scene_frame.radiance[mask], preview_frame.radiance[mask]) < 0.01


def test_the_stack_is_read_through_the_reflection_proxy(rough_sphere_in_a_scene):
    # PARALLAX with BLUR_STACK (shaders/fitted.glsl): a proxy box far beyond the sphere leaves its
    # reads where they were (the proxy's hit seen from the cube's centre is the read's own
    # direction, the distance ratio 1); a room around it moves and widens them.
    from lobeview.scenes.reflection_proxy import ReflectionProxy
    from lobeview.viewer.camera import Camera

    in_scene = rough_sphere_in_a_scene[0]
    camera = Camera(position=CAMERA[0], target=CAMERA[1], fov_y=40.0)
    frames = {}
    for name, proxy in (
        ("none", None),
        ("far", ReflectionProxy.from_box([-1e4, -1e4, -1e4], [1e4, 1e4, 1e4])),
        ("room", ReflectionProxy.from_box([-1.5, -1.2, -1.5], [1.5, 3.0, 1.5])),
    ):
        in_scene.set_reflection_proxy(0, proxy)
        frames[name] = in_scene.render(camera, "lobe-7+norm+fit")
        assert not frames[name].invalid.any()
    in_scene.set_reflection_proxy(0, None)
    mask = frames["none"].object_id == 0
    plain = frames["none"].radiance[mask]
    assert _relative_rms(frames["far"].radiance[mask], plain) < 2e-3
    assert _relative_rms(frames["room"].radiance[mask], plain) > 0.02


def test_no_stack_is_built_for_lobes_the_fitted_path_does_not_read():
    # An anisotropic GGX lobe keeps the thesis pattern under +fit (materials/fitted_pattern.py
    # has_fitted_pattern): its object's cube gets no blur stack and the frame is lobe-7+norm's.
    from lobeview.bench.mitsuba import material
    from lobeview.materials.fitted_pattern import may_read_fitted
    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.material_gpu import pack_material

    anisotropic = specular_lobes(build_bsdf(validate(material("ggx:0.05x0.3"))))
    isotropic = specular_lobes(build_bsdf(validate(material("ggx:0.3"))))
    assert not may_read_fitted(anisotropic) and may_read_fitted(isotropic)
    assert may_read_fitted(anisotropic, per_pixel_lobes=True)  # a texture may make it isotropic
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(lambda d: 0.5 + 2.0 * np.clip(d[..., 1:2], 0, 1) * np.ones(3), 32)
    renderer = spheres_in_a_scene(ctx, ["ggx:0.05x0.3"], env, (48, 48))
    try:
        camera = Camera(position=CAMERA[0], target=CAMERA[1], fov_y=40.0)
        fit = renderer.render(camera, "lobe-7+norm+fit")
        assert renderer.objects[0].cube is not None and renderer.objects[0].cube._blur_stack is None
        memory = renderer.shading.method_memory(renderer.objects[0].cube, renderer.objects[0].material,
                                                Method.parse("lobe-7+norm+fit"))  # fmt: skip
        assert "blur stack" not in memory and "albedo table" in memory  # the bench counts what is built
        isotropic_bsdf = build_bsdf(validate(material("ggx:0.3")))
        memory = renderer.shading.method_memory(renderer.objects[0].cube, pack_material(isotropic_bsdf),
                                                Method.parse("lobe-7+norm+fit"))  # fmt: skip
        assert memory["blur stack"] == bs.STACK_BYTES
        plain = renderer.render(camera, "lobe-7+norm")
        mask = fit.object_id == 0
        assert mask.sum() > 300 and not fit.invalid.any()
        np.testing.assert_allclose(fit.radiance[mask], plain.radiance[mask], rtol=1e-5, atol=1e-6)
    finally:
        renderer.release()
        ctx.release()


def test_a_frame_budget_builds_stacks_over_frames_and_reads_the_chain_meanwhile():
    # The window's frames (app/window.py STACK_BUILD_BUDGET_S): a frame builds at least one missing
    # stack and stops at its budget; the other objects read their MIP chains (u_has_blur_stack off)
    # until a later frame builds theirs, and the last frame is the unbudgeted one exactly.
    from lobeview.bench.lobe_kernel import sunless_sky
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context

    ctx = create_headless_context()
    env = EnvironmentMap.from_function(sunless_sky, height=64, name="sunless-sky")
    renderer = spheres_in_a_scene(ctx, ["ggx:0.3", "ggx:0.3"], env, (96, 48))
    camera = Camera(position=(0.0, 0.0, 5.0), target=(0.0, 0.0, 0.0), fov_y=40.0)
    try:
        frames, pending = [], []
        for _ in range(3):
            renderer.shading.stack_budget(0.0)  # one build a frame
            frames.append(renderer.render(camera, "lobe-7+norm+fit").radiance[..., :3].astype(np.float64))
            pending.append(renderer.shading.stacks_pending)
            built = [obj.cube is not None and obj.cube.has_blur_stack for obj in renderer.objects]
        assert pending == [1, 0, 0] and all(built), pending
        # the multi-draws' stack arrays: the first frame's array had room for the stack built later
        stacks = renderer.drawer.lobe_batches.stacks
        assert len(stacks.arrays) == 1 and stacks.copies == 2
        renderer.shading.stack_budget(None)
        exact = renderer.render(camera, "lobe-7+norm+fit").radiance[..., :3].astype(np.float64)
        ids = renderer.render(camera, "lobe-7+norm+fit").object_id
        assert np.all(np.isfinite(frames[0]))
        np.testing.assert_array_equal(frames[-1], exact)
        # the first frame: one sphere read its stack, the other its chain (a few % apart on this sky)
        errors = [_relative_rms(frames[0][ids == k], exact[ids == k]) for k in (0, 1)]
        assert min(errors) == 0.0 and 0.005 < max(errors) < 0.2, errors
    finally:
        renderer.release()
        ctx.release()
