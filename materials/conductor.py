"""Microfacet conductor BRDF as offline renderers define it (Walter et al. 2007; pbrt-v4
ConductorBxDF; Mitsuba 3 roughconductor):

    f(wi, wo) = F(wo.wm) D(wm) G2(wi, wo) / (4 cos(theta_i) cos(theta_o)),   wm = half vector

with D GGX or Beckmann (isotropic or anisotropic), G2 the height-correlated Smith term and F
none, Schlick or the exact conductor Fresnel equations. GGX is sampled with visible normals
(pdf D_wo(wm) / (4 wo.wm)), Beckmann with D(wm) cos(theta_m).
"""

from __future__ import annotations

import numpy as np

from .bsdf import BSDF, Component, _valid_pair
from .fresnel import Fresnel
from .microfacet import MicrofacetDistribution, reflection_jacobian
from .vec import COS_EPSILON, broadcast_rgb, dot, normalize, reflect


class MicrofacetReflection(Component):
    name = "microfacet reflection"
    transmission = False

    def __init__(self, distribution: MicrofacetDistribution, fresnel: Fresnel, scale=1.0):
        self.distribution = distribution
        self.fresnel = fresnel
        self.scale = broadcast_rgb(scale, "scale")

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.scale))

    def fresnel_term(self, wo_h: np.ndarray) -> np.ndarray:
        return self.fresnel(wo_h)

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        wm = normalize(wi + wo)
        wo_m = dot(wo, wm)
        cos_i = np.maximum(wi[..., 2], COS_EPSILON)
        cos_o = np.maximum(wo[..., 2], COS_EPSILON)
        dg = self.distribution.D(wm) * self.distribution.G(wi, wo, wm) / (4.0 * cos_i * cos_o)
        f = self.scale * self.fresnel_term(wo_m) * dg[..., None]
        return np.where(valid[..., None], f, 0.0)

    def _sample_normal(self, u1, u2, wo):
        if self.distribution.kind == "ggx":
            return self.distribution.sample_visible_normal(wo, u1, u2)
        return self.distribution.half_vector_from_xi(1.0 - np.asarray(u1, dtype=np.float64), u2)

    def _normal_pdf(self, wo, wm):
        if self.distribution.kind == "ggx":
            return self.distribution.pdf_visible_normal(wo, wm)
        return self.distribution.pdf_half_vector(wm)

    def pdf(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        wm = normalize(wi + wo)
        p = self._normal_pdf(wo, wm) * reflection_jacobian(wo, wm)
        return np.where(valid, p, 0.0)

    def lobe_pdf(self, wi, wo):
        """Half-vector density D(wm) cos(theta_m) / (4 wo.wm): the map the deterministic lobe
        patterns are built from (for GGX it differs from the visible-normal sampler)."""
        valid = _valid_pair(wi, wo, False)
        wm = normalize(wi + wo)
        p = self.distribution.pdf_half_vector(wm) * reflection_jacobian(wo, wm)
        return np.where(valid, p, 0.0)

    def sample_wi(self, u1, u2, wo):
        return reflect(wo, self._sample_normal(u1, u2, wo))


def microfacet_bsdf(distribution: str, alpha_x: float, alpha_y: float, fresnel: Fresnel, scale=1.0) -> BSDF:
    dist = MicrofacetDistribution(distribution, alpha_x, alpha_y)
    return BSDF([MicrofacetReflection(dist, fresnel, scale)], name=f"{distribution} conductor")
