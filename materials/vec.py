"""Vector helpers for directions in the local shading frame.

Convention for every BSDF in lobeview: the local frame has the shading normal n = +z, the
tangent t = +x (glTF TEXCOORD_0 u direction) and the bitangent b = +y. ``wi`` points towards the
light, ``wo`` towards the viewer; both point away from the surface and are unit vectors stored
in the last axis of float64 arrays of shape (..., 3).
"""

from __future__ import annotations

import numpy as np

# Smallest cosine treated as "above the surface". Directions closer to the horizon than this
# (about 1e-10 rad) carry no energy and are treated as grazing-exactly, so no 0/0 can appear.
COS_EPSILON = 1e-12


def as_dirs(w) -> np.ndarray:
    """Return ``w`` as a float64 array of shape (..., 3)."""
    w = np.asarray(w, dtype=np.float64)
    if w.shape[-1] != 3:
        raise ValueError(f"directions must have 3 components in the last axis, got shape {w.shape}")
    return w


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def normalize(v: np.ndarray) -> np.ndarray:
    """Normalise along the last axis; zero vectors become (0, 0, 1) rather than NaN."""
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = length > 0.0
    out = np.where(safe, v / np.where(safe, length, 1.0), 0.0)
    # A zero vector has no direction; fall back to the normal so callers never see NaN.
    out[..., 2] = np.where(safe[..., 0], out[..., 2], 1.0)
    return out


def reflect(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror ``w`` about the unit vector ``h``: 2 (w.h) h - w (thesis Eq. 4.8)."""
    return 2.0 * dot(w, h)[..., None] * h - w


def mirror_z(w: np.ndarray) -> np.ndarray:
    """Mirror a direction through the surface plane (z -> -z); used by the thin-surface
    transmission lobes of thesis Eq. 3.5."""
    out = np.array(w, dtype=np.float64, copy=True)
    out[..., 2] = -out[..., 2]
    return out


def spherical_direction(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vector with polar angle ``theta`` from +z and azimuth ``phi`` from +x (Eq. 4.7)."""
    theta = np.asarray(theta, dtype=np.float64)
    phi = np.asarray(phi, dtype=np.float64)
    sin_theta = np.sin(theta)
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)], axis=-1)


def direction_from_angles_deg(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    return spherical_direction(np.radians(theta_deg), np.radians(phi_deg))


def broadcast_rgb(value, name: str = "value") -> np.ndarray:
    """A scalar or an RGB triple as a float64 array of shape (3,)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(3, float(arr))
    if arr.shape == (3,):
        return arr.copy()
    raise ValueError(f"{name} must be a number or an RGB triple, got {value!r}")


def cosine_hemisphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-weighted hemisphere sample (Malley's method on Shirley's concentric disk), pdf
    cos(theta)/pi. Maps [0,1)^2 continuously and area-preservingly onto the disk."""
    a = 2.0 * np.asarray(u1, dtype=np.float64) - 1.0
    b = 2.0 * np.asarray(u2, dtype=np.float64) - 1.0
    use_a = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0.0, 1.0, a)
    safe_b = np.where(b == 0.0, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4.0) * (b / safe_a), np.pi / 2.0 - (np.pi / 4.0) * (a / safe_b))
    r = np.where((a == 0.0) & (b == 0.0), 0.0, r)
    x = r * np.cos(phi)
    y = r * np.sin(phi)
    z = np.sqrt(np.clip(1.0 - x * x - y * y, 0.0, None))
    return np.stack([x, y, z], axis=-1)
