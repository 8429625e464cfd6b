"""lobeview bench light (bench/light.py, issue 39): its table, figure and environment choice; the
renders themselves are what tests/test_cap_lights.py checks."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SHARED_ASSETS

from lobeview.bench import light


def _row(method, before, after):
    return {"view": "studio", "material": "gold-ggx", "method": method, "lights": 4,
            "before": {"rel_rmse": before, "psnr": 20.0, "ms": 100.0},
            "after": {"rel_rmse": after, "psnr": 30.0, "ms": 150.0}}  # fmt: skip


def test_table_and_figure(tmp_path):
    results = {"rows": [_row("lobe-7+norm", 0.223, 0.068)], "size": 8, "reference_spp": 16, "repeats": 1,
               "device": "test", "stamp": "stamp"}  # fmt: skip
    text = light.markdown(results)
    assert "| studio | 4 | gold-ggx | lobe-7+norm | - | 22.3 | 6.8 | - | - | - | - | 20.0 | 30.0 | 100 | 150 |" in text
    results["rows"][0]["before"]["rel_rmse_interior"] = 0.2
    results["rows"][0]["after"]["rel_rmse_interior"] = 0.05
    assert "| 22.3 | 6.8 | - | - | 20.0 | 5.0 | 20.0 |" in light.markdown(results)
    # the reference's own noise, and the error beyond it: sqrt(0.068^2 - 0.03^2) = 0.061
    results["rows"][0]["reference_noise"] = 0.03
    results["rows"][0]["after"]["beyond_noise"] = float(np.sqrt(0.068**2 - 0.03**2))
    assert "| lobe-7+norm | 3.0 | 22.3 | 6.8 | - | 6.1 | 20.0 | 5.0 |" in light.markdown(results)
    mask = np.zeros((9, 9), bool)
    mask[1:8, 1:8] = True
    assert light.interior(mask).sum() == 9  # 7 x 7 less two rings
    frame = np.full((8, 8, 3), 0.5, dtype=np.float32)
    figures = [("studio", "gold-ggx", "before", frame, frame), ("studio", "gold-ggx", "after", frame * 1.1, frame)]
    light.write_figure(figures, tmp_path / "figure.png")
    from PIL import Image

    assert Image.open(tmp_path / "figure.png").size == (32, 8)  # reference | before | after | error


def test_materials_parse_and_psnr():
    assert light.build_material("ggx:0.05").components and light.build_material("gold-ggx").components
    mask = np.ones((4, 4), bool)
    reference = np.ones((4, 4, 3))
    assert light.psnr(reference * 1.1, reference, mask) == pytest.approx(20.0)


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
def test_environment_choice():
    every = light.environment_files()
    assert {p.stem for p in every} >= {"studio", "interior", "chinese_garden_1k"}
    assert [p.stem for p in light.environment_files(["studio"])] == ["studio"]
    with pytest.raises(SystemExit, match="no environment 'nowhere'"):
        light.environment_files(["nowhere"])


def test_after_only_table_and_figure(tmp_path):
    row = _row("prefiltered", 0.3, 0.08)
    del row["before"]
    results = {"rows": [row], "size": 8, "reference_spp": 16, "repeats": 1, "supersample": 4,
               "device": "test", "stamp": "stamp"}  # fmt: skip
    text = light.markdown(results)
    assert "| studio | 4 | gold-ggx | prefiltered | - | - | 8.0 | - | - | - | - | - | 30.0 | - | 150 |" in text
    assert "4x4 points per pixel" in text and "pixel centres" in light.markdown({**results, "supersample": 1})
    frame = np.full((8, 8, 3), 0.5, dtype=np.float32)
    light.write_figure([("studio", "gold-ggx", "after", frame, frame)], tmp_path / "figure.png")
    from PIL import Image

    assert Image.open(tmp_path / "figure.png").size == (24, 8)  # reference | after | error


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
def test_supersampled_methods_meet_the_box_filtered_reference_at_the_silhouette(tmp_path, monkeypatch):
    """A real run, small: shading pixel centres counts the silhouette's partly covered pixels as the
    method's error (the box-filtered reference averages them with the empty background); at 4 x 4
    points per pixel the sphere's error comes down to its interior's."""
    monkeypatch.setattr(light, "SIZE", 48)
    errors = {}
    for supersample in (1, 4):
        results = light.run(["studio"], ["beckmann:0.3"], ["lobe-7+norm+fit"], 256, 1, tmp_path, f"s{supersample}",
                            progress=lambda *_: None, supersample=supersample, before=False)  # fmt: skip
        (row,) = results["rows"]
        assert "before" not in row and results["supersample"] == supersample
        errors[supersample] = row["after"]
    assert (tmp_path / "light-s4.md").exists() and (tmp_path / "light-s4.png").exists()
    # measured: 8.8 % at the pixel centres, 5.1 % supersampled, 5.2 / 4.9 % over the interior (48 px,
    # the 256-sample reference's noise a good part of it)
    assert errors[1]["rel_rmse"] > 1.5 * errors[4]["rel_rmse"]
    assert errors[4]["rel_rmse"] < 1.2 * errors[4]["rel_rmse_interior"]


@pytest.mark.skipif(not SHARED_ASSETS.exists(), reason="shared assets not present")
def test_light_cost_bench_times_both_frames_of_each_row(tmp_path, capsys):
    """bench/light_cost.py, small: one row per capture, material and method, with the capture's
    lights (sunrise.exr: its sun's core and the cone of its glow) and both medians; the table and
    its JSON written; a bad size is a clear message, not a traceback."""
    import json

    from lobeview.bench import light_cost

    argv = ["--views", "sunrise", "--materials", "gold-ggx", "--methods", "lobe-7+norm+fit", "prefiltered",
            "--size", "24", "--repeats", "1", "--out", str(tmp_path)]  # fmt: skip
    assert light_cost.main(argv) == 0
    (table,) = tmp_path.glob("light-cost-*.md")
    rows = json.loads(table.with_suffix(".json").read_text())["rows"]
    assert [r["method"] for r in rows] == ["lobe-7+norm+fit", "prefiltered"]
    for row in rows:
        assert row["view"] == "sunrise" and row["lights"] == 2 and len(row["radii_deg"]) == 2
        assert row["ms_without"] > 0.0 and row["ms_with"] > 0.0
        assert row["ratio"] == pytest.approx(row["ms_with"] / row["ms_without"])
    assert "| sunrise | 2 | gold-ggx | prefiltered |" in table.read_text()
    assert light_cost.main(argv[:-4] + ["--size", "2", "--out", str(tmp_path)]) == 2
    assert "--size >= 8" in capsys.readouterr().err
