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
    assert "| studio | 4 | gold-ggx | lobe-7+norm | 22.3 | 6.8 | - | - | 20.0 | 30.0 | 100 | 150 |" in text
    results["rows"][0]["before"]["rel_rmse_interior"] = 0.2
    results["rows"][0]["after"]["rel_rmse_interior"] = 0.05
    assert "| 22.3 | 6.8 | 20.0 | 5.0 | 20.0 |" in light.markdown(results)
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
