"""A measured material rendered from its table (issue 44 item 1, materials/measured.py): the
table's value, the tabulated sampler against its density (chi-square), the albedo against the
analytic material the table was made from, the GLSL twin against numpy, the material JSON's
trust boundary, and the preview's renders of the table against those of the analytic material."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import run_compute_probe

from lobeview.bench.chi2 import SphereDomain, bsdf_chi2_test
from lobeview.materials.measured import DEFENSIVE_COSINE, MeasuredError, MeasuredLobe, measured_lobe, split_diffuse
from lobeview.materials.measurement import merl_lookup, merl_table_from_bsdf, read_merl, write_merl
from lobeview.materials.spec import (
    MaterialError,
    build_bsdf,
    load_material,
    relative_material_files,
    resolve_material_files,
)
from lobeview.materials.vec import direction_from_angles_deg, reflect

GOLD = {
    "model": "microfacet", "distribution": "ggx", "alpha": 0.15, "fresnel": {"type": "schlick", "r0": [1.0, 0.78, 0.34]}
}  # fmt: skip
# A two-lobe thesis material with a diffuse term: the sampler must cover the whole hemisphere.
PLASTIC = {
    "model": "thesis", "kd": [0.3, 0.1, 0.05],
    "lobes": [{"ks": 0.3, "mx": 0.1, "my": 0.1, "r0": 0.05, "alpha": 0.2},
              {"ks": 0.2, "mx": 0.4, "my": 0.4, "r0": 0.05, "alpha": 0.2}],
}  # fmt: skip


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """MERL files of GOLD and PLASTIC (virtual measurements in MERL's layout)."""
    folder = tmp_path_factory.mktemp("measured")
    paths = {}
    for name, desc in (("gold", GOLD), ("plastic", PLASTIC)):
        paths[name] = folder / f"{name}.binary"
        write_merl(merl_table_from_bsdf(build_bsdf(desc)), paths[name])
    return paths


def _view(theta_deg: float, phi_deg: float = 30.0) -> np.ndarray:
    return direction_from_angles_deg(theta_deg, phi_deg)


def _pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    wi, wo = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    return wi / np.linalg.norm(wi, axis=1, keepdims=True), wo / np.linalg.norm(wo, axis=1, keepdims=True)


@pytest.mark.parametrize("name", ["gold", "plastic"])
def test_eval_is_the_nearest_cell_of_the_table(tables, name):
    """The material is the table's floor (Lambert) plus the residual lobe: max(f, kd / pi) at
    the nearest cell, which is f wherever the table reaches its floor (split_diffuse)."""
    table = read_merl(tables[name])
    bsdf = build_bsdf(load_material(f"measured:{tables[name]}"))
    kd = np.zeros(3) if len(bsdf.components) == 1 else bsdf.components[0].kd
    wi, wo = _pairs(4000, 1)
    measured = np.nan_to_num(merl_lookup(table, wi, wo))
    np.testing.assert_allclose(bsdf.eval(wi, wo), np.maximum(measured, kd / math.pi), rtol=1e-6, atol=1e-7)
    lobe = bsdf.components[-1]
    np.testing.assert_array_equal(lobe.eval(wi, wo), np.nan_to_num(merl_lookup(lobe.table, wi, wo)))
    # Below the horizon: zero, as every lobeview BSDF.
    assert not bsdf.eval(wi * [1, 1, -1], wo).any()


def test_floor_split_recovers_a_diffuse_term(tables):
    """PLASTIC's kd exactly; GGX gold's floor is its tail's smallest value (no invented plateau)."""
    kd, residual = split_diffuse(read_merl(tables["plastic"]))
    np.testing.assert_allclose(kd, PLASTIC["kd"], rtol=1e-9)
    assert np.nanmin(residual) >= 0.0
    gold_table = read_merl(tables["gold"])
    kd, _ = split_diffuse(gold_table)
    assert (kd / math.pi <= np.nanmin(gold_table[:80, :80], axis=(0, 1, 2)) + 1e-12).all() and kd.max() < 0.05
    # A Beckmann tail's floor (~1e-45) is no diffuse term: no Lambert component at all.
    beckmann = {"model": "microfacet", "distribution": "beckmann", "alpha": 0.5, "fresnel": "none"}
    kd, residual = split_diffuse(merl_table_from_bsdf(build_bsdf(beckmann)))
    assert (kd == 0).all() and np.nanmin(residual) >= 0


@pytest.mark.parametrize(
    ("name", "theta", "cap"),
    [("gold", 0.0, None), ("gold", 37.0, 0.6), ("gold", 72.0, None), ("plastic", 20.0, None), ("plastic", 63.0, None)],
)
def test_sampler_matches_its_density_chi_square(tables, tmp_path, name, theta, cap):
    """Views at a bin centre's neighbourhood and between centres (the mixture of two bins), the
    whole sphere and a cap around the specular direction."""
    bsdf = build_bsdf(load_material(f"measured:{tables[name]}"))  # Lambert floor + lobe
    wo = _view(theta)
    if cap is None:
        domain = SphereDomain()
    else:
        domain = SphereDomain(res_a=25, res_b=41, centre=reflect(wo, np.array([0.0, 0.0, 1.0])), cap_angle=cap)
    result = bsdf_chi2_test(bsdf, wo, 300_000, domain, tmp_path, f"measured-{name}-{theta}", seed=7)
    assert result.passed, result.message
    if cap is None:
        assert result.mass_pdf == pytest.approx(result.mass_observed, abs=0.006), result.message


def test_albedo_matches_the_analytic_material_and_the_sampler(tables):
    """The table's albedo (midpoint rule over the sampler's cells) against the analytic GGX it
    was made from (Gauss-Legendre: independent), and the importance-sampled mean of f cos / p."""
    measured = build_bsdf(load_material(f"measured:{tables['gold']}"))
    gold = build_bsdf(GOLD)
    rng = np.random.default_rng(3)
    for theta in (0.0, 30.0, 60.0, 80.0):
        wo = _view(theta)
        table_albedo, _ = measured.albedo(wo)
        analytic, _ = gold.albedo(wo)
        np.testing.assert_allclose(table_albedo, analytic, rtol=5e-3)
        s = measured.sample(rng.random(200_000), rng.random(200_000), wo)
        np.testing.assert_allclose(s.weight.mean(axis=0), table_albedo, rtol=5e-3)
        # Bounded weights: the tabulated density follows f cos (no fireflies in mc-N).
        assert s.weight.max() < 20.0


def test_cosine_share_keeps_the_density_positive(tables):
    lobe = measured_lobe(tables["gold"])
    rng = np.random.default_rng(5)
    wi = rng.normal(size=(2000, 3))
    wi[:, 2] = np.abs(wi[:, 2]) + 1e-3
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = np.broadcast_to(_view(50.0), wi.shape)
    assert (lobe.pdf(wi, wo) >= DEFENSIVE_COSINE * wi[:, 2] / math.pi * (1 - 1e-9)).all()


def test_proxy_distribution_of_a_ggx_table_is_ggx(tables):
    d = measured_lobe(tables["gold"]).distribution
    assert d.kind == "ggx" and d.alpha_x == pytest.approx(0.15, rel=0.05)
    # Two Kurt lobes (0.1 and 0.4): the peak's width is the sharper one's, the broad lobe its tail.
    d = measured_lobe(tables["plastic"]).distribution
    assert 0.08 <= d.alpha_x <= 0.15, (d.kind, d.alpha_x)


def test_glsl_twin_matches_numpy(tables):
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.interface import MEASURED_BINDING
    from lobeview.viewer.shaders import ProgramCache

    lobe: MeasuredLobe = measured_lobe(tables["plastic"])
    rng = np.random.default_rng(2)
    per = 512
    wo = np.concatenate([np.broadcast_to(_view(t, 20.0), (per, 3)) for t in (0.5, 33.0, 75.0)])
    n = len(wo)
    u = rng.random((n, 2))
    wi = lobe.sample_wi(u[:, 0], u[:, 1], wo)
    ctx = create_headless_context()
    try:
        program = ProgramCache(ctx).compute("measured_probe.comp")
        probe = np.zeros((n, 3, 4), np.float32)
        probe[:, 0, :3], probe[:, 1, :3], probe[:, 2, :2] = wi, wo, u
        table = ctx.texture3d(lobe.table.shape[2::-1], 3, np.ascontiguousarray(lobe.table).tobytes(), dtype="f4")
        table.use(0)
        program["u_measured_table"] = 0
        cdf = ctx.buffer(lobe.sampler.pack().tobytes())
        cdf.bind_to_storage_buffer(MEASURED_BINDING)
        out = run_compute_probe(ctx, program, probe, 3, out_binding=4)
    finally:
        ctx.release()
    ok = wi[:, 2] > 1e-3
    f = lobe.eval(wi, wo)
    # Float32 angles land in another cell only on a cell's edge: nearly every value is exact.
    same = np.all(np.isclose(out[:, 0, :3], f, rtol=1e-5, atol=1e-7), axis=1)
    assert same[ok].mean() > 0.99, same[ok].mean()
    # Sampled directions: float32 inside a cell of nearly no mass moves a few by up to ~1e-2.
    error = np.abs(out[ok, 1, :3] - wi[ok]).max(axis=1)
    assert (error < 2e-3).mean() > 0.995 and error.max() < 3e-2, np.quantile(error, [0.5, 0.999, 1])
    pdf = lobe.pdf(wi, wo)
    # A sample's own density comes from the cell it was drawn in (shaders/measured.glsl); where
    # float32 and float64 put it on opposite sides of a cell edge the two differ (~2 %).
    close = np.isclose(out[ok, 1, 3], pdf[ok], rtol=1e-3)
    assert close.mean() > 0.96, close.mean()
    close = np.isclose(out[ok, 2, 0], pdf[ok], rtol=1e-3)
    assert close.mean() > 0.98, close.mean()
    assert np.median(np.abs(out[ok, 2, 0] / pdf[ok] - 1)) < 1e-4


def test_material_sources_and_the_trust_boundary(tables, tmp_path):
    desc = load_material(f"measured:{tables['gold']}")
    assert desc["model"] == "measured" and desc["name"] == "gold"
    assert isinstance(build_bsdf(desc).components[-1], MeasuredLobe)
    # A JSON file names its table relative to its own folder...
    folder = tables["gold"].parent
    (folder / "gold.json").write_text(json.dumps({"model": "measured", "file": "gold.binary"}))
    assert load_material(str(folder / "gold.json"))["file"] == str(tables["gold"].resolve())
    # ... and may not leave it.
    (tmp_path / "outside.json").write_text(json.dumps({"model": "measured", "file": f"../{folder.name}/gold.binary"}))
    with pytest.raises(MaterialError, match="outside"):
        load_material(str(tmp_path / "outside.json"))
    # ... unless the user opts in, as the refusal says (--allow-outside-references: its Limits).
    from lobeview.app.options import OptionError, read_material_edits
    from lobeview.core.trust import Limits

    edits = tmp_path / "edits.json"
    edits.write_text(json.dumps({"box": {"model": "measured", "file": f"../{folder.name}/gold.binary"}}))
    with pytest.raises(OptionError, match="allow-outside-references"):
        read_material_edits(edits)
    opted_in = read_material_edits(edits, Limits(allow_outside=True))
    assert Path(opted_in["box"]["file"]).resolve() == tables["gold"].resolve()
    (tmp_path / "missing.json").write_text(json.dumps({"model": "measured", "file": "none.binary"}))
    with pytest.raises(MaterialError, match="no such file"):
        load_material(str(tmp_path / "missing.json"))
    with pytest.raises(MaterialError, match="no such file"):
        load_material(f"measured:{tmp_path / 'none.binary'}")
    with pytest.raises(MaterialError, match="file"):
        load_material('{"model": "measured"}')
    # The viewer's save names a table inside its folder relatively: read back to the same table.
    saved = relative_material_files(desc, folder)
    assert saved["file"] == "gold.binary"
    assert resolve_material_files(saved, folder)["file"] == desc["file"]
    assert relative_material_files(desc, tmp_path)["file"] == desc["file"]  # outside: kept (refused on load)


def test_unusable_tables_are_refused():
    table = np.full((90, 90, 180, 3), np.nan)
    with pytest.raises(MeasuredError, match="no measured cell"):
        MeasuredLobe(table)
    table[..., :] = 0.1
    table[3, 4, 5, 1] = -1.0
    with pytest.raises(MeasuredError, match="negative"):
        MeasuredLobe(table)


def test_preview_renders_the_table_like_the_analytic_material(tables):
    """Through the real pipeline: the reference of the table against the reference of the GGX it
    was made from (the table's cells and the estimators' noise apart: the same image), and lobe-7
    through the fitted proxy within what lobe-7 is off on the analytic material itself."""
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PREVIEW_CAMERA, PreviewRenderer

    def sky(d):
        glow = np.exp(40.0 * (d @ np.array([0.3, 0.8, 0.52]) - 1.0))[..., None]
        return 0.2 + 0.3 * np.clip(d[..., 1:2], 0, 1) + 20.0 * glow * np.array([1.0, 0.9, 0.8])

    ctx = create_headless_context()
    try:
        env = EnvironmentMap.from_function(sky, height=64, name="glow")
        renderer = PreviewRenderer(ctx, env, uv_sphere(rings=48, segments=96), size=(64, 64), face_size=64)
        position, target, up, fov = PREVIEW_CAMERA
        camera = Camera(position=position, target=target, up=up, fov_y=fov)
        measured, analytic = build_bsdf(load_material(f"measured:{tables['gold']}")), build_bsdf(GOLD)
        images = {}
        for key, bsdf in (("measured", measured), ("analytic", analytic)):
            for method in ("reference", "lobe-7"):
                result = renderer.render(camera, bsdf, method, spp=128, background=False)
                assert np.isfinite(result.radiance).all()
                images[key, method] = result.radiance[result.mask]
        renderer.release()
    finally:
        ctx.release()

    def rel_rmse(a, b):
        return float(np.sqrt(((a - b) ** 2).mean() / (b**2).mean()))

    truth = images["analytic", "reference"]
    assert images["measured", "reference"].mean() == pytest.approx(truth.mean(), rel=0.015)
    assert rel_rmse(images["measured", "reference"], truth) < 0.04
    own_error = rel_rmse(images["analytic", "lobe-7"], truth)
    assert rel_rmse(images["measured", "lobe-7"], truth) < own_error + 0.03, own_error


def test_lobes_with_their_own_buffers_stay_out_of_the_rsibr_bake(tables):
    """shaders/rsibr_bake.comp binds neither a measured table nor a Rational BRDF's functions:
    such lobes keep the automatic prefiltered lookup (their packed lobe holds a proxy only)."""
    from lobeview.viewer.rsibr import rsibr_eligible

    measured = build_bsdf(load_material(f"measured:{tables['plastic']}"))
    assert not rsibr_eligible(measured.components[-1])
    rational = build_bsdf(load_material(str(Path(__file__).parent / "data" / "gold-ggx-rational.json")))
    assert not rsibr_eligible(rational.components[0])
    assert rsibr_eligible(build_bsdf(GOLD).components[0])


def test_fit_render_figure(tmp_path, monkeypatch):
    """``fit --render``: the data rendered as they are beside the fit; identical when the fit is
    the material itself, a clear difference when it is not; CSV data refused before any fit."""
    from lobeview.app import fit_render
    from lobeview.materials.spec import validate

    monkeypatch.setattr(fit_render, "RENDER_SIZE", 40)
    monkeypatch.setattr(fit_render, "RENDER_SPP", 16)
    same = fit_render.render_comparison("virtual:plastic", load_material("plastic"), str(tmp_path / "a.png"), say=print)
    assert same < 1e-6 and (tmp_path / "a.png").stat().st_size > 0
    darker = validate({**load_material("plastic"), "kd": [0.02, 0.05, 0.2]})
    assert fit_render.render_comparison("virtual:plastic", darker, str(tmp_path / "b.png"), say=print) > 0.1
    with pytest.raises(fit_render.RenderError, match="scattered goniophotometer tuples"):
        fit_render.check_renderable(str(tmp_path / "data.csv"))
