"""The prepared GPU bench (bench/gpu.py, issue 42 item 3) runs end to end on llvmpipe at small
sizes, so that it works the moment a GPU machine is lent (bench/gpu_device.sh runs it there at
1680x1050)."""

from __future__ import annotations

import re
import subprocess
import sys


def test_the_gpu_bench_writes_every_table_at_small_sizes(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "lobeview.bench.gpu", "--small", "--out", str(tmp_path), "--cache", str(tmp_path / "c")],
        capture_output=True, text=True, timeout=1200,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    (summary,) = tmp_path.glob("gpu-*.md")
    text = summary.read_text()
    assert "FAILED" not in text
    number = r"([\d.]+)"
    rows = re.findall(
        rf"^\| (\d+) \| {number} \| {number} \| {number} \| {number} \| (\d+) / (\d+) \| {number} / {number} \|$",
        text, re.M,
    )  # fmt: skip
    assert [int(row[0]) for row in rows] == [3, 7], text  # Table 4.1 at the small plan's N
    assert all(float(row[1]) > 0 and float(row[3]) > 0 and float(row[7]) > 0 for row in rows)
    cells = rf"{number} \| {number} \| {number} \| {number}"
    methods = re.findall(rf"^\| ggx:0.3 \| (lobe-7\+norm(?:\+fit)?) \| {cells} \|$", text, re.M)
    assert [row[0] for row in methods] == ["lobe-7+norm", "lobe-7+norm+fit"], text  # the methods' cost
    assert all(float(row[1]) > 0 and 0.2 < float(row[4]) <= 1 for row in methods), text
    linked = re.findall(r"\]\(((?:mirrors|walkthrough|draw-cost)-[^)]+\.md)\)", text)
    assert sorted(name.split("-")[0] for name in linked) == ["draw", "mirrors", "walkthrough"], text
    assert all((tmp_path / name).exists() for name in linked), text
    draw_cost = (tmp_path / next(name for name in linked if name.startswith("draw-cost"))).read_text()
    # one apartment room: per-object, multi-draw with a pass per reflector, multi-draw (planes shared)
    assert draw_cost.count("| 1 | ") == 3, draw_cost
    assert "| multi-draw, a pass per reflector |" in draw_cost and "| multi-draw |" in draw_cost, draw_cost
    # the device-idle flights replayed the measured frames' branches (read-backs, draws, passes)
    assert re.search(r"\(0: the same branches\): 0\.$", draw_cost, re.M), draw_cost


def test_the_draw_cost_timer_counts_query_waits_apart_and_restores_moderngl():
    """bench/draw_cost.py: reading a query's result or a buffer (the occlusion test's wait for
    the device, per query or counted in a buffer) is timed as the wait, not as Python + state, and
    removing the timer puts moderngl back."""
    import moderngl

    from lobeview.bench.draw_cost import DriverWorkTimer
    from lobeview.viewer.context import create_headless_context

    original, original_read = moderngl.Query.__dict__["samples"], moderngl.Buffer.read
    ctx = create_headless_context()
    timer = DriverWorkTimer()
    try:
        query = ctx.query(samples=True)
        with query:
            pass
        assert query.samples == 0
        assert timer.wait_seconds > 0.0 and timer.seconds == 0.0
        waited = timer.wait_seconds
        assert ctx.buffer(bytes(8)).read() == bytes(8)
        assert timer.wait_seconds > waited and timer.seconds == 0.0
    finally:
        timer.remove()
        ctx.release()
    assert moderngl.Query.__dict__["samples"] is original and moderngl.Buffer.read is original_read


def test_device_idle_replays_the_reads_does_no_device_work_and_restores_moderngl():
    """bench/draw_cost.py DeviceIdle: draws and dispatches do nothing, a read returns what the
    measured frame read there (then, past the record, the real contents, counted as a miss), and
    removing it puts moderngl back."""
    import moderngl
    import numpy as np

    from lobeview.bench.draw_cost import DeviceIdle
    from lobeview.viewer.context import create_headless_context

    originals = {name: getattr(moderngl.VertexArray, name) for name in ("render", "render_indirect")}
    original_read = moderngl.Buffer.read
    ctx = create_headless_context()
    try:
        fbo = ctx.simple_framebuffer((4, 4), components=4, dtype="f4")
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        program = ctx.program(
            vertex_shader="#version 450\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }",
            fragment_shader="#version 450\nout vec4 c; void main() { c = vec4(1.0); }",
        )
        triangle = ctx.buffer(np.array([-3, -1, 3, -1, 0, 3], dtype="f4").tobytes())
        vao = ctx.vertex_array(program, [(triangle, "2f", "p")])
        buffer = ctx.buffer(b"real")
        idle = DeviceIdle([[b"kept"]])
        try:
            idle.frame(0)
            vao.render()  # nothing drawn
            assert buffer.read() == b"kept" and idle.missed == 0
            assert buffer.read() == b"real" and idle.missed == 1  # past the record
        finally:
            idle.remove()
        assert not np.frombuffer(fbo.read(components=4, dtype="f4"), "f4").any()
        vao.render()  # drawn again once removed
        assert np.frombuffer(fbo.read(components=4, dtype="f4"), "f4").min() == 1.0
    finally:
        ctx.release()
    assert all(getattr(moderngl.VertexArray, name) is f for name, f in originals.items())
    assert moderngl.Buffer.read is original_read
