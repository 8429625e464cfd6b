"""``lobeview fit --model microfacet``: the glTF metallic-roughness fit (materials/fit_gltf.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lobeview.app.cli import main
from lobeview.materials import measurement as meas
from lobeview.materials.fit import FitError, material_error
from lobeview.materials.fit_gltf import GltfFitOptions, GltfFitProblem, best_scale, fit_gltf
from lobeview.materials.spec import build_bsdf, load_material, validate
from lobeview.materials.virtual import virtual_measurement

# A coarse goniophotometer (the peak scan still resolves the lobes) keeps each fit to seconds.
COARSE = dict(theta_i_deg=(0.0, 20.0, 50.0, 65.0), phi_i_deg=(0.0, 45.0, 90.0), theta_step_deg=10.0, phi_step_deg=30.0)


def _gltf(**kw) -> dict:
    return validate({"model": "gltf", **kw})


def _measure(desc: dict, **kw) -> meas.Measurement:
    return virtual_measurement(desc, **{**COARSE, **kw})


def test_model_is_multilinear_in_metallic_transmission_and_base_colour():
    """The 8 corners of (metallic, transmission, base colour) reproduce gltf_bsdf at random
    parameters exactly, including anisotropy along the bitangent and transmission tuples."""
    m = _measure(_gltf(base_color=[0.5, 0.5, 0.5], metallic=0.0, roughness=0.5, transmission=0.5))
    assert m.transmission.any()
    problem = GltfFitProblem(m, "l1")
    wi, wo = meas.renderer_pair(m.wi, m.wo)
    rng = np.random.default_rng(3)
    for _ in range(6):
        signed = float(rng.uniform(-1, 1))
        params = dict(
            roughness=float(rng.uniform(0.05, 1)),
            metallic=float(rng.uniform()),
            anisotropy=signed,
            transmission=float(rng.uniform()),
        )
        base = rng.uniform(size=3)
        a, c = problem.affine_parts(params)
        desc = _gltf(
            base_color=list(base),
            metallic=params["metallic"],
            roughness=params["roughness"],
            anisotropy=abs(signed),
            anisotropy_rotation=math.pi / 2 if signed < 0 else 0.0,
            transmission=params["transmission"],
        )
        expected = meas.sample_frame_eval(build_bsdf(desc), wi, wo) * np.abs(m.wo[:, 2:3])
        np.testing.assert_allclose(a[:, None] + c[:, None] * base, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("metric", ["l1", "l2"])
def test_best_scale_is_the_constrained_minimum(metric):
    """The weighted median / least squares against a dense scan of b in [0, 1]."""
    rng = np.random.default_rng(7)
    n = 400
    slope = rng.uniform(0, 2, n) * (rng.uniform(size=n) > 0.1)
    offset = rng.uniform(0, 0.3, n)
    weights = rng.uniform(0, 1, n)
    for truth in (0.37, 1.6, -0.4):  # inside, above and below the interval
        target = offset + truth * slope + rng.laplace(scale=0.05, size=n)
        b = best_scale(target, offset, slope, weights, metric)
        scan = np.linspace(0, 1, 20001)
        diff = target[None, :] - offset[None, :] - scan[:, None] * slope[None, :]
        penalty = np.abs(diff) if metric == "l1" else diff**2
        cost = penalty @ weights
        assert 0.0 <= b <= 1.0
        best = float(cost.min())
        b_cost = float(
            weights @ (np.abs(target - offset - b * slope) if metric == "l1" else (target - offset - b * slope) ** 2)
        )
        assert b_cost <= best + 1e-9 * max(best, 1.0)


RECOVERY = {
    # name: (material, fit options)
    "red plastic": (_gltf(base_color=[0.8, 0.2, 0.1], metallic=0.0, roughness=0.45), dict(isotropic=True)),
    "gold": (_gltf(base_color=[1.0, 0.78, 0.34], metallic=1.0, roughness=0.3), dict(isotropic=True)),
    "brushed along the bitangent": (
        _gltf(
            base_color=[0.9, 0.9, 0.9], metallic=1.0, roughness=0.35, anisotropy=0.6, anisotropy_rotation=math.pi / 2
        ),
        dict(fixed={"metallic": 1.0}),
    ),
    "frosted glass": (
        _gltf(base_color=[0.9, 0.95, 1.0], metallic=0.0, roughness=0.3, transmission=0.7),
        dict(isotropic=True, fixed={"metallic": 0.0}),
    ),
}


@pytest.mark.parametrize("name", sorted(RECOVERY))
def test_parameter_recovery(name):
    """Noise-free virtual measurements of known glTF materials are fitted back: every parameter
    within 0.01 (the model is identifiable on these grids), the error near zero."""
    desc, options = RECOVERY[name]
    m = _measure(desc)
    result = fit_gltf(m, GltfFitOptions(grid=6, iterations=4, **options))
    fitted = result.material()
    assert validate(fitted)
    assert fitted["roughness"] == pytest.approx(desc["roughness"], abs=0.01)
    assert fitted["metallic"] == pytest.approx(desc["metallic"], abs=0.01)
    np.testing.assert_allclose(fitted["base_color"], desc["base_color"], atol=0.01)
    assert fitted.get("anisotropy", 0.0) == pytest.approx(desc.get("anisotropy", 0.0), abs=0.01)
    if desc.get("anisotropy", 0.0) > 0:
        assert fitted["anisotropy_rotation"] == pytest.approx(desc["anisotropy_rotation"])
    assert fitted.get("transmission", 0.0) == pytest.approx(desc.get("transmission", 0.0), abs=0.01)
    assert material_error(fitted, m) < 1e-3 * material_error({"model": "thesis", "kd": 0.0, "lobes": []}, m)


def test_l1_fit_ignores_outliers():
    """5 % spikes (10-100 x the median) and 2 % noise: the L1 fit keeps roughness and base colour
    (the thesis' argument for Eq. 3.7), the squared metric does not."""
    desc = _gltf(base_color=[0.8, 0.2, 0.1], metallic=0.0, roughness=0.45)
    m = _measure(desc, noise=0.02, outliers=0.05, seed=4)
    l1 = fit_gltf(m, GltfFitOptions(grid=6, iterations=4, isotropic=True)).material()
    l2 = fit_gltf(m, GltfFitOptions(grid=6, iterations=4, isotropic=True, metric="l2")).material()
    assert l1["roughness"] == pytest.approx(0.45, abs=0.03)
    np.testing.assert_allclose(l1["base_color"], desc["base_color"], atol=0.03)
    l2_off = abs(l2["roughness"] - 0.45) + np.abs(np.subtract(l2["base_color"], desc["base_color"])).max()
    assert l2_off > 0.1


def test_fit_of_another_model_keeps_the_albedo():
    """GGX gold with the exact conductor Fresnel (measured n, k) has no exact glTF twin (Schlick
    from the base colour): the fit is within 1 % relative L1 and keeps the directional albedo
    within 1 % at 0, 35 and 65 deg incidence."""
    gold = load_material("gold-ggx")
    m = _measure(gold)
    result = fit_gltf(m, GltfFitOptions(grid=6, iterations=3))
    fitted = result.material()
    assert fitted["metallic"] == pytest.approx(1.0, abs=0.01)
    assert result.error < 0.01 * material_error({"model": "thesis", "kd": 0.0, "lobes": []}, m)
    for theta in (0.0, 35.0, 65.0):
        wi = meas.spherical_direction(math.radians(theta), 0.0)
        truth = build_bsdf(gold).albedo(wi, order=96)[0].mean()
        assert build_bsdf(fitted).albedo(wi, order=96)[0].mean() == pytest.approx(truth, rel=0.01)


def test_options_are_checked():
    m = _measure(_gltf(base_color=[0.5, 0.5, 0.5], metallic=0.0, roughness=0.5))
    for options, message in [
        (dict(fixed={"mx": 0.1}), "unknown"),
        (dict(fixed={"roughness": 2.0}), "outside"),
        (dict(ranges={"metallic": (0.8, 0.2)}), "LO < HI"),
        (dict(fixed={"transmission": 0.5}), "no transmission tuple"),
        (dict(grid=2), "grid"),
    ]:
        with pytest.raises(FitError, match=message):
            fit_gltf(m, GltfFitOptions(iterations=1, **options))


def test_cli_microfacet_fit(tmp_path, capsys):
    out, png = tmp_path / "plastic.json", tmp_path / "plastic.png"
    coarse = ["--theta-i", "0,20,65", "--phi-i", "0,90", "--theta-step", "10", "--phi-step", "30"]
    args = ["fit", "virtual:gltf-red-plastic", "--model", "microfacet", "--isotropic", "--grid", "5"]
    assert main([*args, "--iterations", "3", "-o", str(out), "--plot", str(png), *coarse]) == 0
    text = capsys.readouterr().out
    assert "Eq. 3.7 L1 error" in text and "directional albedo" in text
    desc = load_material(str(out))  # the viewer's loader accepts it
    truth = load_material("gltf-red-plastic")
    assert desc["model"] == "gltf" and desc["roughness"] == pytest.approx(truth["roughness"], abs=0.01)
    assert png.stat().st_size > 20_000
    assert main([*args, "--fix", "mx=0.1", *coarse]) == 2
    assert "unknown to --model microfacet" in capsys.readouterr().err
    assert main([*args, "--lobes", "2", *coarse]) == 2
