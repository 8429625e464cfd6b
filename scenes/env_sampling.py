"""Importance sampling of incident radiance stored in a cube map (numpy reference of the GLSL
sampler used by the ``reference`` method).

A texel of a coarse "importance" copy of the cube (box-filtered to ``size`` per face) is chosen
with probability P_t proportional to its luminance times its solid angle, and a point uniform in
the texel's (s, t) square is returned. Its density per solid angle is

    pdf(w) = P_t(w) * (size/2)^2 * (1 + sc^2 + tc^2)^(3/2) = P_t(w) * (size/2)^2 / |w_major|^3,

since d(omega) = d(sc) d(tc) / (1 + sc^2 + tc^2)^(3/2) on a face and a texel spans (2/size)^2
in (sc, tc). A floor of ``uniform_fraction`` of the probability mass is spread by solid angle so
that every direction has a positive density (MIS stays unbiased even where the coarse copy is 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lobeview.core.cube_layout import direction_to_face, face_point_directions, texel_solid_angles

from .envmap import equirect_direction, equirect_row_solid_angles, equirect_texel

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def box_downsample_faces(faces: np.ndarray, size: int) -> np.ndarray:
    factor = faces.shape[1] // size
    if factor < 1 or faces.shape[1] % size:
        raise ValueError(f"cannot box-downsample faces of {faces.shape[1]} to {size}")
    return faces.reshape(6, size, factor, size, factor, -1).mean(axis=(2, 4))


TENT_WEIGHTS = np.array([1.0, 3.0, 3.0, 1.0]) / 8.0  # one MIP step of viewer/cubemap.py tent_mipmaps


def tent_downsample_face(face: np.ndarray) -> np.ndarray:
    """One face or 2D level (H, W, C) -> (H/2, W/2, C) with the separable tent [1 3 3 1] / 8 over
    source texels 2j-1 .. 2j+2 (numpy reference of shaders/mip_tent_cube.comp and mip_tent_2d.comp;
    the cube shader reads across face edges, this clamps at them, so the two agree away from the
    border; the 2D shader clamps like this)."""
    face = np.asarray(face, dtype=np.float64)
    height, width = face.shape[:2]
    if height % 2 or width % 2:
        raise ValueError(f"tent_downsample_face needs even sizes, got {face.shape}")

    def taps(size: int) -> np.ndarray:  # (size/2, 4) source indices, clamped at the edges
        return np.clip(2 * np.arange(size // 2)[:, None] + np.arange(-1, 3)[None, :], 0, size - 1)

    rows = np.einsum("k,jk...->j...", TENT_WEIGHTS, face[taps(height)])  # filter along the rows' index
    return np.einsum("k,ijk...->ij...", TENT_WEIGHTS, rows[:, taps(width)])


def _mixed_probabilities(weight: np.ndarray, omega: np.ndarray, uniform_fraction: float) -> np.ndarray:
    """Texel probabilities: (1 - f) weight / sum + f omega / sum (every direction keeps a
    density); by solid angle alone when the weights are all zero or not finite."""
    total = weight.sum()
    uniform = omega / omega.sum()
    if total <= 0 or not np.isfinite(total):
        probabilities = uniform
    else:
        probabilities = (1.0 - uniform_fraction) * weight / total + uniform_fraction * uniform
    return probabilities / probabilities.sum()


def _pick_texel(probabilities: np.ndarray, cdf: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(texel index, position in [0, 1) inside it) for uniform numbers ``u``: the texel by
    inverting the discrete ``cdf``, the position from what of ``u`` is left within its step."""
    index = np.minimum(np.searchsorted(cdf, u, side="right"), len(cdf) - 1)
    lower = np.where(index > 0, cdf[np.maximum(index - 1, 0)], 0.0)
    along = np.clip((u - lower) / np.maximum(probabilities[index], 1e-300), 0.0, 1.0 - 1e-12)
    return index, along


@dataclass
class CubeImportance:
    probabilities: np.ndarray  # (6, size, size) discrete texel probabilities P_t, sum 1
    size: int

    @classmethod
    def from_faces(cls, faces: np.ndarray, size: int = 64, uniform_fraction: float = 0.02) -> CubeImportance:
        size = min(size, faces.shape[1])
        coarse = box_downsample_faces(np.asarray(faces, dtype=np.float64), size)
        # Texel solid angles are symmetric in sc and tc, so the (row, col) order does not matter.
        omega = texel_solid_angles(size)[None].repeat(6, axis=0)
        weight = np.maximum(coarse @ LUMINANCE, 0.0) * omega
        return cls(_mixed_probabilities(weight, omega, uniform_fraction), size)

    @property
    def cdf(self) -> np.ndarray:
        c = np.cumsum(self.probabilities.ravel())
        c[-1] = 1.0
        return c

    def pdf_scale(self) -> np.ndarray:
        """P_t (size/2)^2 per texel: pdf(w) = pdf_scale[texel(w)] / |w_major|^3."""
        return self.probabilities * (self.size / 2.0) ** 2

    def pdf(self, dirs: np.ndarray) -> np.ndarray:
        dirs = np.asarray(dirs, dtype=np.float64)
        dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
        face, sc, tc = direction_to_face(dirs)
        col = np.clip(((sc + 1.0) * 0.5 * self.size).astype(np.int64), 0, self.size - 1)
        row = np.clip(((tc + 1.0) * 0.5 * self.size).astype(np.int64), 0, self.size - 1)
        major = np.max(np.abs(dirs), axis=-1)
        return self.pdf_scale()[face, row, col] / major**3

    def sample(self, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Directions for uniform numbers in [0, 1): u1 picks the texel (and, rescaled, the
        position along s), u2 the position along t."""
        u1 = np.asarray(u1, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        index, s_in = _pick_texel(self.probabilities.ravel(), self.cdf, u1)
        face = index // (self.size * self.size)
        row = (index // self.size) % self.size
        col = index % self.size
        sc = 2.0 * (col + s_in) / self.size - 1.0
        tc = 2.0 * (row + u2) / self.size - 1.0
        out = np.empty(u1.shape + (3,))
        for f in range(6):
            sel = face == f
            if np.any(sel):
                out[sel] = face_point_directions(f, sc[sel], tc[sel])
        return out


@dataclass
class EquirectImportance:
    """Importance sampling of an equirectangular environment (the baker's light samples): a
    texel of a grid of at most ``max_height`` rows is chosen with probability P_t proportional to
    a conservative luminance times its solid angle (plus ``uniform_fraction`` spread by solid
    angle, so every direction keeps a positive density), then a point uniform in the texel's
    (u, v) rectangle. With theta = pi v and phi = 2 pi u, d(omega) = 2 pi^2 sin(theta) du dv, so
    the density per solid angle is

        pdf(w) = P_t(w) H W / (2 pi^2 sin theta).

    Made for :meth:`EnvironmentMap.lookup_nearest` (the baker's lookups): at full resolution the
    density is proportional to the radiance a sample returns, texel by texel, so a 0.6-degree
    sun costs no more variance than the sky. A map taller than ``max_height`` is pooled with the
    maximum, not the mean, of the texels a grid texel covers: L / pdf stays bounded (a mean
    would give a sample landing on a sun the density of the sky around it: unbiased still, but
    with a variance no ray count tames).
    """

    probabilities: np.ndarray  # (H, W) texel probabilities, sum 1

    def __post_init__(self):
        # Built once: the baker draws env_samples batches from one sampler.
        self.cdf = np.cumsum(self.probabilities.ravel())
        self.cdf[-1] = 1.0

    @classmethod
    def from_environment(cls, env, max_height: int = 1024, uniform_fraction: float = 0.02) -> EquirectImportance:
        luminance = np.maximum(env.image.astype(np.float64) @ LUMINANCE, 0.0)
        height, width = luminance.shape
        factor = 1
        while height // factor > max_height and height % (factor * 2) == 0 and width % (factor * 2) == 0:
            factor *= 2
        pooled = luminance.reshape(height // factor, factor, width // factor, factor).max(axis=(1, 3))
        omega = np.broadcast_to(equirect_row_solid_angles(*pooled.shape)[:, None], pooled.shape)
        return cls(np.ascontiguousarray(_mixed_probabilities(pooled * omega, omega, uniform_fraction)))

    def pdf(self, dirs: np.ndarray) -> np.ndarray:
        height, width = self.probabilities.shape
        row, col, v = equirect_texel(dirs, height, width)
        sin_theta = np.sin(np.pi * v)
        return self.probabilities[row, col] * height * width / (2.0 * np.pi**2 * np.maximum(sin_theta, 1e-12))

    def sample(self, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Directions for uniform numbers in [0, 1): u1 picks the texel (and, rescaled, the
        position along u), u2 the position along v."""
        height, width = self.probabilities.shape
        index, along = _pick_texel(self.probabilities.ravel(), self.cdf, np.asarray(u1, dtype=np.float64))
        u2 = np.asarray(u2, dtype=np.float64)
        row, col = index // width, index % width
        return equirect_direction((col + along) / width, (row + u2) / height)


CAP_CHOICE_UNIFORM = 0.1  # shaders/env_sampling.glsl: the uniform share of the light choice


@dataclass
class CapLightSampler:
    """The reference's third strategy (shaders/env_sampling.glsl cap_light_sample / cap_light_pdf):
    the bright sources separated from the cube (scenes/bright_sources.py) as proposals, light k
    chosen with probability ``choice[k]`` (u1, rescaled within its share, then places the point),
    a point uniform in solid angle over its cap. The radiance read there is the whole cube's, so
    the caps only say where to look. Its density, caps overlapping or not,

        pdf(w) = sum_k choice_k [w in cap k] / (2 pi (1 - cos r_k)),

    with membership by 0.5 |w - axis_k|^2 <= 1 - cos r_k (exact for unit vectors and free of the
    cancellation of 1 - dot for caps of a fraction of a degree). Any positive choice keeps MIS
    unbiased; :func:`cap_choice_for_lobe` is the shader's."""

    frames: np.ndarray  # (K, 3, 3) each cap's CapLight.frame(): columns t, b, axis
    one_minus_cos: np.ndarray  # (K,) 1 - cos(radius)
    choice: np.ndarray  # (K,) probabilities, sum 1

    @classmethod
    def from_lights(cls, lights, choice: np.ndarray | None = None) -> CapLightSampler:
        frames = np.array([light.frame() for light in lights], dtype=np.float64).reshape(-1, 3, 3)
        count = len(frames)
        choice = np.full(count, 1.0 / max(count, 1)) if choice is None else np.asarray(choice, dtype=np.float64)
        return cls(frames, np.array([1.0 - light.cos_radius for light in lights], dtype=np.float64), choice)

    @property
    def axes(self) -> np.ndarray:
        """(K, 3) the caps' unit directions."""
        return self.frames[:, :, 2]

    def pdf(self, dirs: np.ndarray) -> np.ndarray:
        dirs = np.asarray(dirs, dtype=np.float64)
        if len(self.frames) == 0:
            return np.zeros(dirs.shape[:-1])
        half_chord2 = 0.5 * np.sum((dirs[..., None, :] - self.axes) ** 2, axis=-1)  # 1 - cos to each axis
        inside = half_chord2 <= self.one_minus_cos
        return np.sum(inside * (self.choice / (2.0 * np.pi * self.one_minus_cos)), axis=-1)

    def sample(self, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        u1 = np.asarray(u1, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        count = len(self.frames)
        if count == 0:
            raise ValueError("CapLightSampler.sample: no lights to sample")
        upper = np.cumsum(self.choice)
        k = np.minimum(np.searchsorted(upper, u1, side="right"), count - 1)
        below = upper[k] - self.choice[k]
        along = np.clip((u1 - below) / np.maximum(self.choice[k], 1e-300), 0.0, 1.0)
        # 1 - cos of the point's angle from the axis, and its sine, without cancellation
        one_minus_cos_t = along * self.one_minus_cos[k]
        sin_t = np.sqrt(np.maximum(one_minus_cos_t * (2.0 - one_minus_cos_t), 0.0))
        phi = 2.0 * np.pi * u2
        local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), 1.0 - one_minus_cos_t], axis=-1)
        return np.einsum("nij,nj->ni", self.frames[k], local)


def cap_choice_for_lobe(lobe, wo: np.ndarray, lights, frame: np.ndarray | None = None) -> np.ndarray:
    """shaders/env_sampling.glsl choose_cap_lights: each light's share of an estimate of what it
    adds through ``lobe`` at ``wo`` (local; ``frame`` columns t, b, n map local to world), its
    luminance power times f cos at its axis, mixed with CAP_CHOICE_UNIFORM of the uniform choice
    (all uniform where every estimate is 0) so that a light the estimate misses (a wide cap whose
    axis lies outside a narrow lobe) is still proposed."""
    count = len(lights)
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    axes_local = np.array([light.direction for light in lights], dtype=np.float64).reshape(-1, 3) @ frame
    wo = np.broadcast_to(np.asarray(wo, dtype=np.float64), axes_local.shape)
    f = np.asarray(lobe.eval(axes_local, wo), dtype=np.float64).reshape(count, -1)
    f = f if f.shape[1] == 3 else np.repeat(f[:, :1], 3, axis=1)
    power = np.array([light.power for light in lights], dtype=np.float64).reshape(count, 3)
    estimate = np.maximum((f * power) @ LUMINANCE * np.abs(axes_local[:, 2]), 0.0)
    total = estimate.sum()
    if total <= 0.0:
        return np.full(count, 1.0 / count)
    return CAP_CHOICE_UNIFORM / count + (1.0 - CAP_CHOICE_UNIFORM) * estimate / total
