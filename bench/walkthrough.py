"""``lobeview bench walkthrough``: what a walkthrough costs along a recorded camera path, and how
that cost grows with the number of objects (issue 18; thesis 4.6.4: an apartment at 30-40 fps
with ~7 samples per lobe).

Scenes: the demo room (scenes/demo.py, its recorded path) and the apartment
(scenes/apartment.py, ``--rooms``, its recorded path). For each:

- start-up, cold (an empty cube-map cache: every cube map rendered, 2 bounces) and warm (the
  same cache folder again: cube maps read from disk), as SceneRenderer's stages;
- cube maps: how many objects have one, their face sizes (scenes/analysis.py sizes each face by
  the object's lobes) and their GPU memory (radiance cube with its MIP chain), and in the same
  run a cold start with every face at full size (what the lobe-width rule saves);
- per frame of the path (``--frames`` times spread over it): the mirror passes alone (drawn,
  then glFinish) and the camera pass (draw + glFinish), objects drawn and culled in the camera
  pass and in the mirror passes, mirror passes drawn and skipped (and why); the occlusion test's
  own time (part of the mirror passes') and, in the same frame, the mirror passes without it
  (every reflector in view drawn: what the test saves) and the camera pass without its depth
  pre-pass (what shading once per pixel saves).

Then the cost table against object count: the apartment with ``--count-rooms`` rooms (about 20,
100 and 290 objects), baked once at a low lightmap quality (timing does not depend on it), the
same measurements summarised per scene size.

Timings are wall-clock on this machine (llvmpipe on a 2-core CPU is shared and noisy; the ratios
between rows measured in one run are what counts); the device is named in the output.
"""

from __future__ import annotations

import json
import shutil
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

DEFAULT_COUNT_ROOMS = (1, 6, 18)
DEFAULT_BUDGET_MB = 128.0  # the budget walk's (the 12-room apartment's cube maps take ~330 MB)
COUNT_BAKE = {"resolution": 512, "rays": 16, "bounces": 1}  # the object-count sweep's lightmaps


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def cube_memory(renderer) -> tuple[int, int]:
    """(cube maps, GPU bytes of their radiance cubes with MIP chains and any prefiltered maps)."""
    from lobeview.viewer.cube_bake import cube_gpu_bytes

    cubes = [obj.cube for obj in renderer.objects if obj.cube is not None]
    return len(cubes), sum(cube_gpu_bytes(c) for c in cubes)


def start_renderer(ctx, scene, env, size, face_size: int, cube_dir: Path, lobe_width_cubes: bool = True):
    """(renderer, seconds): SceneRenderer construction with its cube maps under ``cube_dir``."""
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    t0 = time.perf_counter()
    renderer = SceneRenderer(
        ctx,
        scene,
        env,
        size=size,
        cache_dir=cube_dir,
        settings=RenderSettings(cube_face_size=face_size, lobe_width_cubes=lobe_width_cubes),
    )
    ctx.finish()
    return renderer, time.perf_counter() - t0


def _finished_ms(ctx, draw, *args) -> float:
    """Milliseconds of ``draw(*args)`` from an idle GPU to glFinish."""
    ctx.finish()
    t0 = time.perf_counter()
    draw(*args)
    ctx.finish()
    return (time.perf_counter() - t0) * 1e3


def walk_path(renderer, path, method, frames: int) -> list[dict]:
    """Per frame of ``path``: mirror-pass and camera-pass milliseconds and the draw counters.
    One untimed frame first (shader compilation)."""
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.interface import UNIFORM_WRITES

    rows = []
    times = path.frame_times(frames)
    renderer.draw_frame(Camera.from_scene_camera(path.camera_at(0.0)), method)
    renderer.ctx.finish()
    for n, t in enumerate(times):
        camera = Camera.from_scene_camera(path.camera_at(float(t))).fitted_to(renderer.bounds)
        mirrors_drawn = method.kind != "prefiltered"
        unculled_ms, unculled_passes = 0.0, 0
        unscissored_ms = full_buffers_ms = 0.0
        full_buffer_pixels = 0
        if mirrors_drawn:  # first without the occlusion test, then without the scissor, then
            # with every buffer at the mirror scale: the frame then keeps its own buffers
            renderer.configure(mirror_occlusion=False)
            unculled_ms = _finished_ms(renderer.ctx, renderer.render_mirror_passes, camera, False, method)
            unculled_passes = len(renderer.mirror_passes.drawn)
            renderer.configure(mirror_occlusion=True)
            renderer.configure(mirror_scissor=False)
            renderer.invalidate_mirrors()
            unscissored_ms = _finished_ms(renderer.ctx, renderer.render_mirror_passes, camera, False, method)
            renderer.configure(mirror_scissor=True)
            # Buffers of another size are allocated anew: each variant is drawn once untimed so
            # that neither time holds the allocation (a GPU's is small, llvmpipe's is not).
            renderer.configure(mirror_lobe_sizes=False)
            renderer.invalidate_mirrors()
            renderer.render_mirror_passes(camera, False, method)
            renderer.invalidate_mirrors()
            full_buffers_ms = _finished_ms(renderer.ctx, renderer.render_mirror_passes, camera, False, method)
            full_buffer_pixels = renderer.mirror_passes.drawn_pixels
            renderer.configure(mirror_lobe_sizes=True)
            renderer.invalidate_mirrors()
            renderer.render_mirror_passes(camera, False, method)
        renderer.invalidate_mirrors()
        renderer.draw_counts.new_frame()
        UNIFORM_WRITES.reset()
        mirror_ms = (
            _finished_ms(renderer.ctx, renderer.render_mirror_passes, camera, False, method) if mirrors_drawn else 0.0
        )
        scissored_pixels = sum(renderer.mirror_passes.scissored_pixels.values())
        buffer_pixels = renderer.mirror_passes.drawn_pixels  # each pass at its own size
        mirror = renderer.draw_counts.of("mirror")
        mirror_draws, mirror_culled = mirror.drawn, mirror.culled
        reasons = dict(Counter(renderer.mirror_passes.skipped.values()))
        # Reuses the mirror buffers just drawn (and resets the counters).
        camera_ms = _finished_ms(renderer.ctx, renderer.draw_frame, camera, method)
        uniform_writes, uniform_values = UNIFORM_WRITES.written, UNIFORM_WRITES.written + UNIFORM_WRITES.skipped
        counts = renderer.draw_counts
        camera_drawn, camera_culled = counts.of("camera").drawn, counts.of("camera").culled
        draws = camera_drawn + mirror_draws
        # The same mirror and camera passes with every object's state set value by value
        # (RenderSettings.draw_records off): what recording it once saves.
        renderer.configure(draw_records=False)
        renderer.invalidate_mirrors()
        unrecorded_ms = (
            _finished_ms(renderer.ctx, renderer.render_mirror_passes, camera, False, method) if mirrors_drawn else 0.0
        )
        unrecorded_ms += _finished_ms(renderer.ctx, renderer.draw_frame, camera, method)
        renderer.configure(draw_records=True)
        renderer.configure(depth_prepass=False)  # the same camera pass without the depth pre-pass
        no_prepass_ms = _finished_ms(renderer.ctx, renderer.draw_frame, camera, method)
        renderer.configure(depth_prepass=True)
        rows.append(
            {
                "frame": n,
                "t": float(t),
                "mirror_ms": mirror_ms,
                "occlusion_test_ms": renderer.mirror_passes.occlusion_seconds * 1e3,
                "mirror_ms_without_test": unculled_ms,
                "mirror_ms_without_scissor": unscissored_ms,
                "mirror_ms_full_buffers": full_buffers_ms,
                "mirror_pixels_full_buffers": full_buffer_pixels,
                "mirror_pixels_scissored": scissored_pixels,
                "mirror_pixels": buffer_pixels,
                "mirror_passes_without_test": unculled_passes,
                "camera_ms": camera_ms,
                "frame_ms": mirror_ms + camera_ms,
                "camera_ms_without_prepass": no_prepass_ms,
                "frame_ms_without_records": unrecorded_ms,
                "draws": draws,
                "uniform_values_set": uniform_values,
                "uniform_writes": uniform_writes,
                "camera_drawn": camera_drawn,
                "camera_culled": camera_culled,
                "mirror_draws": mirror_draws,
                "mirror_culled": mirror_culled,
                "mirror_passes": len(renderer.mirror_passes.drawn),  # reflectors given buffers
                "mirror_buffers": renderer.mirror_passes.drawn_passes,  # passes drawn (one per plane)
                "mirror_skipped": len(renderer.mirror_passes.skipped),
                "skip_reasons": reasons,
            }
        )
    return rows


def measure_scene(ctx, label, scene, env, path, method, size, frames: int, face_size: int) -> dict:
    """Cold and warm start-up, cube maps and the per-frame rows of one scene."""
    cube_dir = Path(tempfile.mkdtemp(prefix="lobeview-walk-"))
    try:
        _say(f"[walkthrough] {label}: {len(scene.objects)} objects, cold start with every cube map at full size")
        renderer, cold_full = start_renderer(ctx, scene, env, size, face_size, cube_dir / "full", False)
        _, memory_full = cube_memory(renderer)
        renderer.release()
        _say(f"[walkthrough] {label}: cold start (every cube map rendered at its lobes' face size)")
        renderer, cold = start_renderer(ctx, scene, env, size, face_size, cube_dir)
        face_sizes = sorted(obj.cube.face_size for obj in renderer.objects if obj.cube is not None)
        cold_stages = dict(renderer.timings)
        cube_faces = renderer.draw_counts.of("cube map")
        cube_draws, cube_culled = cube_faces.drawn, cube_faces.culled
        renderer.release()
        renderer, warm = start_renderer(ctx, scene, env, size, face_size, cube_dir)
        warm_stages = dict(renderer.timings)
        cubes, memory = cube_memory(renderer)
        # cubes whose bright sources were separated hold a second MIP chain (the residual)
        cubes_with_lights = sum(1 for obj in renderer.objects if obj.cube is not None and obj.cube.lights)
        reflectors = len(renderer.reflectors())
        probe_groups = [len(g.members) for g in renderer.probes.groups]  # shared probes (scenes/probe_groups.py)
        reflectors_deferred = len(renderer.analysis.cube_mapped) - len(renderer.analysis.cubes_at_start)
        _say(
            f"[walkthrough] {label}: start-up cold {cold:.1f} s, warm {warm:.1f} s; {cubes} cube maps; {frames} frames"
        )
        rows = walk_path(renderer, path, method, frames)
        cubes_on_demand = cube_memory(renderer)[0] - cubes  # reflectors a frame shaded from a cube map
        renderer.release()
    finally:
        shutil.rmtree(cube_dir, ignore_errors=True)
    return {
        "scene": label,
        "objects": len(scene.objects),
        "reflectors": reflectors,
        "cube_maps": cubes,
        "cube_maps_with_bright_sources": cubes_with_lights,
        "cube_memory_mb": memory / 2**20,
        "cube_memory_full_mb": memory_full / 2**20,
        "reflector_cubes_deferred": reflectors_deferred,
        "cubes_built_on_demand": cubes_on_demand,
        "cube_face_sizes": {int(f): face_sizes.count(f) for f in sorted(set(face_sizes))},
        "startup_cold_s": cold,
        "startup_cold_full_s": cold_full,
        "startup_warm_s": warm,
        "cold_stages": cold_stages,
        "warm_stages": warm_stages,
        "cube_face_draws": cube_draws,
        "cube_face_culled": cube_culled,
        "probe_groups": probe_groups,
        "frames": rows,
    }


def _summary(result: dict) -> dict:
    rows = result["frames"]

    def mean(key):
        return statistics.fmean(r[key] for r in rows)

    return {
        "frame_ms_median": statistics.median(r["frame_ms"] for r in rows),
        "frame_ms_max": max(r["frame_ms"] for r in rows),
        "mirror_ms_mean": mean("mirror_ms"),
        "occlusion_test_ms_mean": mean("occlusion_test_ms"),
        "mirror_ms_without_test_mean": mean("mirror_ms_without_test"),
        "mirror_passes_without_test_mean": mean("mirror_passes_without_test"),
        "mirror_ms_without_scissor_mean": mean("mirror_ms_without_scissor"),
        "mirror_ms_full_buffers_mean": mean("mirror_ms_full_buffers"),
        "buffer_pixel_share": sum(r["mirror_pixels"] for r in rows)
        / max(sum(r["mirror_pixels_full_buffers"] for r in rows), 1),
        "scissored_fraction": sum(r["mirror_pixels_scissored"] for r in rows)
        / max(sum(r["mirror_pixels"] for r in rows), 1),
        "camera_ms_mean": mean("camera_ms"),
        "camera_ms_without_prepass_mean": mean("camera_ms_without_prepass"),
        "camera_drawn_mean": mean("camera_drawn"),
        "camera_culled_mean": mean("camera_culled"),
        "mirror_passes_mean": mean("mirror_passes"),
        "mirror_buffers_mean": mean("mirror_buffers") if all("mirror_buffers" in r for r in rows) else float("nan"),
        "mirror_skipped_mean": mean("mirror_skipped"),
        "frame_ms_without_records_mean": mean("frame_ms_without_records"),
        "frame_ms_mean": mean("frame_ms"),
        "draws_mean": mean("draws"),
        "uniform_values_mean": mean("uniform_values_set"),
        "uniform_writes_mean": mean("uniform_writes"),
    }


def budget_walk(ctx, label, scene, env, path, method, size, frames: int, face_size: int, budget_mb: float) -> dict:
    """The recorded path drawn whole (mirror passes and camera pass, draw_frame) with and without
    a cube-map memory budget (viewer/cube_bake.py CubeResidency), from a warm cache: per frame
    the time of both, the cube maps evicted and restored, and the memory resident after it."""
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    cube_dir = Path(tempfile.mkdtemp(prefix="lobeview-budget-"))
    try:
        _say(f"[walkthrough] {label}: the path with a cube-map budget of {budget_mb:g} MB")
        renderers = {
            budget: SceneRenderer(
                ctx, scene, env, size=size, cache_dir=cube_dir, progress=False,
                settings=RenderSettings(cube_face_size=face_size, cube_budget_mb=budget),
            )
            for budget in (None, budget_mb)
        }  # fmt: skip
        rows = []
        cameras = [Camera.from_scene_camera(path.camera_at(float(t))) for t in path.frame_times(frames)]
        for renderer in renderers.values():  # compile the variants
            renderer.draw_frame(cameras[0], method)
        budgeted = renderers[budget_mb]
        residency = budgeted.probes.residency
        for n, camera in enumerate(cameras):
            times = {}
            for budget, renderer in renderers.items():
                renderer.invalidate_mirrors()
                evicted, restored = residency.evictions, sum(residency.restores.values())
                times[budget] = _finished_ms(ctx, renderer.draw_frame, camera, method)
            rows.append(
                {
                    "frame": n,
                    "frame_ms": times[budget_mb],
                    "frame_ms_without_budget": times[None],
                    "evicted": residency.evictions - evicted,
                    "restored": sum(residency.restores.values()) - restored,
                    "resident_mb": cube_memory(budgeted)[1] / 2**20,
                }
            )  # fmt: skip
        peak_without = cube_memory(renderers[None])[1] / 2**20
        summary = residency.report(budgeted.objects)
        for renderer in renderers.values():
            renderer.release()
    finally:
        shutil.rmtree(cube_dir, ignore_errors=True)
    return {"scene": label, "budget_mb": budget_mb, "memory_without_budget_mb": peak_without, "report": summary,
            "frames": rows}  # fmt: skip


def _budget_markdown(result: dict) -> list[str]:
    rows = result["frames"]
    lines = [
        f"### {result['scene']} with a cube-map budget of {result['budget_mb']:g} MB",
        "",
        f"Without a budget the cube maps take {result['memory_without_budget_mb']:.0f} MB. With it: "
        f"{result['report']}. Frame time (draw_frame, mirror passes included, restores inside the frame): "
        f"median {statistics.median(r['frame_ms'] for r in rows):.0f} ms against "
        f"{statistics.median(r['frame_ms_without_budget'] for r in rows):.0f} ms without a budget; max "
        f"{max(r['frame_ms'] for r in rows):.0f} against {max(r['frame_ms_without_budget'] for r in rows):.0f} ms.",
        "",
        "| frame | frame ms | without the budget ms | evicted | restored | resident MB |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['frame']} | {r['frame_ms']:.0f} | {r['frame_ms_without_budget']:.0f} | {r['evicted']} "
            f"| {r['restored']} | {r['resident_mb']:.0f} |"
        )
    return lines + [""]


def _scene_markdown(result: dict) -> list[str]:
    s = _summary(result)
    cold_cubes = result["cold_stages"].get("cube maps", 0.0)
    warm_cubes = result["warm_stages"].get("cube maps", 0.0)
    lines = [
        f"### {result['scene']}",
        "",
        f"{result['objects']} objects, {result['reflectors']} planar reflectors, {result['cube_maps']} cube maps "
        f"({result['cube_memory_mb']:.0f} MB; faces {_face_sizes(result)}; {result['cube_memory_full_mb']:.0f} MB "
        f"and a cold start of {result['startup_cold_full_s']:.1f} s with every face at full size); "
        f"{result['reflector_cubes_deferred']} reflectors without a cube map at start-up, "
        f"{result['cubes_built_on_demand']} built on demand along the path; "
        f"{len(result.get('probe_groups', []))} shared probes serve {sum(result.get('probe_groups', []))} objects.",
        f"Start-up: cold {result['startup_cold_s']:.1f} s (cube maps {cold_cubes:.1f} s: "
        f"{result['cube_face_draws']} object draws into cube faces, {result['cube_face_culled']} culled), "
        f"warm {result['startup_warm_s']:.1f} s (cube maps {warm_cubes:.1f} s, from the cache).",
        f"Frames: median {s['frame_ms_median']:.0f} ms, max {s['frame_ms_max']:.0f} ms; mean split: mirror passes "
        f"{s['mirror_ms_mean']:.0f} ms (of which the occlusion test {s['occlusion_test_ms_mean']:.0f} ms), camera "
        f"pass {s['camera_ms_mean']:.0f} ms ({s['camera_ms_without_prepass_mean']:.0f} ms without the depth "
        "pre-pass). Without the occlusion test the mirror passes took "
        f"{s['mirror_ms_without_test_mean']:.0f} ms ({s['mirror_passes_without_test_mean']:.1f} passes) on average; "
        f"without the scissor {s['mirror_ms_without_scissor_mean']:.0f} ms (the scissor skipped "
        f"{100 * s['scissored_fraction']:.0f} % of the drawn passes' pixels); with every buffer at the mirror "
        f"scale (no lobe sizes) {s['mirror_ms_full_buffers_mean']:.0f} ms (the lobe sizes keep "
        f"{100 * s['buffer_pixel_share']:.0f} % of the buffers' pixels).",
        f"Draw state: {s['draws_mean']:.0f} draws a frame set {s['uniform_values_mean']:.0f} uniform values, of "
        f"which {s['uniform_writes_mean']:.0f} were not already in their program and went to GL; with every "
        f"object's state set value by value (no draw records) the frame took {s['frame_ms_without_records_mean']:.0f}"
        f" against {s['frame_ms_mean']:.0f} ms (means).",
        "",
        "| frame | t (s) | frame ms | mirror passes ms | of which occlusion test ms | camera pass ms "
        "| camera draws / culled | mirror-pass draws / culled | reflectors with buffers / skipped (passes drawn) "
        "| skipped because "
        "| without the test: passes, ms | without the scissor: ms | pixels scissored away "
        "| full-size buffers: ms |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["frames"]:
        reasons = ", ".join(f"{k}: {v}" for k, v in sorted(r["skip_reasons"].items())) or "-"
        lines.append(
            f"| {r['frame']} | {r['t']:.1f} | {r['frame_ms']:.0f} | {r['mirror_ms']:.0f} "
            f"| {r['occlusion_test_ms']:.0f} | {r['camera_ms']:.0f} "
            f"| {r['camera_drawn']} / {r['camera_culled']} | {r['mirror_draws']} / {r['mirror_culled']} "
            f"| {r['mirror_passes']} / {r['mirror_skipped']} ({r.get('mirror_buffers', '-')}) | {reasons} "
            f"| {r['mirror_passes_without_test']}, {r['mirror_ms_without_test']:.0f} "
            f"| {r['mirror_ms_without_scissor']:.0f} | {_share(r['mirror_pixels_scissored'], r['mirror_pixels'])} "
            f"| {r['mirror_ms_full_buffers']:.0f} |"
        )
    return lines + [""]


def _share(part: int, whole: int) -> str:
    return f"{100 * part / whole:.0f} %" if whole else "-"


def _face_sizes(result: dict) -> str:
    return ", ".join(f"{n} x {f}^2" for f, n in sorted(result["cube_face_sizes"].items(), key=lambda kv: -int(kv[0])))


def _mean_or_dash(value: float) -> str:
    """A mean to one decimal, or '-' where the runs did not record it (results of older runs)."""
    return "-" if value != value else f"{value:.1f}"


def _count_markdown(rows: list[dict]) -> list[str]:
    lines = [
        "| rooms | objects | reflectors | cube maps | cube memory MB (all at full size) | start-up cold s (all at full "
        "size) | cube-face draws / culled "
        "| start-up warm s | frame ms (median) | mirror ms (mean) | camera ms (mean) | camera draws / culled (mean) "
        "| reflectors with buffers / skipped (passes drawn; mean) | without the occlusion test: reflectors with "
        "buffers, ms (mean) "
        "| mirror ms without the scissor (mean) | pass pixels scissored away "
        "| mirror ms with full-size buffers (mean; buffer pixels kept) "
        "| camera ms without the depth pre-pass (mean) | draws, uniform values set / sent (mean) "
        "| frame ms without draw records (mean, with) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        s = _summary(r)
        lines.append(
            f"| {r['rooms']} | {r['objects']} | {r['reflectors']} | {r['cube_maps']} "
            f"| {r['cube_memory_mb']:.0f} ({r['cube_memory_full_mb']:.0f}) "
            f"| {r['startup_cold_s']:.1f} ({r['startup_cold_full_s']:.1f}) "
            f"| {r['cube_face_draws']} / {r['cube_face_culled']} | {r['startup_warm_s']:.1f} "
            f"| {s['frame_ms_median']:.0f} | {s['mirror_ms_mean']:.0f} | {s['camera_ms_mean']:.0f} "
            f"| {s['camera_drawn_mean']:.0f} / {s['camera_culled_mean']:.0f} "
            f"| {s['mirror_passes_mean']:.1f} / {s['mirror_skipped_mean']:.1f} "
            f"({_mean_or_dash(s['mirror_buffers_mean'])}) "
            f"| {s['mirror_passes_without_test_mean']:.1f}, {s['mirror_ms_without_test_mean']:.0f} "
            f"| {s['mirror_ms_without_scissor_mean']:.0f} | {100 * s['scissored_fraction']:.0f} % "
            f"| {s['mirror_ms_full_buffers_mean']:.0f} ({100 * s['buffer_pixel_share']:.0f} %) "
            f"| {s['camera_ms_without_prepass_mean']:.0f} "
            f"| {s['draws_mean']:.0f}, {s['uniform_values_mean']:.0f} / {s['uniform_writes_mean']:.0f} "
            f"| {s['frame_ms_without_records_mean']:.0f} ({s['frame_ms_mean']:.0f}) |"
        )
    return lines


def run_walkthrough_bench(
    ctx,
    device: str,
    out_dir: Path,
    stamp: str,
    *,
    size: tuple[int, int],
    frames: int,
    method: str,
    face_size: int,
    rooms: int,
    count_rooms,
    count_frames: int,
    cache: Path,
    quick: bool,
    budget_mb: float = DEFAULT_BUDGET_MB,
) -> Path:
    from lobeview.core.methods import Method
    from lobeview.scenes.apartment import apartment_path, build_apartment_scene
    from lobeview.scenes.demo import demo_path
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import load_scene_and_environment

    method_obj = Method.parse(method)
    t_start = time.perf_counter()
    results = []
    _, demo, env, _ = load_scene_and_environment(None, None, str(cache))
    results.append(measure_scene(ctx, "demo", demo, env, demo_path(), method_obj, size, frames, face_size))
    scene_arg = f"builtin:apartment-{rooms}"
    _, apartment, env, _ = load_scene_and_environment(scene_arg, None, str(cache))
    results.append(
        measure_scene(ctx, scene_arg, apartment, env, apartment_path(rooms), method_obj, size, frames, face_size)
    )
    budget = budget_walk(
        ctx, scene_arg, apartment, env, apartment_path(rooms), method_obj, size, frames, face_size, budget_mb
    )
    count_rows = []
    for count in count_rooms:
        glb = build_apartment_scene(count, directory=cache / "apartment", **COUNT_BAKE)
        scene = load_gltf(glb)
        row = measure_scene(
            ctx,
            f"apartment-{count} (sweep)",
            scene,
            env,
            apartment_path(count),
            method_obj,
            size,
            count_frames,
            face_size,
        )
        row["rooms"] = count
        count_rows.append(row)
    elapsed = time.perf_counter() - t_start

    out_dir.mkdir(parents=True, exist_ok=True)
    stem = f"walkthrough-{stamp}{'-quick' if quick else ''}"
    record = {
        "device": device,
        "size": list(size),
        "method": method,
        "face_size": face_size,
        "frames": frames,
        "count_frames": count_frames,
        "count_bake": COUNT_BAKE,
        "scenes": results,
        "budget": budget,
        "object_count": count_rows,
        "seconds": elapsed,
    }
    (out_dir / f"{stem}.json").write_text(json.dumps(record, indent=1) + "\n")
    lines = [
        f"# Walkthrough bench {stamp}{' (quick)' if quick else ''}",
        "",
        f"Device: {device}. Frame {size[0]}x{size[1]}, method {method}, cube faces {face_size}^2 (2 bounces), "
        f"{frames} frames spread over each recorded path (`lobeview view SCENE --path builtin` flies it). "
        "Wall-clock milliseconds with glFinish after the mirror passes and after the camera pass; mirror "
        "buffers redrawn every frame; one untimed frame first. Cold start: an empty cube-map cache; warm: "
        f"the same cache again. Whole run {elapsed / 60:.1f} min.",
        "",
        "## Cost against object count",
        "",
        f"The apartment at {', '.join(str(c) for c in count_rooms)} rooms (lightmaps baked at "
        f"{COUNT_BAKE['resolution']}^2, {COUNT_BAKE['rays']} rays, {COUNT_BAKE['bounces']} bounce: timing does "
        f"not depend on them), {count_frames} frames of each one's path.",
        "",
        *_count_markdown(count_rows),
        "",
        "## Per frame",
        "",
    ]
    for result in results:
        lines += _scene_markdown(result)
    lines += ["## Cube-map memory budget", "", *_budget_markdown(budget)]
    md = out_dir / f"{stem}.md"
    md.write_text("\n".join(lines) + "\n")
    _say(f"[walkthrough] wrote {md} and {stem}.json ({elapsed / 60:.1f} min)")
    return md


def run_walkthrough_command(args, out_dir: Path, stamp: str) -> int:
    """``lobeview bench walkthrough`` with the command line's options."""
    from lobeview.core.errors import parse_size
    from lobeview.core.paths import cache_dir
    from lobeview.scenes.apartment import DEFAULT_ROOMS
    from lobeview.viewer.context import create_headless_context, renderer_description

    sizes = args.resolutions or (["320x200"] if args.quick else ["640x400"])
    if len(sizes) != 1:
        from lobeview.bench import BenchError

        raise BenchError("walkthrough: one --resolutions size at a time")
    ctx = create_headless_context()
    run_walkthrough_bench(
        ctx,
        renderer_description(ctx),
        out_dir,
        stamp,
        size=parse_size(sizes[0]),
        frames=args.frames or (8 if args.quick else 24),
        method=(args.methods or ["lobe-7"])[0],
        # --quick renders 64^2 faces unless --face-size was changed from its default (256).
        face_size=64 if args.quick and args.face_size == 256 else args.face_size,
        rooms=args.rooms or (6 if args.quick else DEFAULT_ROOMS),
        count_rooms=args.count_rooms or ((1, 4) if args.quick else DEFAULT_COUNT_ROOMS),
        count_frames=args.frames or (4 if args.quick else 12),
        cache=cache_dir(args.cache),
        quick=args.quick,
        budget_mb=args.cube_budget or DEFAULT_BUDGET_MB,
    )
    ctx.release()
    return 0
