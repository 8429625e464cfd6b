"""The Mitsuba comparison's scene (bench/mitsuba.py, issue 45): both renderers see the same
environment in their own conventions, the cases parse to valid materials, and the table is
written. The comparison itself needs Mitsuba 3 (not a lobeview dependency): its test runs where
Mitsuba is installed."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.bench import mitsuba as bench
from lobeview.core.cube_layout import direction_to_equirect
from lobeview.materials.spec import build_bsdf, validate
from lobeview.scenes.envmap import EnvironmentMap


def test_mitsuba_environment_is_lobeviews_turned_by_half_a_turn():
    """Mitsuba's envmap faces -z at u = 0, lobeview's at u = 0.5 (core/cube_layout.py): the same
    directions hold the same radiance once the map is rolled by half its width."""
    height = 64
    ours = EnvironmentMap.from_function(bench.environment, height=height).image
    theirs = bench.mitsuba_equirect(height)
    rolled = np.roll(ours, -height, axis=1)  # lobeview's column u + 0.5 is Mitsuba's column u
    close = np.all(np.isclose(rolled, theirs, rtol=1e-5, atol=1e-6), axis=-1)
    assert close.mean() > 0.999, close.mean()  # texels on a discontinuity may round either way
    # The sun lies where both conventions put its direction.
    u, v = direction_to_equirect(bench.SUN_DIRECTION)
    row, column = int(v * height), int(u * 2 * height)
    assert ours[row, column].max() > 10 and theirs[row, (column + height) % (2 * height)].max() > 10


@pytest.mark.parametrize("case", bench.CASES)
def test_cases_are_valid_materials(case):
    bsdf = build_bsdf(validate(bench.material(case)))
    distribution, au, av = bench.parse_case(case)
    (lobe,) = bsdf.components
    assert lobe.distribution.kind == distribution and (lobe.distribution.alpha_x, lobe.distribution.alpha_y) == (au, av)
    with pytest.raises(ValueError, match="expected ggx"):
        bench.parse_case("phong:0.3")


def test_table_lists_every_case_and_method():
    results = {"rows": [{"case": "ggx:0.5", "reference": 0.021, "lobe-7+norm": 0.147}], "methods": ["lobe-7+norm"],
               "size": 32, "spp": 16, "mitsuba": "3.9.1", "device": "test"}  # fmt: skip
    text = bench.markdown(results, "stamp", "python -m lobeview.bench.mitsuba")
    assert "| ggx:0.5 | 2.1 | 14.7 |" in text and "lobe-7+norm" in text


def test_lobeview_reference_agrees_with_mitsuba(tmp_path):
    """Where Mitsuba is installed: the conventions (environment, camera, sphere, tangent frame)
    hold, i.e. lobeview's converged reference is close to Mitsuba's path tracer on a rough
    isotropic and an anisotropic lobe (a mirrored map or turned frame gives tens of percent)."""
    pytest.importorskip("mitsuba")
    results = bench.run(["ggx:0.3", "ggx:0.05x0.3"], [], 48, 256, tmp_path, progress=lambda _: None)
    for row in results["rows"]:
        assert row["reference"] < 0.2, row  # 256 spp under a sun of 50: ~10 % is noise
