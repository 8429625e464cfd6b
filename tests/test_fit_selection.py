"""Model selection of the thesis fit (issue 44 item 3, materials/fit_selection.py): no diffuse term
invented for a conductor, kept where the data has one, and the (ks, r0) valley reported where the
data does not determine the pair."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lobeview.materials import measurement as meas
from lobeview.materials.fit import FitOptions, fit_thesis
from lobeview.materials.fit_selection import best_scale
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import build_bsdf, validate
from lobeview.materials.virtual import virtual_measurement

COARSE = dict(theta_i_deg=(0.0, 20.0, 50.0, 65.0), phi_i_deg=(0.0, 45.0, 90.0), theta_step_deg=10.0, phi_step_deg=30.0)
# Incidences near the normal only: the grazing Fresnel rise that tells ks from r0 is not measured.
NEAR_NORMAL = dict(COARSE, theta_i_deg=(0.0, 10.0, 20.0))


def _virtual(name, **kw):
    return virtual_measurement(validate(PRESETS[name]), **{**COARSE, **kw})


@pytest.mark.parametrize("metric", ["l1", "l2"])
def test_best_scale_is_the_exact_minimiser(metric):
    """The 1-D minimiser of sum w |t - s u| (weighted median) or of its square (least squares)
    against a dense search; clamped to its interval."""
    rng = np.random.default_rng(1)
    unit = rng.random(500)
    target = 0.7 * unit + rng.normal(scale=0.05, size=500) + (rng.random(500) < 0.05) * 3.0
    weights = rng.random(500)

    def error(s):
        diff = target - s * unit
        return np.sum(weights * (np.abs(diff) if metric == "l1" else diff * diff))

    s = best_scale(target, unit, weights, metric, hi=10.0)
    dense = np.linspace(0.0, 2.0, 20001)
    assert error(s) <= min(error(x) for x in dense) + 1e-12
    assert best_scale(target, unit, weights, metric, hi=0.3) == 0.3
    assert best_scale(target, np.zeros(500), weights, metric, hi=1.0) == 0.0


def test_a_conductor_gets_no_invented_diffuse_term():
    """GGX gold (no diffuse term): its flat tail made the histogram's kd 0.04 (goniophotometer) and
    0.12-0.14 (MERL table); the fit now drops it, says why, and --diffuse histogram restores the
    thesis' behaviour."""
    m = _virtual("gold-ggx")
    auto = fit_thesis(m, FitOptions(grid=6))
    assert np.all(auto.kd == 0.0)
    assert auto.diffuse is not None and not auto.diffuse.kept
    assert auto.diffuse.kd_histogram.max() > 0.02
    assert "not supported" in auto.diffuse.message()
    thesis = fit_thesis(m, FitOptions(grid=6, diffuse="histogram"))
    assert thesis.kd.max() > 0.02 and thesis.diffuse is None
    desc = auto.material(data="gold")
    assert desc["kd"] == 0.0 and desc["fit"]["diffuse"]["kept"] is False
    json.dumps(desc)  # the material file can hold the report
    table = meas.merl_table_from_bsdf(build_bsdf(validate(PRESETS["gold-ggx"])))
    merl = fit_thesis(meas.merl_measurement(table, name="gold"), FitOptions(grid=6, isotropic=True))
    assert np.all(merl.kd == 0.0) and merl.diffuse.kd_histogram.max() > 0.1
    # r0 = 1 there (the model cannot brighten a metal's grazing angles otherwise): reported
    assert any("upper bound" in line for line in merl.warnings)


@pytest.mark.parametrize(
    "name, kw",
    [("plastic", {}), ("plastic", dict(noise=0.05, outliers=0.01, seed=3)), ("alanod-2000gs-1lobe", {})],
)
def test_a_diffuse_term_the_data_has_is_kept(name, kw):
    """Plastic (kd 0.05-0.55), also with noise and outlier spikes (which inflate the data's L1
    mass: the gain is measured against the fit's), and the thesis' Alanod with kd 0.003 (small,
    but the fit is exact with it)."""
    truth = np.broadcast_to(np.asarray(validate(PRESETS[name])["kd"], dtype=float), (3,))
    result = fit_thesis(_virtual(name, **kw), FitOptions(grid=6))
    assert result.diffuse is not None and result.diffuse.kept, result.diffuse.message()
    np.testing.assert_allclose(result.kd, truth, rtol=0.05)


def test_diffuse_option_is_checked():
    from lobeview.materials.fit import FitError

    with pytest.raises(FitError, match="diffuse"):
        fit_thesis(_virtual("plastic"), FitOptions(grid=4, iterations=1, diffuse="maybe"))


def test_degenerate_ks_and_r0_are_reported():
    """Measured near the normal only, plastic's ks and r0 trade off along a valley (ks r0 = 0.04
    exact, r0 anywhere in [0.05, 1]); the full goniophotometer determines both. Without the polish
    step the fit's own point lies off the valley's floor, and the report says so."""
    near = fit_thesis(_virtual("plastic", **NEAR_NORMAL), FitOptions(grid=6))
    valley = near.valleys[0]
    assert valley.degenerate
    assert valley.r0[1] - valley.r0[0] > 0.5
    assert valley.product[0] == pytest.approx(0.04, rel=0.02) and valley.product[1] == pytest.approx(0.04, rel=0.02)
    assert any("not determined separately" in line for line in near.warnings)
    report = near.material()["fit"]
    assert report["lobes"][0]["degenerate"] and report["warnings"]

    full = fit_thesis(_virtual("plastic"), FitOptions(grid=6))
    assert not full.valleys[0].degenerate and not full.warnings
    assert full.lobes[0].params["r0"] == pytest.approx(0.04, rel=0.1)

    rough = fit_thesis(_virtual("plastic"), FitOptions(grid=6, polish=False))
    assert rough.valleys[0].off_valley and any("off the valley" in line for line in rough.warnings)
    # a fixed r0 leaves no valley to report
    fixed = fit_thesis(_virtual("plastic", **NEAR_NORMAL), FitOptions(grid=6, fixed={"r0": 0.04}))
    assert fixed.valleys == [] and not fixed.warnings
    assert fixed.lobes[0].params["k"] == pytest.approx(1.0, rel=0.02)


def test_fit_verdict_says_when_a_fit_cannot_be_trusted():
    """issue 43 item 4: the share of the data's Eq. 3.7 mass a fit leaves unexplained decides the
    verdict; a tuple that dominates the weights makes any fit that tuple's."""
    import dataclasses

    from lobeview.materials.fit import eq37_error, metric_weights
    from lobeview.materials.fit_selection import VERDICT_GOOD, VERDICT_POOR, fit_verdict
    from lobeview.materials.spec import load_material
    from lobeview.materials.virtual import virtual_measurement

    m = virtual_measurement(load_material("plastic"), theta_i_deg=(0, 30, 60), phi_i_deg=(0,))
    mass = eq37_error(m.luminance, np.zeros_like(m.luminance), metric_weights(m))
    assert fit_verdict(m, 0.0)["level"] == "good"
    assert fit_verdict(m, 0.5 * (VERDICT_GOOD + VERDICT_POOR) * mass)["level"] == "fair"
    poor = fit_verdict(m, 0.34 * mass)
    assert poor["level"] == "poor" and "34 % of the data's Eq. 3.7 mass unexplained" in poor["messages"][0]
    weight = np.full_like(m.weight, 1e-6)  # weights are solid angles (<= 4 pi): the others made tiny
    weight[np.argmax(m.wi[:, 2])] = 1.0
    heavy = fit_verdict(dataclasses.replace(m, weight=weight), 0.0)
    assert heavy["level"] == "poor" and "one tuple carries" in heavy["messages"][-1]
