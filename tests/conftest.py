"""Test-wide settings: caches (demo scene, cube maps) go to a temporary folder, never to the
user's ~/.cache, and the demo scene is built at draft quality so CI stays fast."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

# The suite's own cache, removed when the session ends (every run left ~20 MB in /tmp before);
# a cache given from outside (LOBEVIEW_CACHE set) is the caller's and stays.
_TEST_CACHE = None if "LOBEVIEW_CACHE" in os.environ else tempfile.mkdtemp(prefix="lobeview-test-cache-")
if _TEST_CACHE is not None:
    os.environ["LOBEVIEW_CACHE"] = _TEST_CACHE
os.environ.setdefault("LOBEVIEW_DEMO_QUALITY", "draft")

SHARED_ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "assets"


HAVE_XVFB = shutil.which("Xvfb") is not None


def pytest_sessionfinish(session, exitstatus):
    if _TEST_CACHE is not None:
        shutil.rmtree(_TEST_CACHE, ignore_errors=True)


@pytest.fixture(scope="module")
def ctx():
    """A headless OpenGL context (EGL), one per test module, released after the module."""
    from lobeview.viewer.context import create_headless_context

    context = create_headless_context()
    yield context
    context.release()


@pytest.fixture(scope="session")
def xvfb():
    """A virtual X server for the window tests (real viewer, real events)."""
    if not HAVE_XVFB:
        if os.environ.get("CI"):
            pytest.fail("Xvfb is missing on CI: .ci/setup should install it")
        pytest.skip("Xvfb not installed (apt-get install xvfb)")
    from lobeview.bench.soak import start_xvfb

    proc, display = start_xvfb(100 + os.getpid() % 400)
    if proc.poll() is not None:
        pytest.fail(f"Xvfb {display} did not start")
    yield display
    proc.terminate()
    proc.wait(timeout=10)


def run_scripted_view(display: str, folder: Path, script: list, args: list, exit_after: int, timeout: int = 600):
    """``lobeview view ARGS`` on the X display ``display`` driven by ``script`` (written to
    ``folder``/script.json; screenshots go to ``folder``), stopped after ``exit_after`` frames;
    asserts it exits cleanly and returns the completed process (stdout and stderr as text).
    ``--target-fps=0`` (ARGS may override it): scripts count frames, so every frame is rendered
    at full resolution, as on a machine fast enough for the target; tests/test_window_input.py
    covers the frame-rate target."""
    (folder / "script.json").write_text(json.dumps(script))
    result = subprocess.run(
        [sys.executable, "-m", "lobeview", "view", "--target-fps=0", *args, f"--script={folder / 'script.json'}",
         f"--screenshot-dir={folder}", f"--exit-after={exit_after}"],
        env={**os.environ, "DISPLAY": display}, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    return result


def run_compute_probe(ctx, program, probe, out_vec4s: int, out_binding: int = 3):
    """Run a shader probe (shaders/*_probe.comp): ``probe`` (n, ..., 4) float32 items in storage
    buffer 2, ``out_vec4s`` vec4 results per item from buffer ``out_binding``; 64 invocations a
    group, ``u_count`` = n. Returns (n, out_vec4s, 4) float32."""
    import numpy as np

    n = len(probe)
    inputs = ctx.buffer(np.ascontiguousarray(probe, np.float32).tobytes())
    inputs.bind_to_storage_buffer(2)
    outputs = ctx.buffer(reserve=n * out_vec4s * 16)
    outputs.bind_to_storage_buffer(out_binding)
    program["u_count"] = n
    program.run((n + 63) // 64)
    out = np.frombuffer(outputs.read(), np.float32).reshape(n, out_vec4s, 4).copy()
    inputs.release()
    outputs.release()
    return out


def sphere_integral(density, m: int) -> float:
    """The integral of ``density`` (directions (..., 3) -> values) over the sphere by the midpoint
    rule on an m x m grid per cube face: d omega = dsc dtc / (1 + sc^2 + tc^2)^1.5."""
    import numpy as np

    from lobeview.core.cube_layout import face_point_directions

    c = (np.arange(m) + 0.5) / m * 2 - 1
    tc, sc = np.meshgrid(c, c, indexing="ij")
    jacobian = (2 / m) ** 2 / (1 + sc**2 + tc**2) ** 1.5
    return float(sum(np.sum(density(face_point_directions(f, sc, tc)) * jacobian) for f in range(6)))
