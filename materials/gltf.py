"""The glTF 2.0 metallic-roughness BRDF exactly as the specification's Appendix B defines it:

    material        = mix(dielectric_brdf, metal_brdf, metallic)
    metal_brdf      = specular_brdf(alpha) * (baseColor + (1 - baseColor) (1 - |V.H|)^5)
    dielectric_brdf = mix(diffuse_brdf(baseColor), specular_brdf(alpha), 0.04 + 0.96 (1 - |V.H|)^5)
    specular_brdf   = V_GGX * D_GGX,  alpha = roughness^2
    diffuse_brdf    = baseColor / pi

with D_GGX = alpha^2 chi(N.H) / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2) and V the height-correlated
Smith visibility G2 / (4 |N.L| |N.V|). Expanded, that is a diffuse term
(1 - metallic)(1 - F_d) baseColor / pi (cosine-sampled) plus a specular term
((1 - metallic) F_d + metallic F_m) V D (GGX visible-normal sampled).

The roughness -> alpha mapping (alpha = roughness^2) is defined here and nowhere else; alpha is
clamped to ALPHA_MIN (roughness 0.01) because a perfect mirror has no density to sample.

KHR_materials_ior and KHR_materials_specular replace the dielectric's fixed 0.04 (the
extensions' fresnel_mix): F_d = f0 + (1 - f0)(1 - |V.H|)^5 with the colour
f0 = min(((ior - 1) / (ior + 1))^2 specularColor, 1), the dielectric specular weighted by
``specular`` and the diffuse by 1 - specular max(F_d) (max over RGB). ior 1.5, specular 1 and
colour 1 give the core model exactly; ior 0 is the extensions' infinite index (f0 = 1).

KHR_materials_clearcoat layers a dielectric GGX coat over everything else (the extension's
fresnel_coat): coat = clearcoat F_c(N.V) V D with alpha_c = clearcoatRoughness^2 and
F_c = 0.04 + 0.96 (1 - N.V)^5 (ior 1.5; the extension evaluates the coat's Fresnel at N.V), and
the base (diffuse and specular) scaled by 1 - clearcoat F_c(N_c.V). The coat has its own normal
N_c: its clearcoatNormalTexture, or the vertex normal (the base's normal map does not reach it);
one pixel's N_c.V is :class:`BaseLayers` ``coat_cos`` (shaders/scene.frag coat_tbn).

KHR_materials_transmission (thin-walled here: a KHR_materials_volume thickness turns the lobe onto
the path through the volume in the scene renderer, materials/volume.py) moves the fraction
``transmission`` of the dielectric's diffuse into a GGX transmission lobe with the same alpha,
tinted by the base colour: (1 - metallic) transmission baseColor (1 - specular max(F_d)) V D,
evaluated like thesis Eq. 3.5 with the incident direction mirrored through the surface (a thin
wall does not bend light: the lobe is centred on the straight-through direction -V), as the
Khronos Sample Viewer's thin-walled transmission does. The diffuse keeps 1 - transmission.

KHR_materials_sheen is approximated (documented): the sheen lobe sheenColor D_Charlie(alpha_s)
V_Neubelt (alpha_s = sheenRoughness^2; V_Neubelt = 1 / (4 (N.L + N.V - N.L N.V)) includes the
1 / (4 |N.L| |N.V|)) is replaced by a term with the same directional albedo that takes its light
like the diffuse, sheenColor E_s(N.V) / pi (E_s: the white sheen lobe's albedo by
quadrature, a 16-entry table over N.V); the base keeps 1 - max(sheenColor) E_s(N.V) (the
extension's albedo scaling). What this loses: the sheen lobe's direction (its grazing
retro-reflection of a bright source); what it keeps: its energy at every view angle.

KHR_materials_anisotropy stretches the GGX lobe along the anisotropy direction, the tangent
rotated by ``anisotropy_rotation`` about the normal (counter-clockwise towards the bitangent):
alpha_t = mix(alpha, 1, strength^2) along it, alpha_b = alpha across (the extension's
definition). Here the BSDF's local x axis is that direction; :func:`anisotropy_frame` (numpy)
and ``rotate_tangent`` (shaders/frame.glsl) turn the mesh's tangent frame into it.
"""

from __future__ import annotations

import numpy as np

from .bsdf import BSDF, CosineSampled, _valid_pair
from .conductor import MicrofacetReflection
from .fresnel import Fresnel, schlick
from .microfacet import ALPHA_MIN, MicrofacetDistribution
from .vec import broadcast_rgb, dot, mirror_z, normalize

DIELECTRIC_F0 = 0.04

# E[(1 - V.H)^5] over incident directions distributed as cos(theta_i) / pi, at N.V = mu: the
# Schlick factor that a diffuse lit from every direction at once sees (the lightmap, the
# environment's irradiance), with H = (wi + wo) / |wi + wo|, V.H = sqrt((1 + wi.wo) / 2). A
# degree-4 least-squares fit (in mu) to that integral by quadrature; largest error 6e-6
# (tests/test_gltf_grazing.py). It runs from 8e-5 facing to 0.028 at grazing, where the
# view-direction value (1 - N.V)^5 reaches 1 and would darken the diffuse to 0 (issue 40).
SCHLICK_COSINE_AVERAGE_FIT = (0.0281612, -0.0798007, 0.0862515, -0.0433788, 0.0088488)


def schlick_cosine_average(cos_o) -> np.ndarray:
    """E[(1 - V.H)^5] over cosine-distributed incident directions (bsdf.glsl schlick_cosine_average)."""
    mu = np.clip(np.asarray(cos_o, dtype=np.float64), 0.0, 1.0)
    return np.polynomial.polynomial.polyval(mu, SCHLICK_COSINE_AVERAGE_FIT)


def roughness_to_alpha(roughness: float) -> float:
    """glTF perceptual roughness -> GGX alpha (spec Appendix B: alpha = roughness^2)."""
    return max(float(roughness) ** 2, ALPHA_MIN)


def anisotropic_alphas(roughness: float, anisotropy: float = 0.0) -> tuple[float, float]:
    """(alpha_t, alpha_b) of KHR_materials_anisotropy: alpha_t = mix(alpha, 1, strength^2)."""
    alpha = roughness_to_alpha(roughness)
    return alpha + (1.0 - alpha) * float(anisotropy) ** 2, alpha


def anisotropy_frame(frame: np.ndarray, rotation: float) -> np.ndarray:
    """The (3, 3) frame (columns tangent, bitangent, normal) turned by ``rotation`` radians about
    its normal: the new tangent is cos r t + sin r b, the anisotropy direction."""
    c, s = np.cos(rotation), np.sin(rotation)
    t, b, n = frame[:, 0], frame[:, 1], frame[:, 2]
    return np.stack([c * t + s * b, -s * t + c * b, n], axis=1)


COAT_F0 = 0.04  # KHR_materials_clearcoat: the coat is a dielectric of ior 1.5


def specular_f0_unclamped(ior: float = 1.5, specular_color=(1.0, 1.0, 1.0)) -> np.ndarray:
    """((ior - 1) / (ior + 1))^2 specularColor: KHR_materials_specular's f0 before the clamp, which
    comes after the specularColorTexture multiplies it (shaders/scene.frag u_specular_f0_raw)."""
    return ((float(ior) - 1.0) / (float(ior) + 1.0)) ** 2 * broadcast_rgb(specular_color, "specular_color")


def dielectric_f0(ior: float = 1.5, specular_color=(1.0, 1.0, 1.0)) -> np.ndarray:
    """KHR_materials_ior/_specular: min(((ior - 1) / (ior + 1))^2 specularColor, 1) per channel."""
    return np.minimum(specular_f0_unclamped(ior, specular_color), 1.0)


SHEEN_TABLE_SIZE = 16  # E_s(N.V) samples at N.V = (i + 0.5) / 16 (shaders/bsdf.glsl sheen_albedo)


def charlie_d(cos_h: np.ndarray, sheen_roughness: float) -> np.ndarray:
    """KHR_materials_sheen's Charlie distribution (Estevez and Kulla 2017):
    D(h) = (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi), alpha = sheenRoughness^2 (>= 1e-3)."""
    alpha = max(float(sheen_roughness) ** 2, 1e-3)
    sin_h = np.sqrt(np.clip(1.0 - np.asarray(cos_h, dtype=np.float64) ** 2, 0.0, 1.0))
    return (2.0 + 1.0 / alpha) * sin_h ** (1.0 / alpha) / (2.0 * np.pi)


class GltfSheenLobe(CosineSampled):
    """The extension's sheen BRDF, white: D_Charlie(h) V_Neubelt with V = 1 / (4 (N.L + N.V -
    N.L N.V)) (the extension's cheaper visibility). Used for its albedo; not rendered."""

    name = "glTF sheen lobe"

    def __init__(self, sheen_roughness: float):
        self.sheen_roughness = float(sheen_roughness)
        self.diffuse_albedo = np.zeros(3)

    @property
    def selection_weight(self) -> float:
        return 1.0

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        h = normalize(wi + wo)
        n_l, n_v = np.abs(wi[..., 2]), np.abs(wo[..., 2])
        value = charlie_d(h[..., 2], self.sheen_roughness) / (4.0 * (n_l + n_v - n_l * n_v))
        return np.where(valid[..., None], value[..., None] * np.ones(3), 0.0)


def sheen_albedo_table(sheen_roughness: float, order: int = 64) -> np.ndarray:
    """(SHEEN_TABLE_SIZE,) directional albedo of the white sheen lobe at N.V = (i + 0.5) / size."""
    lobe = BSDF([GltfSheenLobe(sheen_roughness)])
    table = np.empty(SHEEN_TABLE_SIZE)
    for i in range(SHEEN_TABLE_SIZE):
        mu = (i + 0.5) / SHEEN_TABLE_SIZE
        reflected, _ = lobe.albedo(np.array([np.sqrt(1.0 - mu * mu), 0.0, mu]), order)
        table[i] = reflected[0]
    return table


class BaseLayers:
    """What lies over the glTF base (diffuse, specular, transmission): the clearcoat and the
    sheen; ``attenuation(N.V)`` = (1 - clearcoat F_c(N_c.V)) (1 - max(sheenColor) E_s(N.V)).
    N_c.V is ``coat_cos`` when the coat has its own normal (clearcoatNormalTexture: one pixel, one
    view), else the base's N.V."""

    def __init__(
        self,
        coat: float = 0.0,
        sheen_color=(0.0, 0.0, 0.0),
        sheen_roughness: float = 0.0,
        coat_cos: float | None = None,
    ):
        self.coat = float(coat)
        self.coat_cos = None if coat_cos is None else float(coat_cos)
        self.sheen_color = broadcast_rgb(sheen_color, "sheen_color")
        self.sheen_roughness = float(sheen_roughness)
        self.sheen_table = (
            sheen_albedo_table(sheen_roughness) if np.any(self.sheen_color > 0) else np.zeros(SHEEN_TABLE_SIZE)
        )

    def sheen_albedo(self, cos_o) -> np.ndarray:
        """E_s(N.V), linear between table entries, clamped at the ends (a GL_LINEAR lookup)."""
        x = np.clip(np.asarray(cos_o, dtype=np.float64) * SHEEN_TABLE_SIZE - 0.5, 0.0, SHEEN_TABLE_SIZE - 1.0)
        i0 = np.minimum(np.floor(x).astype(np.int64), SHEEN_TABLE_SIZE - 2)
        f = x - i0
        return self.sheen_table[i0] * (1.0 - f) + self.sheen_table[i0 + 1] * f

    def attenuation(self, cos_o) -> np.ndarray:
        """What the layers leave of the base (scalar per direction; bsdf.glsl base_attenuation)."""
        coat_view = cos_o if self.coat_cos is None else np.full(np.shape(cos_o), self.coat_cos)
        coat = 1.0 - self.coat * schlick(coat_view, np.full(3, COAT_F0))[..., 0]
        return coat * (1.0 - float(np.max(self.sheen_color)) * self.sheen_albedo(cos_o))


class _GltfDielectric:
    """What the glTF base components share: the dielectric's f0 and specular weight
    (KHR_materials_ior/_specular) and the layers over them (clearcoat, sheen)."""

    def _set_dielectric(self, f0, specular: float, layers: BaseLayers | None) -> None:
        self.f0 = np.broadcast_to(np.asarray(f0, dtype=np.float64), (3,)).copy()
        self.specular = float(specular)
        self.layers = layers if layers is not None else BaseLayers()

    def kept(self, cos_h) -> np.ndarray:
        """What the dielectric's reflection leaves: 1 - specular max(F_d(V.H)) (fresnel_mix;
        bsdf.glsl dielectric_kept)."""
        return 1.0 - self.specular * schlick(cos_h, self.f0).max(axis=-1)

    def kept_irradiance(self, cos_o) -> np.ndarray:
        """``kept`` averaged over incident directions distributed as cos(theta_i) / pi: what the
        dielectric leaves of a diffuse lit from every direction at once (bsdf.glsl
        dielectric_kept_irradiance). Schlick is increasing in f0, so max over RGB is the largest
        f0's: 1 - specular (f0_max + (1 - f0_max) E[(1 - V.H)^5])."""
        f0_max = float(self.f0.max())
        return 1.0 - self.specular * (f0_max + (1.0 - f0_max) * schlick_cosine_average(cos_o))


class GltfSheen(CosineSampled):
    """KHR_materials_sheen, approximated: sheenColor E_s(N.V) / pi, lit like the diffuse (the
    lightmap or the environment's irradiance), cosine-sampled. ``diffuse_albedo`` is 0: the
    shaders add it from u_sheen_color and the E_s table (bsdf.glsl sheen_term)."""

    name = "glTF sheen"

    def __init__(self, layers: BaseLayers):
        self.layers = layers
        self.diffuse_albedo = np.zeros(3)

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.layers.sheen_color)) * 0.5

    def view_albedo(self, cos_o) -> np.ndarray:
        """sheenColor E_s(N.V): the term's radiance under irradiance pi (what it adds)."""
        return self.layers.sheen_color * np.asarray(self.layers.sheen_albedo(cos_o))[..., None]

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        return np.where(valid[..., None], self.view_albedo(wo[..., 2]) / np.pi, 0.0)


class GltfDiffuse(_GltfDielectric, CosineSampled):
    name = "glTF diffuse"

    def __init__(
        self,
        base_color: np.ndarray,
        metallic: float,
        f0=DIELECTRIC_F0,
        specular: float = 1.0,
        layers: BaseLayers | None = None,
        transmission: float = 0.0,
    ):
        self.base_color = base_color
        self.metallic = metallic
        self.transmission = float(transmission)
        self._set_dielectric(f0, specular, layers)
        self.diffuse_albedo = (1.0 - metallic) * (1.0 - self.transmission) * base_color

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.diffuse_albedo))

    def view_weight(self, cos_o) -> np.ndarray:
        """The weight of the lightmapped (or environment-irradiance) diffuse in the shaders
        (bsdf.glsl irradiance_diffuse_weight): eval's weight averaged over incident directions
        distributed as cos(theta_i) / pi, exact under uniform light, since the irradiance
        does not say where its light came from. Taking V.H as N.V instead (the view-direction
        approximation) darkened a white rough sphere to 0.6 at its rim (issue 40)."""
        return self.kept_irradiance(cos_o) * self.layers.attenuation(cos_o)

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        h = normalize(wi + wo)
        weight = self.kept(np.abs(dot(wo, h))) * self.layers.attenuation(wo[..., 2])
        f = weight[..., None] * self.diffuse_albedo / np.pi
        return np.where(valid[..., None], f, 0.0)


class GltfSpecular(_GltfDielectric, MicrofacetReflection):
    name = "glTF specular"

    def __init__(
        self,
        base_color: np.ndarray,
        metallic: float,
        alpha: float,
        alpha_b: float | None = None,
        f0=DIELECTRIC_F0,
        specular: float = 1.0,
        layers: BaseLayers | None = None,
    ):
        alpha_b = alpha if alpha_b is None else alpha_b
        super().__init__(MicrofacetDistribution("ggx", alpha, alpha_b), Fresnel("none"))
        self.base_color = base_color
        self.metallic = metallic
        self._set_dielectric(f0, specular, layers)

    @property
    def selection_weight(self) -> float:
        # Specular energy is roughly F0 at normal incidence plus the grazing rise; weight it so
        # glossy dielectrics still send a fair share of samples into the highlight.
        f0 = (1.0 - self.metallic) * self.specular * float(np.mean(self.f0))
        return max(f0 + self.metallic * float(np.mean(self.base_color)), 0.25)

    @property
    def f90(self) -> float:
        """The Fresnel term's value at grazing: (1 - metallic) specular + metallic."""
        return (1.0 - self.metallic) * self.specular + self.metallic

    def fresnel_term(self, wo_h):
        f_dielectric = self.specular * schlick(np.abs(wo_h), self.f0)
        f_metal = schlick(np.abs(wo_h), self.base_color)
        return (1.0 - self.metallic) * f_dielectric + self.metallic * f_metal

    def eval(self, wi, wo):
        return super().eval(wi, wo) * self.layers.attenuation(wo[..., 2])[..., None]


class GltfTransmission(_GltfDielectric, MicrofacetReflection):
    """KHR_materials_transmission, thin-walled: (1 - metallic) transmission baseColor
    (1 - specular max F_d(V.H)) V D with wi mirrored through the surface (Eq. 3.5's mirroring),
    times the clearcoat's attenuation; GGX visible normals sampled and mirrored."""

    name = "glTF transmission"
    transmission = True
    hemisphere = "transmission"

    def __init__(self, base_color, metallic: float, transmission: float, alpha_t: float, alpha_b: float,
                 f0=DIELECTRIC_F0, specular: float = 1.0, layers: BaseLayers | None = None):  # fmt: skip
        super().__init__(MicrofacetDistribution("ggx", alpha_t, alpha_b), Fresnel("none"))
        self.base_color = base_color
        self.metallic = float(metallic)
        self.amount = float(transmission)
        self._set_dielectric(f0, specular, layers)
        self.tint = (1.0 - self.metallic) * self.amount * np.asarray(base_color, dtype=np.float64)

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.tint))

    def eval(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
        valid = _valid_pair(wi, wo, True)
        wr = mirror_z(wi)
        lobe = super().eval(wr, wo)  # V D of the mirrored pair (Fresnel 'none', scale 1)
        h = normalize(wr + wo)
        kept = self.kept(np.abs(dot(wo, h))) * self.layers.attenuation(wo[..., 2])
        f = self.tint * kept[..., None] * lobe
        return np.where(valid[..., None], f, 0.0)

    def pdf(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
        return np.where(_valid_pair(wi, wo, True), super().pdf(mirror_z(wi), wo), 0.0)

    def lobe_pdf(self, wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
        return np.where(_valid_pair(wi, wo, True), super().lobe_pdf(mirror_z(wi), wo), 0.0)

    def sample_wi(self, u1, u2, wo):
        return mirror_z(super().sample_wi(u1, u2, wo))


class GltfClearcoat(MicrofacetReflection):
    """KHR_materials_clearcoat's layer: clearcoat F_c(N.V) V D (GGX, Fresnel at N.V)."""

    name = "glTF clearcoat"

    def __init__(self, clearcoat: float, alpha: float):
        super().__init__(MicrofacetDistribution("ggx", alpha, alpha), Fresnel("none"), scale=float(clearcoat))

    @property
    def clearcoat(self) -> float:
        return float(self.scale[0])

    def coat_fresnel(self, cos_o) -> np.ndarray:
        """F_c(N.V): the coat's Schlick Fresnel at the view direction (ior 1.5)."""
        return schlick(cos_o, np.full(3, COAT_F0))

    @property
    def selection_weight(self) -> float:
        return max(COAT_F0 * self.clearcoat, 0.1 * self.clearcoat)

    def eval(self, wi, wo):
        return super().eval(wi, wo) * self.coat_fresnel(wo[..., 2])


def gltf_bsdf(
    base_color,
    metallic: float,
    roughness: float,
    anisotropy: float = 0.0,
    anisotropy_rotation: float = 0.0,
    ior: float = 1.5,
    specular: float = 1.0,
    specular_color=(1.0, 1.0, 1.0),
    clearcoat: float = 0.0,
    clearcoat_roughness: float = 0.0,
    transmission: float = 0.0,
    sheen_color=(0.0, 0.0, 0.0),
    sheen_roughness: float = 0.0,
    coat_cos: float | None = None,
) -> BSDF:
    """The glTF BSDF with the KHR_materials_anisotropy (strength, rotation: the BSDF's local x
    is the direction, see :func:`anisotropy_frame`), _ior, _specular, _clearcoat,
    _transmission (thin-walled) and _sheen (approximated) factors. ``coat_cos``: N_c.V of a
    clearcoat with its own normal (its lobe is then evaluated in that normal's frame by the
    caller; :class:`BaseLayers`)."""
    base = broadcast_rgb(base_color, "base_color")
    alpha_t, alpha_b = anisotropic_alphas(roughness, anisotropy)
    f0 = dielectric_f0(ior, specular_color)
    layers = BaseLayers(clearcoat, sheen_color, sheen_roughness, coat_cos)
    components = [
        GltfDiffuse(base, float(metallic), f0, specular, layers, transmission),
        GltfSpecular(base, float(metallic), alpha_t, alpha_b, f0, specular, layers),
    ]
    if transmission > 0:
        components.append(GltfTransmission(base, metallic, transmission, alpha_t, alpha_b, f0, specular, layers))
    if np.any(layers.sheen_color > 0):
        components.append(GltfSheen(layers))
    if clearcoat > 0:
        components.append(GltfClearcoat(clearcoat, roughness_to_alpha(clearcoat_roughness)))
    return BSDF(components, name="glTF metallic-roughness", tangent_rotation=anisotropy_rotation)
