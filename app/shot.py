"""``lobeview shot``: headless screenshot, a contract other tools script against.

Two modes:
- scene (default): a glTF scene with lightmaps (``SCENE``), or the built-in demo scene when
  ``SCENE`` is omitted; diffuse from lightmaps, lobes from per-object cube maps.
- object preview (``--object sphere|MESH_FILE``): one object lit only by a distant
  environment, no lightmaps; the mode for material work and exact comparisons.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from lobeview.app.options import (
    add_method_arguments,
    add_scene_arguments,
    apply_material_edits,
    apply_reflection_proxy,
    camera_from_args,
    check_scene_options,
    read_material_edits,
    resolve_method_args,
    scene_renderer_from_args,
)
from lobeview.core.errors import MAX_RENDER_EDGE, OptionError, check_output_folder, parse_size
from lobeview.core.images import box_downsample
from lobeview.core.methods import MAX_REFERENCE_SPP, PIXEL_FILTERS, Method
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.builtin_env import load_environment
from lobeview.scenes.hdrio import write_hdr_image
from lobeview.scenes.mesh_files import load_mesh_file
from lobeview.scenes.meshes import uv_sphere
from lobeview.scenes.setup import SCENE_ENV, load_scene_and_environment, scene_view
from lobeview.viewer.camera import Camera
from lobeview.viewer.context import gpu_timer_meaningful
from lobeview.viewer.preview import PREVIEW_CAMERA
from lobeview.viewer.tonemap import TONEMAPS, to_uint8, tonemap

OUTPUT_SUFFIXES = (".png", ".exr", ".npy")
MAX_SUPERSAMPLE = 8
PREVIEW_ENV = "builtin:studio"
ShotError = OptionError  # the error type the command line reports as "lobeview: error: ..."


def add_arguments(p) -> None:
    a = p.add_argument
    a(
        "scene",
        nargs="?",
        help="glTF scene (.gltf/.glb) with lightmaps, builtin:demo (default) or builtin:apartment[-ROOMS]",
    )
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
    a(
        "--fov",
        type=float,
        help="vertical field of view in degrees (default: the view's; 40 for --object, 50 for a scene without cameras)",
    )
    a("--size", default="640x400", help="image size WxH (default 640x400)")
    a(
        "--supersample",
        type=int,
        default=1,
        metavar="K",
        help="render K x K shading points a pixel (at K times --size) and average them: edges, creases "
        f"and sub-pixel highlights anti-aliased, K^2 the cost (1-{MAX_SUPERSAMPLE}, default 1; the "
        "reference's box pixel filter already integrates each pixel)",
    )
    add_method_arguments(p)
    a(
        "--spp",
        type=int,
        default=1024,
        help="samples per pixel per lobe for --method reference (default 1024)",
    )
    a(
        "--pixel-filter",
        default="box",
        choices=PIXEL_FILTERS,
        help="--method reference: 'box' (default) renders each pixel's integral, one sub-pixel position "
        "per pass (at least min(spp, 64) passes); 'point' shades the pixel centres only",
    )
    a(
        "--lod-bias",
        type=float,
        default=None,
        help="MIP level bias (default: the method's measured best, -1 for lobe-N on the tent-filtered "
        "MIP chain, -0.5 on the box chain and for fis-N; lobe-N's lobes wider than alpha 0.3 read up "
        "to 1.5 levels coarser on top of it, docs/guide.md)",
    )
    add_scene_arguments(p)
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


def _write(out: Path, radiance: np.ndarray, args) -> None:
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
    check_output_folder(out)
    if args.object is not None and args.scene is not None:
        raise ShotError("give either a SCENE or --object, not both")
    method = resolve_method_args(args)
    if not 1 <= args.spp <= MAX_REFERENCE_SPP:
        raise ShotError(f"--spp must be in [1, {MAX_REFERENCE_SPP}] (the Sobol table: more would repeat its points)")
    check_scene_options(args)
    if args.object is not None and args.materials is not None:
        raise ShotError("--materials edits a scene's materials; with --object use --material")
    size = parse_size(args.size)
    if not 1 <= args.supersample <= MAX_SUPERSAMPLE:
        raise ShotError(f"--supersample must be in [1, {MAX_SUPERSAMPLE}], got {args.supersample}")
    if max(size) * args.supersample > MAX_RENDER_EDGE:
        raise ShotError(
            f"--size {args.size} at --supersample {args.supersample} renders "
            f"{size[0] * args.supersample}x{size[1] * args.supersample}: over {MAX_RENDER_EDGE} pixels a side"
        )
    size = (size[0] * args.supersample, size[1] * args.supersample)  # the render's; the image is /K
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
    _write(out, box_downsample(result.radiance, args.supersample), args)
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
    pixel_filter: str = "box",
    supersample: int = 1,
) -> None:
    extra = f", {samples} spp per lobe, {pixel_filter} pixel filter" if method.kind == "reference" else ""
    if supersample > 1:
        shown = f"{size[0] // supersample}x{size[1] // supersample} ({supersample}x{supersample} supersampled)"
    else:
        shown = f"{size[0]}x{size[1]}"
    print(f"rendered {what}, {shown}, method {method}{extra}")
    print(f"device: {describe(ctx)}")
    print(f"camera: {camera.describe()}")
    print("stages: " + ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in stages.items()))
    print(f"wrote {out}")


def _run_preview(args, out, method, size, stages, t0, create_context, describe) -> int:
    from lobeview.viewer.preview import PreviewRenderer

    bsdf = build_bsdf(load_material(args.material))
    env = load_environment(args.env or PREVIEW_ENV)
    mesh = uv_sphere() if args.object == "sphere" else load_mesh_file(args.object)
    if str(args.object).lower().endswith((".gltf", ".glb")):
        import shlex

        own = Path(out).with_name(Path(out).stem + "_own_materials.png")
        print(
            f"--object renders the file's geometry with --material {args.material}; "
            f"`lobeview shot {shlex.quote(str(args.object))} --out {shlex.quote(str(own))}` renders it with its "
            "own materials and textures"
        )
    if args.object != "sphere":
        lo, hi = mesh.bounds
        mesh.positions = ((mesh.positions - (lo + hi) / 2) / max(float(np.max(hi - lo)) / 2, 1e-9)).astype(np.float32)
    camera = camera_from_args(args, PREVIEW_CAMERA)
    stages["load"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ctx = create_context()
    args.gpu_timer = gpu_timer_meaningful(describe(ctx))
    renderer = PreviewRenderer(
        ctx,
        env,
        mesh,
        size=size,
        face_size=args.face_size,
        mip_filter=args.mip_filter,
        bright_sources=bool(getattr(args, "bright_sources", True)),
    )
    stages["cube maps"] = time.perf_counter() - t0
    result = renderer.render(
        camera,
        bsdf,
        method,
        spp=args.spp,
        lod_bias=args.lod_bias,
        background=not args.no_background,
        pixel_filter=args.pixel_filter,
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
        args.pixel_filter,
        args.supersample,
    )
    renderer.release()
    ctx.release()
    return 0


def _run_scene(args, out, method, size, stages, t0, create_context, describe) -> int:
    edits = read_material_edits(args.materials, args.limits) if args.materials is not None else None
    path, scene, env, cache = load_scene_and_environment(args.scene, args.env, args.cache, args.limits)
    if edits is not None:
        changed = apply_material_edits(scene, edits)
        print(f"materials from {args.materials}: {', '.join(changed) or 'no changes'}")
    apply_reflection_proxy(scene, args.reflection_proxy)
    camera = camera_from_args(args, scene_view(scene, args.view))
    stages["load"] = time.perf_counter() - t0
    ctx = create_context()
    args.gpu_timer = gpu_timer_meaningful(describe(ctx))
    renderer = scene_renderer_from_args(ctx, scene, env, size, cache, args, method)
    print(renderer.analysis.report())
    result = renderer.render(camera, method, spp=args.spp, lod_bias=args.lod_bias, pixel_filter=args.pixel_filter)
    for line in renderer.mirror_report:
        print(f"[mirror] {line}")
    for line in renderer.draw_report:
        print(f"[draw] {line}")
    print(f"[cube] {renderer.probes.residency.report(renderer.objects)}")
    _finish(result, out, args, stages)
    what = f"{'the demo scene' if args.scene is None else path.name} under {env.name}"
    _report(what, method, size, result.samples_per_pixel, ctx, camera, stages, out, describe, args.pixel_filter,
            args.supersample)  # fmt: skip
    renderer.release()
    ctx.release()
    return 0
