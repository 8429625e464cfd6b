"""Lamp highlights (issue 39 item 5): a generated glTF - a glossy gold floor and a white plastic
board under a KHR_lights_punctual point lamp and a spot lamp, a dim grey sky - rendered from two
cameras with lobe-7, fis-16 and prefiltered against the reference; the figure shows that the
highlights move with the camera, the table gives each method's error and time.

    python -m lobeview.bench.lamps [--size 320x200] [--spp 64] [--mitsuba]

``--mitsuba`` adds an independent check of the lamp term itself (the reference shares lobeview's
lamp integrator): a GGX floor without Fresnel under a point lamp and a black sky, against Mitsuba
3 (a sphere emitter of the same radius and radiance over a roughconductor rectangle, path tracer,
box filter, 4x4 supersampled), pixels near the bulb's own image left out (lobeview draws no lamp
geometry).

Writes bench/figures/lamp-highlights.png and bench/results/lamps-STAMP.md. The lamps are spheres
of scenes/lamps.py LAMP_RADIUS for their reflections; the floor is not baked (its diffuse light
is the sky's irradiance), so every highlight is the live lamp term."""

from __future__ import annotations

import argparse
import base64
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

SKY = 0.02  # the dim uniform sky's radiance
METHODS = ("lobe-7", "fis-16", "prefiltered")
CAMERAS = {"front": ((0.0, 1.3, 2.6), (0.0, 0.0, 0.0)), "side": ((2.0, 1.0, 1.6), (0.0, 0.0, 0.0))}


def _quad(size: float, height: float, axis: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(positions, normals, uvs, indices) of a square facing +y (``axis`` 'y', a floor at y =
    ``height``) or +z (``axis`` 'z', a board at z = ``height``)."""
    h = size / 2
    if axis == "y":
        positions = np.array([[-h, height, h], [h, height, h], [h, height, -h], [-h, height, -h]], np.float32)
        normal = [0.0, 1.0, 0.0]
    else:
        positions = np.array([[-h, 0, height], [h, 0, height], [h, size, height], [-h, size, height]], np.float32)
        normal = [0.0, 0.0, 1.0]
    normals = np.tile(np.array([normal], np.float32), (4, 1))
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    return positions, normals, uvs, np.array([0, 1, 2, 0, 2, 3], np.uint16)


def write_lamp_scene(path: Path) -> Path:
    """The bench's glTF (embedded buffer): floor, board, a point and a spot lamp."""
    meshes, accessors, views, blob = [], [], [], b""

    def add(array: np.ndarray, kind: str, component: int, target: int) -> int:
        nonlocal blob
        data = np.ascontiguousarray(array).tobytes()
        blob += b"\0" * (-len(blob) % 4)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data), "target": target})
        blob += data
        accessor = {"bufferView": len(views) - 1, "componentType": component, "count": len(array), "type": kind}
        if kind == "VEC3" and component == 5126:
            accessor.update(min=array.min(axis=0).tolist(), max=array.max(axis=0).tolist())
        accessors.append(accessor)
        return len(accessors) - 1

    for material, (size, height, axis) in enumerate(((4.0, 0.0, "y"), (1.6, -1.0, "z"))):
        positions, normals, uvs, indices = _quad(size, height, axis)
        attributes = {
            "POSITION": add(positions, "VEC3", 5126, 34962),
            "NORMAL": add(normals, "VEC3", 5126, 34962),
            "TEXCOORD_0": add(uvs, "VEC2", 5126, 34962),
        }
        meshes.append({"primitives": [{"attributes": attributes, "indices": add(indices, "SCALAR", 5123, 34963),
                                       "material": material}]})  # fmt: skip
    doc = {
        "asset": {"version": "2.0", "generator": "lobeview bench/lamps.py"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "name": "bulb", "color": [1.0, 0.85, 0.6], "intensity": 3.0},
            {"type": "spot", "name": "spot", "color": [0.6, 0.8, 1.0], "intensity": 6.0,
             "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.45}},
        ]}},
        "materials": [
            {"name": "gold floor", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 0.77, 0.34, 1.0],
                                                           "metallicFactor": 1.0, "roughnessFactor": 0.3}},
            {"name": "white plastic", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0],
                                                              "metallicFactor": 0.0, "roughnessFactor": 0.2}},
        ],
        "meshes": meshes,
        "nodes": [
            {"name": "floor", "mesh": 0},
            {"name": "board", "mesh": 1},
            {"name": "bulb", "translation": [0.4, 0.9, -0.3], "extensions": {"KHR_lights_punctual": {"light": 0}}},
            # A spot 1.5 above the floor, turned -90 degrees about x: it shines straight down.
            {"name": "spot", "translation": [-0.9, 1.5, 0.6], "rotation": [-0.7071068, 0.0, 0.0, 0.7071068],
             "extensions": {"KHR_lights_punctual": {"light": 1}}},
        ],
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "scene": 0,
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": views,
        "accessors": accessors,
    }  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1))
    return path


def main(argv: list[str] | None = None) -> int:
    from lobeview.core.errors import parse_size
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.lamps", description=__doc__.split("\n\n")[0])
    p.add_argument("--size", default="320x200", help="frame size (default 320x200)")
    p.add_argument("--spp", type=int, default=64, help="reference passes (default 64)")
    p.add_argument("--out", default=None, help="Markdown report (default bench/results/lamps-STAMP.md)")
    p.add_argument("--mitsuba", action="store_true", help="also compare a lamp-lit GGX floor with Mitsuba 3")
    args = p.parse_args(argv)
    here = Path(__file__).parent
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else here / "results" / f"lamps-{stamp}.md"
    size = parse_size(args.size)
    gltf = write_lamp_scene(here / "results" / "lamp-scene.gltf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_gltf(gltf)
    ctx = create_headless_context()
    sky = EnvironmentMap.from_function(lambda d: np.full(d.shape[:-1] + (3,), SKY), height=32, name="grey")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(ctx, scene, sky, size=size, progress=False, settings=RenderSettings())
    rows, panels = [], []
    try:
        for name, (eye, target) in CAMERAS.items():
            camera = Camera(eye, target, (0.0, 1.0, 0.0), 50.0)
            t0 = time.perf_counter()
            reference = renderer.render(camera, "reference", spp=args.spp).radiance
            reference_s = time.perf_counter() - t0
            print(f"{name}: reference {args.spp} spp in {reference_s:.1f} s", file=sys.stderr, flush=True)
            panels.append((f"{name}: reference", reference))
            norm = float(np.sqrt(np.mean(reference**2)))
            for method in METHODS:
                renderer.render(camera, method)  # compile, prefilter
                t0 = time.perf_counter()
                frame = renderer.render(camera, method).radiance
                seconds = time.perf_counter() - t0
                error = float(np.sqrt(np.mean((frame - reference) ** 2))) / max(norm, 1e-12)
                peak = np.unravel_index(np.argmax(frame.max(axis=-1)), frame.shape[:2])
                reference_peak = np.unravel_index(np.argmax(reference.max(axis=-1)), frame.shape[:2])
                rows.append((name, method, error, seconds, peak, reference_peak))
                if method == "lobe-7":
                    panels.append((f"{name}: lobe-7", frame))
        device = renderer_description(ctx)
    finally:
        renderer.release()
        ctx.release()
    figure = here / "figures" / "lamp-highlights.png"
    _figure(panels, figure)
    lines = [
        "# Lamp highlights (issue 39 item 5)",
        "",
        f"Device: {device}. Scene: {gltf.name} (bench/lamps.py: gold floor, roughness 0.3; white plastic board, "
        f"roughness 0.2; a point lamp of 3 cd and a spot of 6 cd; sky {SKY}). {size[0]}x{size[1]}, reference "
        f"{args.spp} passes. Relative RMSE against the reference; the peak is the brightest pixel (row, column).",
        "",
        "| camera | method | rel-RMSE | ms | peak | reference peak |",
        "|---|---|---|---|---|---|",
    ]
    for name, method, error, seconds, peak, reference_peak in rows:
        lines.append(
            f"| {name} | {method} | {100 * error:.2f} % | {1e3 * seconds:.0f} | {tuple(int(v) for v in peak)} "
            f"| {tuple(int(v) for v in reference_peak)} |"
        )
    lines += ["", f"Figure: {figure.relative_to(here)} (reference | lobe-7 per camera, Reinhard-mapped)."]
    if args.mitsuba:
        lines += ["", *mitsuba_floor_lines()]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def mitsuba_floor_lines(width: int = 160, height: int = 100, spp: int = 256) -> list[str]:
    """The --mitsuba table: lobeview's methods against Mitsuba 3 on a lamp-lit GGX floor."""
    import math

    import mitsuba as mi

    from lobeview.materials.spec import validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.lamps import LAMP_RADIUS
    from lobeview.scenes.meshes import Mesh
    from lobeview.scenes.scene import PunctualLight, Scene, SceneMaterial, SceneObject
    from lobeview.viewer.camera import Camera, perspective
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    lines = ["## Against Mitsuba 3: a point lamp over a GGX floor", ""]
    eye, target, up, fov = (0.0, -2.5, 1.4), (0.2, 0.0, 0.0), (0.0, 0.0, 1.0), 50.0
    lamp = PunctualLight("bulb", "point", np.array([1.0, 0.5, 0.25]), 3.0, np.array([0.3, -0.2, 1.0]),
                         np.array([0.0, 0.0, -1.0]))  # fmt: skip
    positions = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], np.float32)
    normals, tangents = np.tile(np.float32([[0, 0, 1]]), (4, 1)), np.tile(np.float32([[1, 0, 0, 1]]), (4, 1))
    uvs, indices = np.float32([[0, 1], [1, 1], [1, 0], [0, 0]]), np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    mesh = Mesh(positions, normals, tangents, uvs, indices, "floor")
    mi.set_variant("scalar_rgb")  # llvm_ad_rgb's JIT fails on Debian 12's LLVM 15
    ctx = create_headless_context()
    black = EnvironmentMap.from_function(lambda d: np.zeros(d.shape[:-1] + (3,)), height=16, name="black")
    lines += ["| GGX alpha | method | rel-RMSE | image sum / Mitsuba's | peak | Mitsuba's peak |"]
    lines += ["|---|---|---|---|---|---|"]
    for alpha in (0.05, 0.15, 0.4):
        desc = validate({"model": "microfacet", "distribution": "ggx", "alpha": alpha, "fresnel": {"type": "none"}})
        scene = Scene([SceneObject("floor", mesh, 0, None)], [SceneMaterial("ggx", desc)], lights=[lamp])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            renderer = SceneRenderer(ctx, scene, black, size=(width, height), progress=False,
                                     settings=RenderSettings(cube_face_size=16))  # fmt: skip
        camera = Camera(eye, target, up, fov)
        try:
            ours = {m: renderer.render(camera, m, spp=4 if m == "reference" else 1) for m in ("lobe-7", "fis-16",
                                                                                              "reference")}  # fmt: skip
        finally:
            renderer.release()
        radiance = np.asarray(lamp.colour) * lamp.intensity / (math.pi * LAMP_RADIUS**2)
        sensor = {"type": "perspective", "fov": fov, "fov_axis": "y",
                  "to_world": mi.ScalarTransform4f().look_at(origin=list(eye), target=list(target), up=list(up)),
                  "film": {"type": "hdrfilm", "width": 4 * width, "height": 4 * height, "rfilter": {"type": "box"},
                           "pixel_format": "rgb"},
                  "sampler": {"type": "independent", "sample_count": spp}}  # fmt: skip
        truth = np.array(mi.render(mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 2}, "sensor": sensor,
            "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([2.0, 2.0, 1.0]),
                      "bsdf": {"type": "roughconductor", "distribution": "ggx", "alpha": alpha, "material": "none"}},
            "bulb": {"type": "sphere", "center": lamp.position.tolist(), "radius": LAMP_RADIUS,
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": radiance.tolist()}}},
        })), dtype=np.float32).reshape(height, 4, width, 4, 3).mean(axis=(1, 3))  # fmt: skip
        clip = perspective(fov, width / height, 0.1, 100.0) @ camera.view() @ np.array([*lamp.position, 1.0])
        bx, by = (clip[0] / clip[3] * 0.5 + 0.5) * width, (0.5 - clip[1] / clip[3] * 0.5) * height
        yy, xx = np.mgrid[0:height, 0:width] + 0.5
        keep = ours["lobe-7"].mask & ((xx - bx) ** 2 + (yy - by) ** 2 > 36.0)
        norm = float(np.sqrt(np.mean(truth[keep] ** 2)))
        peak_truth = np.unravel_index(np.argmax(np.where(keep, truth.max(-1), 0)), keep.shape)
        for method, frame in ours.items():
            image = frame.radiance
            error = float(np.sqrt(np.mean((image[keep] - truth[keep]) ** 2))) / norm
            peak = np.unravel_index(np.argmax(np.where(keep, image.max(-1), 0)), keep.shape)
            lines.append(f"| {alpha} | {method} | {100 * error:.2f} % | {image[keep].sum() / truth[keep].sum():.4f} "
                         f"| {tuple(int(v) for v in peak)} | {tuple(int(v) for v in peak_truth)} |")  # fmt: skip
    ctx.release()
    lines += ["", f"{width}x{height}, Mitsuba {spp} samples per subpixel (4x4 per pixel), lobeview's reference "
              "4 passes; a 6-pixel disc around the bulb's image left out."]  # fmt: skip
    return lines


def _figure(panels, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 2.4))
    for ax, (title, image) in zip(np.atleast_1d(axes), panels, strict=True):
        mapped = image / (1.0 + image)  # Reinhard: the lamps' cores stay visible
        ax.imshow(np.clip(mapped, 0, 1) ** (1 / 2.2))
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
