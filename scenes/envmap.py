"""Equirectangular environment maps and the one orientation convention used everywhere.

World space is glTF's: right-handed, +Y up, a default camera looks down -Z.
Equirectangular (u, v) in [0, 1]^2, u to the right, v down from the top row:

    direction(u, v) = (sin(theta) sin(phi), cos(theta), -sin(theta) cos(phi))
    with phi = 2 pi (u - 0.5) and theta = pi v,

so the image centre (u, v) = (0.5, 0.5) faces -Z (what a default glTF camera sees), u = 0.75
faces +X, u = 0.25 faces -X, the top row is +Y (sky) and the bottom row -Y. This matches how
Blender and Poly Haven panoramas appear when the -Z axis is "forward".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lobeview.core.cube_layout import direction_to_equirect, equirect_direction

from .hdrio import read_hdr_image, sanitize_radiance


def equirect_row_solid_angles(height: int, width: int) -> np.ndarray:
    """Solid angle of one texel in each row of a height x width equirectangular grid:
    (2 pi / W) (cos(theta0) - cos(theta1)); shape (H,)."""
    edges = np.linspace(0.0, np.pi, height + 1)
    return (2.0 * np.pi / width) * (np.cos(edges[:-1]) - np.cos(edges[1:]))


def equirect_texel(d: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row, column, v) of the texel of a height x width equirectangular grid containing
    direction(s) ``d`` (nearest lookups and the texel densities of importance sampling)."""
    u, v = direction_to_equirect(d)
    col = np.clip((u * width).astype(np.int64), 0, width - 1)
    row = np.clip((v * height).astype(np.int64), 0, height - 1)
    return row, col, v


@dataclass
class EnvironmentMap:
    """Linear radiance on the sphere, stored equirectangularly (float32, H x W x 3)."""

    image: np.ndarray
    name: str = "environment"

    def __post_init__(self):
        # Every way in (files, functions, arrays) is sanitised: NaN/Inf and negative radiance
        # become 0 with a warning, so no shader ever sees them.
        image = np.asarray(self.image, dtype=np.float32)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"{self.name}: an environment map must be (H, W, 3), got {image.shape}")
        self.image, _ = sanitize_radiance(image, self.name)

    @classmethod
    def load(cls, path: str | Path) -> EnvironmentMap:
        path = Path(path)
        image = read_hdr_image(path)
        if image.shape[1] != 2 * image.shape[0]:
            raise ValueError(
                f"{path}: an equirectangular map must be twice as wide as high, got {image.shape[1]}x{image.shape[0]}"
            )
        return cls(image, str(path))

    @classmethod
    def from_function(cls, fn, height: int = 256, name: str = "procedural") -> EnvironmentMap:
        """Sample ``fn(directions (..., 3)) -> radiance (..., 3)`` at texel centres."""
        v, u = np.meshgrid(
            (np.arange(height) + 0.5) / height,
            (np.arange(2 * height) + 0.5) / (2 * height),
            indexing="ij",
        )
        return cls(np.asarray(fn(equirect_direction(u, v)), dtype=np.float32), name)

    @property
    def height(self) -> int:
        return self.image.shape[0]

    @property
    def width(self) -> int:
        return self.image.shape[1]

    def texel_solid_angles(self) -> np.ndarray:
        """Solid angle of each texel row: (2 pi / W) (cos(theta0) - cos(theta1)); shape (H,)."""
        return equirect_row_solid_angles(self.height, self.width)

    def lookup(self, d: np.ndarray) -> np.ndarray:
        """Bilinear lookup (wrapping in u, clamped in v) in direction(s) ``d``."""
        u, v = direction_to_equirect(d)
        x = u * self.width - 0.5
        y = np.clip(v * self.height - 0.5, 0.0, self.height - 1.0)
        x0 = np.floor(x).astype(np.int64)
        y0 = np.floor(y).astype(np.int64)
        fx = (x - x0)[..., None]
        fy = (y - y0)[..., None]
        x0 %= self.width
        x1 = (x0 + 1) % self.width
        y1 = np.minimum(y0 + 1, self.height - 1)
        img = self.image
        top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
        bottom = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
        return top * (1 - fy) + bottom * fy

    def lookup_nearest(self, d: np.ndarray) -> np.ndarray:
        """The texel containing direction(s) ``d``: the map as piecewise-constant radiance, the
        function the texel quadrature integrates exactly and importance sampling by texel
        (env_sampling.EquirectImportance) matches texel by texel (the baker's lookups)."""
        row, col, _ = equirect_texel(d, self.height, self.width)
        return self.image[row, col]

    def downsampled(self, height: int) -> EnvironmentMap:
        """Box-filtered copy with the given height (must divide the current height)."""
        factor = self.height // height
        if factor < 1 or self.height % height:
            raise ValueError(f"cannot box-downsample height {self.height} to {height}")
        img = self.image.reshape(height, factor, 2 * height, factor, 3).astype(np.float64)
        # Weight rows by their solid angle so the downsampled map keeps the same integral.
        weights = np.sin((np.arange(self.height) + 0.5) / self.height * np.pi).reshape(height, factor)
        img = (img * weights[:, :, None, None, None]).sum(axis=(1, 3)) / (weights.sum(1)[:, None, None] * factor)
        return EnvironmentMap(img.astype(np.float32), self.name)

    def _texel_quadrature(self, source_height: int) -> tuple[np.ndarray, np.ndarray]:
        """(texel centre directions (N, 3), radiance x texel solid angle (N, 3)) of a copy
        box-downsampled to at most ``source_height`` rows: the sum of the second is the
        integral of L over the sphere."""
        src = self
        while src.height > source_height and src.height % 2 == 0:
            src = src.downsampled(src.height // 2)
        v, u = np.meshgrid(
            (np.arange(src.height) + 0.5) / src.height,
            (np.arange(src.width) + 0.5) / src.width,
            indexing="ij",
        )
        dirs = equirect_direction(u, v).reshape(-1, 3)
        return dirs, (src.image.astype(np.float64) * src.texel_solid_angles()[:, None, None]).reshape(-1, 3)

    def irradiance(self, normals: np.ndarray, source_height: int = 64) -> np.ndarray:
        """Irradiance E(n) = integral of L(w) max(0, n.w) dw by brute-force summation over a
        box-downsampled copy of the map (exact up to that resolution)."""
        dirs, radiance = self._texel_quadrature(source_height)
        normals = np.asarray(normals, dtype=np.float64)
        flat = normals.reshape(-1, 3)
        out = np.empty_like(flat)
        for start in range(0, len(flat), 4096):
            cos = np.maximum(flat[start : start + 4096] @ dirs.T, 0.0)
            out[start : start + 4096] = cos @ radiance
        return out.reshape(normals.shape)

    def irradiance_sh9(self, source_height: int = 128) -> np.ndarray:
        """(9, 3) coefficients of the irradiance E(n) = integral L(w) max(0, n.w) dw in the
        order-2 real spherical harmonics of :func:`sh9_basis` (Ramamoorthi and Hanrahan 2001):
        the radiance projected on Y_lm, times the clamped-cosine factors pi, 2 pi / 3, pi / 4.
        Exact for radiance of order <= 2; a smooth approximation (within ~10 % of the
        irradiance's range) for sharp maps. Evaluate with :func:`eval_sh9`."""
        dirs, weighted = self._texel_quadrature(source_height)
        coefficients = sh9_basis(dirs).T @ weighted  # (9, 3): integral L Y_lm dw
        return coefficients * SH9_COSINE_FACTORS[:, None]


#: The clamped cosine's SH factors per band (l = 0, 1, 1, 1, 2, 2, 2, 2, 2).
SH9_COSINE_FACTORS = np.array([np.pi] + [2.0 * np.pi / 3.0] * 3 + [np.pi / 4.0] * 5)


def sh9_basis(d: np.ndarray) -> np.ndarray:
    """Real spherical harmonics Y_00, Y_1-1, Y_10, Y_11, Y_2-2, Y_2-1, Y_20, Y_21, Y_22 of unit
    directions (..., 3) -> (..., 9). shaders/scene.frag sh9_irradiance is the GLSL twin."""
    x, y, z = (np.asarray(d, dtype=np.float64)[..., k] for k in range(3))
    return np.stack(
        [
            np.full_like(x, 0.282095),
            0.488603 * y,
            0.488603 * z,
            0.488603 * x,
            1.092548 * x * y,
            1.092548 * y * z,
            0.315392 * (3.0 * z * z - 1.0),
            1.092548 * x * z,
            0.546274 * (x * x - y * y),
        ],
        axis=-1,
    )


def eval_sh9(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance at unit normals (..., 3) from :meth:`EnvironmentMap.irradiance_sh9`, clamped
    at 0 (the truncated series rings below zero opposite a sun)."""
    return np.maximum(sh9_basis(normals) @ coefficients, 0.0)
