"""``lobeview shot``: headless screenshot, a contract other tools script against.

Implemented: the object preview (``--object sphere|MESH_FILE``: one object lit only by the
environment). Scenes (glTF with lightmaps and per-object cube maps) and the built-in demo are
not implemented yet; asking for them is an error that says so.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lobeview.materials.spec import build_bsdf, load_material
from lobeview.scenes.builtin_env import load_environment
from lobeview.scenes.hdrio import write_hdr_image
from lobeview.scenes.meshes import load_mesh_file, uv_sphere
from lobeview.viewer.camera import Camera
from lobeview.viewer.preview import Method
from lobeview.viewer.tonemap import TONEMAPS, to_uint8, tonemap

OUTPUT_SUFFIXES = (".png", ".exr", ".npy")


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
    p.add_argument("scene", nargs="?", help="glTF scene (not implemented yet; use --object)")
    p.add_argument(
        "--env",
        default="builtin:studio",
        help="equirectangular .exr/.hdr, or builtin:studio|sky (default builtin:studio)",
    )
    p.add_argument("--object", help="preview object: 'sphere' or a mesh file (OBJ/PLY/STL/glTF)")
    p.add_argument(
        "--material",
        default="alanod-2000gs-1lobe",
        help="preset name, JSON file or inline JSON (default alanod-2000gs-1lobe)",
    )
    p.add_argument(
        "--camera", default="0,0.35,3.2", help="camera position X,Y,Z (default 0,0.35,3.2)"
    )
    p.add_argument("--target", default="0,0,0", help="look-at point X,Y,Z (default origin)")
    p.add_argument("--up", default="0,1,0", help="up vector X,Y,Z (default 0,1,0)")
    p.add_argument(
        "--fov", type=float, default=40.0, help="vertical field of view in degrees (default 40)"
    )
    p.add_argument("--size", default="640x400", help="image size WxH (default 640x400)")
    p.add_argument(
        "--method", default="lobe-11", help="lobe-N | fis-N | mc-N | reference (default lobe-11)"
    )
    p.add_argument(
        "--spp",
        type=int,
        default=1024,
        help="samples per pixel per lobe for --method reference (default 1024)",
    )
    p.add_argument(
        "--lod-bias",
        type=float,
        default=None,
        help="MIP level bias (default: 1 for fis-N, 0 for lobe-N)",
    )
    p.add_argument(
        "--face-size", type=int, default=256, help="cube-map face resolution (default 256)"
    )
    p.add_argument("--tonemap", default="aces", choices=TONEMAPS, help="PNG tonemap (default aces)")
    p.add_argument(
        "--exposure", type=float, default=0.0, help="exposure in stops for PNG output (default 0)"
    )
    p.add_argument(
        "--no-background",
        action="store_true",
        help="black instead of the environment behind the object",
    )
    p.add_argument(
        "--out",
        required=True,
        help="output file: .png (tonemapped sRGB) or .exr/.npy (linear radiance)",
    )


def run(args) -> int:
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.preview import PreviewRenderer

    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise ShotError(
            f"--out: unsupported output type {out.suffix!r}; use {', '.join(OUTPUT_SUFFIXES)}"
        )
    if args.scene is not None or args.object is None:
        raise ShotError(
            "scene rendering (glTF + lightmaps) and the built-in demo scene are not implemented "
            "yet; render the object preview with --object sphere (or --object MESH_FILE)"
        )
    method = Method.parse(args.method)
    if args.spp < 1:
        raise ShotError("--spp must be at least 1")
    size = parse_size(args.size)
    camera = Camera(
        position=parse_vec3(args.camera, "--camera"),
        target=parse_vec3(args.target, "--target"),
        up=parse_vec3(args.up, "--up"),
        fov_y=args.fov,
    )
    if not 1.0 <= args.fov <= 170.0:
        raise ShotError(f"--fov must be in [1, 170] degrees, got {args.fov}")
    stages = {}
    t0 = time.perf_counter()
    desc = load_material(args.material)
    bsdf = build_bsdf(desc)
    env = load_environment(args.env)
    mesh = uv_sphere() if args.object == "sphere" else load_mesh_file(args.object)
    if args.object != "sphere":
        lo, hi = mesh.bounds
        mesh.positions = (mesh.positions - (lo + hi) / 2) / max(float(np.max(hi - lo)) / 2, 1e-9)
    stages["load"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    ctx = create_headless_context()
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
    stages.update(result.timings)

    t0 = time.perf_counter()
    if result.invalid.any():
        print(f"warning: {int(result.invalid.sum())} pixels produced NaN/Inf and were set to 0")
    if out.suffix.lower() == ".png":
        from PIL import Image

        out.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(to_uint8(tonemap(result.radiance, args.tonemap, args.exposure))).save(out)
    elif out.suffix.lower() == ".exr":
        write_hdr_image(out, result.radiance)
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        np.save(out, result.radiance.astype(np.float32))
    stages["write"] = time.perf_counter() - t0

    print(
        f"rendered {args.object} with {args.material} under {env.name}, {size[0]}x{size[1]}, "
        f"method {method}"
        + (f", {result.samples_per_pixel} spp per lobe" if method.kind == "reference" else "")
    )
    print(f"device: {renderer_description(ctx)}")
    print(f"camera: {camera.describe()}")
    print("stages: " + ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in stages.items()))
    print(f"wrote {out}")
    renderer.release()
    ctx.release()
    return 0
