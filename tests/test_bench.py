"""``lobeview bench``: the metrics and helpers against independent computations, and the command
end to end on a tiny matrix (its numbers are checked for sense, never for speed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lobeview.app.cli import main
from lobeview.bench import matrix_config, metrics
from lobeview.viewer.render_base import RenderResult


def test_pareto_front_keeps_only_undominated_points():
    times = [1.0, 2.0, 3.0, 2.5, 4.0]
    errors = [0.5, 0.3, 0.1, 0.4, 0.1]
    # (2.5, 0.4) is beaten by (2.0, 0.3); (4.0, 0.1) by (3.0, 0.1).
    assert metrics.pareto_front(times, errors) == [True, True, True, False, False]


def test_log_interpolation_and_first_crossing():
    xs, ys = [8, 16, 32, 64], [20.0, 23.0, 26.0, 29.0]  # +3 dB per doubling
    assert metrics.interpolate_log(np.sqrt(8 * 16), xs, ys) == pytest.approx(21.5)
    assert np.isnan(metrics.interpolate_log(4, xs, ys))
    assert metrics.first_crossing(24.5, xs, ys) == pytest.approx(np.sqrt(16 * 32))
    assert np.isnan(metrics.first_crossing(30.0, xs, ys))
    assert metrics.first_crossing(10.0, xs, ys) == 8  # reached at the first point already


def test_psnr_and_relative_rmse_closed_forms():
    a = np.full((10, 10, 3), 0.5)
    b = a + 10 / 255  # exactly ten 8-bit steps everywhere
    assert metrics.psnr_8bit(a, b) == pytest.approx(20 * np.log10(255 / 10), abs=1e-9)
    assert metrics.relative_rmse(a * 1.1, a) == pytest.approx(0.1)


def test_reference_noise_floor_matches_the_true_error_of_the_reference():
    """Two noisy half references of a known image: the floor estimated from their difference is
    the actual error of their mean against the truth."""
    rng = np.random.default_rng(0)
    truth = 0.2 + rng.random((80, 80, 3))
    sigma = 0.05

    def render(method, spp=1, seed=0, lod_bias=None):
        noise = np.random.default_rng(seed + 1).normal(0.0, sigma, truth.shape)
        z = np.zeros((80, 80, 3))
        return RenderResult(truth + noise, z, z, z, np.ones((80, 80), bool), np.zeros((80, 80), bool))

    reference = metrics.make_reference(render, lambda r: r.mask, 64)
    actual = metrics.relative_rmse(reference.radiance, truth)
    assert reference.rel_rmse_floor == pytest.approx(actual, rel=0.05)
    exact = metrics.Reference(
        truth, reference.mask, reference.exposure, np.clip(bench_tonemap(truth, reference.exposure), 0, 1), 0, 0, 0, 0
    )
    assert reference.psnr_floor == pytest.approx(exact.errors(reference.radiance)["psnr"], abs=0.5)


def bench_tonemap(radiance, exposure):
    from lobeview.viewer.tonemap import tonemap

    return tonemap(radiance, "aces", exposure)


def test_flip_is_zero_for_identical_images_and_grows_with_the_difference():
    rng = np.random.default_rng(1)
    image = rng.random((48, 48, 3)).astype(np.float32)
    mask = np.ones((48, 48), bool)
    assert metrics.flip_error(image, image, mask) == pytest.approx(0.0, abs=1e-6)
    small = metrics.flip_error(np.clip(image + 0.02, 0, 1), image, mask)
    large = metrics.flip_error(np.clip(image + 0.2, 0, 1), image, mask)
    assert 0.0 < small < large


def test_software_renderers_are_timed_by_the_wall_clock():
    from lobeview.viewer.context import gpu_timer_meaningful

    assert not gpu_timer_meaningful("llvmpipe (LLVM 15.0.6, 256 bits) (Mesa/X.org), OpenGL 4.5")
    assert gpu_timer_meaningful("NVIDIA H100 80GB HBM3/PCIe/SSE2, OpenGL 4.6")


def test_bench_command_end_to_end(tmp_path, capsys):
    rc = main(
        [
            "bench",
            "--views",
            "sphere/builtin:studio",
            "--materials",
            "alanod-2000gs-1lobe",
            "--methods",
            "lobe-3",
            "lobe-11",
            "fis-4",
            "fis-32",
            "prefiltered",
            "--resolutions",
            "96x60",
            "--reference-spp",
            "256",
            "--sweep-methods",
            "lobe-7",
            "--sweep-biases",
            "-1",
            "0",
            "--fps-size",
            "64x40",
            "--repeats",
            "1",
            "--out",
            str(tmp_path),
        ]
    )
    assert rc == 0
    md = next(tmp_path.glob("bench-*.md"))
    data = json.loads(next(tmp_path.glob("bench-*.json")).read_text())
    assert len(list(tmp_path.glob("bench-*-pareto-96x60.png"))) == 1
    assert len(list(tmp_path.glob("bench-*-lod-bias.png"))) == 1
    cells = {c["method"]: c for c in data["cells"]}
    assert set(cells) == {"lobe-3", "lobe-11", "fis-4", "fis-32", "prefiltered"}
    for c in cells.values():
        assert c["ms"] > 0 and np.isfinite(c["psnr"]) and 0 <= c["flip"] <= 1 and c["memory_mb"] > 0
        assert c["invalid_pixels"] == 0
    # More samples, less error: the measurement sees what the methods do.
    assert cells["fis-32"]["rel_rmse"] < cells["fis-4"]["rel_rmse"]
    assert cells["lobe-11"]["rel_rmse"] < cells["lobe-3"]["rel_rmse"]
    # Prefiltered maps cost memory beyond the radiance cube.
    assert cells["prefiltered"]["memory_mb"] > cells["lobe-3"]["memory_mb"]
    assert {r["bias"] for r in data["sweep"]} == {-1.0, 0.0}
    assert [r["samples"] for r in data["fps"]] == list(matrix_config.FPS_SAMPLES)
    assert data["fps"][0]["full"]["fraction"] == pytest.approx(1.0)
    assert data["fps"][0]["half"]["fraction"] == pytest.approx(0.5, abs=0.03)
    text = md.read_text()
    for heading in ("Fastest method reaching a PSNR target", "lobe-N against fis-N", "MIP level bias", "Frame rate"):
        assert heading in text
    assert "wall clock" in text  # llvmpipe: its timer query does not cover rasterisation
    assert not list(tmp_path.glob("*.partial.json"))  # the checkpoint goes once the report is written
    # The report can be rewritten from the JSON alone.
    md.unlink()
    assert main(["bench", "report", str(next(tmp_path.glob("bench-*.json")))]) == 0
    assert md.read_text() == text


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--views", "cube/x"], "sphere/ENV or demo/CAMERA"),
        (["--sweep-methods", "mc-8"], "only lobe-N and fis-N"),
        (["--methods", "lobe-0"], "N must be"),
        (["--repeats", "0"], "at least 1"),
        (["report", "/nonexistent/bench.json"], "not a lobeview bench JSON"),
        (["--report", "/nonexistent/bench.json"], "not a lobeview bench JSON"),  # the flag of earlier runs
        (["--stress", "mirrors"], "contradict"),
        (["report"], "give the JSON"),
    ],
)
def test_bench_rejects_bad_options(argv, message, capsys):
    assert main(["bench", *argv]) == 2
    assert message in capsys.readouterr().err


def test_stress_command_reports_every_check(tmp_path, capsys):
    rc = main(["bench", "stress", "--quick", "--methods", "lobe-7+norm", "--out", str(tmp_path)])
    text = next(tmp_path.glob("stress-*.md")).read_text()
    assert rc == 0, capsys.readouterr().out
    assert "0 failures" in text
    assert "plane seen 89.9 deg from its normal" in text
    assert "environment with NaN/Inf/negative texels" in text


def test_mirror_bench_times_0_1_2_reflectors_and_writes_the_figure(tmp_path):
    from PIL import Image

    argv = ["bench", "mirrors", "--quick", "--mirror-samples", "3", "--repeats", "1", "--reference-spp", "16"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    text = next(tmp_path.glob("mirrors-*.md")).read_text()
    rows = [line for line in text.splitlines() if line.startswith("| 320x200 |")]
    assert [row.split("|")[2].strip() for row in rows] == ["0", "1", "2"]
    # No mirror pass without reflectors; one or two passes cost something.
    mirror_ms = [float(row.split("|")[3]) for row in rows]
    assert mirror_ms[0] < mirror_ms[1] and mirror_ms[0] < mirror_ms[2]
    assert "| lobe-3 |" in text and " dB |" in text
    # Refinement against the ray tracer: one row per floor roughness, errors finite and positive.
    refinement = [line.split("|") for line in text.splitlines() if line.startswith(("| 0.05 |", "| 0.15 |", "| 0.3 |"))]
    assert len(refinement) == 3
    assert all(0.0 < float(cell) < 1.0 for row in refinement for cell in row[2:5]), refinement
    pair = Image.open(next(tmp_path.glob("mirrors-*-refinement.png")))
    assert pair.size == (3 * 160 + 8, 100)
    figure = Image.open(next(p for p in tmp_path.glob("mirrors-*.png") if "refinement" not in p.name))
    assert figure.size == (3 * 320 + 8, 200)
    pixels = np.asarray(figure, dtype=np.float64)
    assert pixels.std() > 10.0  # an image, not a flat fill


def test_mip_chain_bench_writes_box_and_tent_per_method_and_bias(tmp_path):
    from lobeview.bench import mip_chain

    argv = ["--envs", "builtin:studio", "--presets", "plastic", "--methods", "lobe-7+norm", "fis-4",
            "--biases", "-0.5", "-1", "--size", "24", "--spp", "32", "--out", str(tmp_path)]  # fmt: skip
    assert mip_chain.main(argv) == 0
    (report,) = tmp_path.glob("mip_chain-*.md")
    text = report.read_text()
    rows = [line.split(" | ") for line in text.splitlines() if line.startswith("| builtin:studio |")]
    assert [(r[2], r[3]) for r in rows] == [("lobe-7+norm", "-0.5"), ("lobe-7+norm", "-1"), ("fis-4", "-0.5"),
                                            ("fis-4", "-1")]  # fmt: skip
    for r in rows:
        box, tent, delta = float(r[4]), float(r[5]), float(r[6])
        assert min(box, tent) > 10.0 and delta == pytest.approx(tent - box, abs=0.011)
    assert "- lobe-7+norm: better on" in text and "- fis-4: better on" in text
    from PIL import Image

    (figure,) = tmp_path.glob("mip_chain-*.png")  # box | tent | reference | two errors, one row
    assert Image.open(figure).size == (5 * 24, 24) and figure.name in text


def test_pattern_bench_reports_falls_and_writes_the_figure(tmp_path):
    from PIL import Image

    from lobeview.bench import patterns

    assert patterns.falls([30.0, 31.0, 30.95, 29.0], (3, 7, 11, 15)) == "11->15 -1.95"
    assert patterns.falls([30.0, 31.0, 30.95], (3, 7, 11)) == "none"  # within the tolerance
    argv = ["--envs", "builtin:studio", "--presets", "lacquer", "gold-ggx", "--samples", "7", "15",
            "--size", "24", "--spp", "64", "--out", str(tmp_path)]  # fmt: skip
    assert patterns.main(argv) == 0
    (report,) = tmp_path.glob("patterns-*.md")
    rows = [line for line in report.read_text().splitlines() if line.startswith("| builtin:studio |")]
    assert [row.split(" | ")[1:3] for row in rows] == [
        ["lacquer", "auto"],
        ["lacquer", "ring"],
        ["gold-ggx", "auto"],
        ["gold-ggx", "ring"],
    ]
    for row in rows:
        values = [float(v) for v in row.split(" | ")[3:5]]
        assert all(np.isfinite(values)) and min(values) > 10.0
    # N = 7 is below DOUBLE_RING_MIN_SAMPLES: both patterns are the ring there, the same image.
    assert rows[0].split(" | ")[3] == rows[1].split(" | ")[3]
    (figure,) = tmp_path.glob("patterns-*.png")
    assert Image.open(figure).size == (5 * 24, 2 * 24)
