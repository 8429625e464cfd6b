"""Shared probes (scenes/probe_groups.py, issue 18): what sharing one cube map between nearby small
objects with wide lobes saves and what it costs in error, for the link distances swept.

Scenes: the one-room apartment (its study: a plastic sphere and a gold torus on a desk), the
Khronos CornellBox (when ../shared/assets is present) and a prop shelf: the apartment's study with
a row of small glossy props (plastic, rough gold, walnut spheres of 6 cm, 20 cm apart) on its desk,
the case sharing is for. For each scene and link, against the same scene with a cube map per
object (``shared_probes=False``), both started cold with the same options: groups, cube maps,
their GPU memory and the start-up time; then every group is framed from the two of eight sides
that show its members best (1.1 x its size away, lobe-7) and each member's pixels (from the
G-buffer's object ids) are compared: relative RMSE and PSNR (peak: the 99th percentile of the
unshared pixels). The worst member per link is what the default rule was chosen by.

    .venv/bin/python -m lobeview.bench.probe_sharing [--links 1.5 2 2.5 3] [--size 320x200]
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.scenes.probe_groups import SHARED_PROBE_LINK

LINKS = (1.5, 2.0, 2.5, 3.0)  # scenes/probe_groups.py SHARED_PROBE_LINK is the chosen one
METHOD = "lobe-7"
SHELF_MATERIALS = ("plastic", "gold-ggx", "walnut")


def prop_shelf(scene):
    """The one-room apartment with a row of ten small glossy spheres along its study desk (no
    lightmap coordinates: their diffuse light is the environment's irradiance, the same with and
    without sharing, which is what is compared)."""
    from lobeview.scenes.meshes import translated, uv_sphere
    from lobeview.scenes.scene import SceneObject

    names = [o.name for o in scene.objects]
    desk = scene.objects[names.index("study 1 desk")].mesh.positions
    top, (x0, x1) = float(desk[:, 1].max()), (float(desk[:, 0].min()), float(desk[:, 0].max()))
    z = float(desk[:, 2].min()) + 0.12
    materials = {m.name: i for i, m in enumerate(scene.materials)}
    radius = 0.06
    for k, x in enumerate(np.linspace(x0 + 0.15, x1 - 0.15, 10)):
        material = SHELF_MATERIALS[k % len(SHELF_MATERIALS)]
        mesh = translated(uv_sphere(radius, 16, 32), [x, top + radius, z], f"prop {k}")
        proxy = scene.objects[names.index("study 1 desk")].reflection_proxy
        scene.objects.append(SceneObject(f"shelf prop {k} ({material})", mesh, materials[material], None, proxy))
    return scene


def _scenes(cache: Path, with_cornell: bool):
    from lobeview.scenes.setup import load_scene_and_environment

    found = []
    _, apartment, env, _ = load_scene_and_environment("builtin:apartment-1", None, str(cache))
    found.append(("apartment-1", apartment, env))
    _, shelf, env, _ = load_scene_and_environment("builtin:apartment-1", None, str(cache))
    found.append(("apartment-1 + prop shelf", prop_shelf(shelf), env))
    cornell = Path(__file__).resolve().parents[2] / "shared" / "assets" / "gltf" / "CornellBox" / "CornellBox.glb"
    if with_cornell and cornell.is_file():
        _, box, env, _ = load_scene_and_environment(str(cornell), None, str(cache))
        found.append(("CornellBox.glb", box, env))
    return found


def _start(ctx, scene, env, size, folder: Path, **options):
    from lobeview.bench.walkthrough import cube_memory
    from lobeview.viewer.scene_renderer import SceneRenderer

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # objects without lightmaps are expected here
        renderer = SceneRenderer(ctx, scene, env, size=size, cache_dir=folder, progress=False, **options)
    ctx.finish()
    seconds = time.perf_counter() - t0
    cubes, memory = cube_memory(renderer)
    return renderer, seconds, cubes, memory


def _views(renderer, groups, method) -> list:
    """Two cameras per group: of eight around it (1.1 x its size away, at least 0.8 m, looking a
    little down), the two that show its least visible member best (walls hide the others)."""
    from lobeview.viewer.camera import Camera

    views = []
    for group in groups:
        centre = group.centre
        reach = max(0.8, 1.1 * float(np.linalg.norm(group.box_max - group.box_min)))
        scored = []
        for angle in np.linspace(0.0, 2 * np.pi, 8, endpoint=False):
            direction = np.array([np.cos(angle), 0.45, np.sin(angle)])
            eye = centre + reach * direction / np.linalg.norm(direction)
            camera = Camera(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), 50.0)
            _, ids = _frame(renderer, camera, method)
            scored.append((min(int((ids == i).sum()) for i in group.members), len(scored), camera))
        views += [(group.members, camera) for _, _, camera in sorted(scored, reverse=True)[:2]]
    return views


def _frame(renderer, camera, method):
    """(radiance, object index per pixel) of one real-time frame."""
    result = renderer.render(camera, method)
    return result.radiance, result.object_id


def member_errors(reference, shared, views, method, figure: list | None = None) -> list[dict]:
    """Per member and view: relative RMSE and PSNR of its pixels; ``figure`` gets, for the view
    with the worst member, a row: own cube maps | shared probe | |difference| x 8 (tone-mapped)."""
    from lobeview.bench.metrics import exposure_for
    from lobeview.viewer.tonemap import tonemap

    rows, worst = [], (-1.0, None)
    for members, camera in views:
        want, ids = _frame(reference, camera, method)
        got, _ = _frame(shared, camera, method)
        first = len(rows)
        for index in members:
            mask = ids == index
            if mask.sum() < 30:
                continue
            a, b = want[mask], got[mask]
            mse = float(np.mean((a - b) ** 2))
            peak = float(np.percentile(a, 99))
            rows.append(
                {
                    "object": reference.objects[index].name,
                    "pixels": int(mask.sum()),
                    "rel_rmse": float(np.sqrt(mse) / max(np.sqrt(np.mean(a**2)), 1e-12)),
                    "psnr": float(10 * np.log10(peak**2 / mse)) if mse > 0 else float("inf"),
                }
            )
        view_worst = max((r["rel_rmse"] for r in rows[first:]), default=-1.0)
        if view_worst > worst[0]:
            worst = (view_worst, (want, got, ids >= 0))
    if figure is not None and worst[1] is not None:
        want, got, geometry = worst[1]
        exposure = exposure_for(want, geometry)

        def ldr(radiance):
            return np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0)

        figure.append(np.concatenate([ldr(want), ldr(got), np.clip(8 * np.abs(ldr(want) - ldr(got)), 0, 1)], axis=1))
    return rows


def run(links, size, cache: Path, with_cornell: bool = True) -> dict:
    from lobeview.core.methods import Method
    from lobeview.viewer.context import create_headless_context, renderer_description

    ctx = create_headless_context()
    method = Method.parse(METHOD)
    results = {"device": renderer_description(ctx), "size": list(size), "method": METHOD, "scenes": []}
    figure = []
    folder = Path(tempfile.mkdtemp(prefix="lobeview-probes-"))
    try:
        for label, scene, env in _scenes(cache, with_cornell):
            print(f"[probes] {label}: {len(scene.objects)} objects", flush=True)
            reference, ref_s, ref_cubes, ref_memory = _start(ctx, scene, env, size, folder / "own")
            entry = {"scene": label, "objects": len(scene.objects), "cube_maps": ref_cubes,
                     "cube_mb": ref_memory / 2**20, "startup_s": ref_s, "links": []}  # fmt: skip
            for link in links:
                shared, seconds, cubes, memory = _start(
                    ctx, scene, env, size, folder / f"l{link}", shared_probes=True, probe_link=link
                )
                views = _views(reference, shared.probes.groups, method)
                errors = member_errors(reference, shared, views, method, figure if link == SHARED_PROBE_LINK else None)
                groups = [[shared.objects[i].name for i in g.members] for g in shared.probes.groups]
                entry["links"].append(
                    {
                        "link": link,
                        "groups": groups,
                        "cube_maps": cubes,
                        "cube_mb": memory / 2**20,
                        "startup_s": seconds,
                        "members": errors,
                    }  # fmt: skip
                )
                worst = max((e["rel_rmse"] for e in errors), default=0.0)
                print(f"[probes]   link {link}: {len(groups)} groups, {cubes} cube maps, worst relRMSE {worst:.3f}")
                shared.release()
            reference.release()
            results["scenes"].append(entry)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        ctx.release()
    results["figure"] = figure
    return results


def markdown(results: dict, stamp: str) -> str:
    lines = [
        f"# Shared probes {stamp}",
        "",
        f"Device: {results['device']}; {results['size'][0]}x{results['size'][1]}, {results['method']}; "
        "errors of group members against a cube map per object, over two views per group "
        "(bench/probe_sharing.py). Cold start-up with an empty cache. Figure (.png): per scene, the view with the "
        f"worst member at the default link ({SHARED_PROBE_LINK}): own cube maps | shared probe | |difference| x 8.",
        "",
        "| scene | link | groups | cube maps (own) | cube MB (own) | start-up s (own) | members measured "
        "| worst member relRMSE | median relRMSE | lowest PSNR dB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for entry in results["scenes"]:
        for row in entry["links"]:
            errors = row["members"]
            rel = [e["rel_rmse"] for e in errors]
            lines.append(
                f"| {entry['scene']} | {row['link']} | {len(row['groups'])} "
                f"| {row['cube_maps']} ({entry['cube_maps']}) "
                f"| {row['cube_mb']:.1f} ({entry['cube_mb']:.1f}) | {row['startup_s']:.1f} ({entry['startup_s']:.1f}) "
                f"| {len(errors)} | {max(rel, default=0.0):.3f} | {statistics.median(rel) if rel else 0.0:.3f} "
                f"| {min((e['psnr'] for e in errors), default=float('inf')):.1f} |"
            )
    lines += ["", "Groups and the worst members:", ""]
    for entry in results["scenes"]:
        for row in entry["links"]:
            worst = sorted(row["members"], key=lambda e: -e["rel_rmse"])[:3]
            said = "; ".join(f"{e['object']} {e['rel_rmse']:.3f} ({e['psnr']:.1f} dB)" for e in worst) or "-"
            lines.append(f"- {entry['scene']}, link {row['link']}: {row['groups'] or 'none'}; worst: {said}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--links", nargs="+", type=float, default=list(LINKS))
    parser.add_argument("--size", default="320x200", help="WxH of the measured frames")
    parser.add_argument("--cache", default=None, help="lobeview cache folder (default: the user's)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    from lobeview.bench.report import write_image_rows
    from lobeview.core.paths import cache_dir

    width, height = (int(v) for v in args.size.lower().split("x"))
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    results = run(sorted(args.links), (width, height), cache_dir(args.cache))
    out = Path(args.out)
    figure = results.pop("figure")
    if figure:
        write_image_rows(out, f"probe_sharing-{stamp}.png", figure)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"probe_sharing-{stamp}.json").write_text(json.dumps(results, indent=1))
    path = out / f"probe_sharing-{stamp}.md"
    path.write_text(markdown(results, stamp))
    print(f"[probes] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
