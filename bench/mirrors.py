"""`lobeview bench --mirrors`: what planar mirror passes (thesis 4.5) cost and how accurate lobe-N
is through them.

Scene: boxes on a glossy floor (scenes/mirror_scene.py) with an optional glossy back wall, so a
frame has 0, 1 or 2 reflectors on mirror passes (0: the same objects shaded from their cube
maps). Per resolution and reflector count: the mirror passes alone (scene render from the
mirrored camera + MIP chain, per reflector) and the whole frame for lobe-N, N in --mirror-samples,
as the median of --repeats frames after a warm-up, the mirror buffers re-rendered every frame (as
in a walkthrough). With one reflector at the first resolution the floor's error against the
converged `reference` through the same mirror buffer is reported too (relative RMSE and PSNR of
the ACES-tonemapped 8-bit image over the floor pixels): the error of the sampling pattern and the
filter, not of the mirror-buffer approximation itself (the ray-traced comparison of a sharp
mirror is in tests/test_planar_mirror.py).

Refinement section: the converged `reference` on floors of roughness 0.05 / 0.15 / 0.3 (grey
environment, first resolution halved) with the plain two-step projection and with the averaged
tangent plane of Fig. 4.46b, both against a ray tracer (scenes/mirror_scene.traced_floor_reflection,
the same number of samples), and the noise floor of that comparison (the ray tracer's own
noise). The figure `mirrors-*-refinement.png` shows plain | averaged | ray traced for m = 0.15:
the plain projection frames the blurred reflections with sharp outlines, the averaged
plane lets them fade.
"""

from __future__ import annotations

import datetime
import statistics
import sys
import time
from pathlib import Path

import numpy as np

MIRROR_SAMPLES = (3, 7, 11, 15, 19)
REFINEMENT_ROUGHNESS = (0.05, 0.15, 0.3)
REFINEMENT_BACKGROUND = 0.5  # grey environment: what the ray tracer's missed rays see


def _frame_ms(renderer, camera, method, repeats: int) -> tuple[float, float, object]:
    """(median whole-frame ms, median mirror-pass ms, last result), mirror buffers invalidated
    before every frame."""
    frame, passes, result = [], [], None
    for k in range(repeats + 1):
        renderer.invalidate_mirrors()
        renderer.ctx.finish()
        t0 = time.perf_counter()
        if method.kind != "prefiltered":
            renderer.render_mirror_passes(camera)
        renderer.ctx.finish()
        t1 = time.perf_counter()
        result = renderer.render(camera, method)  # reuses the buffers just drawn
        if k:  # the first frame compiles shaders
            passes.append((t1 - t0) * 1e3)
            frame.append((t1 - t0) * 1e3 + result.timings["shade"] * 1e3)  # main pass: draw + glFinish
    return statistics.median(frame), statistics.median(passes), result


def run_mirror_bench(
    ctx,
    device: str,
    out_dir: Path,
    stamp: str,
    resolutions,
    samples,
    repeats: int,
    spp: int,
    *,
    refinement: bool = True,
) -> Path:
    """Frame and mirror-pass times at each resolution with 0 / 1 / 2 reflectors, the floor's error
    against ``reference``, the convergence figure and (``refinement``) the mirror buffer's
    refinement against the CPU ray tracer; writes ``mirrors-STAMP.md`` into ``out_dir``."""
    from lobeview.core.methods import Method
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.mirror_scene import CAMERA, mirror_floor_scene
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.tonemap import tonemap

    from .metrics import psnr_8bit, relative_rmse

    def say(text):
        print(f"[mirrors] {text}", file=sys.stderr, flush=True)

    env = EnvironmentMap.from_function(
        lambda d: 0.4 + 0.8 * np.clip(d[..., 1:2], 0.0, 1.0) * np.ones(3), height=64, name="gradient sky"
    )
    camera = Camera(tuple(CAMERA.position), tuple(CAMERA.target), tuple(CAMERA.up), CAMERA.fov_y)
    methods = [Method("lobe", n, normalize=True) for n in samples]
    rows, errors = [], []
    for size in resolutions:
        renderer = SceneRenderer(ctx, mirror_floor_scene(0.05, extra_reflector=True), env, size=size, progress=False)
        for count, enabled in ((0, set()), (1, {0}), (2, {0, 4})):
            renderer.configure(enabled_reflectors=enabled)
            row = {"size": f"{size[0]}x{size[1]}", "reflectors": count, "frame_ms": {}}
            for method in methods:
                ms, pass_ms, result = _frame_ms(renderer, camera, method, repeats)
                row["frame_ms"][str(method.samples)] = ms
                row["mirror_ms"] = pass_ms
                say(
                    f"{row['size']}, {count} reflector(s), lobe-{method.samples}: {ms:.1f} ms"
                    f" (mirror passes {pass_ms:.1f} ms)"
                )
            row["report"] = list(renderer.mirror_report)
            rows.append(row)
            if count == 1 and size == resolutions[0]:
                reference = renderer.render(camera, "reference", spp=spp).radiance
                floor = result.object_id == 0
                exposure = 0.0
                ref_ldr = np.clip(tonemap(reference, "aces", exposure), 0, 1)
                for method in methods:
                    image = renderer.render(camera, method).radiance
                    ldr = np.clip(tonemap(image, "aces", exposure), 0, 1)
                    errors.append(
                        {
                            "method": f"lobe-{method.samples}",
                            "rel_rmse": relative_rmse(image[floor], reference[floor]),
                            "psnr": psnr_8bit(ldr[floor], ref_ldr[floor]),
                        }
                    )
                    say(f"error lobe-{method.samples}: {errors[-1]['psnr']:.1f} dB")
        renderer.release()
    out_dir.mkdir(parents=True, exist_ok=True)
    figure = write_convergence_figure(ctx, env, camera, out_dir / f"mirrors-{stamp}.png", resolutions[0], spp)
    half = (max(1, resolutions[0][0] // 2), max(1, resolutions[0][1] // 2))
    refined = None
    if refinement:
        refined = refinement_against_ray_tracing(
            ctx, camera, half, spp, out_dir / f"mirrors-{stamp}-refinement.png", say
        )
    path = out_dir / f"mirrors-{stamp}.md"
    lines = [
        "# lobeview bench --mirrors: planar mirror passes (thesis 4.5)",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- device: {device}",
        "- scene: boxes on a glossy floor (Beckmann m = 0.05) + optional glossy back wall (m = 0.05),"
        " scenes/mirror_scene.py, camera 'mirror floor', environment: gradient sky",
        f"- timing: wall clock around glFinish, median of {repeats} frames after a warm-up, mirror buffers"
        " re-rendered every frame; 'mirror passes' = the scene drawn from the mirrored camera(s) + MIP chains;"
        " 0 reflectors = the floor and wall shaded from their cube maps",
        "- methods: lobe-N (normalised, multi-ring pattern on reflectors)",
        "",
        "| resolution | reflectors | mirror passes ms | " + " | ".join(f"lobe-{n} ms" for n in samples) + " |",
        "|---|---|---|" + "---|" * len(samples),
    ]
    for row in rows:
        cells = " | ".join(f"{row['frame_ms'][str(n)]:.1f}" for n in samples)
        lines.append(f"| {row['size']} | {row['reflectors']} | {row['mirror_ms']:.1f} | {cells} |")
    if errors:
        lines += [
            "",
            f"## Floor error against `reference` ({spp} spp per lobe) through the same mirror buffer,"
            f" {resolutions[0][0]}x{resolutions[0][1]}, 1 reflector",
            "",
            "| method | relative RMSE | PSNR (ACES 8-bit, floor pixels) |",
            "|---|---|---|",
        ]
        lines += [f"| {e['method']} | {e['rel_rmse']:.4f} | {e['psnr']:.1f} dB |" for e in errors]
    if refined is not None:
        refinement_rows, refinement_figure = refined
        lines += [
            "",
            f"## Refinement against a ray tracer ({half[0]}x{half[1]}, {spp} samples per pixel, grey environment)",
            "",
            "`reference` through the mirror buffer with the plain two-step projection (4.5.2) and with the"
            " averaged tangent plane (Fig. 4.46b, plus a third step), relative RMSE over the floor pixels against"
            " a ray tracer with the same number of samples; 'noise floor' = the ray tracer's own noise (its"
            " difference from a second trace with another seed, / sqrt 2): what an exact renderer would score."
            " The rest is the mirror buffer's approximation: rays that hit geometry the mirrored camera does"
            " not see, or whose hit the tangent planes do not find.",
            "",
            "| floor roughness | plain two-step | averaged plane | noise floor |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {r['roughness']:g} | {r['plain']:.4f} | {r['averaged']:.4f} | {r['noise']:.4f} |"
            for r in refinement_rows
        ]
        lines += [
            "",
            f"![refinement]({refinement_figure.name})",
            "",
            "m = 0.15: plain two-step | averaged tangent plane | ray traced. The plain projection switches"
            " planes where P_R crosses a depth edge, so the blurred reflections of the floating box and the"
            " pillar are framed by sharp outlines; with the averaged plane they fade softly.",
        ]
    else:
        lines += ["", "Refinement against the ray tracer: not run here (a CPU measurement; `python -m"
                  " lobeview.bench.mirrors` runs it)."]  # fmt: skip
    lines += [
        "",
        f"![mirror floor]({figure.name})",
        "",
        "Left: sharp mirror floor (m = 0.002, lobe-5). Middle: glossy floor (m = 0.05), lobe-11 in real"
        f" time. Right: the same glossy floor, `reference` ({spp} spp per lobe) through the mirror buffer:"
        " the reflection blurs with the distance between floor and reflected surface (the floating red"
        " box more than the pillar's foot), as in thesis Fig. 4.32/4.45.",
    ]
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
    return path


def write_convergence_figure(ctx, env, camera, path: Path, size, spp: int) -> Path:
    """Sharp mirror | glossy lobe-11 | glossy reference, tonemapped side by side (PNG)."""
    from PIL import Image

    from lobeview.core.methods import Method
    from lobeview.scenes.mirror_scene import mirror_floor_scene
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.tonemap import tonemap

    panels = []
    for roughness, method in ((0.002, Method("lobe", 5, normalize=True)), (0.05, Method("lobe", 11, normalize=True)),
                              (0.05, Method.parse("reference"))):  # fmt: skip
        renderer = SceneRenderer(ctx, mirror_floor_scene(roughness), env, size=size, progress=False)
        image = renderer.render(camera, method, spp=spp).radiance
        renderer.release()
        panels.append((np.clip(tonemap(image, "aces", 0.0), 0, 1) * 255 + 0.5).astype(np.uint8))
    gap = np.full((size[1], 4, 3), 255, np.uint8)
    Image.fromarray(np.concatenate([panels[0], gap, panels[1], gap, panels[2]], axis=1)).save(path)
    return path


def refinement_against_ray_tracing(ctx, camera, size, spp: int, figure_path: Path, say) -> tuple[list, Path]:
    """Rows {roughness, plain, averaged, noise} (relative RMSE over the floor) and the m = 0.15
    figure plain | averaged | ray traced."""
    from PIL import Image

    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.mirror_scene import CAMERA, mirror_floor_scene, traced_floor_reflection
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings
    from lobeview.viewer.tonemap import tonemap

    from .metrics import relative_rmse

    grey = EnvironmentMap.from_function(
        lambda d: np.full(d.shape[:-1] + (3,), REFINEMENT_BACKGROUND), height=16, name="grey"
    )
    rows, panels = [], None
    for roughness in REFINEMENT_ROUGHNESS:
        scene = mirror_floor_scene(roughness)
        renderer = SceneRenderer(
            ctx, scene, grey, size=size, progress=False, settings=RenderSettings(cube_face_size=64)
        )
        images = {}
        for averaged in (False, True):
            renderer.configure(mirror_plane_average=averaged)
            # at the pixel centres: the ray tracer below starts from the G-buffer's points
            result = renderer.render(camera, "reference", spp=spp, pixel_filter="point")
            images[averaged] = result.radiance
        renderer.release()
        floor = result.object_id == 0
        lobe = specular_lobes(build_bsdf(scene.materials[0].desc))[0]
        points = result.position[floor]
        t0 = time.perf_counter()
        traced = traced_floor_reflection(points, CAMERA.position, lobe, spp, REFINEMENT_BACKGROUND, seed=1)
        again = traced_floor_reflection(points, CAMERA.position, lobe, spp, REFINEMENT_BACKGROUND, seed=2)
        row = {
            "roughness": roughness,
            "plain": relative_rmse(images[False][floor], traced),
            "averaged": relative_rmse(images[True][floor], traced),
            # Two independent traces differ by sqrt(2) times one trace's noise: a renderer without
            # bias or noise of its own would show 1 / sqrt(2) of their difference.
            "noise": relative_rmse(again, traced) / np.sqrt(2.0),
        }
        rows.append(row)
        say(
            f"refinement m = {roughness:g}: plain {row['plain']:.4f}, averaged {row['averaged']:.4f},"
            f" noise floor {row['noise']:.4f} (ray tracing {time.perf_counter() - t0:.1f} s)"
        )
        if roughness == 0.15:
            traced_image = images[False].copy()
            traced_image[floor] = traced
            panels = [images[False], images[True], traced_image]
    gap = np.full((size[1], 4, 3), 255, np.uint8)
    ldr = [(np.clip(tonemap(p, "aces", 0.0), 0, 1) * 255 + 0.5).astype(np.uint8) for p in panels]
    Image.fromarray(np.concatenate([ldr[0], gap, ldr[1], gap, ldr[2]], axis=1)).save(figure_path)
    return rows, figure_path


def run_mirrors_command(args, out_dir: Path, stamp: str) -> int:
    """``lobeview bench mirrors``: the run above with the command line's sizes, samples and spp."""
    from lobeview.core.errors import parse_size
    from lobeview.viewer.context import create_headless_context, renderer_description

    default_sizes = ["320x200"] if args.quick else ["640x400", "1680x1050"]
    sizes = [parse_size(text) for text in (args.resolutions or default_sizes)]
    ctx = create_headless_context()
    samples = args.mirror_samples or ([3, 7] if args.quick else list(MIRROR_SAMPLES))
    spp = args.reference_spp or (128 if args.quick else 512)
    run_mirror_bench(ctx, renderer_description(ctx), out_dir, stamp, sizes, samples, args.repeats, spp)
    ctx.release()
    return 0
