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


def _in_plane_table() -> np.ndarray:
    shape = (len(oblique.OBLIQUE_ALPHAS), len(oblique.OBLIQUE_COSINES), -1)
    return np.asarray(oblique.IN_PLANE_OFFSETS["beckmann"]).reshape(shape)


def test_the_in_plane_table_is_its_computation():
    """IN_PLANE_OFFSETS (Beckmann's in-plane quantile line) against split_sum_in_plane's
    quadrature on cells from narrow to wide lobes and normal to grazing views; at normal
    incidence the nodes meet at the normal, off it the median leans from the mirror direction
    towards the normal (the off-specular shift), more for wider lobes and grazing views."""
    from lobeview.materials import split_sum_in_plane

    table = _in_plane_table()
    alphas, cosines = (0.15, 0.5, 1.0), (0.2, 0.7, 1.0)
    computed = split_sum_in_plane.in_plane_offset_table("beckmann", alphas=alphas, cosines=cosines)
    stored = table[np.ix_([oblique.OBLIQUE_ALPHAS.index(a) for a in alphas],
                          [oblique.OBLIQUE_COSINES.index(c) for c in cosines])]  # fmt: skip
    np.testing.assert_allclose(computed, stored, atol=2e-3)
    assert np.all(stored[:, -1] == 0.0)  # closed at normal incidence
    median = stored[..., 5]
    assert np.all(median[:, :2] > 0.0) and median[1, 0] > median[0, 0] and median[0, 0] > median[0, 1]


def test_in_plane_angles_interpolate_the_table():
    table = _in_plane_table()
    i, j = oblique.OBLIQUE_ALPHAS.index(0.3), oblique.OBLIQUE_COSINES.index(0.6)
    theta_o = np.arccos(0.6)
    np.testing.assert_allclose(oblique.in_plane_angles("beckmann", 0.3, 0.6), -theta_o + 0.3 * table[i, j])
    middle = oblique.in_plane_angles("beckmann", 0.35, 0.65)  # bilinear between the four cells
    expected = -np.arccos(0.65) + 0.35 * table[i : i + 2, j : j + 2].mean(axis=(0, 1))
    np.testing.assert_allclose(middle, expected, atol=1e-9)
    # below alpha 0.1 the 0.1 row, scaled by alpha: a narrow lobe's nodes close in on the mirror
    narrow = oblique.in_plane_angles("beckmann", 0.01, 0.8)
    assert np.all(np.abs(narrow + np.arccos(0.8)) < 0.05) and np.all(np.diff(narrow) > 0)


def test_the_in_plane_line_closes_at_normal_incidence():
    """Near the centre of a sphere the plane of incidence turns all the way round: a line of
    fixed length there would draw a pinwheel (Beckmann 0.8 under courtyard.exr did), so the nodes
    close onto the mirror direction as cos theta_o goes to 1."""
    for alpha in (0.15, 0.5, 0.8, 1.0):
        near = oblique.in_plane_angles("beckmann", alpha, 0.9999)
        assert np.ptp(near) < 0.01, (alpha, near)
        assert np.ptp(oblique.in_plane_angles("beckmann", alpha, 0.95)) < 0.55 * np.ptp(
            oblique.in_plane_angles("beckmann", alpha, 0.9)
        )


def test_the_shader_holds_the_in_plane_table():
    source = (Path(__file__).resolve().parents[1] / "shaders" / "prefiltered.glsl").read_text()
    block = source[source.index("IN_PLANE_OFFSETS[880]") :].split(";")[0]
    numbers = [float(x) for x in re.findall(r"-?\d+\.\d+", block)]
    np.testing.assert_allclose(numbers, np.ravel(oblique.IN_PLANE_OFFSETS["beckmann"]), atol=5e-4)


@pytest.mark.parametrize(
    "alpha, limit, gain, sun", [(0.15, 0.04, 0.5, None), (0.5, 0.045, 1.0, 0.02), (0.8, 0.05, 0.95, 0.03)]
)
def test_beckmann_in_plane_line_is_closer_to_the_lobe_on_the_sky(alpha, limit, gain, sun):
    """Issue 45: split-sum's lookups of Beckmann lobes against the exact lobe integral of issue
    45's sunless sky (bench/split_sum_line.py's numpy twin, 8 x 8 sphere pixels): the in-plane
    quantile line within ``limit`` relative RMSE and at most ``gain`` x the symmetric line's error
    (8.1 / 3.1 / 5.0 % at 12 x 12 pixels, 2.9 / 3.1 / 4.5 % for the line: at 0.5 its gain near
    the normal went with its closing there, its point there is the sun's pixel), and, for the wide
    lobes, whose sun window was too bright, the sky's part at the sun's mirror pixel within ``sun``
    (the symmetric line: 1.028 / 1.076; the table's interpolation leaves 0.8 at 1.023, per pixel
    1.017; at 0.15 the sun's own part, a cap light, dominates that pixel)."""
    from lobeview.bench import lobe_kernel, mitsuba
    from lobeview.bench import split_sum_line as bench

    twin = bench.SplitSumTwin(*bench.light_texels("sky", 256))
    errors = {}
    for in_plane in (True, False):
        truth, estimate = [], []
        for wo, frame in lobe_kernel.sphere_views(8):
            weights, _ = twin.lobe_weights("beckmann", alpha, alpha, wo, frame)
            truth.append(twin.truth(weights))
            estimate.append(twin.lookups("beckmann", alpha, alpha, wo, frame, own_quantiles=in_plane))
        truth, estimate = np.asarray(truth), np.asarray(estimate)
        errors[in_plane] = float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth**2)))
    assert errors[True] < min(limit, gain * errors[False]), errors
    if sun is None:
        return
    normal = mitsuba.sun_mirror_normal()
    tangent = np.cross([0.0, 1.0, 0.0], normal)
    tangent /= np.linalg.norm(tangent)
    frame = np.stack([tangent, np.cross(normal, tangent), normal], axis=1)
    camera = np.asarray(mitsuba.CAMERA[0], dtype=float)
    wo = frame.T @ ((camera - normal) / np.linalg.norm(camera - normal))
    weights, _ = twin.lobe_weights("beckmann", alpha, alpha, wo, frame)
    ratio = twin.lookups("beckmann", alpha, alpha, wo, frame, own_quantiles=True) / twin.truth(weights)
    assert abs(ratio - 1.0) < sun, ratio
