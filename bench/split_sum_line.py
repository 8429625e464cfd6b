"""Split-sum's oblique line against the lobe it stands for, in numpy (issues 45 and 39): the
symmetric line `prefiltered` reads for GGX (and read for Beckmann before), Beckmann's in-plane
quantile line as built, and that line computed per pixel without its table.

What is measured: for each pixel of the preview sphere (bench/lobe_kernel.py sphere_views, issue
45's camera), the split-sum estimate of the lobe's normalised integral of the light map, against
the exact integral of the same map by the lobe's f cos (no Fresnel; the split-sum's albedo factor
is exact by construction here, so only the lookups differ), over a quadrature of the map's own
texels. The map is what a cube map keeps after the bright sources became cap lights (integrated
exactly by every method): issue 45's sky without its sun, or a capture of ../shared/assets/env
after `separate_equirect`. The split-sum reads are modelled as the shader makes them: the level
`split_sum_lod` gives, blended between the two split-sum levels around it, each level the
normalised kernel `split_sum_profile` at that level's roughness. (The twin reproduces the GPU: on
the sky, Beckmann 0.5's sun pixel read 1.028 x the truth here with the symmetric line, 1.028
against Mitsuba in bench/results/mitsuba-20261130-122434.md.)

The ways of placing the lookups of an isotropic lobe seen off the normal:
  *symmetric line*: materials/prefilter.py split_sum_lookups(in_plane=False), the symmetric
    quantile line of the normal-incidence marginal along the plane of incidence (scale
    sqrt(alpha^2 - alpha'^2)), leant towards the normal by split_sum_lean;
  *prefiltered*: split_sum_lookups as `prefiltered` reads it (Beckmann: the in-plane line from
    split_sum_oblique.py IN_PLANE_OFFSETS; GGX: the symmetric line);
  *in-plane, exact*: the 11 nodes at the quantiles (the middles of SPLIT_SUM_LINE_EDGES) of this
    pixel's lobe f cos over the angle within the plane of incidence (asymmetric, cut by the
    horizon, its off-specular shift included: no lean), their offsets from the median shrunk by
    sqrt(1 - (IQR_kernel / IQR_lobe)^2) (the level kernel's own in-plane spread, which every
    lookup adds), the level alpha' = alpha rho as today. (The built table shrinks quantile by
    quantile instead, materials/split_sum_in_plane.py: the same on Beckmann, worse on GGX.)

    .venv/bin/python -m lobeview.bench.split_sum_line [--envs sky interior courtyard]
        [--cases beckmann:0.3 ggx:0.3 ...] [--pixels 12] [--height 256]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from lobeview.materials import prefilter as pf
from lobeview.materials.split_sum_in_plane import LINE_QUANTILES, weighted_quantiles
from lobeview.materials.split_sum_levels import SPLIT_SUM_LEVELS, split_sum_alpha, split_sum_lod
from lobeview.materials.split_sum_oblique import oblique_alpha_ratio

ENVS = ("sky", "interior", "courtyard")
CASES = tuple(f"{kind}:{alpha}" for kind in ("beckmann", "ggx") for alpha in (0.15, 0.3, 0.5, 0.8))
#: symmetric line and lean (GGX's, and Beckmann's before), `prefiltered` as built (Beckmann: the
#: in-plane table), the in-plane quantile line from each pixel's own quadrature (untabulated)
WAYS = ("symmetric line", "prefiltered", "in-plane, exact")


def light_texels(env: str, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(directions (k, 3), solid angles (k,), luminance-like radiance (k,): the mean of RGB) of the
    map a cube keeps under ``env``: the sunless sky, or a capture's residual after its bright
    sources became cap lights, averaged down to ``height`` rows."""
    from lobeview.bench import lobe_kernel, mitsuba
    from lobeview.scenes.bright_sources import equirect_texels, separate_equirect

    if env == "sky":
        directions, omega, radiance = lobe_kernel.sky_quadrature(height)
        return directions.reshape(-1, 3), omega.reshape(-1), np.asarray(radiance).reshape(-1, 3).mean(axis=1)
    residual = separate_equirect(mitsuba.capture_image(env)).residual
    factor = residual.shape[0] // height
    if factor < 1 or residual.shape[0] % height:
        raise ValueError(f"--height {height} must divide the capture's {residual.shape[0]} rows")
    residual = residual.reshape(height, factor, 2 * height, factor, 3).mean(axis=(1, 3))
    directions, omega = equirect_texels(height)
    return directions.reshape(-1, 3), omega.reshape(-1), residual.reshape(-1, 3).mean(axis=1)


class SplitSumTwin:
    """The truth and both split-sum estimates for one map."""

    def __init__(self, directions, omega, radiance):
        self.directions, self.omega, self.radiance = directions, omega, radiance
        self._profiles: dict = {}
        self._iqr: dict = {}

    def profile(self, kind: str, alpha: float):
        key = (kind, round(alpha, 5))
        if key not in self._profiles:
            self._profiles[key] = pf.split_sum_profile(kind, max(alpha, pf.ALPHA_MIN))
        return self._profiles[key]

    def lobe_weights(self, kind, alpha, wo, frame) -> tuple[np.ndarray, np.ndarray]:
        """The lobe's f cos times the texels' solid angles, and the texels in the pixel's frame."""
        from lobeview.materials.conductor import MicrofacetReflection
        from lobeview.materials.fresnel import Fresnel
        from lobeview.materials.microfacet import MicrofacetDistribution

        lobe = MicrofacetReflection(MicrofacetDistribution(kind, alpha, alpha), Fresnel("none"))
        local = self.directions @ frame
        f_cos = lobe.eval(local, np.broadcast_to(wo, local.shape))[:, 0] * np.maximum(local[:, 2], 0.0)
        return f_cos * self.omega, local

    def truth(self, weights) -> float:
        return float(np.sum(weights * self.radiance) / np.sum(weights))

    def read(self, kind: str, level_alpha: float, direction: np.ndarray) -> float:
        """One split-sum lookup: the two levels around split_sum_lod(level_alpha), blended."""
        lod = float(split_sum_lod(level_alpha, kind=kind))
        lower = min(int(np.floor(lod)), SPLIT_SUM_LEVELS - 1)
        upper = min(lower + 1, SPLIT_SUM_LEVELS - 1)
        cosines = self.directions @ direction
        value = 0.0
        for blend, level in ((1.0 - (lod - lower), lower), (lod - lower, upper)):
            if blend > 0.0:
                kernel = self.profile(kind, split_sum_alpha(level)).of_cosine(cosines) * self.omega
                value += blend * float(np.sum(kernel * self.radiance) / np.sum(kernel))
        return value

    def lookups(self, kind, alpha, wo, frame, in_plane: bool) -> float:
        """`prefiltered`'s lookups (split_sum_lookups): Beckmann's in-plane line or the symmetric one."""
        world, weights, level_alpha = pf.split_sum_lookups(wo, frame, kind, alpha, alpha, in_plane=in_plane)
        return sum(w * self.read(kind, level_alpha, d) for d, w in zip(world, weights, strict=True) if w > 0)

    def kernel_iqr(self, kind: str, alpha: float) -> float:
        """Interquartile range of the angle across a great circle through the kernel's centre."""
        key = (kind, round(alpha, 5))
        if key not in self._iqr:
            z = self.directions[:, 2]
            weights = self.profile(kind, alpha).of_cosine(z) * self.omega
            q1, q3 = weighted_quantiles(np.arcsin(np.clip(self.directions[:, 1], -1.0, 1.0)), weights, [0.25, 0.75])
            self._iqr[key] = float(q3 - q1)
        return self._iqr[key]

    def exact_in_plane(self, kind, alpha, wo, frame, lobe_weights, local) -> float:
        """The in-plane quantile line from this pixel's own quadrature (no table), for any kind."""
        along = float(np.hypot(wo[0], wo[1]))
        plane = np.array([wo[0], wo[1], 0.0]) / along if along > pf.MIN_OBLIQUE_XY else np.array([1.0, 0.0, 0.0])
        level_alpha = alpha * oblique_alpha_ratio(kind, alpha, wo[2])
        angle = np.arctan2(local @ plane, local[:, 2])
        quantiles = weighted_quantiles(angle, lobe_weights, np.concatenate([LINE_QUANTILES, [0.25, 0.5, 0.75]]))
        nodes, (q1, median, q3) = quantiles[:-3], quantiles[-3:]
        shrink = np.sqrt(max(1.0 - (self.kernel_iqr(kind, level_alpha) / max(q3 - q1, 1e-9)) ** 2, 0.0))
        theta = median + shrink * (nodes - median)
        directions = (np.sin(theta)[:, None] * plane + np.cos(theta)[:, None] * np.array([0.0, 0.0, 1.0])) @ frame.T
        weights = pf.split_sum_line_weights()
        return sum(w * self.read(kind, level_alpha, d) for d, w in zip(directions, weights, strict=True))


def case_errors(twin: SplitSumTwin, case: str, pixels: int) -> dict:
    """Relative RMSE of each way over the sphere's pixels (and the worst pixel's |ratio - 1|)."""
    from lobeview.bench import lobe_kernel

    kind, alpha = case.split(":")[0], float(case.split(":")[1])
    values: dict = {way: [] for way in ("truth", *WAYS)}
    for wo, frame in lobe_kernel.sphere_views(pixels):
        weights, local = twin.lobe_weights(kind, alpha, wo, frame)
        values["truth"].append(twin.truth(weights))
        values[WAYS[0]].append(twin.lookups(kind, alpha, wo, frame, in_plane=False))
        values[WAYS[1]].append(twin.lookups(kind, alpha, wo, frame, in_plane=True))
        values[WAYS[2]].append(twin.exact_in_plane(kind, alpha, wo, frame, weights, local))
    truth = np.asarray(values.pop("truth"))
    out = {}
    for way, estimate in values.items():
        estimate = np.asarray(estimate)
        rmse = float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth**2)))
        out[way] = (rmse, float(np.max(np.abs(estimate / truth - 1.0))))
    return out


def markdown(results: dict, args, command: str, stamp: str, seconds: float) -> str:
    lines = [
        f"# Split-sum's oblique line against the lobe, numpy ({stamp})",
        "",
        f"`{command}` ({seconds / 60:.1f} min)",
        "",
        f"Preview sphere at {args.pixels}^2 pixel centres (issue 45's camera), each map's texels at "
        f"{args.height} rows as the quadrature; relative RMSE % over the sphere against the exact "
        "lobe integral of the same map (bright sources already cap lights), worst pixel's "
        "|ratio - 1| % in brackets. bench/split_sum_line.py says what each way is.",
        "",
        "| map | case | " + " | ".join(WAYS) + " |",
        "|---|---|" + "---|" * len(WAYS),
    ]
    for (env, case), errors in results.items():
        cells = [f"{100 * e[0]:.2f} ({100 * e[1]:.0f})" for e in errors.values()]
        lines.append(f"| {env} | {case} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    from lobeview.bench.report import stamped_report_path

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=list(ENVS), help="sky or capture stems (../shared/assets/env)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), help="DIST:ALPHA, isotropic")
    parser.add_argument("--pixels", type=int, default=12, help="the sphere's pixel grid (default 12)")
    parser.add_argument("--height", type=int, default=256, help="rows of the maps' quadrature (default 256)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    start = time.perf_counter()
    results = {}
    for env in args.envs:
        twin = SplitSumTwin(*light_texels(env, args.height))
        for case in args.cases:
            results[(env, case)] = case_errors(twin, case, args.pixels)
            errors = ", ".join(f"{k} {100 * v[0]:.2f} %" for k, v in results[(env, case)].items())
            print(f"[split-sum line] {env} {case}: {errors}", flush=True)
    path, stamp, command = stamped_report_path(args.out, "split-sum-line", "split_sum_line", argv)
    path.write_text(markdown(results, args, command, stamp, time.perf_counter() - start))
    print(f"[split-sum line] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
