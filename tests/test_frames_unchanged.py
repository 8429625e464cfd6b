"""The renderer's frames do not change unless a change means them to: the demo in every method,
the apartment's geometry with its mirror passes and two textured glTF models render the radiance
stored in tests/data/stored-frames.npz.

The frames were first stored on 06d6647, before the renderer's redesign (issue 38), which left
them bit-identical; they were written again with the GGX tail fix of lobe-N+norm (issue 45),
which changed the frames of wide GGX lobes, and with lobe-N+norm+fit added (the default lobe-N
from the twenty-ninth session: lobe-11 on the demo, lobe-7 on the apartment and the models), and
with the GGX tables of 15-23 reads refitted (thirtieth session: demo/lobe-11+norm+fit moved by at
most 2e-3 on 21 values, the rest bit-identical), and with MIN_SOURCE_FACTOR (thirty-seventh session:
a hard cap fainter than 300x its cube's median stays in the cube; every demo frame moved, by
5e-4 to 2.4e-3 relative RMSE on 134-353 of its 4000 pixels, the other cases bit-identical). The
stored frames were rendered on llvmpipe; on the same GL renderer and CPU the frames must be equal
bit for bit. A different renderer (another llvmpipe build or CPU vector width, a GPU) or another
CPU rounds differently, so there the bound is a relative RMSE of 1e-3 per frame (a changed
formula or a lost texture moves a frame by more than 1e-2). A change meant to alter frames writes
them again in the same commit, with ``LOBEVIEW_WRITE_FRAMES=1 pytest
tests/test_frames_unchanged.py``, and says in its message which frames changed and why.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_ASSETS
from test_textures import _smooth_env, _textured_quad_scene

from lobeview.viewer.camera import Camera

DATA = Path(__file__).parent / "data" / "stored-frames.npz"
WRITE = os.environ.get("LOBEVIEW_WRITE_FRAMES") == "1"
SIZE = (80, 50)
OTHER_RENDERER_RELATIVE_RMSE = 1e-3

# Every method kind and option of the grammar (core/methods.py), each prefiltered mode: multi and
# rsibr on the textured quad (on the demo's lobes their maps take 60 and 95 s to make here).
DEMO_METHODS = (
    "lobe-7", "lobe-7+norm", "lobe-11+norm+fit", "lobe-11+eq4.24", "lobe-15+ring", "lobe-15+norm", "fis-8", "mc-4",
    "reference",
    "prefiltered", "prefiltered-splitsum", "prefiltered-lobe", "prefiltered-lobe2d", "prefiltered-phong",
    "prefiltered-banks",
)  # fmt: skip
QUAD_METHODS = ("lobe-5", "lobe-5+norm", "prefiltered", "prefiltered-multi", "prefiltered-rsibr", "reference")
MODEL_METHODS = ("lobe-7+norm", "lobe-7+norm+fit", "fis-8", "prefiltered", "reference")


def _spp(method: str) -> int:
    return 3 if method == "reference" else 1  # passes with their own seeds and pixel positions


def _renderer(ctx, scene, size=SIZE, **options):
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    env = EnvironmentMap.from_function(_smooth_env, height=32, name="smooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SceneRenderer(
            ctx, scene, env, size=size, progress=False, **options, settings=RenderSettings(cube_face_size=32)
        )


def _scene_camera(scene, name=None) -> Camera:
    return Camera.from_scene_camera(next(c for c in scene.cameras if name is None or c.name == name))


def _demo_scene():
    from lobeview.scenes.demo import build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf

    return load_gltf(build_demo_scene())


def _apartment_scene():
    from lobeview.scenes.apartment import apartment_geometry

    return apartment_geometry(1)


def _model(name: str):
    from lobeview.scenes.gltf_loader import load_gltf

    path = SHARED_ASSETS / "gltf" / name
    path = next(path.glob("*.glb"), None) or next(path.glob("*.gltf"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_gltf(path)


def _model_camera(scene) -> Camera:
    """A camera 2.5 bounding radii in front of the model (+z), looking at its centre."""
    points = np.concatenate([o.mesh.positions for o in scene.objects])
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    eye = centre + np.array([0.3, 0.35, 1.0]) / np.linalg.norm([0.3, 0.35, 1.0]) * 2.5 * radius
    return Camera(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), 45.0)


def _render(renderer, camera, method: str) -> np.ndarray:
    renderer.invalidate_mirrors()
    return renderer.render(camera, method, spp=_spp(method)).radiance.astype(np.float32)


def _cases():
    """(scene builder, camera maker, methods) per case; the scene is built once per case."""
    cases = {"demo": (_demo_scene, lambda s: _scene_camera(s, "overview"), DEMO_METHODS)}
    cases["apartment-1"] = (_apartment_scene, _scene_camera, ("lobe-7+norm", "lobe-7+norm+fit", "fis-8", "prefiltered",
                                                               "reference"))  # fmt: skip
    cases["textured-quad"] = (_textured_quad_scene, lambda s: Camera((0.0, 1.2, 1.4), (0, 0, 0), (0, 1, 0), 50.0),
                              QUAD_METHODS)  # fmt: skip
    cases["WaterBottle"] = (lambda: _model("WaterBottle"), _model_camera, MODEL_METHODS)
    cases["CornellBox"] = (lambda: _model("CornellBox"), _model_camera, (*MODEL_METHODS, "prefiltered-rsibr"))
    return cases


def _cpu_name() -> str:
    """The CPU's model and a digest of its feature flags: llvmpipe's JIT and the libraries that
    prepare a scene choose their code by them. The same llvmpipe on an AVX-512 AMD EPYC rendered
    WaterBottle's frames 5e-4 (relative RMSE) away from the machine that stored them."""
    try:
        info = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return "unknown CPU"
    model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), "unknown CPU")
    flags = next((line.split(":", 1)[1].split() for line in info if line.startswith("flags")), [])
    return f"{model}, flags {hashlib.sha256(' '.join(sorted(flags)).encode()).hexdigest()[:12]}"


def _renderer_name(ctx) -> str:
    return f"{ctx.info['GL_RENDERER']} | {ctx.info['GL_VERSION']} | {_cpu_name()}"


def _frames_of(ctx, case: str) -> dict[str, np.ndarray]:
    build, camera_of, methods = _cases()[case]
    scene = build()
    renderer = _renderer(ctx, scene)
    camera = camera_of(scene)
    try:
        return {f"{case}/{method}": _render(renderer, camera, method) for method in methods}
    finally:
        renderer.release()


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
def test_write_frames_when_asked(ctx):
    if not WRITE:
        pytest.skip("LOBEVIEW_WRITE_FRAMES=1 writes the stored frames")
    frames = {}
    for case in _cases():
        frames.update(_frames_of(ctx, case))
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, renderer=np.array(_renderer_name(ctx)), **frames)


@pytest.mark.skipif(WRITE, reason="writing the stored frames")
@pytest.mark.parametrize("case", list(_cases()))
def test_frames_equal_the_stored_frames(ctx, case):
    if case in ("WaterBottle", "CornellBox") and not SHARED_ASSETS.exists():
        pytest.skip("shared assets not present")
    stored = np.load(DATA)
    same_renderer = str(stored["renderer"]) == _renderer_name(ctx)
    frames = _frames_of(ctx, case)
    assert frames and set(frames) == {k for k in stored.files if k.startswith(case + "/")}
    for key, frame in frames.items():
        expected = stored[key]
        assert np.all(np.isfinite(frame)) and frame.max() > 0.01, key  # not a black or NaN frame
        if same_renderer:
            differ = np.argwhere(np.any(frame != expected, axis=-1))
            assert len(differ) == 0, (
                f"{key}: {len(differ)} pixels differ, first at {differ[0].tolist()}: "
                f"{frame[tuple(differ[0])]} against {expected[tuple(differ[0])]}"
            )
        else:
            relative_rmse = np.sqrt(np.mean((frame - expected) ** 2)) / max(np.sqrt(np.mean(expected**2)), 1e-6)
            assert relative_rmse < OTHER_RENDERER_RELATIVE_RMSE, f"{key}: relative RMSE {relative_rmse:.2e}"
