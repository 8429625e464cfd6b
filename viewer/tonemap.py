"""Tonemapping linear radiance to display sRGB (the only place sRGB appears: docs/architecture.md, conventions).

operators:
  aces      Narkowicz's fit of the ACES filmic curve (2015): (x (2.51 x + 0.03)) /
            (x (2.43 x + 0.59) + 0.14), per channel, after exposure. Default.
  reinhard  x / (1 + x) per channel, after exposure.
  none      no curve: exposure only, then clipped to [0, 1] for 8-bit output (raw radiance is
            what .exr / .npy outputs hold).
Exposure is in stops: radiance is multiplied by 2^exposure first.
"""

from __future__ import annotations

import numpy as np

TONEMAPS = ("aces", "reinhard", "none")


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tonemap(radiance: np.ndarray, operator: str = "aces", exposure: float = 0.0) -> np.ndarray:
    """Linear radiance (H, W, 3) -> display-referred sRGB in [0, 1]."""
    if operator not in TONEMAPS:
        raise ValueError(f"unknown tonemap {operator!r}; use one of {TONEMAPS}")
    x = np.nan_to_num(np.asarray(radiance, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    x = np.maximum(x, 0.0) * 2.0**exposure
    if operator == "aces":
        x = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    elif operator == "reinhard":
        x = x / (1.0 + x)
    return linear_to_srgb(x)


def to_uint8(srgb: np.ndarray) -> np.ndarray:
    return np.clip(np.round(srgb * 255.0), 0, 255).astype(np.uint8)
