"""Real light (issue 39): every method on the preview sphere under real HDR captures, with and
without bright-source separation (scenes/bright_sources.py), against ``reference --pixel-filter
box`` (which reads the whole cube either way), with time.

    lobeview bench light [--quick] [--materials gold-ggx ggx:0.05 ...] [--views studio ...]
                         [--methods lobe-7+norm+fit ...] [--reference-spp 2048] [--supersample 4]
                         [--after-only] [--out DIR]

Materials: presets by name, or DIST:ALPHA (a microfacet reflector without Fresnel, as in
bench/mitsuba.py). Views: files of ../shared/assets/env by stem (studio, chinese_garden_1k, ...)
or paths. For every (view, material): the reference once, then each method on a renderer whose
cube keeps its bright sources ("before") and on one that separates them ("after"): relative RMSE
and PSNR over the sphere, and the median shading time of --repeats frames. A figure per view of
the first material: reference | before | after | |after - reference| x4 for lobe-7+norm+fit.

The errors compare equal pixel footprints: the reference's box filter integrates each pixel, so
the real-time methods are rendered at --supersample (default 4) times the size and averaged down
(bench/mitsuba.py's protocol). Shading pixel centres instead (--supersample 1, the tables before
2026-12-01) counts the silhouette's partly covered pixels as the method's error: on Beckmann 0.3
under courtyard.exr lobe-7+norm+fit is 13.6 % off that way and 2.9 % supersampled, 2.4 % over the
sphere's interior either way. The times are of frames at the bench's own size. --after-only skips
the renders with the bright sources left in the cube (the 'before' columns).
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.bench.captures import environment_files  # noqa: F401 (the bench's views; tests call it here)

MATERIALS = (
    "gold-ggx", "beckmann:0.3", "ggx:0.05", "alanod-2000gs-1lobe", "miro5-2lobe", "frosted-glass",
    "gltf-red-plastic",
)  # fmt: skip
QUICK_MATERIALS = ("gold-ggx", "ggx:0.05", "frosted-glass")
# lobe-N as the viewer runs it by default (+norm+fit: the fitted pattern where a lobe has a table)
METHODS = ("lobe-3+norm+fit", "lobe-7+norm+fit", "lobe-11+norm+fit", "lobe-15+norm+fit", "lobe-19+norm+fit",
           "fis-16", "prefiltered", "prefiltered-rsibr")  # fmt: skip
QUICK_METHODS = ("lobe-7+norm+fit", "lobe-15+norm+fit", "fis-16", "prefiltered")
FIGURE_METHOD = "lobe-7+norm+fit"
SUPERSAMPLE = 4
SIZE = 160
CAMERA = ((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0)


def build_material(name: str):
    from lobeview.materials.spec import build_bsdf, load_material, validate

    if ":" in name:
        from lobeview.bench.mitsuba import material

        return build_bsdf(validate(material(name)))
    return build_bsdf(load_material(name))


def interior(mask: np.ndarray, pixels: int = 2) -> np.ndarray:
    """``mask`` without its outer ``pixels`` rings: the real-time methods shade pixel centres while
    the box-filtered reference averages the silhouette's pixels with the empty background, so a
    sun reflected at a grazing rim (a brushed metal's streak) differs there by the filter alone."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, iterations=pixels)


def reference_and_noise(renderer, camera, bsdf, spp: int):
    """The reference frame (box pixel filter, the bright sources as its third strategy's proposals,
    shaders/env_sampling.glsl) as the mean of two halves of ``spp`` with seeds 0 and 1, and its
    noise: the relative RMSE of the mean from the truth, |half_0 - half_1| / 2 in relative RMS.
    An error measured against it is sqrt(error^2 + noise^2) in expectation, so the table reports
    sqrt(max(error^2 - noise^2, 0)) beside it (under night.exr at 2048 spp the noise alone was
    5 %: lobe-7's 8.0 % there fell to 6.3 and 5.9 % against 8192 and 32768 spp)."""
    import dataclasses

    from lobeview.bench.mitsuba import relative_rmse

    halves = [
        renderer.render(camera, bsdf, "reference", spp=max(spp // 2, 1), background=False, seed=seed) for seed in (0, 1)
    ]
    mask = halves[0].mask
    noise = 0.5 * relative_rmse(halves[0].radiance, halves[1].radiance, mask)
    mean = dataclasses.replace(halves[0], radiance=0.5 * (halves[0].radiance + halves[1].radiance))
    return mean, noise


def psnr(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    peak = float(np.max(reference[mask]))
    mse = float(np.mean((image[mask] - reference[mask]) ** 2))
    return 10.0 * np.log10(peak * peak / max(mse, 1e-30))


def preview_pair(ctx, env, size: int) -> dict:
    """{False: the preview sphere's renderer with the capture's bright sources left in the cube,
    True: with them separated into cap lights}, ``size`` pixels square (the capture's sanitising
    warnings silenced: the benches report its lights instead)."""
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.preview import PreviewRenderer

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {
            separate: PreviewRenderer(ctx, env, uv_sphere(1.0), size=(size, size), bright_sources=separate)
            for separate in (False, True)
        }


def run(
    views,
    materials,
    methods,
    reference_spp: int,
    repeats: int,
    out: Path,
    stamp: str,
    progress=print,
    supersample: int = SUPERSAMPLE,
    before: bool = True,
) -> dict:
    from lobeview.bench.mitsuba import relative_rmse
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    if supersample < 1:
        raise ValueError(f"--supersample must be at least 1, got {supersample}")
    ctx = create_headless_context()
    camera = Camera(*CAMERA)
    labels = ((False, "before"), (True, "after")) if before else ((True, "after"),)
    rows, figures = [], []
    for path in environment_files(views):
        env = load_environment(str(path))
        renderers = preview_pair(ctx, env, SIZE)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fine = SIZE * supersample
            fine_renderers = {
                separate: renderers[separate]
                if supersample == 1
                else PreviewRenderer(ctx, env, uv_sphere(1.0), size=(fine, fine), bright_sources=separate)
                for separate, _ in labels
            }
        lights = renderers[True].cubes.lights
        progress(f"[light] {path.stem}: {len(lights)} light(s), radii "
                 + ", ".join(f"{np.degrees(light.radius):.2f}" for light in lights) + " deg")  # fmt: skip
        for m, name in enumerate(materials):
            bsdf = build_material(name)
            reference, reference_noise = reference_and_noise(renderers[True], camera, bsdf, reference_spp)
            inner = interior(reference.mask)
            progress(f"[light] {path.stem} {name} reference: noise {100 * reference_noise:.1f} % ({reference_spp} spp)")
            for method in methods:
                row = {"view": path.stem, "material": name, "method": method, "lights": len(lights),
                       "reference_noise": reference_noise}  # fmt: skip
                for separate, label in labels:
                    renderer = renderers[separate]
                    frame = renderer.render(camera, bsdf, method, background=False)  # warm-up (maps, programs)
                    seconds = []
                    for _ in range(repeats):
                        t0 = time.perf_counter()
                        frame = renderer.render(camera, bsdf, method, background=False)
                        seconds.append(time.perf_counter() - t0)
                    radiance = frame.radiance
                    if supersample > 1:  # the reference's pixel footprints (the module's docstring)
                        fine_frame = fine_renderers[separate].render(camera, bsdf, method, background=False)
                        radiance = fine_frame.radiance.reshape(SIZE, supersample, SIZE, supersample, 3).mean(
                            axis=(1, 3)
                        )
                    error = relative_rmse(radiance, reference.radiance, reference.mask)
                    row[label] = {
                        "rel_rmse": error,
                        "beyond_noise": float(np.sqrt(max(error**2 - reference_noise**2, 0.0))),
                        "rel_rmse_interior": relative_rmse(radiance, reference.radiance, inner),
                        "psnr": psnr(radiance, reference.radiance, reference.mask),
                        "ms": 1000.0 * float(np.median(seconds)),
                    }
                    if m == 0 and method == FIGURE_METHOD:
                        figures.append((path.stem, name, label, radiance, reference.radiance))
                rows.append(row)
                a = row["after"]
                errors = (f"{100 * a['rel_rmse']:.1f} % (interior {100 * a['rel_rmse_interior']:.1f}, beyond the "
                          f"reference's noise {100 * a['beyond_noise']:.1f}), {a['ms']:.0f} ms")  # fmt: skip
                if before:
                    b = row["before"]
                    errors = f"{100 * b['rel_rmse']:.1f} % -> {errors} (before {b['ms']:.0f} ms)"
                progress(f"[light] {path.stem} {name} {method}: {errors}")
        for renderer in {id(r): r for r in (*renderers.values(), *fine_renderers.values())}.values():
            renderer.release()
    ctx.release()
    results = {"rows": rows, "size": SIZE, "reference_spp": reference_spp, "repeats": repeats,
               "supersample": supersample, "device": "Mesa llvmpipe (CPU)", "stamp": stamp}  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    (out / f"light-{stamp}.json").write_text(json.dumps(results, indent=1))
    if figures:
        write_figure(figures, out / f"light-{stamp}.png")
    (out / f"light-{stamp}.md").write_text(markdown(results))
    progress(f"[light] wrote {out / f'light-{stamp}.md'}")
    return results


def write_figure(figures: list, path: Path) -> None:
    """One row per view: reference | before | after | |after - reference| x4 (relative); without
    'before' frames (--after-only) reference | after | error."""
    from PIL import Image, ImageDraw

    def tonemap(x):
        return (np.clip(x / (1.0 + x), 0.0, 1.0) ** (1 / 2.2) * 255).astype(np.uint8)

    by_view: dict = {}
    for view, _name, label, frame, reference in figures:
        by_view.setdefault(view, {"reference": reference})[label] = frame
    rows = []
    for view, frames in by_view.items():
        after, reference = frames["after"], frames["reference"]
        error = np.abs(after - reference).mean(-1) / np.maximum(reference.mean(-1), 1e-3)
        error = (np.clip(4.0 * error, 0.0, 1.0)[..., None] * 255).repeat(3, -1).astype(np.uint8)
        shown = [reference, frames["before"], after] if "before" in frames else [reference, after]
        row = np.concatenate([tonemap(x) for x in shown] + [error], axis=1)
        image = Image.fromarray(row)
        ImageDraw.Draw(image).text((4, 4), view, fill=(255, 255, 0))
        rows.append(np.asarray(image))
    Image.fromarray(np.concatenate(rows, axis=0)).save(path)


def markdown(results: dict) -> str:
    lines = [
        f"# Bright-source separation: before / after ({results['stamp']})",
        "",
        f"`lobeview bench light`: preview sphere {results['size']}x{results['size']} px, camera 4 units, fov 40; "
        f"against `reference` at {results['reference_spp']} samples per lobe, box pixel filter (reading the whole "
        f"cube); before = bright sources left in the cube, after = separated into cap lights. Relative RMSE (%) "
        f"over the sphere, and over its interior (without the 2 outer pixel rings, where the box-filtered reference "
        f"mixes in the background); reference noise: the relative RMSE of the reference itself (half its "
        f"samples at seed 0 against half at seed 1, halved), and beyond noise: sqrt(error^2 - noise^2), the "
        f"method's own error; and median frame time (ms, {results['repeats']} frames) on {results['device']}. "
        + supersample_sentence(results.get("supersample", 1)),
        "",
        "| view | lights | material | method | reference noise | rel. RMSE before | after | beyond noise before "
        "| after | interior before | after | PSNR before | after | ms before | after |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        noise = row.get("reference_noise")
        cells = ["-" if noise is None else f"{100 * noise:.1f}"]
        for key, scale, digits in (("rel_rmse", 100, 1), ("beyond_noise", 100, 1), ("rel_rmse_interior", 100, 1),
                                   ("psnr", 1, 1), ("ms", 1, 0)):  # fmt: skip
            for label in ("before", "after"):
                value = row.get(label, {}).get(key)
                cells.append("-" if value is None else f"{scale * value:.{digits}f}")
        lines.append(
            f"| {row['view']} | {row['lights']} | {row['material']} | {row['method']} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines) + "\n"


def supersample_sentence(supersample: int) -> str:
    if supersample == 1:
        return "The real-time methods shade the pixel centres (the silhouette's pixels count as their error)."
    return (
        f"The real-time methods at {supersample}x{supersample} points per pixel, averaged (the reference's "
        "footprints); times of frames at the table's size."
    )


def run_light_command(args, out_dir: Path, stamp: str) -> int:
    quick = bool(args.quick)
    materials = args.materials or (QUICK_MATERIALS if quick else MATERIALS)
    methods = args.methods or (QUICK_METHODS if quick else METHODS)
    views = args.views or (["chinese_garden_1k", "studio", "interior"] if quick else None)
    spp = args.reference_spp or (512 if quick else 2048)
    repeats = 1 if quick else max(1, int(args.repeats))
    for name in materials:
        build_material(name)  # fail early on a misspelt material
    supersample = SUPERSAMPLE if args.supersample is None else int(args.supersample)
    if supersample < 1:
        raise SystemExit(f"--supersample must be at least 1, got {supersample}")
    run(views, materials, methods, spp, repeats, out_dir, stamp, supersample=supersample, before=not args.after_only)
    return 0
