"""``lobeview shot``: headless screenshot, a contract other tools script against.

Two modes:
- scene (default): a glTF scene with lightmaps (``SCENE``), or the built-in demo scene when
  ``SCENE`` is omitted; diffuse from lightmaps, lobes from per-object cube maps.
- object preview (``--object sphere|MESH_FILE``): one object lit only by a distant
  environment, no lightmaps; the mode for material work and exact comparisons.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.builtin_env import load_environment
from lobeview.scenes.hdrio import write_hdr_image
from lobeview.scenes.meshes import load_mesh_file, uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import gpu_timer_meaningful
from lobeview.viewer.render_base import Method
from lobeview.viewer.tonemap import TONEMAPS, to_uint8, tonemap

OUTPUT_SUFFIXES = (".png", ".exr", ".npy")
PREVIEW_ENV = "builtin:studio"
SCENE_ENV = "builtin:overcast"
PREVIEW_CAMERA = ((0.0, 0.35, 3.2), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0)


class ShotError(ValueError):
    pass


def parse_vec3(text: str, name: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ShotError(f"{name}: expected X,Y,Z numbers, got {text!r}") from None
    if len(values) != 3 or not all(np.isfinite(values)):
        raise ShotError(f"{name}: expected three finite numbers X,Y,Z, got {text!r}")
    return values


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ShotError(f"--size: expected WxH, got {text!r}") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise ShotError(f"--size: width and height must be in [1, 8192], got {text!r}")
    return w, h


def add_arguments(p) -> None:
    a = p.add_argument
    a("scene", nargs="?", help="glTF scene (.gltf/.glb) with lightmaps; omitted: the built-in demo")
    a(
        "--env",
        help="equirectangular .exr/.hdr or builtin:studio|sky|overcast "
        f"(default {SCENE_ENV} for scenes, {PREVIEW_ENV} for --object)",
    )
    a(
        "--object",
        help="object preview instead of a scene: 'sphere' or a mesh file (OBJ/PLY/STL/glTF)",
    )
    a(
        "--material",
        default="alanod-2000gs-1lobe",
        help="--object material: preset, JSON file or inline JSON (default alanod-2000gs-1lobe)",
    )
    a("--view", help="scene camera by name or index (default: the scene's first camera)")
    a("--camera", help="camera position X,Y,Z (overrides --view)")
    a("--target", default="0,0,0", help="look-at point X,Y,Z (default origin)")
    a("--up", default="0,1,0", help="up vector X,Y,Z (default 0,1,0)")
    a("--fov", type=float, help="vertical field of view in degrees (default: the view's, or 40)")
    a("--size", default="640x400", help="image size WxH (default 640x400)")
    a("--method", default="lobe-11", help="lobe-N | fis-N | mc-N | reference (default lobe-11)")
    a(
        "--spp",
        type=int,
        default=1024,
        help="samples per pixel per lobe for --method reference (default 1024)",
    )
    a(
        "--lod-bias",
        type=float,
        default=None,
        help="MIP level bias (default: -0.5 for fis-N and lobe-N, measured by lobeview bench)",
    )
    a(
        "--lobe-normalize",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="lobe-N: rescale Eq. 4.25 by each lobe's directional albedo, exact under uniform light"
        " (default on; --no-lobe-normalize: Eq. 4.25 as printed)",
    )
    a("--face-size", type=int, default=256, help="cube-map face resolution (default 256)")
    a(
        "--reflection-proxy",
        choices=("scene", "none", "floor", "room"),
        default="scene",
        help="cube-map lookup correction for every glossy object (thesis 4.4.1): floor = bounding plane at "
        "the scene's lowest point, room = box-projected to the scene bounds, none = distant lookup; "
        "default 'scene': what each node's extras say (none if unset)",
    )
    a(
        "--mirrors",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="planar mirror passes for the reflectors the scene analysis lists (thesis 4.5; default on;"
        " --no-mirrors: cube maps for every object)",
    )
    a(
        "--mirror-scale",
        type=float,
        default=1.0,
        help="mirror-buffer resolution relative to the frame, 0.05..2 (default 1)",
    )
    a(
        "--cache",
        help="cache folder for the demo scene and cube maps (default ~/.cache/lobeview or $LOBEVIEW_CACHE)",
    )
    a("--tonemap", default="aces", choices=TONEMAPS, help="PNG tonemap (default aces)")
    a("--exposure", type=float, default=0.0, help="exposure in stops for PNG output (default 0)")
    a(
        "--no-background",
        action="store_true",
        help="--object: black instead of the environment behind the object",
    )
    a(
        "--out",
        required=True,
        help="output file: .png (tonemapped sRGB) or .exr/.npy (linear radiance)",
    )


def _camera_from_args(args, default) -> Camera:
    position, target, up, fov = default
    if args.camera is not None:
        position = parse_vec3(args.camera, "--camera")
        target = parse_vec3(args.target, "--target")
        up = parse_vec3(args.up, "--up")
    if args.fov is not None:
        fov = args.fov
    if not 1.0 <= fov <= 170.0:
        raise ShotError(f"--fov must be in [1, 170] degrees, got {fov}")
    camera = Camera(position=tuple(position), target=tuple(target), up=tuple(up), fov_y=fov)
    camera.view()  # validates position != target and up not parallel
    return camera


def _scene_view(scene, view: str | None):
    if not scene.cameras:
        lo, hi = scene.bounds
        centre = (lo + hi) / 2
        eye = centre + np.array([0.0, 0.25, 1.2]) * float(np.max(hi - lo))
        return (tuple(eye), tuple(centre), (0.0, 1.0, 0.0), 50.0)
    if view is None:
        cam = scene.cameras[0]
    elif view.isdigit() and int(view) < len(scene.cameras):
        cam = scene.cameras[int(view)]
    else:
        matches = [c for c in scene.cameras if c.name == view]
        if not matches:
            raise ShotError(f"--view: no camera {view!r}; the scene has {[c.name for c in scene.cameras]}")
        cam = matches[0]
    return (tuple(cam.position), tuple(cam.target), tuple(cam.up), cam.fov_y)


def _write(out: Path, radiance: np.ndarray, args) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".png":
        from PIL import Image

        Image.fromarray(to_uint8(tonemap(radiance, args.tonemap, args.exposure))).save(out)
    elif out.suffix.lower() == ".exr":
        write_hdr_image(out, radiance)
    else:
        np.save(out, radiance.astype(np.float32))


def run(args) -> int:
    from lobeview.viewer.context import create_headless_context, renderer_description

    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise ShotError(f"--out: unsupported output type {out.suffix!r}; use {', '.join(OUTPUT_SUFFIXES)}")
    if args.object is not None and args.scene is not None:
        raise ShotError("give either a SCENE or --object, not both")
    method = Method.parse(args.method)
    if method.kind == "lobe":
        method = dataclasses.replace(method, normalize=args.lobe_normalize)
    if args.spp < 1:
        raise ShotError("--spp must be at least 1")
    if not 8 <= args.face_size <= 2048 or args.face_size & (args.face_size - 1):
        raise ShotError(f"--face-size must be a power of two in [8, 2048], got {args.face_size}")
    size = parse_size(args.size)
    args.gpu_timer = False
    stages = {}
    t0 = time.perf_counter()
    if args.object is not None:
        return _run_preview(args, out, method, size, stages, t0, create_headless_context, renderer_description)
    return _run_scene(args, out, method, size, stages, t0, create_headless_context, renderer_description)


def _finish(result, out: Path, args, stages: dict) -> None:
    # The GL timer is reported only where it measures the GPU's work (not on llvmpipe).
    stages.update({k: v for k, v in result.timings.items() if k != "gpu shade" or args.gpu_timer})
    if result.invalid.any():
        print(f"warning: {int(result.invalid.sum())} pixels produced NaN/Inf and were set to 0", file=sys.stderr)
    t0 = time.perf_counter()
    _write(out, result.radiance, args)
    stages["write"] = time.perf_counter() - t0


def _report(
    what: str,
    method: Method,
    size,
    samples: int,
    ctx,
    camera: Camera,
    stages: dict,
    out: Path,
    describe,
) -> None:
    extra = f", {samples} spp per lobe" if method.kind == "reference" else ""
    print(f"rendered {what}, {size[0]}x{size[1]}, method {method}{extra}")
    print(f"device: {describe(ctx)}")
    print(f"camera: {camera.describe()}")
    print("stages: " + ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in stages.items()))
    print(f"wrote {out}")


def _run_preview(args, out, method, size, stages, t0, create_context, describe) -> int:
    from lobeview.viewer.preview import PreviewRenderer

    bsdf = build_bsdf(load_material(args.material))
    env = load_environment(args.env or PREVIEW_ENV)
    mesh = uv_sphere() if args.object == "sphere" else load_mesh_file(args.object)
    if args.object != "sphere":
        lo, hi = mesh.bounds
        mesh.positions = ((mesh.positions - (lo + hi) / 2) / max(float(np.max(hi - lo)) / 2, 1e-9)).astype(np.float32)
    camera = _camera_from_args(args, PREVIEW_CAMERA)
    stages["load"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ctx = create_context()
    args.gpu_timer = gpu_timer_meaningful(describe(ctx))
    renderer = PreviewRenderer(ctx, env, mesh, size=size, face_size=args.face_size)
    stages["cube maps"] = time.perf_counter() - t0
    result = renderer.render(
        camera,
        bsdf,
        method,
        spp=args.spp,
        lod_bias=args.lod_bias,
        background=not args.no_background,
    )
    _finish(result, out, args, stages)
    _report(
        f"{args.object} with {args.material} under {env.name}",
        method,
        size,
        result.samples_per_pixel,
        ctx,
        camera,
        stages,
        out,
        describe,
    )
    renderer.release()
    ctx.release()
    return 0


def load_scene_and_environment(scene_arg: str | None, env_arg: str | None, cache_arg: str | None):
    """(scene path, Scene, EnvironmentMap, cache folder) for ``shot`` and ``view``: the demo
    (built and cached on first use) when no scene is given, with the matching default sky."""
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene, cache_dir
    from lobeview.scenes.gltf_loader import load_gltf

    cache = Path(cache_arg) if cache_arg else cache_dir()
    if scene_arg is None:
        path = build_demo_scene(directory=cache / "demo")
        env_name = env_arg or DEMO_ENVIRONMENT
    else:
        path = Path(scene_arg)
        env_name = env_arg or SCENE_ENV
    return path, load_gltf(path), load_environment(env_name), cache


def scene_renderer_from_args(ctx, scene, env, size, cache, args):
    """The SceneRenderer of ``shot`` and ``view``: cube-map size, cache and mirror-pass options."""
    from lobeview.viewer.scene_renderer import SceneRenderer

    renderer = SceneRenderer(
        ctx,
        scene,
        env,
        size=size,
        cube_face_size=args.face_size,
        cache_dir=cache / "cubes",
        mirror_scale=args.mirror_scale,
    )
    renderer.mirrors_enabled = args.mirrors
    return renderer


def apply_reflection_proxy(scene, choice: str) -> None:
    """``--reflection-proxy``: override every object's proxy unless the choice is 'scene'."""
    from lobeview.scenes.reflection_proxy import ReflectionProxy

    if choice == "scene":
        return
    proxy = ReflectionProxy.from_description({"type": choice}, scene.bounds)
    for obj in scene.objects:
        obj.reflection_proxy = proxy


def _run_scene(args, out, method, size, stages, t0, create_context, describe) -> int:
    path, scene, env, cache = load_scene_and_environment(args.scene, args.env, args.cache)
    apply_reflection_proxy(scene, args.reflection_proxy)
    camera = _camera_from_args(args, _scene_view(scene, args.view))
    stages["load"] = time.perf_counter() - t0
    ctx = create_context()
    args.gpu_timer = gpu_timer_meaningful(describe(ctx))
    if not 0.05 <= args.mirror_scale <= 2.0:
        raise ShotError(f"--mirror-scale must be in [0.05, 2], got {args.mirror_scale}")
    renderer = scene_renderer_from_args(ctx, scene, env, size, cache, args)
    print(renderer.analysis.report())
    result = renderer.render(camera, method, spp=args.spp, lod_bias=args.lod_bias)
    for line in renderer.mirror_report:
        print(f"[mirror] {line}")
    _finish(result, out, args, stages)
    what = f"{'the demo scene' if args.scene is None else path.name} under {env.name}"
    _report(what, method, size, result.samples_per_pixel, ctx, camera, stages, out, describe)
    renderer.release()
    ctx.release()
    return 0
