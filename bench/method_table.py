"""The error table behind the cheapest-method rule (issue 45; materials/method_choice.py).

For each lobe shape (GGX or Beckmann, the narrower roughness alpha_min and the anisotropy ratio
alpha_max / alpha_min) and each candidate real-time method, the preview sphere is rendered under
demanding light and compared with lobeview's converged ``reference`` (which matches Mitsuba 3
within 1-3 % on the same sphere: bench/mitsuba.py); the relative RMSE is kept over the whole sphere
and in bins of n.v, so the rule can ask about a view. The lights:

- ``sky``: bench/mitsuba.py's analytic sky, a 3-degree sun of radiance 50 and six saturated
  rectangles (the issue's scene: a light 1e3 times brighter than its surroundings);
- ``interior``: the Blender studio-light interior capture (windows to 3.5e4; ../shared/assets,
  a built-in studio sky when absent, which the table then says).

As the viewer renders: bright sources separated into cap lights (the default), cube faces sized by
the lobes' width (the scene analysis' rule, materials/lobe_spread.py lobe_width_face_size; the
reference reads a full-size cube), real-time methods rendered at ``supersample`` times the size and
averaged down so that they and the box-filtered reference cover the same pixel footprints.

    .venv/bin/python -m lobeview.bench.method_table                 # writes materials/method_errors.json
    .venv/bin/python -m lobeview.bench.method_table --size 64 --spp 256 --cases ggx:0.2 --out /tmp/t.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.materials.method_choice import (
    CANDIDATES,
    NV_EDGES,
    TABLE_PATH,
    lookups_per_lobe,
)

KINDS = ("ggx", "beckmann")
ALPHAS = (0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.8)
RATIOS = (1.0, 3.0, 8.0)
ENVS = ("sky", "interior")
FULL_FACE = 256
NOISE_TARGET = 0.025  # the reference's own relative RMSE a row is measured with, at most
MAX_REFERENCE_PARTS = 16  # renders of spp / 2 each (16 384 samples per lobe at the default spp)


def default_cases() -> list[tuple[str, float, float]]:
    """(kind, alpha_min, ratio) with alpha_max = alpha_min x ratio <= 1."""
    return [(k, a, r) for k in KINDS for r in RATIOS for a in ALPHAS if a * r <= 1.0 + 1e-9]


def parse_case(text: str) -> tuple[str, float, float]:
    """'ggx:0.2' or 'ggx:0.05x8' (alpha_min x ratio) -> (kind, alpha_min, ratio)."""
    kind, _, rest = text.partition(":")
    alpha, _, ratio = rest.partition("x")
    if kind not in KINDS or not alpha:
        raise SystemExit(f"case {text!r}: expected ggx:ALPHA or beckmann:ALPHAxRATIO")
    return kind, float(alpha), float(ratio or 1.0)


def case_material(kind: str, alpha_min: float, ratio: float) -> dict:
    """The lobe as the preview renders it: no Fresnel (the table is about the lobe's shape), the
    narrow axis along the tangent."""
    return {"model": "microfacet", "distribution": kind, "alpha_u": alpha_min, "alpha_v": min(1.0, alpha_min * ratio),
            "fresnel": {"type": "none"}, "scale": 1.0}  # fmt: skip


def load_env(name: str):
    from lobeview.scenes.envmap import EnvironmentMap

    from .mitsuba import ENV_HEIGHT, environment
    from .targets import resolve_environment

    if name == "sky":
        return EnvironmentMap.from_function(environment, height=ENV_HEIGHT, name="issue 45 sky"), "issue 45 sky"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = resolve_environment(name)
    fallback = [str(w.message) for w in caught if "instead" in str(w.message)]  # targets.resolve_environment's
    return env, (f"{name} (absent: {fallback[0]})" if fallback else name)


def view_cosines(result, camera_position) -> np.ndarray:
    """n.v per pixel of a preview render (its world positions and normals)."""
    to_camera = np.asarray(camera_position, dtype=np.float64) - result.position
    to_camera /= np.maximum(np.linalg.norm(to_camera, axis=-1, keepdims=True), 1e-12)
    return np.clip(np.sum(result.normal * to_camera, axis=-1), 0.0, 1.0)


def binned_errors(image, reference, mask, nv, noise=None) -> tuple[float, list[float | None]]:
    """Relative RMSE over ``mask`` and in each NV_EDGES bin (None where a bin has no pixel).
    ``noise``: the reference's per-pixel noise variance (:func:`reference_noise`), taken out of the
    squared error (the error against the exact image, in expectation; 0 where it is all noise)."""

    def rel(sel):
        if not np.any(sel):
            return None
        d2 = np.mean((image[sel] - reference[sel]) ** 2)
        if noise is not None:
            d2 = max(d2 - np.mean(noise[sel]), 0.0)
        return float(np.sqrt(d2) / max(np.sqrt(np.mean(reference[sel] ** 2)), 1e-12))

    bins = [rel(mask & (nv > lo) & (nv <= hi)) for lo, hi in zip(NV_EDGES[:-1], NV_EDGES[1:], strict=True)]
    return rel(mask), bins


def inner_pixels(mask: np.ndarray) -> np.ndarray:
    """The sphere's pixels whose 3 x 3 neighbourhood is all sphere: a silhouette pixel mixes the
    background by its coverage, which the box-filtered reference integrates and k x k points only
    sample (on a capture with a bright window behind the sphere, tens of percent that are no
    method's)."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, structure=np.ones((3, 3), dtype=bool))


def reference_noise(renders: list[np.ndarray]) -> np.ndarray:
    """Per-pixel variance of the mean of m independent renders: their sample variance / m (for two,
    (A - B)^2 / 4)."""
    stack = np.asarray(renders, dtype=np.float64)
    m = len(stack)
    return np.sum((stack - stack.mean(axis=0)) ** 2, axis=0) / (m * (m - 1))


def run(cases, envs, methods, size: int, spp: int, supersample: int, say=print) -> dict:
    from lobeview.core.methods import Method
    from lobeview.materials.lobe_spread import finest_sample_solid_angle, lobe_width_face_size
    from lobeview.materials.patterns import specular_lobes
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context, renderer_description
    from lobeview.viewer.preview import PreviewRenderer

    from .mitsuba import CAMERA

    ctx = create_headless_context()
    device = renderer_description(ctx)
    camera = Camera(*CAMERA)
    rows, env_names = [], {}
    start = time.perf_counter()
    for env_key in envs:
        env, env_names[env_key] = load_env(env_key)
        renderers: dict = {}

        def renderer(face: int, fine: bool, env=env, renderers=renderers):
            key = (face, fine)
            if key not in renderers:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    side = size * supersample if fine else size
                    renderers[key] = PreviewRenderer(ctx, env, uv_sphere(1.0), size=(side, side), face_size=face,
                                                     bright_sources=True)  # fmt: skip
            return renderers[key]

        for kind, alpha, ratio in cases:
            t0 = time.perf_counter()
            bsdf = build_bsdf(validate(case_material(kind, alpha, ratio)))
            face = lobe_width_face_size(finest_sample_solid_angle(specular_lobes(bsdf)), FULL_FACE)
            # Renders of spp / 2 samples with independent seeds: their mean is the reference, their
            # spread its noise; twice as many until the noise is below NOISE_TARGET (a small window
            # of a capture seen in a sharp lobe needs 4-8 times the sky's samples).
            parts = [renderer(FULL_FACE, False).render(camera, bsdf, "reference", spp=spp // 2, seed=s) for s in (0, 1)]
            reference = parts[0]
            nv = view_cosines(reference, camera.position)
            mask = inner_pixels(reference.mask)
            while True:
                truth = np.mean([p.radiance for p in parts], axis=0)
                noise = reference_noise([p.radiance for p in parts])
                floor = binned_errors(truth + np.sqrt(noise), truth, mask, nv)  # the noise's own size
                if floor[0] <= NOISE_TARGET or len(parts) >= MAX_REFERENCE_PARTS:
                    break
                parts += [renderer(FULL_FACE, False).render(camera, bsdf, "reference", spp=spp // 2, seed=s)
                          for s in range(len(parts), 2 * len(parts))]  # fmt: skip
            row = {"env": env_key, "kind": kind, "alpha_min": alpha, "ratio": ratio, "face": int(face),
                   "reference_spp": len(parts) * (spp // 2),
                   "reference_noise": {"overall": floor[0], "bins": floor[1]}, "overall": {}, "bins": {},
                   "raw_overall": {}, "pixels_per_bin": []}  # fmt: skip
            row["pixels_per_bin"] = [
                int(np.sum(mask & (nv > lo) & (nv <= hi))) for lo, hi in zip(NV_EDGES[:-1], NV_EDGES[1:], strict=True)
            ]
            for text in methods:
                method = Method.parse(text)
                frame = renderer(face, supersample > 1).render(camera, bsdf, method, spp=1).radiance
                frame = frame.reshape(size, supersample, size, supersample, 3).mean(axis=(1, 3))
                overall, bins = binned_errors(frame, truth, mask, nv, noise)
                row["overall"][text], row["bins"][text] = overall, bins
                row["raw_overall"][text] = binned_errors(frame, truth, mask, nv)[0]
            rows.append(row)
            best = min(row["overall"], key=row["overall"].get)
            say(f"[method table] {env_key} {kind}:{alpha:g}x{ratio:g} (faces {face}^2, reference noise "
                f"{100 * floor[0]:.1f} %): best {best} "
                f"{100 * row['overall'][best]:.1f} %, " + ", ".join(f"{m} {100 * e:.1f}" for m, e in
                row["overall"].items()) + f" ({time.perf_counter() - t0:.0f} s)")  # fmt: skip
        for r in renderers.values():
            r.release()
    ctx.release()
    return {
        "about": "relative RMSE of each real-time method against lobeview's reference on the preview sphere "
        "(bench/method_table.py); read by materials/method_choice.py",
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "device": device,
        "size": size,
        "spp": spp,
        "supersample": supersample,
        "envs": env_names,
        "nv_edges": list(NV_EDGES),
        "methods": list(methods),
        "lookups": {m: [lookups_per_lobe(m, False, kind) for kind in KINDS] for m in methods},
        "minutes": round((time.perf_counter() - start) / 60, 1),
        "rows": rows,
    }


def updated_table(table: dict, update: dict) -> dict:
    """``table`` with the rows of ``update`` (measured with every method of ``table``) in place of
    its rows of the same light and lobe shape; ``update``'s date and command join its "updates"."""
    if list(update["methods"]) != list(table["methods"]):
        raise SystemExit(f"--update measures every method of the table: {', '.join(table['methods'])}")
    key = lambda row: (row["env"], row["kind"], row["alpha_min"], row["ratio"])  # noqa: E731
    new_rows = {key(row): row for row in update["rows"]}
    kept = [row for row in table["rows"] if key(row) not in new_rows]
    rows = kept + list(new_rows.values())
    rows.sort(
        key=lambda row: (
            list(table["envs"]).index(row["env"]),
            KINDS.index(row["kind"]),
            row["ratio"],
            row["alpha_min"],
        )
    )
    entry = {"date": update["date"], "command": update["command"], "rows": len(new_rows), "minutes": update["minutes"]}
    return {**table, "rows": rows, "updates": [*table.get("updates", []), entry]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.method_table", description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", nargs="+", help="KIND:ALPHA or KIND:ALPHAxRATIO (default: the full grid)")
    p.add_argument("--envs", nargs="+", default=list(ENVS), choices=ENVS)
    p.add_argument("--methods", nargs="+", default=list(CANDIDATES))
    p.add_argument("--size", type=int, default=128, help="frame width and height (default 128)")
    p.add_argument(
        "--spp",
        type=int,
        default=2048,
        help="reference samples per lobe, in two halves, doubled while its noise is above 2.5 %% (default 2048)",
    )
    p.add_argument("--supersample", type=int, default=2, help="real-time methods at this many times the size")
    p.add_argument("--out", default=str(TABLE_PATH), help=f"the table (default {TABLE_PATH})")
    p.add_argument(
        "--update",
        action="store_true",
        help="replace only the measured rows of the table at --out (same lights, every candidate method), "
        "after a change that moves some lobe shapes; the table lists its updates",
    )
    args = p.parse_args(argv)
    cases = [parse_case(c) for c in args.cases] if args.cases else default_cases()
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    say(f"[method table] {len(cases)} lobe shapes x {len(args.envs)} lights x {len(args.methods)} methods")
    table = run(cases, args.envs, args.methods, args.size, args.spp, args.supersample, say)
    table["command"] = "python -m lobeview.bench.method_table " + " ".join(argv if argv is not None else sys.argv[1:])
    minutes = table["minutes"]  # this run's (an update's table keeps the full run's own)
    if args.update:
        table = updated_table(json.loads(Path(args.out).read_text()), table)
    Path(args.out).write_text(json.dumps(table, indent=1) + "\n")
    say(f"[method table] wrote {args.out} ({minutes} min)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
