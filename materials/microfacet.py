"""Microfacet distributions shared by the BSDFs, the lobe patterns and the prefilters.

One roughness convention everywhere: ``alpha_x`` / ``alpha_y`` are the slope-space widths of the
distribution along the tangent (+x) and bitangent (+y). For Beckmann they are the ``m_x``, ``m_y``
of the thesis (Eq. 3.3: D = exp(-tan^2 theta_h (cos^2 phi/m_x^2 + sin^2 phi/m_y^2)) /
(pi m_x m_y cos^4 theta_h)); for GGX they are the Trowbridge-Reitz alphas of pbrt/Heitz. The glTF
mapping ``alpha = roughness^2`` lives in :mod:`lobeview.materials.gltf` and nowhere else.

Both distributions are normalised so that the projected microfacet area is one:
integral of D(wm) cos(theta_m) over the hemisphere = 1 (tested by quadrature).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erfc

from .vec import dot, normalize

DISTRIBUTIONS = ("beckmann", "ggx")

# Smallest slope width accepted; below it the lobe is narrower than float32 cube-map texels can
# resolve and the GLSL side would overflow. Documented range of all roughness inputs.
ALPHA_MIN = 1e-4
ALPHA_MAX = 1.0

_TINY_Z2 = 1e-300


def _tan2_components(w: np.ndarray):
    """x^2, y^2 and a clipped z^2 (never 0, so ratios stay finite)."""
    x2 = w[..., 0] ** 2
    y2 = w[..., 1] ** 2
    z2 = np.maximum(w[..., 2] ** 2, _TINY_Z2)
    return x2, y2, z2


@dataclass(frozen=True)
class MicrofacetDistribution:
    """An anisotropic Beckmann or GGX (Trowbridge-Reitz) normal distribution."""

    kind: str
    alpha_x: float
    alpha_y: float

    def __post_init__(self):
        if self.kind not in DISTRIBUTIONS:
            raise ValueError(f"unknown microfacet distribution {self.kind!r}; use {DISTRIBUTIONS}")
        for name in ("alpha_x", "alpha_y"):
            value = getattr(self, name)
            if not np.isfinite(value) or not (ALPHA_MIN <= value <= ALPHA_MAX):
                raise ValueError(f"{name} = {value!r} is outside [{ALPHA_MIN}, {ALPHA_MAX}]")

    # -- normal distribution -------------------------------------------------------------------
    def D(self, wm: np.ndarray) -> np.ndarray:
        """Microfacet density per unit solid angle of normals; 0 below the horizon."""
        ax, ay = self.alpha_x, self.alpha_y
        x2, y2, z2 = _tan2_components(wm)
        above = wm[..., 2] > 0.0
        if self.kind == "ggx":
            # 1 / (pi ax ay cos^4 (1 + tan^2 (cos^2/ax^2 + sin^2/ay^2))^2), rewritten without
            # dividing by cos so it stays finite at the horizon.
            denom = x2 / ax**2 + y2 / ay**2 + wm[..., 2] ** 2
            d = 1.0 / (np.pi * ax * ay * np.maximum(denom, 1e-300) ** 2)
        else:
            # Thesis Eq. 3.3, evaluated in the log domain: exp(-e) / cos^4 underflows cleanly.
            e = (x2 / ax**2 + y2 / ay**2) / z2
            d = np.exp(-e - 2.0 * np.log(z2)) / (np.pi * ax * ay)
        return np.where(above, d, 0.0)

    # -- masking -------------------------------------------------------------------------------
    def lambda_(self, w: np.ndarray) -> np.ndarray:
        """Smith's Lambda(w) for the distribution (Heitz 2014); +inf at the horizon."""
        x2, y2, z2 = _tan2_components(w)
        s = (self.alpha_x**2 * x2 + self.alpha_y**2 * y2) / z2  # alpha_0^2 tan^2(theta)
        if self.kind == "ggx":
            # (sqrt(1 + s) - 1) / 2 written without cancellation for small s.
            lam = s / (2.0 * (np.sqrt(1.0 + s) + 1.0))
        else:
            with np.errstate(divide="ignore"):
                a = 1.0 / np.sqrt(s)  # 1 / (alpha_0 tan theta)
            finite = np.isfinite(a) & (a < 30.0)
            a_safe = np.where(finite, a, 1.0)
            lam_mid = (np.exp(-a_safe * a_safe) / (a_safe * np.sqrt(np.pi)) - erfc(a_safe)) / 2.0
            lam = np.where(finite, np.maximum(lam_mid, 0.0), 0.0)
            lam = np.where(s == 0.0, 0.0, lam)
        lam = np.where(np.abs(w[..., 2]) <= 0.0, np.inf, lam)
        return lam

    def G1(self, w: np.ndarray, wm: np.ndarray | None = None) -> np.ndarray:
        """Smith masking of direction ``w``; with ``wm``, zero where w is behind the facet."""
        g = 1.0 / (1.0 + self.lambda_(w))
        if wm is not None:
            g = np.where(dot(w, wm) > 0.0, g, 0.0)
        return g

    def G(self, wi: np.ndarray, wo: np.ndarray, wm: np.ndarray | None = None) -> np.ndarray:
        """Height-correlated Smith masking-shadowing 1 / (1 + Lambda(wi) + Lambda(wo))."""
        g = 1.0 / (1.0 + self.lambda_(wi) + self.lambda_(wo))
        if wm is not None:
            g = np.where((dot(wi, wm) > 0.0) & (dot(wo, wm) > 0.0), g, 0.0)
        return g

    # -- half-vector sampling of D(wm) cos(theta_m) (thesis Eq. 4.5-4.7) ------------------------
    def phi_from_xi(self, xi2: np.ndarray) -> np.ndarray:
        """Eq. 4.5 / 4.12: phi_h = arctan(m_y/m_x tan(2 pi xi2)), quadrant-correct."""
        angle = 2.0 * np.pi * np.asarray(xi2, dtype=np.float64)
        return np.arctan2(self.alpha_y * np.sin(angle), self.alpha_x * np.cos(angle))

    def inv_alpha2(self, phi: np.ndarray) -> np.ndarray:
        """cos^2(phi)/alpha_x^2 + sin^2(phi)/alpha_y^2, the anisotropic width factor."""
        return np.cos(phi) ** 2 / self.alpha_x**2 + np.sin(phi) ** 2 / self.alpha_y**2

    def tan2_theta_from_xi(self, xi1: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Eq. 4.6 for Beckmann (tan^2 = -ln xi1 / A(phi)), and its GGX analogue
        (tan^2 = (1 - xi1)/xi1 / A(phi)). xi1 in (0, 1]: xi1 = 1 is the lobe centre, xi1 -> 0
        the horizon (the thesis' convention, so Eq. 4.10 applies unchanged)."""
        xi1 = np.clip(np.asarray(xi1, dtype=np.float64), 1e-300, 1.0)
        if self.kind == "beckmann":
            t = -np.log(xi1)
        else:
            t = (1.0 - xi1) / xi1
        return t / self.inv_alpha2(phi)

    def half_vector_from_xi(self, xi1: np.ndarray, xi2: np.ndarray) -> np.ndarray:
        """Map (xi1, xi2) to a half vector distributed with pdf D(h) cos(theta_h)."""
        phi = self.phi_from_xi(xi2)
        theta = np.arctan(np.sqrt(self.tan2_theta_from_xi(xi1, phi)))
        sin_t = np.sin(theta)
        return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), np.cos(theta)], axis=-1)

    def pdf_half_vector(self, wm: np.ndarray) -> np.ndarray:
        """Density of :meth:`half_vector_from_xi` per unit solid angle: D(wm) cos(theta_m)."""
        return self.D(wm) * np.maximum(wm[..., 2], 0.0)

    # -- visible normals (GGX, Heitz 2018) ------------------------------------------------------
    def sample_visible_normal(self, wo: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Sample wm with density D_wo(wm) = G1(wo) max(0, wo.wm) D(wm) / cos(theta_o).

        GGX only (Heitz, "Sampling the GGX Distribution of Visible Normals", JCGT 2018). Callers
        must pass wo with positive z.
        """
        if self.kind != "ggx":
            raise NotImplementedError("visible-normal sampling is implemented for GGX only")
        ax, ay = self.alpha_x, self.alpha_y
        vh = normalize(np.stack([ax * wo[..., 0], ay * wo[..., 1], wo[..., 2]], axis=-1))
        lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
        inv_len = np.where(lensq > 0.0, 1.0 / np.sqrt(np.where(lensq > 0.0, lensq, 1.0)), 0.0)
        t1 = np.stack(
            [
                np.where(lensq > 0.0, -vh[..., 1] * inv_len, 1.0),
                np.where(lensq > 0.0, vh[..., 0] * inv_len, 0.0),
                np.zeros_like(lensq),
            ],
            axis=-1,
        )
        t2 = np.cross(vh, t1)
        r = np.sqrt(np.asarray(u1, dtype=np.float64))
        phi = 2.0 * np.pi * np.asarray(u2, dtype=np.float64)
        p1 = r * np.cos(phi)
        p2 = r * np.sin(phi)
        s = 0.5 * (1.0 + vh[..., 2])
        p2 = (1.0 - s) * np.sqrt(np.clip(1.0 - p1 * p1, 0.0, None)) + s * p2
        p3 = np.sqrt(np.clip(1.0 - p1 * p1 - p2 * p2, 0.0, None))
        nh = p1[..., None] * t1 + p2[..., None] * t2 + p3[..., None] * vh
        return normalize(np.stack([ax * nh[..., 0], ay * nh[..., 1], np.maximum(nh[..., 2], 0.0)], axis=-1))

    def pdf_visible_normal(self, wo: np.ndarray, wm: np.ndarray) -> np.ndarray:
        cos_o = np.maximum(wo[..., 2], 1e-300)
        return self.G1(wo) * np.maximum(dot(wo, wm), 0.0) * self.D(wm) / cos_o


def reflection_jacobian(wo: np.ndarray, wm: np.ndarray) -> np.ndarray:
    """d(omega_m)/d(omega_i) for wi = reflect(wo, wm): 1 / (4 |wo.wm|) (Walter et al. 2007)."""
    return 1.0 / (4.0 * np.maximum(np.abs(dot(wo, wm)), 1e-300))


def fit_peak_shape(theta_h: np.ndarray, shape: np.ndarray, kinds=("beckmann",)) -> tuple[str, float]:
    """(kind, alpha) of the isotropic distribution among ``kinds`` whose D(theta_h) / D(0) best
    matches ``shape`` (a peak normalised to 1 at theta_h[0] = 0; least squares, sin theta_h
    weighted) over 200 alphas log-spaced in [1e-3, ALPHA_MAX]: the proxy that places lobe-N's
    pattern for a lobe given only by its values (a Rational BRDF, a measured table)."""
    alphas = np.geomspace(max(ALPHA_MIN, 1e-3), ALPHA_MAX, 200)[:, None]
    tan2, cos4 = (np.tan(theta_h) ** 2)[None, :], (np.cos(theta_h) ** 4)[None, :]
    models = {
        "beckmann": lambda: np.exp(-tan2 / alphas**2) / cos4,
        "ggx": lambda: alphas**4 / (cos4 * (alphas**2 + tan2) ** 2),
    }
    best = None
    for kind in kinds:
        err = ((models[kind]() - shape[None, :]) ** 2 * np.sin(theta_h)[None, :]).sum(axis=1)
        i = int(np.argmin(err))
        if best is None or err[i] < best[0]:
            best = (float(err[i]), kind, float(alphas[i, 0]))
    return best[1], best[2]
