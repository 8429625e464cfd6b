"""lobe-N's effective kernel against its lobe (issue 45: where lobe-7's error against Mitsuba lives).

lobe-N+norm is linear in its lookups: its result is sum_j w_j L_j, each L_j a read of the cube's
MIP chain at level lod_j, i.e. the environment blurred around direction d_j. So the method is
one kernel, K_eff = sum_j w_j G_j, against the lobe's f cos; how far apart the two are bounds the
error on any environment. This module finds the weights w_j by linearity
(:func:`lookup_weights`), models each read as a Gaussian (its sigma measured on the GPU by
:func:`measure_mip_kernel_sigma`) and reports, per lobe and view angle:

- the kernel's relative L2 and L1 distance to f cos over the sphere of directions;
- with ``--floor``, lobe-N with *ideal* Gaussian reads against exact quadrature on issue 45's sky
  without its sun (the sky and its six rectangles, bench/mitsuba.py): what a perfect MIP chain would
  leave. 2026-11-29 (sky, 32 x 32 pixels of the preview sphere, lobe-7+norm): GGX 0.3 7.2 %,
  Beckmann 0.15 4.0 %, Beckmann 0.5 6.9 %, against 8.1 / 5.7 / 9.0 % for the GPU against Mitsuba:
  the MIP chain is not what keeps lobe-7 above issue 45's 5 %; the pattern's kernel is
  (docs/measurements.md "lobe-7's kernel"). The fitted pattern's reads, the same way: 1.0 / 1.5 /
  1.1 %.

The model of one read (materials/fitted_pattern.py read_sigma_texels): the tent chain
(viewer/mip_chain.py) filters each level from the one above with [1 3 3 1] / 8 (3/4 of a source
texel^2), which sums to 1/4 (4^L - 1) base texels^2 at level L; the bilinear read adds a tent of one
level-L texel (4^L / 6); a trilinear read between two levels blends their variances. Each base texel
is (2 / face_size) max|d|^1.5 radians wide (the solid angle of a texel is (2 / face_size)^2 max|d|^3,
cube_map_lod). :func:`measure_mip_kernel_sigma` measures it on the GPU.

    .venv/bin/python -m lobeview.bench.lobe_kernel [--cases ggx:0.3 beckmann:0.15] [--n 7] [--floor]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from lobeview.bench.report import stamped_report_path
from lobeview.materials import blur_stack, fitted_pattern, patterns
from lobeview.materials.microfacet import MicrofacetDistribution

FACE_SIZE = 256
VIEWS_DEG = (0.0, 30.0, 50.0, 70.0, 80.0)
CASES = ("ggx:0.05", "ggx:0.15", "ggx:0.3", "ggx:0.5", "beckmann:0.15", "beckmann:0.5")
GRID_HEIGHT = 256  # the direction grid of the kernel distances (equirectangular about +z)
FLOOR_ENV_HEIGHT = 128  # the sky's quadrature grid of the floor (4 x 4 points per texel)
FLOOR_PIXELS = 32  # the preview sphere's pixel grid of the floor
# The floor's sky grid has 1.4 degree texels: narrower lobes (and their reads, finer than a texel)
# are not resolved by it, so the floor is left out below this alpha = sqrt(alpha_x alpha_y).
FLOOR_MIN_ALPHA = 0.1


def lobe_of(case: str):
    """The specular lobe of a bench.mitsuba case ('ggx:0.3', 'beckmann:0.05x0.3')."""
    from lobeview.bench.mitsuba import material
    from lobeview.materials.spec import build_bsdf, validate

    return patterns.specular_lobes(build_bsdf(validate(material(case))))[0]


def lookup_weights(lobe, wo: np.ndarray, n: int, table, face_size: int = FACE_SIZE, frame=None):
    """lobe-N+norm's lookups at view ``wo`` (local) as (weights (m,), world directions (m, 3),
    MIP levels (m,)) with result = sum_j weights_j L_j (red channel; the lobes here are grey), found
    by linearity: one pass records the reads, one more per read returns 1 there and 0 elsewhere."""
    reads = []

    def record(world, lod):
        reads.append((np.array(world, dtype=np.float64), np.array(lod, dtype=np.float64)))
        return np.zeros((len(world), 3))

    patterns.integrate_lobe(lobe, wo, record, n, face_size, frame, albedo_table=table)
    weights, directions, lods = [], [], []
    for call, (world, lod) in enumerate(reads):
        for j in range(len(world)):
            unit = _unit_reads(call, j)
            weights.append(patterns.integrate_lobe(lobe, wo, unit, n, face_size, frame, albedo_table=table)[0])
            directions.append(world[j])
            lods.append(lod[j])
    return np.array(weights), np.array(directions).reshape(-1, 3), np.array(lods)


def _unit_reads(call: int, index: int):
    """A radiance function that returns 1 for read ``index`` of its ``call``-th call, 0 elsewhere."""
    seen = [-1]

    def reads(dirs, levels):
        seen[0] += 1
        out = np.zeros((len(dirs), 3))
        if seen[0] == call:
            out[index] = 1.0
        return out

    return reads


def lookup_sigmas(directions: np.ndarray, lods: np.ndarray, face_size: int = FACE_SIZE) -> np.ndarray:
    """The angular standard deviation (rad) of each read's blur (the module's model, kept with the
    fitted patterns that choose levels by it: materials/fitted_pattern.py read_sigma_texels)."""
    return fitted_pattern.read_sigma_texels(lods) * fitted_pattern.texel_angle(directions, face_size)


def direction_grid(height: int = GRID_HEIGHT) -> tuple[np.ndarray, np.ndarray]:
    """Texel-centre directions (height * 2 height, 3) of an equirectangular grid about +z and their
    solid angles."""
    v, u = np.meshgrid((np.arange(height) + 0.5) / height, (np.arange(2 * height) + 0.5) / (2 * height), indexing="ij")
    theta, phi = np.pi * v, 2.0 * np.pi * u
    dirs = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    return dirs.reshape(-1, 3), (np.sin(theta) * (np.pi / height) ** 2).reshape(-1)


def gaussian_kernel(grid: np.ndarray, solid_angles: np.ndarray, axis: np.ndarray, sigma: float) -> np.ndarray:
    """A spherical Gaussian exp((cos - 1) / sigma^2) about ``axis``, normalised to integrate to 1
    on the grid (for small sigma a Gaussian of standard deviation sigma per tangent axis)."""
    kernel = np.exp(np.minimum((grid @ axis - 1.0) / max(sigma * sigma, 1e-12), 0.0))
    return kernel / np.sum(kernel * solid_angles)


def effective_kernel(weights, directions, sigmas, grid, solid_angles) -> np.ndarray:
    kernel = np.zeros(len(grid))
    for weight, axis, sigma in zip(weights, directions, sigmas, strict=True):
        kernel += weight * gaussian_kernel(grid, solid_angles, axis, sigma)
    return kernel


def kernel_distances(lobe, view_deg: float, n: int, table, grid, solid_angles, face_size: int = FACE_SIZE):
    """(relative L2, relative L1) distance between lobe-N+norm's kernel and f cos at a view
    ``view_deg`` from the normal (local frame, the identity as world frame)."""
    t = np.radians(view_deg)
    wo = np.array([np.sin(t), 0.0, np.cos(t)])
    above = grid[:, 2] > 0.0
    truth = np.zeros(len(grid))
    truth[above] = lobe.eval(grid[above], np.broadcast_to(wo, (int(above.sum()), 3)))[:, 0] * grid[above, 2]
    weights, directions, lods = lookup_weights(lobe, wo, n, table, face_size)
    kernel = effective_kernel(weights, directions, lookup_sigmas(directions, lods, face_size), grid, solid_angles)
    l2 = np.sqrt(np.sum((kernel - truth) ** 2 * solid_angles) / np.sum(truth**2 * solid_angles))
    l1 = np.sum(np.abs(kernel - truth) * solid_angles) / np.sum(truth * solid_angles)
    return float(l2), float(l1)


def fitted_kernel_distance(kind: str, alpha: float, view_deg: float, table) -> float:
    """The fitted pattern's relative L2 distance at a view, its reads interpolated from ``table``
    (so between nodes as the estimator reads them)."""
    distribution = MicrofacetDistribution(kind, alpha, alpha)
    target = fitted_pattern.lobe_target(distribution, float(np.cos(np.radians(view_deg))))
    a, b, weight, sigma = fitted_pattern.table_reads(table, alpha, float(np.cos(np.radians(view_deg))))
    return fitted_pattern.kernel_distance(fitted_pattern.FittedPattern(a, b, weight, sigma, 0.0), target)


def sunless_sky(directions: np.ndarray) -> np.ndarray:
    """Issue 45's sky (bench/mitsuba.py environment) without its sun: the part a cube map keeps."""
    from lobeview.bench import mitsuba

    sun = mitsuba.SUN_RADIANCE
    try:
        mitsuba.SUN_RADIANCE = 0.0
        return mitsuba.environment(directions)
    finally:
        mitsuba.SUN_RADIANCE = sun


def sky_quadrature(height: int = FLOOR_ENV_HEIGHT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel-centre directions (+y up, bench/mitsuba.py's convention), solid angles and the sunless
    sky's radiance averaged over 4 x 4 points per texel (the rectangles have sharp edges)."""
    rows, cols = np.arange(height), np.arange(2 * height)
    radiance = np.zeros((height, 2 * height, 3))
    for a in range(4):
        for b in range(4):
            theta = np.pi * (rows[:, None] + (a + 0.5) / 4) / height + 0.0 * cols[None, :]
            phi = 2.0 * np.pi * (cols[None, :] + (b + 0.5) / 4) / (2 * height) + 0.0 * rows[:, None]
            d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
            radiance += sunless_sky(d) / 16.0
    theta = np.pi * (rows + 0.5) / height
    phi = 2.0 * np.pi * (cols + 0.5) / (2 * height)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.sin(p), np.cos(t), -np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    solid = (np.sin(t) * (np.pi / height) * (np.pi / height)).reshape(-1)
    return dirs, solid, radiance.reshape(-1, 3)


def sphere_pixel_view(ix: int, iy: int, size: int):
    """(wo local, frame) of pixel (ix, iy)'s centre of the preview sphere at ``size`` x ``size``
    pixels seen by bench/mitsuba.py's camera (at +4 z, fov 40), the frame's tangent horizontal;
    None off the sphere or where the tangent is undefined."""
    half = np.tan(np.radians(20.0))
    eye = np.array([0.0, 0.0, 4.0])
    ray = np.array([((ix + 0.5) / size * 2 - 1) * half, (1 - (iy + 0.5) / size * 2) * half, -1.0])
    ray /= np.linalg.norm(ray)
    b = eye @ ray
    disc = b * b - (eye @ eye - 1.0)
    if disc <= 0.0:
        return None
    normal = eye - (b + np.sqrt(disc)) * ray
    normal /= np.linalg.norm(normal)
    tangent = np.cross([0.0, 1.0, 0.0], normal)
    if np.linalg.norm(tangent) < 1e-6:
        return None
    tangent /= np.linalg.norm(tangent)
    frame = np.stack([tangent, np.cross(normal, tangent), normal], axis=1)
    return frame.T @ -ray, frame


def sphere_views(pixels: int = FLOOR_PIXELS):
    """(wo local, frame) of the preview sphere's pixel centres (:func:`sphere_pixel_view`) on a
    ``pixels`` x ``pixels`` grid; grazing views (wo.z < 0.02) left out."""
    for iy in range(pixels):
        for ix in range(pixels):
            view = sphere_pixel_view(ix, iy, pixels)
            if view is not None and view[0][2] >= 0.02:
                yield view


def ideal_floor(lobe, n: int, pixels: int = FLOOR_PIXELS, sigma_scale: float = 1.0, fitted=None) -> float:
    """Relative RMSE (fraction) of lobe-N+norm with ideal Gaussian reads (the module's sigmas times
    ``sigma_scale``) against exact quadrature of the sunless sky, over the preview sphere's pixels;
    with ``fitted`` (a materials/fitted_pattern.py PatternTable) the fitted pattern's reads."""
    dirs, solid, radiance = sky_quadrature()
    table = patterns.AlbedoTable.build(lobe)

    def gaussian_reads(world, lod):
        return blur_stack.vmf_blur(
            world, np.maximum(sigma_scale * lookup_sigmas(world, lod), 1e-6), dirs, solid, radiance
        )

    truth, estimate = [], []
    for wo, frame in sphere_views(pixels):
        local = dirs @ frame
        above = local[:, 2] > 0.0
        f = lobe.eval(local[above], np.broadcast_to(wo, (int(above.sum()), 3)))
        truth.append(np.sum(f * (local[above, 2] * solid[above])[:, None] * radiance[above], axis=0))
        if fitted is None:
            estimate.append(patterns.integrate_lobe(lobe, wo, gaussian_reads, n, FACE_SIZE, frame, albedo_table=table))
        else:
            estimate.append(fitted_pattern.integrate_fitted(lobe, wo, gaussian_reads, fitted, FACE_SIZE, frame, table))
    truth, estimate = np.array(truth), np.array(estimate)
    return float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth**2)))


def measure_mip_kernel_sigma(ctx, levels=(2, 3, 4), face_size: int = FACE_SIZE) -> dict[int, float]:
    """The standard deviation, in level-L texels along one axis, of what reading level L of the tent
    chain returns around a point source: a 2 x 2 block of texels at the centre of face +z (its own
    variance, 1/4 base texel^2, taken out), read on a fine grid of directions through the driver's
    filtering (viewer/gl_probes.py CubeLookup)."""
    from lobeview.viewer.gl_probes import CubeLookup
    from lobeview.viewer.mip_chain import upload_cube

    faces = np.zeros((6, face_size, face_size, 3), np.float32)
    centre = face_size // 2
    faces[4, centre - 1 : centre + 1, centre - 1 : centre + 1] = 1.0  # +z is face 4 (GL order)
    cube = upload_cube(ctx, faces, mipmaps=True, mip_filter="tent")
    lookup = CubeLookup(ctx)
    out = {}
    try:
        for level in levels:
            reach = 6.0 * 2**level  # base texels either side
            x = (np.arange(-reach, reach, 0.25) + 0.125) * 2.0 / face_size  # face coordinates at z = 1
            gx, gy = np.meshgrid(x, x)
            dirs = np.stack([gx, gy, np.ones_like(gx)], axis=-1).reshape(-1, 3)
            response = lookup(cube, dirs / np.linalg.norm(dirs, axis=-1, keepdims=True), float(level))[:, 0]
            texels = gx.reshape(-1) * face_size / 2.0
            variance = np.sum(response * texels**2) / np.sum(response) - 0.25
            out[level] = float(np.sqrt(max(variance, 0.0)) / 2**level)
    finally:
        cube.release()
    return out


FITTED_NOTE = "N reads for Beckmann, N + 4 for GGX: lobe-N+norm's budget with its tail term"


def fitted_table_for(lobe, n: int):
    """The committed fitted table of an isotropic lobe's distribution at lobe-N, or None."""
    dist = lobe.distribution
    if dist.alpha_x != dist.alpha_y:
        return None
    try:
        return fitted_pattern.load_table(dist.kind, fitted_pattern.read_count(dist.kind, n))
    except (OSError, KeyError, ValueError):
        return None


def markdown(rows, n: int, stamp: str, command: str, floors=None, fitted_rows=None) -> str:
    lines = [f"# lobe-{n}+norm's kernel against its lobe ({stamp})", "", f"`{command}`", "",
             "Relative L2 / L1 distance between sum_j w_j G_j (each read a Gaussian of the trilinear read's "
             f"sigma, fitted_pattern.read_sigma_texels; cube faces {FACE_SIZE}^2) and f cos, by view angle from the "
             "normal (bench/lobe_kernel.py).", "",
             "| case | " + " | ".join(f"{v:g} deg" for v in VIEWS_DEG) + " |",
             "|---|" + "---|" * len(VIEWS_DEG)]  # fmt: skip
    for case, cells in rows:
        lines.append(f"| {case} | " + " | ".join(f"{l2:.3f} / {l1:.3f}" for l2, l1 in cells) + " |")
    if fitted_rows:
        lines += ["", f"The fitted pattern (materials/fitted_pattern.py, {FITTED_NOTE}): relative L2 distance, "
                  "its reads interpolated from the committed table at each view:", "",
                  "| case | " + " | ".join(f"{v:g} deg" for v in VIEWS_DEG) + " |",
                  "|---|" + "---|" * len(VIEWS_DEG)]  # fmt: skip
        for case, cells in fitted_rows:
            lines.append(f"| {case} | " + " | ".join(f"{l2:.3f}" for l2 in cells) + " |")
    if floors:
        lines += ["", f"lobe-{n}+norm with ideal Gaussian reads against exact quadrature, issue 45's sky without its "
                  f"sun, {FLOOR_PIXELS}^2 pixels of the preview sphere (relative RMSE %):", "",
                  "| case | thesis pattern | fitted pattern |", "|---|---|---|"]  # fmt: skip
        lines += [f"| {case} | {100 * floor:.1f} | " + ("-" if fitted is None else f"{100 * fitted:.1f}") + " |"
                  for case, floor, fitted in floors]  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), help="DIST:ALPHA (bench.mitsuba's cases)")
    parser.add_argument("--n", type=int, default=7, help="lobe-N's sample count (default 7)")
    parser.add_argument("--floor", action="store_true", help="also lobe-N with ideal reads on the sunless sky")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    lobes = {case: lobe_of(case) for case in args.cases}  # a bad case stops here
    grid, solid_angles = direction_grid()
    rows, floors, fitted_rows = [], [], []
    for case, lobe in lobes.items():
        table = patterns.AlbedoTable.build(lobe)
        cells = [kernel_distances(lobe, view, args.n, table, grid, solid_angles) for view in VIEWS_DEG]
        rows.append((case, cells))
        by_view = ", ".join(f"{v:g} deg {l2:.3f}" for v, (l2, _) in zip(VIEWS_DEG, cells, strict=True))
        print(f"[lobe kernel] {case}: {by_view}")
        fitted = fitted_table_for(lobe, args.n)
        if fitted is not None:
            dist = lobe.distribution
            fitted_cells = [fitted_kernel_distance(dist.kind, dist.alpha_x, view, fitted) for view in VIEWS_DEG]
            fitted_rows.append((case, fitted_cells))
            print(f"[lobe kernel] {case} fitted: " + ", ".join(f"{l2:.3f}" for l2 in fitted_cells))
        if args.floor and np.sqrt(lobe.distribution.alpha_x * lobe.distribution.alpha_y) >= FLOOR_MIN_ALPHA:
            thesis_floor = ideal_floor(lobe, args.n)
            fitted_floor = None if fitted is None else ideal_floor(lobe, args.n, fitted=fitted)
            floors.append((case, thesis_floor, fitted_floor))
            print(f"[lobe kernel] {case}: ideal-read floor {100 * thesis_floor:.1f} % (thesis pattern)"
                  + ("" if fitted_floor is None else f", {100 * fitted_floor:.1f} % (fitted)"))  # fmt: skip
    path, stamp, command = stamped_report_path(args.out, "lobe-kernel", "lobe_kernel", argv)
    path.write_text(markdown(rows, args.n, stamp, command, floors, fitted_rows))
    print(f"[lobe kernel] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
