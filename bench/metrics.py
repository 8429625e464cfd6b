"""Error measures of the benchmark: exposure, PSNR, relative RMSE, FLIP, the two-half
reference with its noise floor, Pareto fronts and crossings."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from lobeview.core.methods import Method


def exposure_for(reference: np.ndarray, mask: np.ndarray) -> float:
    """Stops that map the reference's median luminance over the mask to 0.18."""
    luminance = reference[mask] @ np.array([0.2126, 0.7152, 0.0722])
    return float(np.log2(0.18 / max(float(np.median(luminance)), 1e-6)))


def psnr_8bit(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.round(a * 255) / 255 - np.round(b * 255) / 255) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((image - reference) ** 2)) / max(np.sqrt(np.mean(reference**2)), 1e-30))


def flip_error(test_ldr: np.ndarray, reference_ldr: np.ndarray, mask: np.ndarray) -> float:
    """Mean LDR-FLIP (NVIDIA's flip-evaluator, 67 pixels per degree) over the mask; the images
    are tonemapped sRGB in [0, 1]."""
    import flip_evaluator

    test = np.where(mask[..., None], test_ldr, reference_ldr).astype(np.float32)
    error_map, _, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(reference_ldr, np.float32), np.ascontiguousarray(test), "LDR", applyMagma=False
    )
    error_map = np.asarray(error_map)
    if error_map.ndim == 3:
        error_map = error_map[..., 0]
    return float(error_map[mask].mean())


@dataclasses.dataclass
class Reference:
    radiance: np.ndarray
    mask: np.ndarray
    exposure: float
    ldr: np.ndarray  # tonemapped sRGB in [0, 1]
    psnr_floor: float  # PSNR the reference's own noise allows (estimated from two halves)
    rel_rmse_floor: float
    seconds: float
    spp: int

    def errors(self, radiance: np.ndarray) -> dict:
        from lobeview.viewer.tonemap import tonemap

        ldr = np.clip(tonemap(radiance, "aces", self.exposure), 0.0, 1.0)
        return {
            "rel_rmse": relative_rmse(radiance[self.mask], self.radiance[self.mask]),
            "psnr": psnr_8bit(ldr[self.mask], self.ldr[self.mask]),
            "flip": flip_error(ldr, self.ldr, self.mask),
        }


def make_reference(render, mask_of, spp: int) -> Reference:
    """Mean of two independent half-sample references (seeds 0 and 1). Their difference
    estimates the reference's noise: with per-pixel variance s^2 of the full reference, the
    halves differ by variance 4 s^2, so the full reference lies ~6 dB closer to the truth than
    the two halves to each other (PSNR floor = PSNR(A, B) + 6.02 dB, relRMSE floor = relRMSE(A, B)/2)."""
    from lobeview.viewer.tonemap import tonemap

    t0 = time.perf_counter()
    half = max(spp // 2, 1)
    a = render(Method.parse("reference"), spp=half, seed=0)
    b = render(Method.parse("reference"), spp=half, seed=1)
    seconds = time.perf_counter() - t0
    mask = mask_of(a)
    radiance = 0.5 * (a.radiance + b.radiance)
    exposure = exposure_for(radiance, mask)
    ldr_a = np.clip(tonemap(a.radiance, "aces", exposure), 0, 1)
    ldr_b = np.clip(tonemap(b.radiance, "aces", exposure), 0, 1)
    return Reference(
        radiance=radiance,
        mask=mask,
        exposure=exposure,
        ldr=np.clip(tonemap(radiance, "aces", exposure), 0.0, 1.0),
        psnr_floor=psnr_8bit(ldr_a[mask], ldr_b[mask]) + 6.02,
        rel_rmse_floor=relative_rmse(a.radiance[mask], b.radiance[mask]) / 2.0,
        seconds=seconds,
        spp=2 * half,
    )


def pareto_front(times, errors) -> list[bool]:
    """True for the points no other point beats in both time and error (lower is better)."""
    times, errors = np.asarray(times, float), np.asarray(errors, float)
    front = []
    for i in range(len(times)):
        dominated = np.any((times <= times[i]) & (errors <= errors[i]) & ((times < times[i]) | (errors < errors[i])))
        front.append(not bool(dominated) and np.isfinite(errors[i]))
    return front


def interpolate_log(x_query: float, xs, ys) -> float:
    """y at x_query by linear interpolation in log x over the points sorted by x; NaN outside."""
    order = np.argsort(xs)
    xs, ys = np.log(np.asarray(xs, float)[order]), np.asarray(ys, float)[order]
    x = np.log(x_query)
    if len(xs) < 2 or x < xs[0] or x > xs[-1]:
        return float("nan")
    return float(np.interp(x, xs, ys))


def first_crossing(target: float, xs, ys) -> float:
    """Smallest x (log-linear between points sorted by x) at which y reaches ``target``; NaN if
    it never does. Used for 'time (or samples) fis-N needs for lobe-N's PSNR'."""
    order = np.argsort(xs)
    xs, ys = np.asarray(xs, float)[order], np.asarray(ys, float)[order]
    if len(xs) == 0:
        return float("nan")
    if ys[0] >= target:
        return float(xs[0])  # reached at the smallest measured x already (an upper bound)
    for i in range(1, len(xs)):
        if ys[i] >= target:
            f = (target - ys[i - 1]) / (ys[i] - ys[i - 1])
            return float(np.exp(np.log(xs[i - 1]) + f * (np.log(xs[i]) - np.log(xs[i - 1]))))
    return float("nan")
