"""A scene's lightmap bake in a separate process (issue 42 item 2: a first frame in seconds;
issue 40 item 3: a user's glTF baked on first use). On first use the demo and the apartment are
baked on the CPU (half a minute for the demo, about two for the 12-room apartment), and so is a
glTF file without lightmaps (scenes/gltf_bake.py: Suzanne 13 s, into the cache, keyed by
content); the window does not wait: it opens on the scene without lightmaps (diffuse light from
the environment, nothing occluded) while a worker process builds and caches the baked .glb, then
swaps it in (app/finishing.py).

A process, not a thread: the baker's numpy loops would hold the interpreter's lock against the
window's frames. The worker reports its progress lines through a queue; its result is the cached
file's path or the error that stopped it. Closing the window stops the worker; the bake writes
its file atomically (scenes/demo.py bake_and_write), so a stopped bake leaves nothing half
written and the next start bakes again."""

from __future__ import annotations

import multiprocessing
import queue
import time
from pathlib import Path

PROGRESS_INTERVAL_S = 0.25  # the worker sends at most this many progress lines a second


def _trace_horizon_maps(scene_path: str, horizon_cache: str, limits) -> Path:
    """The self-occlusion of the scene file's objects traced into the viewer's cache folder, where
    its renderer finds them: the horizon maps per lightmap texel (scenes/horizon_maps.py; taken by
    SceneShading.prepare_horizon_maps) and the vertices' visibility cones (scenes/
    self_visibility.py; which a renderer made for the file would otherwise trace between frames)."""
    from lobeview.core.progress import report
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.horizon_maps import trace_horizon_maps
    from lobeview.scenes.self_visibility import object_visibility_cones

    scene = load_gltf(Path(scene_path), limits)
    report("self-occlusion cones of the vertices", None)
    for obj in scene.objects:
        object_visibility_cones(obj, Path(horizon_cache))
    trace_horizon_maps(scene, Path(horizon_cache))
    return Path(scene_path)


def _horizon_maps_after_bake(path: Path, horizon_cache: str | None, limits) -> None:
    """A bake's horizon maps traced in the same worker, so that the baked scene comes in with them;
    a failure here is left to the window's own horizon-map worker (which says why)."""
    if horizon_cache is None:
        return
    try:
        _trace_horizon_maps(str(path), horizon_cache, limits)
    except Exception:  # noqa: BLE001 - the bake itself succeeded
        pass


def _build_builtin(scene_arg: str | None, cache: str, horizon_cache: str | None = None) -> Path:
    from lobeview.core.trust import DEFAULT_LIMITS
    from lobeview.scenes.setup import build_builtin_scene

    path = build_builtin_scene(scene_arg, Path(cache))
    _horizon_maps_after_bake(path, horizon_cache, DEFAULT_LIMITS)
    return path


def _bake_gltf_file(source: str, environment_spec: str, out: str, limits, horizon_cache: str | None = None) -> Path:
    from lobeview.scenes.gltf_bake import bake_first_use

    path = bake_first_use(Path(source), environment_spec, Path(out), limits)
    _horizon_maps_after_bake(path, horizon_cache, limits)
    return path


def bake_worker(build, arguments: tuple, messages) -> None:
    """The worker process: ``build(*arguments)`` (bakes and returns the written scene's path),
    telling ``messages`` ("progress", text, fraction), then ("done", path) or ("error", text)."""
    from lobeview.core import progress

    last = [0.0]

    def listener(what: str, fraction) -> None:
        now = time.monotonic()
        if now - last[0] >= PROGRESS_INTERVAL_S:
            last[0] = now
            messages.put(("progress", what, fraction))

    try:
        with progress.listening(listener):
            path = build(*arguments)
        messages.put(("done", str(path)))
    except BaseException as exc:  # noqa: BLE001 - any failure is the window's message, not a crash
        messages.put(("error", f"{type(exc).__name__}: {exc}"))


class BackgroundBake:
    """A worker running ``build(*arguments)`` (a module-level function: the spawned process
    imports it); made by :meth:`for_builtin` or :meth:`for_gltf`. ``label``: what the window's
    title calls the result (None: the written file's name)."""

    def __init__(self, build, arguments: tuple, label: str | None = None, what: str = "lightmaps"):
        self.label = label
        self.what = what  # what the status line says is being made
        context = multiprocessing.get_context("spawn")  # no fork of a process that holds a GL context
        self._messages = context.Queue()
        self.process = context.Process(
            target=bake_worker, args=(build, arguments, self._messages), name="lobeview bake", daemon=True
        )
        self.process.start()
        self.status = f"{what}: starting"
        self.fraction: float | None = None
        self.path: Path | None = None
        self.error: str | None = None

    @classmethod
    def for_builtin(cls, scene_arg: str | None, cache: Path, horizon_cache: Path | None = None) -> BackgroundBake:
        """The built-in scene ``scene_arg`` built and baked into ``cache``, its horizon maps traced
        into ``horizon_cache`` (the renderer's cache folder) after."""
        return cls(_build_builtin, (scene_arg, str(cache), None if horizon_cache is None else str(horizon_cache)))

    @classmethod
    def for_horizon_maps(cls, scene_path: Path, horizon_cache: Path, limits) -> BackgroundBake:
        """The horizon maps per lightmap texel of the baked scene file ``scene_path`` traced into
        ``horizon_cache`` (the window's renderer takes them from there: app/finishing.py)."""
        arguments = (str(scene_path), str(horizon_cache), limits)
        return cls(_trace_horizon_maps, arguments, what="self-occlusion horizons")

    @classmethod
    def for_gltf(
        cls, source: Path, environment_spec: str, out: Path, limits, horizon_cache: Path | None = None
    ) -> BackgroundBake:
        """The first-use bake of the glTF file ``source`` under ``environment_spec`` into ``out``
        (scenes/gltf_bake.py first_use_bake_file), with the trust ``limits`` of its load; its
        horizon maps traced into ``horizon_cache`` after."""
        horizons = None if horizon_cache is None else str(horizon_cache)
        arguments = (str(source), environment_spec, str(out), limits, horizons)
        return cls(_bake_gltf_file, arguments, label=f"{Path(source).name} (baked)")

    @property
    def finished(self) -> bool:
        return self.path is not None or self.error is not None

    def _read(self, wait: float = 0.0) -> None:
        """Take every message the worker has sent, waiting up to ``wait`` seconds for the first."""
        while True:
            try:
                kind, *values = self._messages.get(timeout=wait) if wait > 0 else self._messages.get_nowait()
            except queue.Empty:
                return
            wait = 0.0
            if kind == "progress":
                self.status, self.fraction = f"{self.what}: {values[0]}", values[1]
            elif kind == "done":
                self.path = Path(values[0])
            else:
                self.error = values[0]

    def poll(self) -> bool:
        """Read what the worker said; True once it finished (``path`` or ``error`` set)."""
        self._read()
        if not self.finished and not self.process.is_alive():
            self.process.join(timeout=1.0)
            self._read(wait=0.5)  # what it sent just before it exited may arrive after the exit
            if not self.finished:
                self.error = f"the bake process ended without a result (exit code {self.process.exitcode})"
        return self.finished

    def cancel(self) -> None:
        """Stop the worker (the window closes)."""
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=5.0)
