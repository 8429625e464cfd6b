"""How good the viewer's refinement estimates are (viewer/refinement.py): on a demo view, the
window's refinement is replayed headless (two independently randomised halves, one sub-pixel
position per pass) and at each checkpoint the two-half estimates of the refined mean's error,
the real-time frame's error and the shown blend's error are set beside their true values
against a converged box-filtered reference (display RMS x 255, ACES, exposure 0).

    python -m lobeview.bench.refinement [--size 240x150] [--view table] [--method lobe-11+norm]
                                        [--batch 4] [--reference-spp 2048] [--out bench/results]

Writes refinement-STAMP.md (the table) and refinement-STAMP.png (top: real-time, then the shown
blend at each checkpoint; bottom: the converged reference, then the blend's weight of the
refined mean, white = refined).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

CHECKPOINTS = (8, 16, 32, 64, 128, 256, 512)


def replay(renderer, camera, realtime: np.ndarray, batch: int, checkpoints, say):
    """Yield (spp, mean, estimate) at each checkpoint of a refinement replayed as the window
    runs it (app/window.py _refine, with a fixed batch), against the real-time frame ``realtime``."""
    from lobeview.core.methods import Method
    from lobeview.viewer.refinement import REFINEMENT_TEXTURE_FOOTPRINT, Refinement, two_half_estimate

    refinement = Refinement()
    refinement.batch = batch
    sums = [np.zeros_like(realtime), np.zeros_like(realtime)]
    while refinement.samples < max(checkpoints):
        plan = refinement.next_pass()
        renderer.draw_frame(
            camera, Method("reference", plan.samples), plan.sample_offset, seed=plan.half, jitter=plan.jitter,
            texture_footprint=REFINEMENT_TEXTURE_FOOTPRINT,
        )  # fmt: skip
        sums[plan.half] += renderer.read(0)[..., :3] * plan.samples
        refinement.added(plan.samples, plan.half)
        if refinement.samples in checkpoints:
            weights = refinement.weights
            estimate = two_half_estimate(sums[0] / weights[0], weights[0], sums[1] / weights[1], weights[1], realtime)
            say(f"[refinement] {refinement.samples} spp: estimated noise {estimate.noise * 255:.2f}")
            yield refinement.samples, (sums[0] + sums[1]) / refinement.samples, estimate


def main(argv=None) -> int:
    from PIL import Image

    from lobeview.core.errors import parse_size
    from lobeview.core.methods import Method
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import scene_view
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings
    from lobeview.viewer.tonemap import to_uint8, tonemap

    parser = argparse.ArgumentParser(prog="python -m lobeview.bench.refinement", description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", default="240x150")
    parser.add_argument("--view", default="table", help="demo camera (default table)")
    parser.add_argument("--method", default="lobe-11+norm", help="the real-time method (default lobe-11+norm)")
    parser.add_argument("--batch", type=int, default=4, help="samples per pass (default 4)")
    parser.add_argument("--reference-spp", type=int, default=2048)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args(argv)

    def say(text):
        print(text, file=sys.stderr, flush=True)

    size = parse_size(args.size)
    scene = load_gltf(build_demo_scene())
    camera = Camera(*scene_view(scene, args.view))
    ctx = create_headless_context()
    env = load_environment(DEMO_ENVIRONMENT)
    renderer = SceneRenderer(ctx, scene, env, size=size, progress=False, settings=RenderSettings(cube_face_size=64))
    t0 = time.perf_counter()
    truth = renderer.render(camera, "reference", spp=args.reference_spp).radiance.astype(np.float64)
    say(f"[refinement] reference ({args.reference_spp} spp, box filter) in {time.perf_counter() - t0:.1f} s")
    display_truth = tonemap(truth)

    def true_error(image):
        return float(np.sqrt(np.mean((tonemap(image) - display_truth) ** 2))) * 255

    renderer.draw_frame(camera, Method.parse(args.method))
    realtime = renderer.read(0)[..., :3].astype(np.float64)
    rows, top, bottom = [], [to_uint8(tonemap(realtime))], [to_uint8(display_truth)]
    for spp, mean, estimate in replay(renderer, camera, realtime, args.batch, CHECKPOINTS, say):
        weight = estimate.weight[..., None]
        shown = weight * mean + (1 - weight) * realtime
        rows.append(
            f"| {spp} | {estimate.noise * 255:.2f} | {true_error(mean):.2f} | {estimate.realtime * 255:.2f} |"
            f" {true_error(realtime):.2f} | {estimate.shown * 255:.2f} | {true_error(shown):.2f} |"
            f" {100 * estimate.refined_share:.0f} % |"
        )
        top.append(to_uint8(tonemap(shown)))
        bottom.append(np.repeat(to_uint8(estimate.weight)[..., None], 3, axis=-1))
    device = renderer_description(ctx)
    renderer.release()
    ctx.release()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    figure = out / f"refinement-{stamp}.png"
    Image.fromarray(np.concatenate([np.concatenate(top, 1), np.concatenate(bottom, 1)], 0)).save(figure)
    text = [
        f"# Refinement estimates against the truth ({stamp})",
        "",
        f"Demo view `{args.view}`, {size[0]}x{size[1]}, real-time `{args.method}`, refinement passes of"
        f" {args.batch} samples per lobe (two halves, sub-pixel positions), truth: `reference` at"
        f" {args.reference_spp} spp (box filter). Display RMS error x 255 (ACES, exposure 0). Device: {device}.",
        "",
        "| spp | refined: estimated | true | real-time: estimated | true | shown blend: estimated | true |"
        " refined share |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"![refinement]({figure.name}) top: real-time, then the shown blend per checkpoint; bottom: the"
        " reference, then the refined mean's weight (white = refined).",
        "",
    ]
    path = out / f"refinement-{stamp}.md"
    path.write_text("\n".join(text))
    print("\n".join(text))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
