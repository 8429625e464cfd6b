"""Fresnel terms: none (F = 1), Schlick (thesis Eq. 2.9) and the exact conductor equations."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .vec import broadcast_rgb

FRESNEL_KINDS = ("none", "schlick", "conductor")


def schlick(cos_theta: np.ndarray, r0: np.ndarray) -> np.ndarray:
    """F(u) = r0 + (1 - r0)(1 - u)^5 (thesis Eq. 2.9); u clipped to [0, 1]; returns (..., 3)."""
    u = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)[..., None]
    r0 = np.asarray(r0, dtype=np.float64)
    return r0 + (1.0 - r0) * (1.0 - u) ** 5


def conductor(cos_theta: np.ndarray, eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor with complex IOR eta + i k (relative to the
    outside medium), for incidence cosine ``cos_theta``; returns (..., 3).

    Exact form (Born & Wolf; pbrt-v3 FrConductor): with a^2 + b^2 = sqrt((eta^2 - k^2 - sin^2)^2
    + 4 eta^2 k^2), Rs = (a^2+b^2 - 2 a cos + cos^2) / (a^2+b^2 + 2 a cos + cos^2),
    Rp = Rs (cos^2 (a^2+b^2) - 2 a cos sin^2 + sin^4) / (cos^2 (a^2+b^2) + 2 a cos sin^2 + sin^4).
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)[..., None]
    eta = np.asarray(eta, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = eta * eta - k * k - s2
    a2plusb2 = np.sqrt(t0 * t0 + 4.0 * eta * eta * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2plusb2 + t0), 0.0))
    t1 = a2plusb2 + c2
    t2 = 2.0 * c * a
    rs = (t1 - t2) / np.maximum(t1 + t2, 1e-300)
    t3 = c2 * a2plusb2 + s2 * s2
    t4 = t2 * s2
    rp = rs * (t3 - t4) / np.maximum(t3 + t4, 1e-300)
    return np.clip(0.5 * (rp + rs), 0.0, 1.0)


def conductor_f0(eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Normal-incidence reflectance ((n-1)^2 + k^2) / ((n+1)^2 + k^2), the closed form."""
    eta = np.asarray(eta, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    return ((eta - 1.0) ** 2 + k * k) / ((eta + 1.0) ** 2 + k * k)


@dataclass(frozen=True)
class Fresnel:
    """A selectable Fresnel term: ``none`` (F = 1), ``schlick`` (r0, scalar or RGB) or
    ``conductor`` (eta, k, RGB)."""

    kind: str = "none"
    r0: np.ndarray = field(default_factory=lambda: np.ones(3))
    eta: np.ndarray = field(default_factory=lambda: np.ones(3))
    k: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        if self.kind not in FRESNEL_KINDS:
            raise ValueError(f"unknown Fresnel kind {self.kind!r}; use one of {FRESNEL_KINDS}")
        object.__setattr__(self, "r0", broadcast_rgb(self.r0, "r0"))
        object.__setattr__(self, "eta", broadcast_rgb(self.eta, "eta"))
        object.__setattr__(self, "k", broadcast_rgb(self.k, "k"))

    def __call__(self, cos_theta: np.ndarray) -> np.ndarray:
        cos_theta = np.asarray(cos_theta, dtype=np.float64)
        if self.kind == "none":
            return np.ones(cos_theta.shape + (3,))
        if self.kind == "schlick":
            return schlick(cos_theta, self.r0)
        return conductor(cos_theta, self.eta, self.k)
