"""Any scene scale renders the same (issue 16, item 5): near/far planes fitted to the scene,
walking speed from its size. A scene authored in millimetres or kilometres (CornellBox is
556 units across) used to render as sky only behind fixed 0.05/200 clip planes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lobeview.app.walk import walk_speed_for
from lobeview.scenes.mirror_scene import CAMERA, mirror_floor_scene
from lobeview.viewer.camera import DEPTH_RANGE_RATIO, Camera, fit_clip_planes

SIZE = (96, 64)


def test_clip_planes_hold_the_scene_and_its_mirror_image():
    rng = np.random.default_rng(5)
    for _ in range(200):
        scale = 10.0 ** rng.uniform(-4, 4)
        low = rng.normal(size=3) * scale
        high = low + rng.uniform(0.01, 1.0, size=3) * scale
        eye = rng.normal(size=3) * scale * rng.uniform(0.1, 20)
        near, far = fit_clip_planes(eye, low, high)
        assert 0 < near < far and far / near <= DEPTH_RANGE_RATIO * (1 + 1e-9)
        corners = np.array(np.meshgrid(*zip(low, high, strict=True))).reshape(3, -1).T
        # Every corner, seen from the eye and from the eye mirrored in a plane through the box.
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        point = low + rng.uniform(size=3) * (high - low)
        mirrored = eye - 2.0 * np.dot(eye - point, normal) * normal
        for viewpoint in (eye, mirrored):
            assert np.linalg.norm(corners - viewpoint, axis=1).max() < far
        # Outside the box: nothing of the scene lies before the near plane.
        closest = np.linalg.norm(eye - np.clip(eye, low, high))
        assert near <= max(closest, far / DEPTH_RANGE_RATIO) + 1e-12


def test_walking_speed_follows_the_scene_size():
    assert walk_speed_for((np.zeros(3), np.array([6.0, 3.0, 6.0]))) == pytest.approx(1.5)
    assert walk_speed_for((np.zeros(3), np.array([6000.0, 3.0, 6.0]))) == pytest.approx(1500.0)


def _scaled(scene, factor):
    for obj in scene.objects:
        obj.mesh = dataclasses.replace(obj.mesh, positions=(obj.mesh.positions * factor).astype(np.float32))
    return scene


def _render(ctx, factor):
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = _scaled(mirror_floor_scene(roughness=0.05), factor)
    environment = EnvironmentMap.from_function(
        lambda d: np.stack([0.5 + 0.5 * d[..., 1], np.full(d.shape[:-1], 0.6), 0.4 - 0.2 * d[..., 0]], -1),
        height=32,
        name="gradient",
    )
    renderer = SceneRenderer(
        ctx, scene, environment, size=SIZE, progress=False, settings=RenderSettings(cube_face_size=32)
    )
    try:
        camera = Camera(tuple(CAMERA.position * factor), tuple(CAMERA.target * factor), (0, 1, 0), CAMERA.fov_y)
        return renderer.render(camera, "lobe-5").radiance
    finally:
        renderer.release()


@pytest.mark.parametrize("factor", [1e-3, 1e3, 1e5])
def test_a_scene_renders_the_same_at_any_scale(ctx, factor):
    metres = _render(ctx, 1.0)
    scaled = _render(ctx, factor)
    assert np.all(np.isfinite(scaled))
    # Before the fit, 1e3 and 1e5 rendered the environment only and 1e-3 lost the geometry to
    # the near plane; now the images agree up to float32 rounding of the scaled geometry.
    differs = np.abs(scaled - metres).max(axis=-1) > 0.02 * max(float(metres.max()), 1e-6)
    assert differs.mean() < 0.01, f"{differs.mean():.1%} of the pixels differ at scale {factor}"
