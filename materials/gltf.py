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
from .vec import broadcast_rgb, dot, normalize

DIELECTRIC_F0 = 0.04


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


def _dielectric_fresnel(wo_h: np.ndarray) -> np.ndarray:
    return schlick(np.abs(wo_h), np.full(3, DIELECTRIC_F0))


class GltfDiffuse(CosineSampled):
    name = "glTF diffuse"

    def __init__(self, base_color: np.ndarray, metallic: float):
        self.base_color = base_color
        self.metallic = metallic
        self.diffuse_albedo = (1.0 - metallic) * base_color

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.diffuse_albedo))

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        h = normalize(wi + wo)
        f = (1.0 - self.metallic) * (1.0 - _dielectric_fresnel(dot(wo, h))) * self.base_color / np.pi
        return np.where(valid[..., None], f, 0.0)


class GltfSpecular(MicrofacetReflection):
    name = "glTF specular"

    def __init__(self, base_color: np.ndarray, metallic: float, alpha: float, alpha_b: float | None = None):
        alpha_b = alpha if alpha_b is None else alpha_b
        super().__init__(MicrofacetDistribution("ggx", alpha, alpha_b), Fresnel("none"))
        self.base_color = base_color
        self.metallic = metallic

    @property
    def selection_weight(self) -> float:
        # Specular energy is roughly F0 at normal incidence plus the grazing rise; weight it so
        # glossy dielectrics still send a fair share of samples into the highlight.
        f0 = (1.0 - self.metallic) * DIELECTRIC_F0 + self.metallic * float(np.mean(self.base_color))
        return max(f0, 0.25)

    def fresnel_term(self, wo_h):
        f_dielectric = _dielectric_fresnel(wo_h)
        f_metal = schlick(np.abs(wo_h), self.base_color)
        return (1.0 - self.metallic) * f_dielectric + self.metallic * f_metal


def gltf_bsdf(
    base_color, metallic: float, roughness: float, anisotropy: float = 0.0, anisotropy_rotation: float = 0.0
) -> BSDF:
    """The glTF BRDF; ``anisotropy`` and ``anisotropy_rotation`` are KHR_materials_anisotropy's
    strength and rotation (the BSDF's local x is the direction; see :func:`anisotropy_frame`)."""
    base = broadcast_rgb(base_color, "base_color")
    alpha_t, alpha_b = anisotropic_alphas(roughness, anisotropy)
    return BSDF(
        [GltfDiffuse(base, float(metallic)), GltfSpecular(base, float(metallic), alpha_t, alpha_b)],
        name="glTF metallic-roughness",
        tangent_rotation=anisotropy_rotation,
    )
