"""CPU cost of a frame against the scene's size (issue 42): one draw call per object against the
multi-draws of viewer/object_batches.py, on the apartment at several room counts.

    python -m lobeview.bench.draw_cost                      # 1, 6, 18 rooms at 64x40 and 160x100
    python -m lobeview.bench.draw_cost --rooms 1 6 18 40 --frames 24

For each apartment (lightmaps baked at 512^2, 16 rays, 1 bounce, cached; cube faces 64^2) and
each frame size, the recorded path is flown twice in one run, with ``RenderSettings``
``indirect_draws`` off and on; every frame draws its mirror passes again (as while moving).
Per frame it records the milliseconds ``SceneRenderer.draw_frame`` takes to return (the CPU's
part: Python, uniform and binding calls, the driver's submission; on llvmpipe also its vertex
processing) and to glFinish (everything), and the draw calls made (per-object draws, multi-draws,
culling compute passes). At these small sizes llvmpipe's rasterising is small, as the shading
is beside a GPU. Wall-clock on a shared machine: compare the rows of one run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.bench.walkthrough import COUNT_BAKE

DEFAULT_ROOMS = (1, 6, 18)
# The calls in which a driver does the pass's work (llvmpipe shades vertices and runs compute
# passes inside them; a GPU's driver only queues it): the rest of the submit time is Python and
# state calls, which a GPU does not take away.
DRIVER_WORK_CALLS = (("VertexArray", "render"), ("VertexArray", "render_indirect"), ("ComputeShader", "run"),
                     ("Context", "memory_barrier"))  # fmt: skip


class ModernglPatches:
    """Replaces moderngl's wrappers of DRIVER_WORK_CALLS, of reading a query's samples and of
    reading a buffer while installed; ``remove`` puts them back. ``work(original)`` and
    ``read(original)`` make the replacements."""

    def __init__(self):
        import moderngl

        self._originals = []
        for class_name, method in DRIVER_WORK_CALLS:
            cls = getattr(moderngl, class_name)
            original = getattr(cls, method)
            self._originals.append((cls, method, original))
            setattr(cls, method, self.work(original))
        samples = moderngl.Query.samples  # a property
        self._originals.append((moderngl.Query, "samples", samples))
        moderngl.Query.samples = property(self.read(samples.fget))
        read = moderngl.Buffer.read  # the counted occlusion test's read-back
        self._originals.append((moderngl.Buffer, "read", read))
        moderngl.Buffer.read = self.read(read)

    def work(self, original):
        raise NotImplementedError

    def read(self, original):
        raise NotImplementedError

    def remove(self) -> None:
        for cls, method, original in self._originals:
            setattr(cls, method, original)


class DriverWorkTimer(ModernglPatches):
    """Seconds spent inside DRIVER_WORK_CALLS while installed (moderngl's Python wrappers timed),
    and apart from them (``wait_seconds``) in reading query results and buffers: the mirror
    passes' occlusion test waits there for the device to finish its depth pass and its queries or
    counting draw (viewer/occlusion.py; on llvmpipe: the rasterising itself, done on the CPU's
    cores; on a GPU: the round trip, a sync point that keeps CPU and GPU from overlapping)."""

    def __init__(self):
        self.seconds = 0.0
        self.wait_seconds = 0.0
        self.reads: list = []  # results of the reads (query samples, buffers), in order
        super().__init__()

    def work(self, original):
        return self._timed(original)

    def read(self, original):
        return self._timed(original, wait=True)

    def _timed(self, original, wait: bool = False):
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                result = original(*args, **kwargs)
            finally:
                if wait:
                    self.wait_seconds += time.perf_counter() - t0
                else:
                    self.seconds += time.perf_counter() - t0
            if wait:  # what the frame read back, for DeviceIdle to give again
                self.reads.append(result)
            return result

        return timed


class DeviceIdle(ModernglPatches):
    """While installed, the calls of DRIVER_WORK_CALLS do nothing and each read (a query's
    samples, a buffer) returns what the measured flight read at that point of the same frame, so
    a path flown again takes the same branches (the occlusion test's counts decide the mirror
    passes) with no device work at all: the Python and state calls alone, without llvmpipe's
    rasterising between them, whose cache traffic slows the Python in proportion to the scene's
    pixels and vertices (a GPU's work leaves the CPU's caches alone). ``frames``: the reads of
    each measured frame (DriverWorkTimer.reads per frame). ``missed``: reads asked for beyond the
    recorded ones (then read for real), and frames whose draw calls or mirror passes differ from
    the measured frame's (idle_walk): 0 when the flights took the same branches."""

    def __init__(self, frames: list[list]):
        self.frames = frames
        self.missed = 0
        self._pending: list = []
        super().__init__()

    def work(self, original):
        return lambda *args, **kwargs: None

    def frame(self, k: int) -> None:
        """The next reads are frame ``k``'s."""
        self._pending = list(self.frames[k])

    def read(self, original):
        def replayed(*args, **kwargs):
            if self._pending:
                return self._pending.pop(0)
            self.missed += 1
            return original(*args, **kwargs)

        return replayed


DEFAULT_SIZES = ("64x40", "160x100")
# (multi-draws, reflectors in one plane share its pass) per measured path: one draw per object,
# the multi-draws with a mirror pass per reflector (as before issue 42's plane sharing), and today's.
PATHS = ((False, True), (True, False), (True, True))


def path_label(indirect: bool, shared: bool = True) -> str:
    if not indirect:
        return "per object"
    return "multi-draw" if shared else "multi-draw, a pass per reflector"


FACE_SIZE = 64


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def walk(renderer, path, method, frames: int, timer: DriverWorkTimer) -> list[dict]:
    """Per frame of ``path``: submit and finished milliseconds and the draw calls."""
    from lobeview.viewer.camera import Camera

    ctx = renderer.ctx
    rows = []
    renderer.draw_frame(Camera.from_scene_camera(path.camera_at(0.0)), method)  # compile shaders
    ctx.finish()
    for t in path.frame_times(frames):
        camera = Camera.from_scene_camera(path.camera_at(float(t)))
        renderer.invalidate_mirrors()
        ctx.finish()
        calls = renderer.drawer.draw_calls.total()
        driver_before, wait_before = timer.seconds, timer.wait_seconds
        timer.reads = []
        t0 = time.perf_counter()
        renderer.draw_frame(camera, method)
        submitted = time.perf_counter()
        driver = timer.seconds - driver_before
        wait = timer.wait_seconds - wait_before
        ctx.finish()
        finished = time.perf_counter()
        single, multi, culls = np.subtract(renderer.drawer.draw_calls.total(), calls)
        rows.append(
            {
                "t": float(t),
                "submit_ms": (submitted - t0) * 1e3,
                "python_ms": (submitted - t0 - driver - wait) * 1e3,
                "wait_ms": wait * 1e3,
                "finished_ms": (finished - t0) * 1e3,
                "single_draws": int(single),
                "multi_draws": int(multi),
                "cull_passes": int(culls),
                "objects_drawn": renderer.draw_counts.of("camera").drawn + renderer.draw_counts.of("mirror").drawn,
                "mirror_passes": renderer.mirror_passes.drawn_passes,
                "reads": timer.reads,
            }
        )
    return rows


IDLE_FLIGHTS = 5  # device-idle flights of a path; a frame's fastest is kept (noise only adds)


def idle_walk(renderer, path, method, rows: list[dict], flights: int = IDLE_FLIGHTS) -> int:
    """Fly ``rows``' frames again ``flights`` times with the device idle (DeviceIdle): each row
    gets ``idle_ms``, the fewest milliseconds ``draw_frame`` took then (a millisecond's work, on
    a shared machine). Returns DeviceIdle.missed (0: the same branches)."""
    from lobeview.viewer.camera import Camera

    idle = DeviceIdle([row["reads"] for row in rows])
    try:
        for k, row in [(k, row) for _ in range(flights) for k, row in enumerate(rows)]:
            camera = Camera.from_scene_camera(path.camera_at(row["t"]))
            renderer.invalidate_mirrors()
            idle.frame(k)
            calls = renderer.drawer.draw_calls.total()
            t0 = time.perf_counter()
            renderer.draw_frame(camera, method)
            row["idle_ms"] = min(row.get("idle_ms", np.inf), (time.perf_counter() - t0) * 1e3)
            single, multi, culls = np.subtract(renderer.drawer.draw_calls.total(), calls)
            same = (single, multi, culls, renderer.mirror_passes.drawn_passes) == (
                row["single_draws"],
                row["multi_draws"],
                row["cull_passes"],
                row["mirror_passes"],
            )
            idle.missed += 0 if same else 1  # a frame that took other branches counts as a miss
    finally:
        idle.remove()
    for row in rows:
        del row["reads"]  # buffers' bytes: not for the JSON
    return idle.missed


def measure(ctx, rooms: int, sizes, frames: int, cache: Path, method: str) -> list[dict]:
    from lobeview.core.methods import Method
    from lobeview.scenes.apartment import apartment_path, build_apartment_scene
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import load_scene_and_environment
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    _say(f"apartment-{rooms}: building (lightmaps cached after the first run)")
    # The walkthrough sweep's lightmaps: cached, shared with it.
    glb = build_apartment_scene(rooms, directory=cache / "apartment", **COUNT_BAKE)
    scene = load_gltf(glb)
    _, _, env, _ = load_scene_and_environment(None, None, str(cache))
    path = apartment_path(rooms)
    out = []
    for size in sizes:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            renderer = SceneRenderer(
                ctx, scene, env, size=size, progress=False, cache_dir=cache / "cubes",
                settings=RenderSettings(cube_face_size=FACE_SIZE),
            )  # fmt: skip
        try:
            for indirect, shared in PATHS:
                renderer.configure(indirect_draws=indirect, mirror_plane_sharing=shared)
                _say(f"apartment-{rooms} {size[0]}x{size[1]}: {path_label(indirect, shared)}")
                timer = DriverWorkTimer()
                try:
                    rows = walk(renderer, path, Method.parse(method), frames, timer)
                finally:
                    timer.remove()
                missed = idle_walk(renderer, path, Method.parse(method), rows)
                renderer.ctx.finish()
                out.append(
                    {
                        "rooms": rooms,
                        "objects": len(scene.objects),
                        "size": list(size),
                        "indirect": indirect,
                        "shared_planes": shared,
                        "frames": rows,
                        "idle_missed_reads": missed,
                    }
                )
        finally:
            renderer.release()
    return out


def summary(run: dict) -> dict:
    rows = run["frames"]

    def median(key):
        return statistics.median(r[key] for r in rows)

    def mean(key):
        return statistics.fmean(r[key] for r in rows)

    return {
        "submit_ms": median("submit_ms"),
        "python_ms": median("python_ms"),
        "idle_ms": median("idle_ms") if all("idle_ms" in r for r in rows) else float("nan"),
        "wait_ms": median("wait_ms") if all("wait_ms" in r for r in rows) else float("nan"),
        "finished_ms": median("finished_ms"),
        "single_draws": mean("single_draws"),
        "multi_draws": mean("multi_draws"),
        "cull_passes": mean("cull_passes"),
        "objects_drawn": mean("objects_drawn"),
        "mirror_passes": mean("mirror_passes") if all("mirror_passes" in r for r in rows) else float("nan"),
    }


def markdown(runs: list[dict], device: str, method: str, frames: int, elapsed: float) -> str:
    lines = [
        "# Frame CPU cost against scene size (issue 42)",
        "",
        f"Device: {device}. Method {method}, cube faces {FACE_SIZE}^2, {frames} frames along each apartment's "
        "recorded path, mirror passes redrawn every frame. *submit*: milliseconds until `draw_frame` returns "
        "(Python, GL calls, driver submission; llvmpipe also shades vertices there), *Python + state*: submit "
        "minus the time inside the draw, dispatch and barrier calls (where llvmpipe does the pass's work and a "
        "GPU's driver only queues it: the CPU cost a GPU does not take away) and in *occlusion wait*, "
        "*occlusion wait*: reading the mirror passes' occlusion test (its queries or its counts), which waits "
        "for the device to finish the test's depth pass (llvmpipe: its rasterising, on the CPU; a GPU: a round "
        "trip that stalls the CPU), *finished*: until glFinish, *device idle*: `draw_frame` when the same "
        f"frames are flown again ({IDLE_FLIGHTS} times, each frame's fastest) with the draw, dispatch and "
        "barrier calls doing nothing and every read-back "
        "returning what the measured frame read (the same branches, no device work: the Python and state "
        "calls without llvmpipe's rasterising in between, whose cache traffic slows the Python more the "
        "bigger the scene; what a GPU leaves of the frame's CPU cost, its driver's queuing aside). "
        f"Medians over the frames; draw calls are means per frame. Whole run {elapsed / 60:.1f} min.",
        "",
        "| rooms | objects | size | path | submit ms | Python + state ms | device idle ms | occlusion wait ms "
        "| finished ms | per-object draws | multi-draws | culling passes | mirror passes "
        "| objects drawn (camera + mirror) | submit vs per-object |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    base = {}
    for run in runs:
        s = summary(run)
        key = (run["rooms"], tuple(run["size"]))
        if not run["indirect"]:
            base[key] = s["submit_ms"]
        ratio = s["submit_ms"] / base[key] if key in base and base[key] > 0 else float("nan")
        lines.append(
            f"| {run['rooms']} | {run['objects']} | {run['size'][0]}x{run['size'][1]} "
            f"| {path_label(run['indirect'], run.get('shared_planes', True))} | {s['submit_ms']:.1f} "
            f"| {s['python_ms']:.1f} | {s['idle_ms']:.1f} | {s['wait_ms']:.1f} | {s['finished_ms']:.1f} "
            f"| {s['single_draws']:.0f} | {s['multi_draws']:.0f} | {s['cull_passes']:.0f} | {s['mirror_passes']:.1f} "
            f"| {s['objects_drawn']:.0f} "
            f"| {ratio:.2f} |"
        )
    for column, label in (("submit_ms", "submit"), ("python_ms", "Python + state"), ("idle_ms", "device idle")):
        by_size: dict = {}
        for run in runs:
            if run["indirect"] and run.get("shared_planes", True):
                by_size.setdefault(tuple(run["size"]), []).append((run["rooms"], summary(run)[column]))
        lines += ["", f"Growth with the scene (multi-draw path, {label} ms against the smallest apartment):", ""]
        for size, values in by_size.items():
            values.sort()
            first = max(values[0][1], 1e-9)
            growth = ", ".join(f"{rooms} rooms {ms / first:.2f}x ({ms:.1f} ms)" for rooms, ms in values)
            lines.append(f"- {size[0]}x{size[1]}: {growth}")
    missed = sum(run.get("idle_missed_reads", 0) for run in runs)
    lines += [
        "",
        "Device-idle frames that read back more than the measured frame or drew other calls or mirror passes "
        f"(0: the same branches): {missed}.",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from lobeview.core.errors import parse_size
    from lobeview.core.paths import cache_dir
    from lobeview.viewer.context import create_headless_context, renderer_description

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.draw_cost", description=__doc__.split("\n\n")[0])
    p.add_argument("--rooms", type=int, nargs="+", default=list(DEFAULT_ROOMS), help="apartment sizes (default 1 6 18)")
    p.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES), help="frame sizes (default 64x40 160x100)")
    p.add_argument("--frames", type=int, default=16, help="frames along each path (default 16)")
    p.add_argument("--method", default="lobe-7", help="the frame's method (default lobe-7)")
    p.add_argument("--cache", default=None, help="cache folder (default: lobeview's)")
    p.add_argument(
        "--out",
        default=None,
        help="Markdown report, or a folder for draw-cost-STAMP.md in it (default bench/results; + .json)",
    )
    args = p.parse_args(argv)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = Path(args.out) if args.out else Path(__file__).parent / "results"
    if out.is_dir() or not out.suffix:  # a folder: the stamped name in it
        out = out / f"draw-cost-{stamp}.md"
    sizes = [parse_size(s) for s in args.sizes]
    ctx = create_headless_context()
    device = renderer_description(ctx)
    t0 = time.perf_counter()
    runs = []
    for rooms in args.rooms:
        runs += measure(ctx, rooms, sizes, args.frames, cache_dir(args.cache), args.method)
    text = markdown(runs, device, args.method, args.frames, time.perf_counter() - t0)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    out.with_suffix(".json").write_text(json.dumps({"device": device, "runs": runs}, indent=1) + "\n")
    print(text)
    _say(f"written {out}")
    ctx.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
