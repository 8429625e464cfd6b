"""BSDF evaluation against independent computations: reciprocity, closed forms, white furnace,
brute-force quadrature, the glTF specification formulas and the thesis' fitted albedos."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.materials.bsdf import BSDF
from lobeview.materials.conductor import microfacet_bsdf
from lobeview.materials.fresnel import Fresnel
from lobeview.materials.gltf import gltf_bsdf
from lobeview.materials.presets import PRESETS, THESIS_MEASURED_THETA_DEG, THESIS_TABLE_ALBEDO
from lobeview.materials.spec import build_bsdf
from lobeview.materials.thesis import thesis_bsdf
from lobeview.materials.vec import direction_from_angles_deg


def _random_upper(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


REFLECTION_MODELS = {
    "thesis-alanod2": lambda: build_bsdf(PRESETS["alanod-2000gs-2lobe"]),
    "thesis-aniso-alpha": lambda: thesis_bsdf(0.2, [(0.8, 0.05, 0.3, 0.3, 0.7)]),
    "ggx-conductor": lambda: build_bsdf(PRESETS["gold-ggx"]),
    "beckmann-aniso": lambda: build_bsdf(PRESETS["brushed-steel-beckmann"]),
    "gltf": lambda: gltf_bsdf([0.5, 0.4, 0.3], 0.3, 0.5),
}


@pytest.mark.parametrize("name", sorted(REFLECTION_MODELS))
def test_reflection_is_reciprocal(name):
    bsdf = REFLECTION_MODELS[name]()
    rng = np.random.default_rng(11)
    wi, wo = _random_upper(rng, 5000), _random_upper(rng, 5000)
    np.testing.assert_allclose(bsdf.eval(wi, wo), bsdf.eval(wo, wi), rtol=1e-10, atol=1e-300)


def test_lambert_albedo_equals_kd():
    bsdf = thesis_bsdf([0.2, 0.5, 0.8], [])
    for theta in (0, 40, 80, 89.9):
        r, t = bsdf.albedo(direction_from_angles_deg(theta, 10), order=64)
        np.testing.assert_allclose(r, [0.2, 0.5, 0.8], rtol=1e-10)
        assert np.all(t == 0)


PLAUSIBLE = {
    # Kurt et al.: alpha = 0 is always energy conserving; kd + ks <= 1.
    "thesis-alpha0-rough": lambda: thesis_bsdf(0.3, [(0.7, 0.4, 0.4, 1.0, 0.0)]),
    "thesis-alpha0-aniso": lambda: thesis_bsdf(0.0, [(1.0, 0.01, 0.5, 1.0, 0.0)]),
    "thesis-alpha0-transmission": lambda: thesis_bsdf(0.0, [(1.0, 0.2, 0.2, 0.1, 0.0)], [(1.0, 0.2, 0.2, 0.1, 0.0)]),
    "ggx-white": lambda: microfacet_bsdf("ggx", 0.6, 0.6, Fresnel("none")),
    "ggx-white-aniso": lambda: microfacet_bsdf("ggx", 0.02, 0.8, Fresnel("none")),
    "beckmann-white": lambda: microfacet_bsdf("beckmann", 0.8, 0.8, Fresnel("none")),
    "gltf-white-metal": lambda: gltf_bsdf(1.0, 1.0, 0.7),
}
PLAUSIBLE.update(
    {
        f"preset-{k}": (lambda k=k: build_bsdf(PRESETS[k]))
        for k in (
            "chrome",
            "lacquer",
            "plastic",
            "porcelain",
            "clear-glass",
            "frosted-glass",
            "gold-ggx",
            "brushed-steel-beckmann",
            "gltf-red-plastic",
        )
    }
)


@pytest.mark.parametrize("name", sorted(PLAUSIBLE))
def test_white_furnace_albedo_at_most_one(name):
    bsdf = PLAUSIBLE[name]()
    for theta in (0.0, 30.0, 60.0, 80.0, 85.0, 89.0, 89.9):
        for phi in (0.0, 37.0, 90.0):
            r, t = bsdf.albedo(direction_from_angles_deg(theta, phi), order=160)
            total = r + t
            assert np.all(total <= 1.0 + 2e-3), f"{name} theta={theta} phi={phi}: albedo {total}"
            assert np.all(total >= 0.0)


def test_gltf_fresnel_mix_gains_energy_at_grazing_as_specified():
    """The spec's fresnel_mix weights the diffuse base by 1 - F(V.H) per light direction, which is
    not energy conserving: a white rough dielectric reflects more than it receives towards
    grazing. lobeview implements the spec as written; this pins the (known) excess."""
    bsdf = gltf_bsdf(1.0, 0.0, 0.3)
    at_normal = bsdf.albedo(direction_from_angles_deg(0))[0][0]
    at_80 = bsdf.albedo(direction_from_angles_deg(80))[0][0]
    assert at_normal == pytest.approx(1.0, abs=2e-3)
    assert 1.15 < at_80 < 1.3


def test_white_ggx_albedo_bounds_from_closed_form():
    """Single-scattering GGX with F = 1 at normal incidence: E = integral over theta_h < 45 deg
    of D(h) G cos(theta_h) dh. For alpha = 1, D = 1/pi is constant, so E < 2 int_0^{pi/4}
    cos sin = 1/2 exactly without masking; Smith masking brings it lower. For alpha = 0.05
    only the GGX tail beyond 45 deg (mass 1 - 1/(1 + alpha^2), about alpha^2) is lost."""
    rough = microfacet_bsdf("ggx", 1.0, 1.0, Fresnel("none")).albedo(direction_from_angles_deg(0))[0]
    assert 0.25 < rough[0] < 0.5
    smooth = microfacet_bsdf("ggx", 0.05, 0.05, Fresnel("none")).albedo(direction_from_angles_deg(0))[0]
    lost_tail = 1.0 - 1.0 / (1.0 + 0.05**2)
    assert smooth[0] == pytest.approx(1.0 - lost_tail, abs=1e-3)


def _brute_force_albedo(bsdf: BSDF, wo: np.ndarray, n_theta=1500, n_phi=720):
    """Midpoint quadrature over the whole sphere of wi, independent of the samplers."""
    theta = (np.arange(n_theta) + 0.5) * np.pi / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    wi = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    f = bsdf.eval(wi, np.broadcast_to(wo, wi.shape))
    w = (np.abs(np.cos(T)) * np.sin(T))[..., None] * (np.pi / n_theta) * (2 * np.pi / n_phi)
    upper = (T < np.pi / 2)[..., None]
    return np.sum(np.where(upper, f * w, 0), axis=(0, 1)), np.sum(np.where(upper, 0, f * w), axis=(0, 1))


@pytest.mark.parametrize(
    "preset,theta",
    [
        ("white-foil", 0),
        ("white-foil", 60),
        ("alanod-2000gs-2lobe", 30),
        ("frosted-glass", 45),
        ("gltf-red-plastic", 70),
        ("brushed-steel-beckmann", 20),
        ("plastic", 50),
    ],
)
def test_albedo_quadrature_matches_brute_force(preset, theta):
    bsdf = build_bsdf(PRESETS[preset])
    wo = direction_from_angles_deg(theta, 25)
    r, t = bsdf.albedo(wo, order=128)
    r_ref, t_ref = _brute_force_albedo(bsdf, wo)
    np.testing.assert_allclose(r, r_ref, rtol=5e-3, atol=2e-4)
    np.testing.assert_allclose(t, t_ref, rtol=5e-3, atol=2e-4)


@pytest.mark.parametrize("preset", sorted(THESIS_TABLE_ALBEDO))
def test_fitted_presets_reproduce_thesis_reflectance(preset):
    """The thesis tables give one 'Albedo' per fit. lobeview's directional reflectance averaged
    over the goniophotometer's measured incidence angles (and azimuths 0/45/90) matches it to
    0.025 (absolute); the remaining gap is within the spread of the directional values
    themselves (e.g. Alanod 1-lobe: 0.80 at 0 deg, 0.72 at 60 deg)."""
    bsdf = build_bsdf(PRESETS[preset])
    values = []
    for theta in THESIS_MEASURED_THETA_DEG[preset]:
        for phi in (0.0, 45.0, 90.0):
            r, _ = bsdf.albedo(direction_from_angles_deg(theta, phi), order=128)
            values.append(r.mean())
    assert np.mean(values) == pytest.approx(THESIS_TABLE_ALBEDO[preset]["reflectance"], abs=0.025)


def test_white_foil_transmittance_follows_model_not_table():
    """Known discrepancy (README, 'Presets'): Eq. 3.5 with Table 3.2's lobe (kt 0.67, r0 0.75)
    transmits ~kt (1 - r0) = 0.1675 near normal incidence, the table says 0.093. lobeview keeps
    the published parameters; this pins the model's value against that closed form."""
    bsdf = build_bsdf(PRESETS["white-foil"])
    _, t = bsdf.albedo(direction_from_angles_deg(0), order=160)
    assert t.mean() == pytest.approx(0.67 * (1 - 0.75), rel=0.03)


def _gltf_spec_brdf(base, metallic, roughness, l, v):
    """glTF 2.0 spec Appendix B written out independently with the spec's own names."""
    n = np.array([0.0, 0.0, 1.0])
    h = (l + v) / np.linalg.norm(l + v, axis=-1, keepdims=True)
    a = roughness**2
    n_l, n_v, n_h = l @ n, v @ n, h @ n
    v_h, l_h = np.sum(v * h, -1), np.sum(l * h, -1)
    d = a * a * (n_h > 0) / (np.pi * (n_h * n_h * (a * a - 1) + 1) ** 2)
    vis = (
        (l_h > 0)
        * (v_h > 0)
        * 0.5
        / (n_l * np.sqrt(n_v * n_v * (1 - a * a) + a * a) + n_v * np.sqrt(n_l * n_l * (1 - a * a) + a * a))
    )
    specular = (vis * d)[:, None]
    diffuse = np.asarray(base) / np.pi
    fw = ((1 - np.abs(v_h)) ** 5)[:, None]
    metal = specular * (np.asarray(base) + (1 - np.asarray(base)) * fw)
    dielectric_f = 0.04 + 0.96 * fw
    dielectric = (1 - dielectric_f) * diffuse + dielectric_f * specular
    return (1 - metallic) * dielectric + metallic * metal


@pytest.mark.parametrize(
    "base,metallic,roughness",
    [([0.8, 0.2, 0.1], 0.0, 0.5), ([0.9, 0.7, 0.3], 1.0, 0.25), ([0.5, 0.5, 0.5], 0.4, 0.8)],
)
def test_gltf_matches_specification_appendix_b(base, metallic, roughness):
    rng = np.random.default_rng(5)
    l, v = _random_upper(rng, 4000), _random_upper(rng, 4000)
    ours = gltf_bsdf(base, metallic, roughness).eval(l, v)
    np.testing.assert_allclose(ours, _gltf_spec_brdf(base, metallic, roughness, l, v), rtol=1e-10)


def test_thesis_lobe_matches_equation_3_4_written_out():
    """Eq. 3.4 with Eq. 3.3 and Eq. 2.9 evaluated from angles, independently of the vector code."""
    ks, mx, my, r0, alpha = 0.9, 0.11, 0.072, 0.89, 0.43
    bsdf = thesis_bsdf(0.0, [(ks, mx, my, r0, alpha)])
    rng = np.random.default_rng(2)
    wi, wo = _random_upper(rng, 3000), _random_upper(rng, 3000)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    theta_h = np.arccos(h[:, 2])
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    d = np.exp(-(np.tan(theta_h) ** 2) * (np.cos(phi_h) ** 2 / mx**2 + np.sin(phi_h) ** 2 / my**2)) / (
        np.pi * mx * my * np.cos(theta_h) ** 4
    )
    u = np.sum(wo * h, -1)
    f = r0 + (1 - r0) * (1 - u) ** 5
    expected = ks * f * d / (4 * u * (wi[:, 2] * wo[:, 2]) ** alpha)
    np.testing.assert_allclose(bsdf.eval(wi, wo)[:, 0], expected, rtol=1e-9, atol=1e-300)


def test_transmission_lobe_is_reflection_lobe_mirrored():
    """Eq. 3.5: f_t(wi, wo) = (1 - F)/F times the reflection lobe at the mirrored wi."""
    refl = thesis_bsdf(0.0, [(1.0, 0.2, 0.1, 0.3, 0.4)])
    trans = thesis_bsdf(0.0, [], [(1.0, 0.2, 0.1, 0.3, 0.4)])
    rng = np.random.default_rng(9)
    wi, wo = _random_upper(rng, 2000), _random_upper(rng, 2000)
    wi_below = wi * np.array([1.0, 1.0, -1.0])
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    u = np.sum(wo * h, -1)
    f = 0.3 + 0.7 * (1 - u) ** 5
    np.testing.assert_allclose(
        trans.eval(wi_below, wo)[:, 0],
        refl.eval(wi, wo)[:, 0] * (1 - f) / f,
        rtol=1e-9,
        atol=1e-250,
    )
    assert np.all(trans.eval(wi, wo) == 0.0)
    assert np.all(refl.eval(wi_below, wo) == 0.0)


def _anisotropy_spec_brdf(base, metallic, roughness, strength, l, v):
    """KHR_materials_anisotropy's specular BRDF written out with the extension's (and the Khronos
    Sample Viewer's) names, the direction along +x: D_GGX_anisotropic and V_GGX_anisotropic."""
    a = roughness**2
    at, ab = a + (1 - a) * strength**2, a
    h = (l + v) / np.linalg.norm(l + v, axis=-1, keepdims=True)
    t_h, b_h, n_h = h[:, 0], h[:, 1], h[:, 2]
    a2 = at * ab
    f = np.stack([ab * t_h, at * b_h, a2 * n_h], -1)
    w2 = a2 / np.sum(f * f, -1)
    d = a2 * w2 * w2 / np.pi * (n_h > 0)
    n_l, n_v = l[:, 2], v[:, 2]
    ggx_v = n_l * np.linalg.norm(np.stack([at * v[:, 0], ab * v[:, 1], n_v], -1), axis=-1)
    ggx_l = n_v * np.linalg.norm(np.stack([at * l[:, 0], ab * l[:, 1], n_l], -1), axis=-1)
    vis = 0.5 / (ggx_v + ggx_l)
    v_h = np.sum(v * h, -1)
    fw = ((1 - np.abs(v_h)) ** 5)[:, None]
    specular = (vis * d)[:, None]
    base = np.asarray(base)
    metal = specular * (base + (1 - base) * fw)
    dielectric_f = 0.04 + 0.96 * fw
    dielectric = (1 - dielectric_f) * base / np.pi + dielectric_f * specular
    return (1 - metallic) * dielectric + metallic * metal


@pytest.mark.parametrize(
    "base,metallic,roughness,strength",
    [([0.9, 0.7, 0.3], 1.0, 0.3, 0.8), ([0.5, 0.4, 0.3], 0.0, 0.5, 0.5), ([0.6, 0.6, 0.6], 0.6, 0.2, 1.0)],
)
def test_gltf_anisotropy_matches_the_extension(base, metallic, roughness, strength):
    rng = np.random.default_rng(11)
    l, v = _random_upper(rng, 4000), _random_upper(rng, 4000)
    ours = gltf_bsdf(base, metallic, roughness, strength).eval(l, v)
    expected = _anisotropy_spec_brdf(base, metallic, roughness, strength, l, v)
    np.testing.assert_allclose(ours, expected, rtol=1e-9)
    assert gltf_bsdf(base, metallic, roughness, strength, 0.7).tangent_rotation == 0.7


def test_anisotropy_frame_turns_the_tangent_towards_the_bitangent():
    from lobeview.materials.gltf import anisotropy_frame

    frame = np.eye(3)
    turned = anisotropy_frame(frame, np.pi / 2)
    np.testing.assert_allclose(turned, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    # Evaluating in the turned frame = evaluating the unturned BSDF with directions rotated back.
    rng = np.random.default_rng(4)
    l, v = _random_upper(rng, 100), _random_upper(rng, 100)
    r = 0.6
    bsdf = gltf_bsdf([0.8, 0.8, 0.8], 1.0, 0.3, 0.9)
    local = anisotropy_frame(frame, r)
    rotated = bsdf.eval(l @ local, v @ local)  # world -> local coordinates: x' = t'.x
    c, s = np.cos(r), np.sin(r)
    back = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # rotate directions by -r about z
    np.testing.assert_allclose(rotated, bsdf.eval(l @ back, v @ back), rtol=1e-12)


def test_gltf_thin_transmission_matches_the_sample_viewer_and_conserves_energy():
    """KHR_materials_transmission, thin-walled, as the Khronos Sample Viewer evaluates it: the
    light direction mirrored through the surface, (1 - F(V.H)) baseColor V_GGX D_GGX of the
    mirrored pair, weighted by the transmission factor. A white clear glass (transmission 1)
    then reflects and transmits no more than arrives, at every angle."""
    base, roughness, t = np.array([0.8, 0.9, 0.7]), 0.4, 0.9
    bsdf = gltf_bsdf(base, 0.0, roughness, transmission=t)
    rng = np.random.default_rng(3)
    v = _random_upper(rng, 3000)
    l_below = _random_upper(rng, 3000) * np.array([1.0, 1.0, -1.0])
    l_mirror = l_below * np.array([1.0, 1.0, -1.0])
    # A white metal's Fresnel is 1 + 0 (1 - V.H)^5 = 1: the spec's BRDF then is V D alone.
    spec = _gltf_spec_brdf([1.0, 1.0, 1.0], 1.0, roughness, l_mirror, v)
    h = (l_mirror + v) / np.linalg.norm(l_mirror + v, axis=-1, keepdims=True)
    fresnel = 0.04 + 0.96 * (1 - np.sum(v * h, -1)) ** 5
    expected = t * base * ((1 - fresnel)[:, None] * spec)
    np.testing.assert_allclose(bsdf.eval(l_below, v), expected, rtol=1e-9)
    white = gltf_bsdf(1.0, 0.0, 0.1, transmission=1.0)
    for theta in (0, 30, 60, 80):
        reflected, transmitted = white.albedo(direction_from_angles_deg(theta), order=128)
        # Most of it passes, less at grazing where the Fresnel reflection grows (0.41 at 80 degrees).
        assert np.all(reflected + transmitted <= 1.0 + 2e-3), (theta, reflected, transmitted)
        assert transmitted.mean() > (0.7 if theta <= 60 else 0.5), (theta, transmitted)


@pytest.mark.parametrize("sheen_roughness", [0.2, 0.5, 1.0])
def test_charlie_distribution_is_normalised(sheen_roughness):
    """KHR_materials_sheen's D_Charlie: integral of D(h) cos(theta_h) over the hemisphere = 1
    (midpoint quadrature in theta_h)."""
    from lobeview.materials.gltf import charlie_d

    theta = (np.arange(20000) + 0.5) / 20000 * (np.pi / 2)
    integral = np.sum(charlie_d(np.cos(theta), sheen_roughness) * np.cos(theta) * np.sin(theta)) * 2 * np.pi
    assert integral * (np.pi / 2) / 20000 == pytest.approx(1.0, rel=1e-4)


def test_sheen_approximation_keeps_the_lobes_albedo_and_the_base_gives_way():
    """GltfSheen (sheenColor E_s(N.V) / pi) reflects what the extension's sheen lobe reflects
    (its albedo by quadrature, per view angle), and the base is scaled by 1 - max(sheenColor)
    E_s so that a white sheen over a white diffuse never exceeds 1."""
    from lobeview.materials.bsdf import BSDF
    from lobeview.materials.gltf import SHEEN_TABLE_SIZE, GltfSheen, GltfSheenLobe

    colour = np.array([0.9, 0.5, 0.7])
    bsdf = gltf_bsdf([1.0, 1.0, 1.0], 0.0, 0.6, sheen_color=colour, sheen_roughness=0.4)
    sheen = next(c for c in bsdf.components if isinstance(c, GltfSheen))
    lobe = BSDF([GltfSheenLobe(0.4)])
    for i in (0, 5, 15):
        mu = (i + 0.5) / SHEEN_TABLE_SIZE
        wo = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
        true_albedo, _ = lobe.albedo(wo, order=96)
        np.testing.assert_allclose(sheen.view_albedo(np.array(mu)), colour * true_albedo[0], rtol=2e-3)
        approx_albedo, _ = BSDF([sheen]).albedo(wo, order=96)
        np.testing.assert_allclose(approx_albedo, colour * true_albedo[0], rtol=2e-3)
    white = gltf_bsdf([1.0, 1.0, 1.0], 0.0, 0.8, sheen_color=[1.0, 1.0, 1.0], sheen_roughness=0.3)
    for theta in (0, 45, 80):
        reflected, _ = white.albedo(direction_from_angles_deg(theta), order=96)
        assert np.all(reflected <= 1.0 + 5e-3), (theta, reflected)
