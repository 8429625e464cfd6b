"""Image helpers on numpy arrays, shared by the commands and the benches."""

from __future__ import annotations

import numpy as np


def box_downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """The mean of each ``factor`` x ``factor`` block of an (H factor, W factor, ...) image: the
    box filter of a supersampled render (``shot --supersample``, the Cycles bench)."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    blocks = image[: h * factor, : w * factor].reshape(h, factor, w, factor, *image.shape[2:])
    return blocks.mean(axis=(1, 3), dtype=np.float64).astype(image.dtype)
