"""The prefiltered methods (issue 6), measured in one run:

1. accuracy and cost on the preview sphere: every prefiltered mode beside lobe-N and fis-N
   against the converged reference (PSNR after ACES, relative RMSE), time per frame (median of
   --repeats after a warm-up), preprocessing time and memory of the maps;
2. the hierarchical prefilter (seed 001, 5.1) against brute force for Phong exponents 10-500:
   kernel evaluations, wall time, speed-ups and the resulting error;
3. the lobe-fitting error (relative RMS over the BRDF slice) against the number of greedy lobes
   (seed 000, Figure 7) for the presets, plus the single 3D / 2D / Phong lobes, as a plot;
4. the 2D-lobe limitation: a glossy floor seen at glancing angles, rendered with the 3D lobe
   map, the 2D lobe, the multi-lobe map and the reference, with the error per band of view angle.

    python bench/prefiltered.py [--env FILE] [--size 200] [--reference-spp 2048] [--out bench/results]
                                [--presets P ...] [--methods M ...] [--accuracy-only]
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402

from lobeview.bench.preview_accuracy import DEFAULT_ENV, psnr, timed  # noqa: E402
from lobeview.materials import prefilter as pf  # noqa: E402
from lobeview.materials.banks import fit_banks  # noqa: E402
from lobeview.materials.bsdf import CosineSampled  # noqa: E402
from lobeview.materials.lobe_fit import (  # noqa: E402
    MAP_LOBES,
    fit_lobe_map,
    fit_lobe_maps,
    fit_multi_lobe,
    is_isotropic,
)
from lobeview.materials.spec import build_bsdf, load_material  # noqa: E402
from lobeview.scenes.builtin_env import load_environment  # noqa: E402
from lobeview.scenes.meshes import quad, uv_sphere  # noqa: E402
from lobeview.viewer.camera import Camera  # noqa: E402
from lobeview.viewer.context import create_headless_context, renderer_description  # noqa: E402
from lobeview.viewer.cubemap import equirect_to_cube_faces  # noqa: E402
from lobeview.viewer.preview import PreviewRenderer  # noqa: E402
from lobeview.viewer.tonemap import tonemap  # noqa: E402

PRESETS = (
    "gold-ggx",
    "gltf-red-plastic",
    "plastic",
    "lacquer",
    "alanod-2000gs-1lobe",
    "frosted-glass",
    "brushed-steel-beckmann",
)
METHODS = (
    "prefiltered",
    "prefiltered-lobe",
    "prefiltered-lobe2d",
    "prefiltered-phong",
    "prefiltered-multi",
    "prefiltered-banks",  # only for materials with an anisotropic lobe (else it is prefiltered-lobe)
    "prefiltered-rsibr",
    "lobe-7",
    "lobe-15",
    "fis-16",
    "fis-40",
)
FIT_PRESETS = (
    "plastic",
    "lacquer",
    "alanod-2000gs-1lobe",
    "gold-ggx",
    "porcelain",
    "frosted-glass",
    "brushed-steel-beckmann",
    "miro5-1lobe",
)
PHONG_EXPONENTS = (10, 50, 100, 200, 500)


def _specular(preset):
    return [c for c in build_bsdf(load_material(preset)).components if not isinstance(c, CosineSampled)]


def _anisotropic(comp) -> bool:
    return getattr(comp, "distribution", None) is not None and not is_isotropic(comp)


def accuracy(args, env, lines, stamp, out_dir):
    ctx = create_headless_context()
    renderer = PreviewRenderer(ctx, env, uv_sphere(), size=(args.size, args.size))
    camera = Camera(position=(0.0, 0.35, 3.2), fov_y=40.0)
    lines += [
        "## 1. Preview sphere: prefiltered modes beside lobe-N and fis-N",
        "",
        f"- device: {renderer_description(ctx)}; environment {env.name}; {args.size}x{args.size} px; cube faces 256",
        f"- reference: {args.reference_spp} BSDF + environment MIS samples per lobe; PSNR on ACES 8-bit"
        " object pixels (exposure: reference median luminance -> 0.18); relRMSE of linear radiance",
        f"- ms / frame: median of {args.repeats} after a warm-up (maps cached), shading pass, wall clock"
        " around glFinish; 'prep s' = first-use preprocessing of the maps this method needed"
        " (fits + GPU prefiltering + DFG table), 'MB' = their memory",
        "",
        "| preset | method | PSNR (dB) | relRMSE | ms / frame | prep s | MB |",
        "|---|---|---|---|---|---|---|",
    ]
    for preset in args.presets:
        bsdf = build_bsdf(load_material(preset))
        ref = renderer.render(camera, bsdf, "reference", spp=args.reference_spp, background=False)
        mask = ref.mask
        lum = ref.radiance[mask] @ np.array([0.2126, 0.7152, 0.0722])
        exposure = float(np.log2(0.18 / max(np.median(lum), 1e-6)))
        ref_tm = tonemap(ref.radiance, "aces", exposure)[mask]
        anisotropic = any(_anisotropic(c) for c in _specular(preset))
        for method in args.methods:
            if method == "prefiltered-banks" and not anisotropic:
                continue
            maps = renderer.cubes.prefiltered_maps()
            before_mem, before_keys = maps.total_memory(), set(maps.seconds)
            t0 = time.perf_counter()
            renderer.render(camera, bsdf, method, background=False)  # builds the maps
            first = time.perf_counter() - t0
            result, seconds = timed(renderer, args.repeats, camera, bsdf, method, background=False)
            prep = first - seconds if method.startswith("prefiltered") else 0.0
            new_keys = set(maps.seconds) - before_keys
            memory = (maps.total_memory() - before_mem) / 2**20
            img = result.radiance[mask]
            rel = float(np.sqrt(np.mean((img - ref.radiance[mask]) ** 2)) / np.sqrt(np.mean(ref.radiance[mask] ** 2)))
            value = psnr(tonemap(result.radiance, "aces", exposure)[mask], ref_tm)
            mem_text = f"{memory:.2f}" if method.startswith("prefiltered") else ""
            prep_text = f"{max(prep, 0.0):.2f}" if method.startswith("prefiltered") else ""
            if method.startswith("prefiltered") and not new_keys:
                prep_text, mem_text = "shared", "shared"
            lines.append(
                f"| {preset} | {method} | {value:.2f} | {rel:.4f} | {seconds * 1000:.1f} | {prep_text} | {mem_text} |"
            )
            print(f"{preset:20s} {method:20s} PSNR {value:6.2f} relRMSE {rel:.4f} {seconds * 1000:7.1f} ms", flush=True)
    lines.append("")

    renderer.release()
    glancing(args, env, ctx, lines, out_dir)
    ctx.release()


GLANCING_MATERIAL = (
    '{"model": "thesis", "kd": 0.02, "lobes": [{"ks": 1.0, "mx": 0.06, "my": 0.06, "r0": 0.04, "alpha": 0.3}]}'
)
GLANCING_METHODS = ("prefiltered-lobe", "prefiltered-lobe2d", "prefiltered-multi", "reference")
GLANCING_BANDS = ((50, 70), (70, 80), (80, 85), (85, 90))


def glancing(args, env, ctx, lines, out_dir):
    """A dark glossy floor (Kurt lobe m = 0.06, almost no diffuse) seen from 0.6 m towards the
    horizon: views from about 55 to 90 degrees from the normal."""
    floor = quad([-30.0, 0.0, 10.0], [60.0, 0.0, 0.0], [0.0, 0.0, -60.0])
    renderer = PreviewRenderer(ctx, env, floor, size=(480, 300))
    camera = Camera(position=(0.0, 0.6, 4.0), target=(0.0, 0.0, -8.0), fov_y=50.0)
    bsdf = build_bsdf(load_material(GLANCING_MATERIAL))
    images = [renderer.render(camera, bsdf, m, spp=args.reference_spp) for m in GLANCING_METHODS]
    reference = images[-1]
    strip = np.concatenate([tonemap(r.radiance, "aces", 0.0) for r in images], axis=1)
    figure = out_dir.parent / "figures" / "prefiltered-lobe3d-vs-lobe2d.png"
    figure.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((np.clip(strip, 0, 1) * 255).astype(np.uint8)).save(figure)
    to_eye = np.asarray(camera.position) - reference.position
    to_eye /= np.maximum(np.linalg.norm(to_eye, axis=-1, keepdims=True), 1e-9)
    view_angle = np.degrees(np.arccos(np.clip(np.sum(to_eye * reference.normal, axis=-1), -1.0, 1.0)))
    (comp,) = [c for c in bsdf.components if not isinstance(c, CosineSampled)]
    lobe3d, lobe2d = fit_lobe_map(comp, "lobe"), fit_lobe_map(comp, "lobe2d")
    medians = np.degrees([p.median_angle for p in lobe3d.profiles])
    lines += [
        "## 4. The single 2D lobe loses glancing-angle sharpening",
        "",
        f"`{figure.relative_to(out_dir.parent)}`: a dark glossy floor (`{GLANCING_MATERIAL}`) seen from"
        " 0.6 m above it towards the horizon, 480x300; left to right: 3D lobe map (16 elevations),"
        f" single 2D lobe, multi-lobe map, reference ({args.reference_spp} spp). relRMSE against the"
        " reference per band of the angle between view and normal:",
        "",
        "| view angle | pixels | " + " | ".join(GLANCING_METHODS[:-1]) + " |",
        "|---|---|" + "---|" * (len(GLANCING_METHODS) - 1),
    ]
    for low, high in GLANCING_BANDS:
        band = reference.mask & (view_angle >= low) & (view_angle < high)
        ref = reference.radiance[band]
        errors = [np.sqrt(np.mean((r.radiance[band] - ref) ** 2)) / np.sqrt(np.mean(ref**2)) for r in images[:-1]]
        lines.append(f"| {low}-{high} deg | {int(band.sum())} | " + " | ".join(f"{e:.4f}" for e in errors) + " |")
    lines += [
        "",
        "Median angle of the fitted radially symmetric lobe (degrees) per elevation, cos(theta_o) ="
        " "
        + ", ".join(f"{c:.2f}" for c in lobe3d.cos_theta_o[::3])
        + ": "
        + ", ".join(f"{m:.1f}" for m in medians[::3])
        + f"; the 2D lobe's single shape: {np.degrees(lobe2d.profiles[0].median_angle):.1f}.",
        "",
        "The true lobe narrows towards grazing views (compressed in the plane of incidence), and the"
        " 3D map follows that with a narrower fitted shape per elevation, while the 2D lobe (Kautz &"
        " McCool 3.2) uses one average shape for every elevation: its reflections near the horizon"
        " stay as blurred as at steep views, and its error grows faster with the view angle. Neither"
        " single radially symmetric lobe can make the vertical streaks of the reference (the lobe is"
        " stretched across the plane of incidence); the multi-lobe map's off-axis lobes start to.",
        "",
    ]
    renderer.release()


def hierarchical(args, env, lines):
    faces = equirect_to_cube_faces(env, args.hier_face)
    dirs = np.random.default_rng(0).normal(size=(args.hier_targets, 3))
    lines += [
        "## 2. Hierarchical prefiltering (seed 001, 5.1) against brute force",
        "",
        f"- numpy, this machine's CPU; cube faces {args.hier_face}^2 of {env.name};"
        f" {args.hier_targets} random target directions; Phong kernel cos^n; threshold"
        f" {args.threshold} on the kernel variation x texel solid angle relative to the kernel integral",
        "- speed-up = brute-force / hierarchical; error = relative RMS of the hierarchical result",
        "",
        "| Phong n | brute force s | hierarchical s | speed-up (time) | speed-up (kernel evaluations)"
        " | relRMSE | max rel. error |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in PHONG_EXPONENTS:
        kernel = pf.phong_kernel(float(n))
        brute = pf.prefilter_kernel_brute_force(faces, kernel, dirs)
        fast = pf.prefilter_hierarchical(faces, kernel, dirs, threshold=args.threshold)
        scale = np.sqrt(np.mean(brute.values**2))
        rel = np.sqrt(np.mean((fast.values - brute.values) ** 2)) / scale
        max_rel = np.max(np.abs(fast.values - brute.values) / np.maximum(brute.values, 1e-3 * scale))
        lines.append(
            f"| {n} | {brute.seconds:.3f} | {fast.seconds:.3f} | {brute.seconds / fast.seconds:.1f} |"
            f" {brute.kernel_evaluations / fast.kernel_evaluations:.1f} | {rel:.4f} | {max_rel:.4f} |"
        )
        print(f"hierarchical n={n}: {brute.seconds / fast.seconds:.1f}x, relRMSE {rel:.4f}", flush=True)
    lines.append("")


def fitting(lines, out_dir, stamp):
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    lines += [
        "## 3. Lobe-fitting error (relative RMS over the slice f cos, luminance)",
        "",
        "Greedy minimum-profile lobes at cos(theta_o) = 0.5 (seed 000, 3.3) and the rendered"
        " modes averaged over the 16 elevations: single 3D lobe (3.1), 2D lobe (3.2), Phong, the"
        f" multi-lobe map ({MAP_LOBES} lobes: {MAP_LOBES - 1} minimum profiles + the mean profile of"
        " the remainder, rescaled to the albedo); Banks: the fit error of the Banks kernel (over"
        " 16 views, materials/banks.py) for anisotropic lobes:",
        "",
        "| lobe | greedy 1 | 2 | 4 | 8 | single 3D (mean) | 2D (mean) | Phong (mean) | multi (mean) | Banks |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for preset in FIT_PRESETS:
        for i, comp in enumerate(_specular(preset)):
            label = f"{preset} {'T' if comp.transmission else 'R'}{i}"
            multi = fit_multi_lobe(comp, 0.5, lobes=8)
            ax.plot(range(1, 9), multi.errors, marker="o", label=label)
            singles = [float(np.mean(fit_lobe_map(comp, mode).error)) for mode in ("lobe", "lobe2d", "phong")]
            singles.append(float(np.mean(fit_lobe_maps(comp, "multi")[0].error)))
            banks = f"{fit_banks(comp).error:.3f}" if _anisotropic(comp) else "-"
            e = multi.errors
            lines.append(
                f"| {label} | {e[0]:.3f} | {e[1]:.3f} | {e[3]:.3f} | {e[7]:.3f} | "
                + " | ".join(f"{v:.3f}" for v in singles)
                + f" | {banks} |"
            )
    ax.set_xlabel("number of lobes (greedy, minimum profiles)")
    ax.set_ylabel("relative RMS error over the slice")
    ax.set_title("Lobe fitting error at cos(theta_o) = 0.5 (cf. Kautz & McCool Fig. 7)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    path = out_dir / f"lobe_fit_error-{stamp}.png"
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    lines += ["", f"Plot: `{path.name}`", ""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default=str(DEFAULT_ENV) if DEFAULT_ENV.exists() else "builtin:studio")
    parser.add_argument("--size", type=int, default=200)
    parser.add_argument("--reference-spp", type=int, default=2048)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--presets", nargs="*", default=list(PRESETS))
    parser.add_argument("--methods", nargs="*", default=list(METHODS), help="section 1's methods")
    parser.add_argument(
        "--accuracy-only", action="store_true", help="section 1 alone (skip the hierarchical and fitting sections)"
    )
    parser.add_argument("--hier-face", type=int, default=64)
    parser.add_argument("--hier-targets", type=int, default=300)
    parser.add_argument("--threshold", type=float, default=1e-3)
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    env = load_environment(args.env)
    lines = [
        "# Prefiltered environment lookups (issue 6)",
        "",
        f"- date: {datetime.datetime.now().isoformat(timespec='seconds')}",
        f"- command: python bench/prefiltered.py {' '.join(argv or sys.argv[1:])}",
        "",
    ]
    if not args.accuracy_only:
        hierarchical(args, env, lines)
        fitting(lines, out_dir, stamp)
    accuracy(args, env, lines, stamp, out_dir)
    path = out_dir / f"prefiltered-{stamp}.md"
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
