"""Progressive refinement while the camera stands still (thesis 4.4.2), and when to show it.

Each still frame adds one pass of ``reference`` samples (a batch sized to keep frames near
TARGET_FRAME_MS), shaded at another sub-pixel position (viewer/camera.py pixel_offset), so the
accumulation converges to each pixel's box-filtered integral. The passes go alternately to two
half accumulations A and B (each to the one holding fewer samples). The halves are two
independent randomisations of the same quasi-random estimator: each reads the Sobol table from
its start with its own per-pixel rotation (the shader's seed 0 or 1) and its own shifted
sequence of sub-pixel positions. (Interleaving one sequence between the halves would not do:
even and odd Sobol or Halton indices lie in opposite halves of the unit interval, and the halves'
difference would then measure that split, not the noise.) Their difference estimates the noise
of the running mean (the two-half estimate), in the display's own units:

    noise^2    = mean over pixels of |d(A) - d(B)|^2  *  w_A w_B / (w_A + w_B)^2
    realtime^2 = max(mean over pixels of |d(R) - d(M)|^2 - noise^2, 0)

with d the display transform (tonemap and exposure, values in [0, 1]), M the running mean, R
the real-time frame and w the halves' sample counts. For independent halves with per-sample
variance s^2, Var(A - B) = s^2 (1/w_A + 1/w_B) and Var(M) = s^2 / (w_A + w_B), hence the
factor; E|R - M|^2 = bias(R)^2 + Var(M), hence the subtraction. The same two sums taken over a
LOCAL_WINDOW x LOCAL_WINDOW neighbourhood of each pixel give local noise^2 n and bias^2 b, and
the window shows per pixel mix(R, M, b / (b + k n)), k = noise_caution(spp) = 1 + 96 / spp.
With exact n and b, k = 1 would be the convex combination of least expected squared error; but
n is estimated from the samples themselves, and where they are heavy-tailed (a few bright paths
on a glossy gold torus or a frosted pane) most neighbourhoods have not met a bright path yet, so
n is typically underestimated, the more so the fewer the samples, and the mean is chosen too
early: with k = 1 the first estimate (32 spp) showed the demo's torus and pane 17 % worse than
the real-time frame (display RMS x 255: 15.3 against 13.0 with batches of 4 samples, 14.8 with
batches of 1; tests/test_refinement_improves.py). Measured there for k = 1, 1.5, 2, 3 at 32, 64
and 128 spp and batches of 1, 2, 4 and 8: large k is best at 32 spp, 1.5-2 at 64, 1-1.5 at 128,
which 1 + 64 / spp follows (torus and pane with batches of 4: 12.4, 11.3, 9.9 against the plain
rule's 15.3, 11.5, 9.7; the whole image 3.3, 2.2, 1.8, as with k = 1). Since the demo's ceiling
lamp became a soft-edged cap light in the objects' cubes (issue 39, 12-20 degrees) the real-time
frame there is better (torus and pane 9.84, 13.70 before) and 1 + 64 / spp showed them 0.4 % worse
at 32 spp (9.88); 1 + 96 / spp: 9.50, 8.73, 8.10 (the whole image 3.24, 1.92, 1.50 against 4.66 for
the real-time frame); 1 + 128 / spp: 9.34, 8.75, 8.15 (whole 3.32, 1.94, 1.52). For any true
n, b a blend with weight b / (b + k n), k >= 1, is still better than either image alone (its
error bn(b + k^2 n) / (b + k n)^2 is below both). Where the real-time method is exact (lightmapped
diffuse) the mean is taken (n = b = 0: weight 1). Refinement stops when the noise falls below CONVERGED_NOISE (a quarter
of an 8-bit step) or each half has read the whole Sobol table (HALF_SAMPLE_BUDGET: beyond it a
half would repeat its points). The estimates are taken when the sample count has doubled since
the last one (a read back of three frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.ndimage import uniform_filter

from lobeview.viewer.camera import pixel_offset
from lobeview.viewer.shading import SOBOL_SIDE
from lobeview.viewer.tonemap import tonemap

TARGET_FRAME_MS = 50.0
MAX_BATCH = 64
# spp per lobe at the first two-half estimate, then at every doubling; with fewer samples heavy
# tails make the estimate optimistic (measured on the demo: 6.7 estimated vs 9.2 true at 8 spp)
FIRST_ESTIMATE_AT = 32
LOCAL_WINDOW = 9  # pixels: the neighbourhood of the per-pixel noise and bias estimates
CAUTION_SAMPLES = 96.0  # noise_caution: the blend counts the estimated noise 1 + this / spp times
CONVERGED_NOISE = 0.25 / 255.0  # display RMS noise at which refinement stops
# A refinement pass's share of the pixel for its texture reads: 1/sqrt(64), a box-filtered
# reference's of 64 passes (refinement runs that many or more before it converges); a whole
# pixel's footprint on top of the pixel integral blurred the textures twice.
REFINEMENT_TEXTURE_FOOTPRINT = 1.0 / 8.0
ERROR_FLOOR = 1e-6  # display RMS error below which a pixel's errors count as zero
HALF_SAMPLE_BUDGET = SOBOL_SIDE * SOBOL_SIDE  # the Sobol table: a half never wraps around it


def noise_caution(samples: float) -> float:
    """How many times the blend weight counts the estimated noise at ``samples`` spp (module doc)."""
    return 1.0 + CAUTION_SAMPLES / max(float(samples), 1.0)


@dataclass(frozen=True, eq=False)
class RefinementEstimate:
    samples: int  # spp per lobe in the running mean
    noise: float  # estimated display RMS error of the running mean
    realtime: float  # estimated display RMS error of the real-time frame
    shown: float  # estimated display RMS error of the blend the window shows
    weight: np.ndarray  # (H, W) the mean's weight per pixel in the shown blend

    @property
    def refined_share(self) -> float:
        """The mean weight of the refined image in what is shown."""
        return float(np.mean(self.weight))


def two_half_estimate(
    half_a: np.ndarray,
    weight_a: float,
    half_b: np.ndarray,
    weight_b: float,
    realtime: np.ndarray,
    operator: str = "aces",
    exposure: float = 0.0,
    window: int = LOCAL_WINDOW,
    caution: float | None = None,
) -> RefinementEstimate:
    """The module doc's estimates from the two half means (H, W, 3 linear radiance) with their
    sample counts, and the real-time frame: image-wide RMS errors and the per-pixel weight
    (``caution``: how many times the weight counts the noise; None: noise_caution(spp), 1 is the
    plain rule)."""
    if weight_a <= 0 or weight_b <= 0:
        raise ValueError("both halves need samples for a two-half estimate")
    total = weight_a + weight_b
    mean = (weight_a * half_a + weight_b * half_b) / total
    display_a, display_b = tonemap(half_a, operator, exposure), tonemap(half_b, operator, exposure)
    display_mean, display_realtime = tonemap(mean, operator, exposure), tonemap(realtime, operator, exposure)
    noise2 = np.mean((display_a - display_b) ** 2, axis=-1) * (weight_a * weight_b / total**2)
    difference2 = np.mean((display_realtime - display_mean) ** 2, axis=-1)
    # The filter's running sums leave round-off (~1e-19) where the errors are exactly 0: clipped,
    # and errors far below an 8-bit step (ERROR_FLOOR) count as none (weight 1: the mean).
    local_noise2 = np.maximum(uniform_filter(noise2, window, mode="nearest"), 0.0)
    local_bias2 = np.maximum(uniform_filter(difference2, window, mode="nearest") - local_noise2, 0.0)
    caution = noise_caution(total) if caution is None else float(caution)
    total2 = local_bias2 + caution * local_noise2
    some = total2 > ERROR_FLOOR**2
    weight = np.where(some, np.clip(local_bias2 / np.where(some, total2, 1.0), 0.0, 1.0), 1.0)
    shown2 = weight**2 * local_noise2 + (1.0 - weight) ** 2 * local_bias2
    noise = float(np.mean(noise2))
    return RefinementEstimate(
        samples=int(round(total)),
        noise=noise**0.5,
        realtime=max(float(np.mean(difference2)) - noise, 0.0) ** 0.5,
        shown=float(np.mean(shown2)) ** 0.5,
        weight=weight.astype(np.float32),
    )


class RefinementPass(NamedTuple):
    """One refinement pass: draw ``samples`` reference samples per lobe with the shader's seed =
    ``half``, from Sobol index ``sample_offset``, at sub-pixel position ``jitter``; then
    Refinement.added(samples actually drawn, half)."""

    samples: int
    half: int
    sample_offset: int
    jitter: tuple[float, float]


class Refinement:
    """The refinement state of one still period: samples, the adaptive batch, the halves'
    weights, the last estimate and whether the refined image is shown or refinement is done."""

    def __init__(self):
        self.batch = 4
        self.reset()

    def reset(self) -> None:
        self.samples = 0
        self.half_passes = [0, 0]
        self.still_frames = 0
        self.weights = [0.0, 0.0]
        self.next_estimate = FIRST_ESTIMATE_AT
        self.estimate: RefinementEstimate | None = None
        self.finished = ""  # why refinement stopped ('' while it runs)

    def adapt(self, pass_ms: float) -> None:
        """Scale the batch by the measured cost of the last pass (at most x2 / x0.5 a frame)."""
        ratio = TARGET_FRAME_MS / max(pass_ms, 1e-3)
        self.batch = int(np.clip(self.batch * np.clip(ratio, 0.5, 2.0), 1, MAX_BATCH))

    def next_pass(self) -> RefinementPass:
        """The next pass: into the half holding fewer samples (that is not done), the batch cut
        to that half's budget, at that half's next sub-pixel position. Half B's Sobol indices
        start one table further: the shader reads index i at i mod table size, so both halves
        read the same points, and only a first pass of all (offset 0) starts the reflectors'
        plane averages afresh (shaders/incident.glsl)."""
        half = int(self.weights[1] < self.weights[0])
        if self.weights[half] >= HALF_SAMPLE_BUDGET:
            half = 1 - half
        return RefinementPass(
            samples=min(int(self.batch), HALF_SAMPLE_BUDGET - int(self.weights[half])),
            half=half,
            sample_offset=int(self.weights[half]) + half * HALF_SAMPLE_BUDGET,
            jitter=pixel_offset(self.half_passes[half], stream=half),
        )

    def added(self, samples: int, half: int) -> None:
        self.samples += samples
        self.half_passes[half] += 1
        self.weights[half] += samples
        if min(self.weights) >= HALF_SAMPLE_BUDGET:
            self.finished = f"sample budget ({HALF_SAMPLE_BUDGET} spp per half: the Sobol table)"

    @property
    def estimate_due(self) -> bool:
        """At every doubling of the samples, and once more when refinement has stopped."""
        if min(self.weights) <= 0 or (self.estimate is not None and self.estimate.samples == self.samples):
            return False
        return self.samples >= self.next_estimate or bool(self.finished)

    def update(self, estimate: RefinementEstimate) -> None:
        """Take a two-half estimate (the window shows its blend); stop when converged."""
        self.estimate = estimate
        self.next_estimate = 2 * self.samples
        if estimate.noise < CONVERGED_NOISE and not self.finished:
            self.finished = f"converged (noise {estimate.noise * 255:.2f} / 255)"

    def status(self) -> str:
        """The panel's line."""
        if not self.samples:
            return "real-time frame"
        line = f"refinement: {self.samples} spp per lobe (batch {self.batch})"
        if self.estimate is not None:
            e = self.estimate
            line += (
                f"; shown: {100 * e.refined_share:.0f} % refined; est. RMS error x255: refined {e.noise * 255:.2f},"
                f" real-time {e.realtime * 255:.2f}, shown {e.shown * 255:.2f}"
            )
        return line + (f"; stopped: {self.finished}" if self.finished else "")
