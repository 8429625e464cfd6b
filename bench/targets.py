"""What the benchmark renders (the preview sphere, the demo scene from a camera) and how a frame
is timed."""

from __future__ import annotations

import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.core.methods import Method

from . import BenchError
from .matrix_config import SHARED_ENV_DIR, SPHERE_ENVS


def parse_method(text: str) -> Method:
    try:
        return Method.parse(text)
    except ValueError as exc:
        raise BenchError(f"--methods: {exc}") from None


def resolve_environment(name: str):
    """sphere/ENV: a named shared capture (falls back to a built-in sky when the shared assets
    are absent), builtin:NAME, or a file."""
    from lobeview.scenes.builtin_env import load_environment

    if name in SPHERE_ENVS:
        relative, fallback = SPHERE_ENVS[name]
        path = SHARED_ENV_DIR / relative if SHARED_ENV_DIR is not None else None
        if path is not None and path.exists():
            return load_environment(str(path))
        missing = path if path is not None else f"the shared assets ($LOBEVIEW_ASSETS) for sphere/{name}"
        warnings.warn(f"{missing} not found: sphere/{name} uses {fallback} instead", stacklevel=2)
        return load_environment(fallback)
    return load_environment(name)


class SphereTarget:
    """The preview sphere under a distant environment (no lightmaps)."""

    def __init__(self, ctx, env_name: str, size, face_size: int):
        from lobeview.scenes.meshes import uv_sphere
        from lobeview.viewer.camera import Camera
        from lobeview.viewer.preview import (
            PREVIEW_CAMERA,  # the camera of `lobeview shot --object`
            PreviewRenderer,
        )

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # capture clamps (a few negative texels) are not news here
            env = resolve_environment(env_name)
        self.env_label = Path(env.name).name
        self.renderer = PreviewRenderer(ctx, env, uv_sphere(), size=size, face_size=face_size)
        position, target, up, fov = PREVIEW_CAMERA  # the camera of `lobeview shot --object`
        self.camera = Camera(position=position, target=target, up=up, fov_y=fov)
        self.bsdf = None
        self.packed = None

    def set_material(self, preset: str) -> None:
        from lobeview.materials.spec import build_bsdf, load_material
        from lobeview.viewer.material_gpu import pack_material

        self.bsdf = build_bsdf(load_material(preset))
        self.packed = pack_material(self.bsdf)

    def render(self, method: Method, spp: int = 1, lod_bias=None, seed: int = 0):
        return self.renderer.render(
            self.camera, self.bsdf, method, spp=spp, lod_bias=lod_bias, background=False, seed=seed
        )

    @staticmethod
    def mask_of(result) -> np.ndarray:
        return result.mask

    def memory(self, method: Method) -> int:
        return sum(self.renderer.shading.method_memory(self.renderer.cubes, self.packed, method).values())

    def release(self):
        self.renderer.release()


class DemoTarget:
    """The built-in demo scene from one of its cameras; its materials are the scene's."""

    def __init__(self, ctx, view: str, size, face_size: int, cache):
        from lobeview.scenes.setup import load_scene_and_environment, scene_view
        from lobeview.viewer.camera import Camera
        from lobeview.viewer.scene_renderer import SceneRenderer
        from lobeview.viewer.settings import RenderSettings

        _, scene, env, cache = load_scene_and_environment(None, None, cache)
        self.env_label = Path(env.name).name
        position, target, up, fov = scene_view(scene, view)
        self.camera = Camera(position=position, target=target, up=up, fov_y=fov)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # Every cube map at full size: the reference reads level 0, finer than the lobe-N
            # footprints that size the faces by default (scenes/analysis.py).
            self.renderer = SceneRenderer(
                ctx,
                scene,
                env,
                size=size,
                cache_dir=cache / "cubes",
                progress=False,
                settings=RenderSettings(cube_face_size=face_size, lobe_width_cubes=False),
            )

    def set_material(self, preset: str) -> None:  # the scene's own materials
        pass

    def render(self, method: Method, spp: int = 1, lod_bias=None, seed: int = 0):
        return self.renderer.render(self.camera, method, spp=spp, lod_bias=lod_bias, seed=seed)

    def mask_of(self, result) -> np.ndarray:
        """The view-dependent pixels: objects with a cube map."""
        return np.isin(result.object_id, self.renderer.analysis.cube_mapped)

    def memory(self, method: Method) -> int:
        total = 0
        for obj in self.renderer.objects:
            if obj.cube is not None:
                total += sum(self.renderer.shading.method_memory(obj.cube, obj.material, method).values())
        return total

    def release(self):
        self.renderer.release()


def time_frames(render, repeats: int, timer: str):
    """Call ``render()`` once as a warm-up (compiles the variant, builds maps), then ``repeats``
    times: (last result, ms by the ``timer`` in use ('gpu' or 'wall'), median GPU-timer ms or
    None, median wall ms, wall seconds of the warm-up frame)."""
    start = time.perf_counter()
    render()
    first_s = time.perf_counter() - start
    gpu, wall = [], []
    result = None
    for _ in range(max(repeats, 1)):
        result = render()
        wall.append(result.timings["shade"] * 1e3)
        if "gpu shade" in result.timings:
            gpu.append(result.timings["gpu shade"] * 1e3)
    gpu_ms = statistics.median(gpu) if gpu else None
    wall_ms = statistics.median(wall)
    return result, (gpu_ms if timer == "gpu" and gpu_ms is not None else wall_ms), gpu_ms, wall_ms, first_s
