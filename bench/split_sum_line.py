"""Split-sum's lines against the lobe they stand for, in numpy (issues 45 and 39): the symmetric
line `prefiltered` reads for isotropic GGX seen off the normal (and read for Beckmann and for
anisotropic lobes before), the lobe's own quantile lines as built (Beckmann's in-plane table, an
anisotropic lobe's reweighted marginal), and those lines computed per pixel by quadrature.

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
  *symmetric line*: materials/prefilter.py split_sum_lookups(own_quantiles=False), the symmetric
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
and of an anisotropic lobe (a case DIST:AXxAY), along its wider axis at level alpha_min:
  *symmetric line*: the slope marginal's symmetric quantiles at scale sqrt(ax^2 - ay^2), leant at
    alpha_min (`prefiltered` before the 36th session);
  *prefiltered*: the marginal's nodes reweighted by the rest of f cos, as built
    (materials/split_sum_anisotropic.py anisotropic_line_slopes);
  *own quantiles, exact*: the quantiles of this pixel's lobe f cos over the half-vector slope
    along the wider axis, by quadrature, shrunk about the median by sqrt(1 - (a_min / a_max)^2).
On the sky each case also reports the 9 x 9 window around the sun's mirror pixel of
bench/mitsuba.py's 192 x 192 frame: the sum of the estimates over the sum of the truths (the sun
itself is a cap light, exact in every method; this is what the map adds there).

    .venv/bin/python -m lobeview.bench.split_sum_line [--envs sky interior courtyard]
        [--cases beckmann:0.3 ggx:0.3 ggx:0.05x0.3 ...] [--pixels 12] [--height 256]
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
WAYS = ("symmetric line", "prefiltered", "own quantiles, exact")
ANISOTROPIC_CASES = ("ggx:0.05x0.3", "ggx:0.3x0.05", "ggx:0.1x0.5", "ggx:0.02x0.2", "beckmann:0.05x0.3",
                     "beckmann:0.1x0.5")  # fmt: skip
WINDOW_SIZE = 192  # bench/mitsuba.py's frame, whose sun window issue 45 reads


def parse_case(case: str) -> tuple[str, float, float]:
    """DIST:ALPHA or DIST:AXxAY -> (kind, alpha_x, alpha_y)."""
    kind, alphas = case.split(":")
    ax, _, ay = alphas.partition("x")
    return kind, float(ax), float(ay or ax)


def light_texels(env: str, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(directions (k, 3), solid angles (k,), luminance-like radiance (k,): the mean of RGB) of the
    map a cube keeps under ``env``: the sunless sky, or a capture without its bright sources (what
    the prefiltered maps are made from: bright_sources.py Separation.without_sources) after they
    became cap lights, averaged down to ``height`` rows."""
    from lobeview.bench import lobe_kernel, mitsuba
    from lobeview.scenes.bright_sources import equirect_texels, separate_equirect

    if env == "sky":
        directions, omega, radiance = lobe_kernel.sky_quadrature(height)
        return directions.reshape(-1, 3), omega.reshape(-1), np.asarray(radiance).reshape(-1, 3).mean(axis=1)
    residual = separate_equirect(mitsuba.capture_image(env)).without_sources
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

    def lobe_weights(self, kind, ax, ay, wo, frame) -> tuple[np.ndarray, np.ndarray]:
        """The lobe's f cos times the texels' solid angles, and the texels in the pixel's frame."""
        from lobeview.materials.conductor import MicrofacetReflection
        from lobeview.materials.fresnel import Fresnel
        from lobeview.materials.microfacet import MicrofacetDistribution

        lobe = MicrofacetReflection(MicrofacetDistribution(kind, ax, ay), Fresnel("none"))
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

    def lookups(self, kind, ax, ay, wo, frame, own_quantiles: bool) -> float:
        """`prefiltered`'s lookups (split_sum_lookups): the lobe's own quantile line or the symmetric one."""
        world, weights, level_alpha = pf.split_sum_lookups(wo, frame, kind, ax, ay, own_quantiles=own_quantiles)
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

    def exact_in_plane(self, kind, alpha, _, wo, frame, lobe_weights, local) -> float:
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

    def exact_anisotropic(self, kind, ax, ay, wo, frame, lobe_weights, local) -> float:
        """An anisotropic lobe's line at the quantiles of its f cos over the half-vector slope
        along its wider axis, from this pixel's own quadrature, shrunk as anisotropic_line_slopes."""
        from lobeview.materials.split_sum_anisotropic import line_half_vectors, mirror_directions, wider_axis

        a_min, a_max = min(ax, ay), max(ax, ay)
        major = wider_axis(ax, ay)
        keep = lobe_weights > 0.0
        h = local[keep] + wo
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        slope = -(h[:, :2] @ major) / h[:, 2]
        quantiles = weighted_quantiles(slope, lobe_weights[keep], np.concatenate([LINE_QUANTILES, [0.5]]))
        nodes, median = quantiles[:-1], quantiles[-1]
        slopes = median + (nodes - median) * np.sqrt(1.0 - (a_min / a_max) ** 2)
        directions = mirror_directions(wo, line_half_vectors(slopes, major)) @ frame.T
        weights = pf.split_sum_line_weights()
        return sum(w * self.read(kind, a_min, d) for d, w in zip(directions, weights, strict=True))


def case_errors(twin: SplitSumTwin, case: str, pixels: int, window: bool) -> dict:
    """Relative RMSE of each way over the sphere's pixels (and the worst pixel's |ratio - 1|), and
    with ``window`` each way's 9 x 9 sun window ratio."""
    from lobeview.bench import lobe_kernel, mitsuba

    views = list(lobe_kernel.sphere_views(pixels))
    row, column = mitsuba.sun_pixel(WINDOW_SIZE)
    pixels_around = [(ix, iy) for iy in range(row - 4, row + 5) for ix in range(column - 4, column + 5)]
    window_views = [lobe_kernel.sphere_pixel_view(ix, iy, WINDOW_SIZE) for ix, iy in pixels_around] if window else []
    sphere, sun = (_estimates(twin, case, chosen) for chosen in (views, window_views))
    out = {}
    truth = sphere.pop("truth")
    for way, estimate in sphere.items():
        rmse = float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth**2)))
        sun_ratio = float(sun[way].sum() / sun["truth"].sum()) if window else None
        out[way] = (rmse, float(np.max(np.abs(estimate / truth - 1.0))), sun_ratio)
    return out


def _estimates(twin: SplitSumTwin, case: str, views) -> dict:
    """Each way's estimate and the truth at ``views`` (arrays)."""
    kind, ax, ay = parse_case(case)
    values: dict = {way: [] for way in ("truth", *WAYS)}
    for wo, frame in views:
        weights, local = twin.lobe_weights(kind, ax, ay, wo, frame)
        values["truth"].append(twin.truth(weights))
        values[WAYS[0]].append(twin.lookups(kind, ax, ay, wo, frame, own_quantiles=False))
        values[WAYS[1]].append(twin.lookups(kind, ax, ay, wo, frame, own_quantiles=True))
        exact = twin.exact_in_plane if ax == ay else twin.exact_anisotropic
        values[WAYS[2]].append(exact(kind, ax, ay, wo, frame, weights, local))
    return {way: np.asarray(v) for way, v in values.items()}


def markdown(results: dict, args, command: str, stamp: str, seconds: float) -> str:
    lines = [
        f"# Split-sum's lines against the lobe, numpy ({stamp})",
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
    windows = [(key, errors) for key, errors in results.items() if next(iter(errors.values()))[2] is not None]
    if windows:
        lines += ["", "The sun's 9 x 9 window (sky only; estimate / truth summed over its 81 pixels):", "",
                  "| map | case | " + " | ".join(WAYS) + " |", "|---|---|" + "---|" * len(WAYS)]  # fmt: skip
        for (env, case), errors in windows:
            lines.append(f"| {env} | {case} | " + " | ".join(f"{e[2]:.3f}" for e in errors.values()) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    from lobeview.bench.report import stamped_report_path

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=list(ENVS), help="sky or capture stems (../shared/assets/env)")
    parser.add_argument(
        "--cases", nargs="+", default=[*CASES, *ANISOTROPIC_CASES],
        help="DIST:ALPHA or DIST:AXxAY (default: the isotropic cases and ANISOTROPIC_CASES)",
    )  # fmt: skip
    parser.add_argument("--pixels", type=int, default=12, help="the sphere's pixel grid (default 12)")
    parser.add_argument("--height", type=int, default=256, help="rows of the maps' quadrature (default 256)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    start = time.perf_counter()
    results = {}
    for env in args.envs:
        twin = SplitSumTwin(*light_texels(env, args.height))
        for case in args.cases:
            results[(env, case)] = case_errors(twin, case, args.pixels, window=env == "sky")
            errors = ", ".join(f"{k} {100 * v[0]:.2f} %" for k, v in results[(env, case)].items())
            print(f"[split-sum line] {env} {case}: {errors}", flush=True)
    path, stamp, command = stamped_report_path(args.out, "split-sum-line", "split_sum_line", argv)
    path.write_text(markdown(results, args, command, stamp, time.perf_counter() - start))
    print(f"[split-sum line] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
