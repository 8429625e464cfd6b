"""The blur stack (numpy reference): the radiance a coarse fitted read needs, kept at a fixed
resolution instead of in ever-smaller MIP levels (issue 45; docs/measurements.md "The blur stack").

A MIP level holds a blur of about half its own texel, so the coarse levels are undersampled for
their blur and a bilinear read between their few texels is a lumpy kernel (3-14 % from a Gaussian
for sigma 3-30 degrees on issue 45's sky), whatever filter made them. The stack's LAYERS layers
have STACK_FACE^2 faces and constant angular sigmas, sqrt(2) apart from SIGMA0_TEXELS stack texels
(at a face's centre) up: every layer holds its blur with 1.5 texels or more per sigma.

Layout (viewer/blur_stack_gpu.py builds it, shaders/blur_stack.glsl reads it): a 2D texture array
of (STACK_FACE + 2 STACK_PAD)^2 texels, layer = 6 k + face (faces as core/cube_layout.py), a
border of STACK_PAD texels around each face holding the blur at the directions of its extended
face coordinates, so a bilinear read within [-1, 1]^2 of face coordinates needs no neighbour face.

Each texel is the von Mises-Fisher blur (weight exp((d . axis - 1) / s^2)) of the environment with
s^2 = sigma_k^2 - texel^2 / 6 (:func:`texel_blur`: a bilinear read adds a tent of one texel);
a read of sigma (rad) >= sigma_0 blends the two layers around sigma^2 linearly in variance
(:func:`read_stack`); below sigma_0 the MIP chain keeps the read (its fine levels are sampled
finely enough).
"""

from __future__ import annotations

import numpy as np

from lobeview.core.cube_layout import direction_to_face, face_point_directions

from .fitted_pattern import texel_angle

STACK_FACE = 32
STACK_PAD = 1
STACK_LAYERS = 10  # sigma_0 x 22.6 at the last: 95 degrees from a 32^2 face
#: bytes of one cube's stack on the GPU: 6 x STACK_LAYERS padded faces, RGBA32F (viewer/blur_stack_gpu.py)
STACK_BYTES = 6 * STACK_LAYERS * (STACK_FACE + 2 * STACK_PAD) ** 2 * 4 * 4
SIGMA0_TEXELS = 1.5
# shaders/blur_stack.comp: taps a side of the tangent-plane grid (2 BUILD_TAPS + 1)^2 out to 3.5
# sigma; the build against the exact blur is tests/test_blur_stack.py's
BUILD_TAPS = 12


def stack_sigmas(layers: int = STACK_LAYERS) -> np.ndarray:
    """The layers' angular sigmas (rad): SIGMA0_TEXELS texels of a STACK_FACE face at its centre
    (90 / STACK_FACE degrees each) times sqrt(2)^k."""
    return SIGMA0_TEXELS * np.radians(90.0 / STACK_FACE) * np.sqrt(2.0) ** np.arange(layers)


def texel_blur(sigma: float, directions: np.ndarray) -> np.ndarray:
    """The blur a layer's texels hold so that a bilinear read of the layer blurs by ``sigma``:
    sigma^2 less a tent of one texel (texel^2 / 6), at least 0.3 sigma."""
    texel = texel_angle(directions, STACK_FACE)
    return np.sqrt(np.maximum(sigma * sigma - texel * texel / 6.0, (0.3 * sigma) ** 2))


def padded_face_directions(face: int) -> np.ndarray:
    """(S + 2 P, S + 2 P, 3) unit directions of a padded face's texel centres, rows = t: the border
    texels lie on the face's plane beyond [-1, 1] (their directions on the neighbouring faces)."""
    size = STACK_FACE + 2 * STACK_PAD
    coords = ((np.arange(size) - STACK_PAD) + 0.5) / STACK_FACE * 2.0 - 1.0
    tc, sc = np.meshgrid(coords, coords, indexing="ij")
    return face_point_directions(face, sc, tc)


def vmf_blur(axes: np.ndarray, sigma, dirs: np.ndarray, solid: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """The environment (quadrature ``dirs``, ``solid`` angles, ``radiance``) averaged around each
    of ``axes`` with the weight exp((d . axis - 1) / sigma^2): a Gaussian of sigma for narrow
    kernels, a von Mises-Fisher kernel (kappa = 1 / sigma^2) over the whole sphere for wide ones."""
    axes = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (len(axes),))
    out = np.zeros((len(axes), radiance.shape[-1]))
    for start in range(0, len(axes), 256):  # bounded memory: 256 x quadrature points at a time
        block = slice(start, start + 256)
        weight = np.exp(np.minimum((axes[block] @ dirs.T - 1.0) / sigma[block, None] ** 2, 0.0)) * solid
        out[block] = (weight @ radiance) / np.sum(weight, axis=1, keepdims=True)
    return out


def exact_stack(dirs: np.ndarray, solid: np.ndarray, radiance: np.ndarray, layers: int = STACK_LAYERS) -> np.ndarray:
    """(layers, 6, S + 2 P, S + 2 P, 3) the stack of an environment given by quadrature, each texel
    its exact blur (the reference the GPU's build is tested against)."""
    size = STACK_FACE + 2 * STACK_PAD
    out = np.zeros((layers, 6, size, size, radiance.shape[-1]))
    for k, sigma in enumerate(stack_sigmas(layers)):
        for face in range(6):
            axes = padded_face_directions(face).reshape(-1, 3)
            out[k, face] = vmf_blur(axes, texel_blur(sigma, axes), dirs, solid, radiance).reshape(size, size, -1)
    return out


def read_layer(stack: np.ndarray, layer: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear reads of ``stack`` (layers, 6, S + 2 P, S + 2 P, C) at integer ``layer`` in
    ``directions``, as GL's LINEAR filter of the padded face (clamped to its edge)."""
    # the major axis as shaders/blur_stack.glsl takes it (x before y before z on ties)
    face, sc, tc = direction_to_face(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    size = STACK_FACE + 2 * STACK_PAD
    u = (sc + 1.0) * 0.5 * STACK_FACE + STACK_PAD - 0.5  # texel-centre coordinates of the padded face
    v = (tc + 1.0) * 0.5 * STACK_FACE + STACK_PAD - 0.5
    i0, j0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - i0, v - j0
    layer = np.broadcast_to(np.asarray(layer, dtype=int), face.shape)

    def texel(i, j):
        return stack[layer, face, np.clip(j, 0, size - 1), np.clip(i, 0, size - 1)]

    top = (1.0 - fu)[:, None] * texel(i0, j0) + fu[:, None] * texel(i0 + 1, j0)
    bottom = (1.0 - fu)[:, None] * texel(i0, j0 + 1) + fu[:, None] * texel(i0 + 1, j0 + 1)
    return (1.0 - fv)[:, None] * top + fv[:, None] * bottom


def layer_blend(sigma: np.ndarray, sigmas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, t): a read of ``sigma`` blends layers k and k + 1 as (1 - t) L_k + t L_k+1, linear in
    variance; clamped to the first and the last layer."""
    variance = np.clip(np.asarray(sigma, dtype=np.float64) ** 2, sigmas[0] ** 2, sigmas[-1] ** 2)
    layer_variance = sigmas**2
    k = np.clip(np.searchsorted(layer_variance, variance, side="right") - 1, 0, len(sigmas) - 2)
    t = np.clip((variance - layer_variance[k]) / (layer_variance[k + 1] - layer_variance[k]), 0.0, 1.0)
    return k, t


def read_stack(stack: np.ndarray, directions: np.ndarray, sigma) -> np.ndarray:
    """A read of ``sigma`` (rad) in ``directions`` (world, unit): :func:`layer_blend` of two
    bilinear layer reads (the twin of shaders/blur_stack.glsl blur_stack_read)."""
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), (len(directions),))
    k, t = layer_blend(sigma, stack_sigmas(stack.shape[0]))
    low = read_layer(stack, k, directions)
    high = read_layer(stack, k + 1, directions)
    return (1.0 - t)[:, None] * low + t[:, None] * high


class StackReads:
    """The stack as lobe-N+norm+fit's numpy twin reads it: ``sigma0`` and ``reads(directions,
    sigma)``; ``stack`` as :func:`exact_stack` returns it or viewer/blur_stack_gpu.py downloads it."""

    def __init__(self, stack: np.ndarray):
        self.stack = np.asarray(stack, dtype=np.float64)
        self.sigma0 = float(stack_sigmas(self.stack.shape[0])[0])

    def __call__(self, directions: np.ndarray, sigma) -> np.ndarray:
        return read_stack(self.stack, directions, sigma)
