"""Split-sum lookups of isotropic lobes at oblique views (materials/split_sum_oblique.py): the
table of the lobe's narrowing across the plane of incidence against its computation and against
the closed form of narrow lobes, and the GLSL copy of the table."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lobeview.materials import split_sum_oblique as oblique


def test_narrow_lobes_narrow_by_the_view_cosine():
    """A half vector tilted by d across the plane of incidence turns the reflected direction by
    2 d cos(theta_o), within it by 2 d: a narrow lobe's spread across the plane is its spread at
    normal incidence times cos(theta_o), so rho = cos(theta_o) (quadrature, no table)."""
    for kind in ("ggx", "beckmann"):
        normal = oblique.perpendicular_spread(kind, 0.08, 1.0, points=200_000)
        for cosine in (0.9, 0.6, 0.4):
            ratio = oblique.perpendicular_spread(kind, 0.08, cosine, points=200_000) / normal
            assert ratio == pytest.approx(cosine, abs=0.03), (kind, cosine, ratio)


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_the_table_is_its_computation(kind):
    """OBLIQUE_RATIO against oblique_ratio_table at a coarser quadrature, on cells from narrow to
    wide lobes and from normal to grazing views; wide lobes narrow less than cos(theta_o)."""
    alphas, cosines = (0.15, 0.5), (0.3, 0.6, 1.0)
    computed = oblique.oblique_ratio_table(kind, points=150_000, alphas=alphas, cosines=cosines)
    table = np.asarray(oblique.OBLIQUE_RATIO[kind])
    stored = table[np.ix_([oblique.OBLIQUE_ALPHAS.index(a) for a in alphas],
                          [oblique.OBLIQUE_COSINES.index(c) for c in cosines])]  # fmt: skip
    np.testing.assert_allclose(computed, stored, atol=0.02)
    assert np.all(stored[:, -1] == 1.0) and stored[1, 0] > stored[0, 0] + 0.1
    assert oblique.oblique_alpha_ratio(kind, 0.5, 0.3) == pytest.approx(stored[1, 0])
    assert oblique.oblique_alpha_ratio(kind, 0.01, 0.7) == pytest.approx(table[0, 6])  # clamped to 0.1
    middle = oblique.oblique_alpha_ratio(kind, 0.25, 0.45)  # bilinear between the four cells
    i, j = oblique.OBLIQUE_ALPHAS.index(0.2), oblique.OBLIQUE_COSINES.index(0.4)
    assert middle == pytest.approx(table[i : i + 2, j : j + 2].mean())


def test_the_shader_holds_the_table():
    source = (Path(__file__).resolve().parents[1] / "shaders" / "prefiltered.glsl").read_text()
    block = source[source.index("OBLIQUE_RATIO[160]") :].split(";")[0]
    numbers = [float(x) for x in re.findall(r"\d+\.\d+", block)]
    expected = np.concatenate([np.ravel(oblique.OBLIQUE_RATIO["ggx"]), np.ravel(oblique.OBLIQUE_RATIO["beckmann"])])
    np.testing.assert_allclose(numbers, expected, atol=5e-4)
    block = source[source.index("OBLIQUE_ALPHAS[8]") :].split(";")[0]
    assert [float(x) for x in re.findall(r"\d+\.\d+", block)] == list(oblique.OBLIQUE_ALPHAS)
    assert float(re.search(r"#define MIN_OBLIQUE_XY (\S+)", source).group(1)) == oblique.MIN_OBLIQUE_XY
