"""The fuzzer's worker (bench/fuzz.py starts it): runs the cases of a work folder one by one in
this process, under an address-space limit and an audit hook that records every file opened
outside the case folders, and prints one JSON line per case. A plain script, so that the cases
can run against another checkout of lobeview (``python -m lobeview.bench.fuzz --pythonpath``):
it imports lobeview only inside a case, from whatever ``sys.path`` finds first.

    python bench/fuzz_worker.py WORK_FOLDER START_INDEX
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

WORKER_ADDRESS_LIMIT = 12 << 30  # llvmpipe maps generously; Python allocations hit this first
CANARY = "canary.txt"
SYSTEM_FILES = ("/etc/passwd", "/etc/shadow", "/dev/zero", "/dev/urandom", "/proc/self/cmdline", "/proc/self/environ")


def _finite(array) -> bool:
    a = np.asarray(array, dtype=np.float64)
    return bool(np.all(np.isfinite(a)))


def _numbers(value) -> list[float]:
    """Every number in a JSON value (the fitted material's parameters and provenance)."""
    if isinstance(value, bool):
        return []
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, dict):
        value = list(value.values())
    return [x for item in value for x in _numbers(item)] if isinstance(value, list) else []


def _run_program(argv: list[str]) -> int:
    """``lobeview ARGV`` run as the program it is (``python -m lobeview``), in this process so that
    the audit hook sees every file it opens; its exit status."""
    import runpy

    saved = sys.argv
    sys.argv = ["lobeview", *argv]
    try:
        runpy.run_module("lobeview", run_name="__main__", alter_sys=False)
    except SystemExit as done:
        code = done.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    finally:
        sys.argv = saved
    return 0


def _run_target(case: dict, work: Path) -> tuple[str, str]:
    """Run one case in this process; returns (outcome, message)."""
    import contextlib
    import io
    import warnings

    entry = work / case["entry"]
    case_dir = entry.parent
    target = case["target"]
    stderr = io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stderr(stderr):
        warnings.simplefilter("always")
        if target == "load":
            from lobeview.scenes.analysis import analyse
            from lobeview.scenes.gltf_loader import GltfError, load_gltf

            try:
                scene = load_gltf(entry)
            except GltfError as exc:
                return "error", str(exc)
            analyse(scene)
            for obj in scene.objects:
                if not all(_finite(a) for a in (obj.mesh.positions, obj.mesh.normals, obj.mesh.tangents, obj.mesh.uvs)):
                    return "nonfinite", f"object {obj.name} has NaN/Inf vertex data"
            for mat in scene.materials:
                images = [slot.linear() for slot in mat.textures.values()]
                for image in (*images, mat.lightmap.image if mat.lightmap else None):
                    if image is not None and not (_finite(image) and np.min(image) >= 0):
                        return "nonfinite", f"material {mat.name} has a NaN/Inf/negative image"
        elif target == "path":
            from lobeview.scenes.camera_path import CameraPath, CameraPathError

            try:
                path = CameraPath.load(entry)
            except CameraPathError as exc:
                return "error", str(exc)
            for t in np.linspace(0.0, path.duration, 17):
                camera = path.camera_at(float(t))
                if not _finite([*camera.position, *camera.target, camera.fov_y]):
                    return "nonfinite", f"camera path gives a non-finite camera at t = {t}"
        elif target == "script":
            from lobeview.core.viewer_script import ScriptError, load_script

            try:
                load_script(entry)
            except ScriptError as exc:
                return "error", str(exc)
        elif target == "env":
            from lobeview.scenes.builtin_env import load_environment
            from lobeview.scenes.hdrio import HDRImageError

            try:
                env = load_environment(str(entry))
            except (HDRImageError, ValueError) as exc:
                return "error", str(exc)
            if not (_finite(env.image) and env.image.min() >= 0):
                return "nonfinite", "environment has NaN/Inf/negative texels"
        else:
            out = case_dir / "out.npy"
            argv = {
                "material": ["material", "show", str(entry)],
                "edits": [
                    "shot",
                    str(case_dir / "lit.glb"),
                    "--materials",
                    str(entry),
                    "--size",
                    "24x16",
                    "--face-size",
                    "8",
                    "--out",
                    str(out),
                ],
                "shot": ["shot", "--size", "24x16", "--face-size", "8", "--out", str(out)]
                + (
                    ["--object", "sphere", "--env", str(entry)]
                    if entry.suffix in (".exr", ".hdr")
                    else [str(entry), "--env", "builtin:studio"]
                ),
                "fit": [
                    "fit",
                    str(entry),
                    "--quiet",
                    "--grid",
                    "3",
                    "--iterations",
                    "1",
                    "--alternations",
                    "1",
                    "--no-polish",
                    "-o",
                    str(case_dir / "fit.json"),
                ],  # fmt: skip
                "bake": [
                    "bake",
                    str(entry),
                    "--resolution",
                    "16",
                    "--rays",
                    "4",
                    "--bounces",
                    "1",
                    "--light-samples",
                    "2",
                    "--out",
                    str(case_dir / "baked" / "out.glb"),
                ],
            }[target]
            if target == "bake":
                (case_dir / "baked").mkdir(exist_ok=True)  # bake refuses an --out folder that does not exist
            with contextlib.redirect_stdout(io.StringIO()):
                rc = _run_program(argv)
            if rc != 0:
                text = stderr.getvalue().strip().splitlines()
                return ("error" if text and "lobeview: error" in text[-1] else "traceback"), (text[-1] if text else "")
            fitted = case_dir / "fit.json"
            if target == "fit" and fitted.exists():
                values = _numbers(json.loads(fitted.read_text()))
                if not _finite(values):
                    return "nonfinite", "the fitted material holds NaN/Inf"
            if out.exists():
                radiance = np.load(out)
                if not (_finite(radiance) and radiance.min() >= 0):
                    return "nonfinite", "rendered image has NaN/Inf/negative pixels"
                if radiance.max() <= 0:
                    return "nonfinite", "rendered image is black"
    messages = [str(w.message) for w in caught] + [
        line for line in stderr.getvalue().splitlines() if "warning" in line.lower()
    ]
    return ("warned" if messages else "ok"), (messages[0][:300] if messages else "")


def _reset_peak_memory() -> None:
    """Reset this process's peak resident set (Linux: 5 > /proc/self/clear_refs), so that the
    next case's peak is its own (the interpreter and what earlier cases left resident included)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass


def _peak_memory_mib() -> float:
    """Peak resident set since the last reset, MiB (VmHWM; 0 where /proc is not available)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def worker(work: Path, start: int) -> int:
    """Run cases from ``start``; one JSON line per case on stdout (flushed before the next)."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (WORKER_ADDRESS_LIMIT, WORKER_ADDRESS_LIMIT))
    cases = [json.loads(line) for line in (work / "cases.jsonl").read_text().splitlines()]
    watched = {os.path.realpath(work / CANARY), *SYSTEM_FILES}
    opened: list[str] = []

    def audit(event, args):
        if event == "open" and args and isinstance(args[0], (str, bytes, os.PathLike)):
            try:
                real = os.path.realpath(os.fsdecode(args[0]))
            except (TypeError, ValueError):
                return
            if real in watched or real.startswith("/proc/self/"):
                opened.append(real)

    sys.addaudithook(audit)
    out = sys.stdout
    sys.stdout = sys.stderr  # nothing but results on the pipe
    for case in cases[start:]:
        _reset_peak_memory()  # before the audited window: the worker's own /proc reads are not the case's
        opened.clear()
        t0 = time.perf_counter()
        print(json.dumps({"start": case["index"]}), file=out, flush=True)
        try:
            outcome, message = _run_target(case, work)
        except MemoryError:
            outcome, message = "memory", "MemoryError"
        except Exception as exc:  # noqa: BLE001 - that is exactly what the fuzzer looks for
            import traceback

            outcome = "traceback"
            frames = traceback.extract_tb(exc.__traceback__)
            where = f"{Path(frames[-1].filename).name}:{frames[-1].lineno} {frames[-1].name}" if frames else ""
            message = f"{type(exc).__name__}: {str(exc)[:200]} at {where}"
        if "out of memory" in message:
            outcome = "memory"
        escaped = sorted({p for p in opened if not p.startswith("/proc/self/fd")})
        if escaped:
            outcome, message = "escape", f"opened {escaped}"
        seconds = time.perf_counter() - t0
        result = {"index": case["index"], "outcome": outcome, "message": message, "seconds": seconds,
                  "peak_mib": _peak_memory_mib()}  # fmt: skip
        print(json.dumps(result), file=out, flush=True)
    return 0


if __name__ == "__main__":
    # 'lobeview' must resolve to the checkout on PYTHONPATH (or the installed one), not to this
    # file's folder.
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
    sys.exit(worker(Path(sys.argv[1]), int(sys.argv[2])))
