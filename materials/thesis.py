"""The thesis material model: Kurt, Szirmay-Kalos and Krivanek's anisotropic multi-lobe BRDF
with the thesis' thin-surface transmission lobes (thesis Eq. 3.2-3.6).

    f_s(wi, wo) = kd / pi + sum_n ks_n f_lobe_n(wi, wo) + sum_m kt_m f_tlobe_m(wi, wo)   (3.6)

    f_lobe  = F(wo.h) D(h) / (4 (wo.h) ((wi.n)(wo.n))^alpha)                            (3.4)
    f_tlobe = (1 - F(wo.h')) D(h') / (4 (wo.h') ((wi'.n)(wo.n))^alpha),  wi' = wi mirrored
              through the surface plane, h' = normalize(wi' + wo)                         (3.5)

D is the normalised anisotropic Beckmann distribution (Eq. 3.3) with widths (mx, my), F is
Schlick's approximation with r0 (Eq. 2.9). Importance sampling of every lobe uses Eq. 4.5-4.8;
its pdf is D(h) cos(theta_h) / (4 (wo.h)) (Eq. 4.9; derived: the half vector is drawn with
density D cos(theta_h), and reflecting wo about it has Jacobian 1 / (4 wo.h)).
"""

from __future__ import annotations

import numpy as np

from .bsdf import BSDF, HalfVectorLobe, Lambert, _valid_pair
from .fresnel import schlick
from .microfacet import MicrofacetDistribution
from .vec import COS_EPSILON, broadcast_rgb, dot, normalize


class KurtLobe(HalfVectorLobe):
    """One reflection lobe (ks, mx, my, r0, alpha), or with ``transmission=True`` one thin-surface
    transmission lobe (kt, mx, my, r0, alpha) evaluated by mirroring (Eq. 3.5) with 1 - F."""

    def __init__(self, k, mx: float, my: float, r0, alpha: float, transmission: bool = False):
        self.k = broadcast_rgb(k, "kt" if transmission else "ks")
        self.r0 = broadcast_rgb(r0, "r0")
        self.alpha = float(alpha)
        self.transmission = transmission
        self.distribution = MicrofacetDistribution("beckmann", float(mx), float(my))
        self.name = "transmission lobe" if transmission else "reflection lobe"

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.k))

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, self.transmission)
        wr = self._reflected_wi(wi)
        h = normalize(wr + wo)
        wo_h = np.maximum(dot(wo, h), COS_EPSILON)
        cos_i = np.maximum(wr[..., 2], COS_EPSILON)
        cos_o = np.maximum(wo[..., 2], COS_EPSILON)
        fresnel = schlick(wo_h, self.r0)
        if self.transmission:
            fresnel = 1.0 - fresnel
        d = self.distribution.D(h)
        # (cos_i cos_o)^alpha evaluated as exp(alpha log(.)) so alpha = 0 gives exactly 1.
        denom = 4.0 * wo_h * np.exp(self.alpha * (np.log(cos_i) + np.log(cos_o)))
        f = self.k * fresnel * (d / denom)[..., None]
        return np.where(valid[..., None], f, 0.0)


def thesis_bsdf(kd, lobes, transmission_lobes=(), name: str = "thesis") -> BSDF:
    """Build the Eq. 3.6 BSDF from kd and lists of (k, mx, my, r0, alpha) tuples or dicts."""

    def make(spec, transmission):
        if isinstance(spec, dict):
            key = "kt" if transmission else "ks"
            return KurtLobe(spec[key], spec["mx"], spec["my"], spec["r0"], spec["alpha"], transmission)
        return KurtLobe(*spec, transmission=transmission)

    components = [Lambert(broadcast_rgb(kd, "kd"))]
    components += [make(s, False) for s in lobes]
    components += [make(s, True) for s in transmission_lobes]
    return BSDF(components, name=name)
