"""What the bright sources' lights cost a frame (issue 39: "at most 1.5x today's lobe-7 frame
time"): the preview sphere under each capture rendered with its bright sources left in the cube
and separated into cap lights, frames of the two interleaved in one run, so the ratio holds on a
shared machine.

    python -m lobeview.bench.light_cost                          # night, studio, interior, sunrise
    python -m lobeview.bench.light_cost --views studio --size 512 --repeats 9

Per capture, material and method: the median milliseconds of ``--repeats`` frames (after one
warm-up) without and with the lights, and their ratio. A frame is PreviewRenderer.render at
``--size`` (the sphere covers about 60 % of it), read back, so the ratio understates the shading's
own (the read-back and Python are in both). The lights' count and radii come from
scenes/bright_sources.py at the preview's 256^2 cube.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_VIEWS = ("night", "studio", "interior", "sunrise")
DEFAULT_MATERIALS = ("ggx:0.05", "gold-ggx", "beckmann:0.3", "miro5-2lobe")
DEFAULT_METHODS = ("lobe-7+norm+fit", "prefiltered")


def measure(views, materials, methods, size: int, repeats: int, progress=print) -> tuple[list[dict], str]:
    """(rows of {view, lights, radii_deg, material, method, ms_without, ms_with, ratio}, the device)."""
    from lobeview.bench.captures import environment_files
    from lobeview.bench.light import CAMERA, build_material, preview_pair
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description

    if repeats < 1 or size < 8:
        raise ValueError(f"light_cost needs --repeats >= 1 and --size >= 8, got {repeats} and {size}")
    ctx = create_headless_context()
    device = renderer_description(ctx)
    camera = Camera(*CAMERA)
    rows = []
    try:
        for path in environment_files(views):
            renderers = preview_pair(ctx, load_environment(str(path)), size)
            lights = renderers[True].cubes.lights
            try:
                for name in materials:
                    bsdf = build_material(name)
                    for method in methods:
                        seconds = {False: [], True: []}
                        for renderer in renderers.values():  # warm-up: programs, maps
                            renderer.render(camera, bsdf, method, background=False)
                        for _ in range(repeats):
                            for separate, renderer in renderers.items():
                                t0 = time.perf_counter()
                                renderer.render(camera, bsdf, method, background=False)
                                seconds[separate].append(time.perf_counter() - t0)
                        without, with_lights = (1e3 * float(np.median(seconds[s])) for s in (False, True))
                        rows.append({"view": path.stem, "lights": len(lights),
                                     "radii_deg": [round(float(np.degrees(light.radius)), 2) for light in lights],
                                     "material": name, "method": method, "ms_without": without,
                                     "ms_with": with_lights, "ratio": with_lights / without})  # fmt: skip
                        progress(f"[light-cost] {path.stem} ({len(lights)} lights) {name} {method}: "
                                 f"{without:.0f} -> {with_lights:.0f} ms, x{with_lights / without:.2f}")  # fmt: skip
            finally:
                for renderer in renderers.values():
                    renderer.release()
    finally:
        ctx.release()
    return rows, device


def markdown(rows: list[dict], size: int, repeats: int, device: str, stamp: str) -> str:
    lines = [
        f"# What the lights cost a frame ({stamp})",
        "",
        f"`python -m lobeview.bench.light_cost`: preview sphere {size}x{size} px on {device}, median of "
        f"{repeats} frames each, the frames without and with the cap lights interleaved in one run. "
        "Without: the bright sources left in the cube; with: separated into cap lights (the default).",
        "",
        "| view | lights | material | method | ms without | ms with | ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['view']} | {r['lights']} | {r['material']} | {r['method']} | {r['ms_without']:.0f} | "
                     f"{r['ms_with']:.0f} | {r['ratio']:.2f} |")  # fmt: skip
    if rows:
        ratios = [r["ratio"] for r in rows]
        lines += ["", f"Ratio median {np.median(ratios):.2f}, range {min(ratios):.2f}-{max(ratios):.2f}."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.light_cost", description=__doc__.split("\n\n")[0])
    p.add_argument("--views", nargs="+", default=list(DEFAULT_VIEWS), help="captures (stems or paths)")
    p.add_argument("--materials", nargs="+", default=list(DEFAULT_MATERIALS), help="materials (as bench light)")
    p.add_argument("--methods", nargs="+", default=list(DEFAULT_METHODS), help="methods")
    p.add_argument("--size", type=int, default=320, help="frame size in pixels (default 320)")
    p.add_argument("--repeats", type=int, default=5, help="frames per median (default 5)")
    p.add_argument("--out", default=None, help="folder for light-cost-STAMP.md/.json (default bench/results)")
    args = p.parse_args(argv)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path(__file__).parent / "results"
    try:
        rows, device = measure(args.views, args.materials, args.methods, args.size, args.repeats)
    except ValueError as error:
        print(f"light_cost: {error}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(rows, args.size, args.repeats, device, stamp)
    (out / f"light-cost-{stamp}.md").write_text(text)
    record = {"device": device, "size": args.size, "repeats": args.repeats, "rows": rows}
    (out / f"light-cost-{stamp}.json").write_text(json.dumps(record, indent=1))
    print(text)
    print(f"[light-cost] wrote {out / f'light-cost-{stamp}.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
