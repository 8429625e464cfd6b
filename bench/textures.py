"""Cost of glTF textures per pixel (issue 16): frame time of a textured scene against the same
scene with its textures removed (factors only), measured alternately in one run.

    python -m lobeview.bench.textures [--scene WaterBottle.glb] [--size 640x640] [--frames 8]

Writes bench/results/textures-<stamp>.md. Times are wall clock per frame after ctx.finish()
(llvmpipe has no meaningful GPU timer); methods lobe-7, fis-8 and prefiltered.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time
from pathlib import Path

import numpy as np

METHODS = ("lobe-7", "fis-8", "prefiltered")


def untextured(scene, slots=None):
    """A shallow copy of ``scene`` whose materials lack the textures of ``slots`` (all: None)."""
    plain = copy.copy(scene)
    plain.materials = []
    for material in scene.materials:
        stripped = copy.copy(material)
        stripped.textures = {k: v for k, v in material.textures.items() if slots is not None and k not in slots}
        plain.materials.append(stripped)
    return plain


def run(scene_path: Path, size: tuple[int, int], frames: int) -> str:
    from lobeview.core.methods import Method
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import scene_view
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    ctx = create_headless_context()
    scene = load_gltf(scene_path)
    env = load_environment("builtin:overcast")
    position, target, up, fov = scene_view(scene, None)
    camera = Camera(position, target, up, fov)
    renderers = {
        "textured": SceneRenderer(
            ctx, scene, env, size=size, progress=False, settings=RenderSettings(cube_face_size=128)
        ),
        "factors only": SceneRenderer(
            ctx, untextured(scene), env, size=size, progress=False, settings=RenderSettings(cube_face_size=128)
        ),
    }
    rows = []
    for method in METHODS:
        times = {name: [] for name in renderers}
        for renderer in renderers.values():  # warm-up: programs, prefiltered maps
            renderer.render(camera, method)
        for _ in range(frames):  # alternate so drift on a shared machine hits both alike
            for name, renderer in renderers.items():
                t0 = time.perf_counter()
                renderer.draw_frame(camera, Method.parse(method))
                ctx.finish()
                times[name].append(time.perf_counter() - t0)
        textured = statistics.median(times["textured"]) * 1000
        plain = statistics.median(times["factors only"]) * 1000
        rows.append(f"| {method} | {textured:.1f} | {plain:.1f} | {textured / plain:.2f} |")
    for renderer in renderers.values():
        renderer.release()
    textures = sum(len(m.textures) for m in scene.materials)
    texels = sum(int(np.prod(s.image.shape[:2])) for m in scene.materials for s in m.textures.values())
    return "\n".join(
        [
            f"# Cost of glTF textures: {scene_path.name}",
            "",
            f"device: {renderer_description(ctx)}; {size[0]}x{size[1]}; median of {frames} frames each, alternating;"
            f" {textures} textures, {texels / 1e6:.1f} Mtexels; environment builtin:overcast; no lightmap.",
            "",
            "| method | textured (ms/frame) | factors only (ms/frame) | ratio |",
            "|---|---|---|---|",
            *rows,
            "",
        ]
    )


def main(argv=None) -> int:
    from lobeview.core.errors import parse_size
    from lobeview.core.paths import bench_results_dir

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.textures", description=__doc__.split("\n\n")[0])
    default_scene = Path(__file__).resolve().parents[1].parent / "shared/assets/gltf/WaterBottle/WaterBottle.glb"
    p.add_argument("--scene", default=str(default_scene), help="a textured glTF scene (default: WaterBottle)")
    p.add_argument("--size", default="640x640", help="frame size (default 640x640)")
    p.add_argument("--frames", type=int, default=8, help="timed frames per method and variant (default 8)")
    args = p.parse_args(argv)
    report = run(Path(args.scene), parse_size(args.size), args.frames)
    out = bench_results_dir() / f"textures-{time.strftime('%Y%m%d-%H%M%S')}.md"
    out.write_text(report)
    print(report)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
