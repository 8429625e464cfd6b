"""lobeview's preview sphere against Mitsuba 3 (issue 45: an independent renderer's table, rerun
after every change to a method).

The scene: a unit sphere at the origin, camera at (0, 0, 4) looking at it (up +y, vertical field
of view 40 degrees), a square frame with a box pixel filter; light from an analytic environment:
a smooth sky, a 3-degree sun of radiance 50 and six saturated rectangles of radiance 3-5 around
the horizon (:func:`environment`). The material is a perfect microfacet reflector (no Fresnel:
lobeview's ``"fresnel": {"type": "none"}``, Mitsuba's roughconductor with ``material: none``),
GGX or Beckmann, isotropic or anisotropic. Both renderers sample the same function at the texel
centres of their own equirectangular convention: lobeview's u = 0.5 faces -z
(core/cube_layout.py), Mitsuba's envmap has u = atan2(x, -z) / 2 pi, i.e. u = 0 faces -z; the
first column of the table (lobeview's converged ``reference`` against Mitsuba) verifies the
conventions: a mirrored or turned environment shows as tens of percent there.

Error: relative RMSE over the sphere's pixels against Mitsuba (its own noise at the default 8192
samples per pixel is about 1 %, 2.5 % at 2048: the reference column's floor), and the ratio at
the sun's mirror pixel and its 9 x 9 neighbourhood. The one model difference, the Smith term
(Mitsuba 3's separable G1 G1, lobeview's height-correlated G2: up to 9 % at the rim of GGX 0.5),
is taken out in a third table: Mitsuba's image times their per-pixel ratio under the same
environment (bench/smith_model.py), compared over the sphere's interior. Mitsuba's images are cached (the lobeview
cache folder, keyed by the scene, samples and Mitsuba's version): a rerun after a change to a
method renders only lobeview.

    pip install mitsuba==3.9.1   # not a lobeview dependency; the scalar_rgb variant is used
    .venv/bin/python -m lobeview.bench.mitsuba [--size 192] [--spp 8192] [--supersample 4] [--bright-sources]
                                               [--cases ggx:0.5 ...] [--env sky|studio|CAPTURE] [--no-cache]

``--env studio`` replaces the sky by builtin:studio (soft boxes whose radiance falls to their rims:
the soft-edged cap lights of scenes/bright_sources.py); the sun's pixel ratios are then not made.
``--env courtyard`` (any capture of ../shared/assets/env by stem, or an .exr / .hdr path): a real
HDR capture, read once (scenes/hdrio.py sanitises it) and given to both renderers texel for texel,
Mitsuba's copy rolled by half its width (:func:`capture_image`).
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
import warnings
from pathlib import Path

import numpy as np

CASES = ("ggx:0.05", "ggx:0.15", "ggx:0.3", "ggx:0.5", "ggx:1.0", "beckmann:0.15", "beckmann:0.5", "beckmann:0.8",
         "ggx:0.05x0.3")  # fmt: skip
METHODS = ("lobe-7+norm", "lobe-15+norm", "fis-40", "prefiltered", "prefiltered-rsibr")
ENV_HEIGHT = 512
CAMERA = ((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0)
SUN_DIRECTION = np.array([0.4, 0.6, 0.69]) / np.linalg.norm([0.4, 0.6, 0.69])
SUN_RADIANCE = 50.0
RECTANGLES = ((4, 0.3, 0.3), (0.3, 4, 0.3), (0.3, 0.3, 5), (3, 3, 0.3), (0.3, 3, 3), (3, 0.3, 3))


ENVIRONMENTS = ("sky", "studio")  # analytic; any other --env names an HDR capture (capture_path)


def is_capture(env: str) -> bool:
    return env not in ENVIRONMENTS


def capture_path(env: str) -> Path:
    """The HDR file of ``--env``: a stem of ../shared/assets/env (bench/light.py's views) or a path."""
    from lobeview.bench.captures import environment_files

    return environment_files([env])[0]


def capture_image(env: str) -> np.ndarray:
    """lobeview's equirectangular image of a capture (H, 2H, 3), sanitised as the viewer reads it."""
    from lobeview.scenes.envmap import EnvironmentMap

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sanitising warnings are the viewer's to show
        return np.asarray(EnvironmentMap.load(capture_path(env)).image, dtype=np.float32)


def environment(d: np.ndarray, name: str = "sky") -> np.ndarray:
    """Radiance (..., 3) of the test environment in directions ``d`` (..., 3), +y up: issue 45's
    sky, or ``studio``: builtin:studio (scenes/builtin_env.py: soft boxes 11-16 degrees wide, whose
    radiance falls to their rims; the case of the soft-edged cap lights)."""
    if name == "studio":
        from lobeview.scenes.builtin_env import studio

        return studio(d)
    if name != "sky":
        raise ValueError(f"unknown environment {name!r}; use one of {ENVIRONMENTS}")
    up = d[..., 1:2]
    sky = np.where(up > 0, np.array([0.35, 0.5, 0.8]) * (0.5 + 0.5 * up), np.array([0.3, 0.25, 0.2]) * (0.6 + 0.4 * up))
    sun = (np.sum(d * SUN_DIRECTION, -1) > np.cos(np.radians(1.5)))[..., None] * SUN_RADIANCE
    out = sky + sun
    azimuth, elevation = np.arctan2(d[..., 0], d[..., 2]), np.arcsin(np.clip(d[..., 1], -1.0, 1.0))
    for k, colour in enumerate(RECTANGLES):
        start = -np.pi + k * np.pi / 3 + 0.3
        inside = (azimuth > start) & (azimuth < start + 0.45) & (elevation > 0.05) & (elevation < 0.45)
        out = np.where(inside[..., None], np.array(colour, dtype=np.float64), out)
    return out


def mitsuba_equirect(height: int, env: str = "sky") -> np.ndarray:
    """The environment as Mitsuba's envmap reads it: (height, 2 height, 3), texel centres, u = 0
    facing -z (lobeview's map rolled by half its width). A capture keeps its own resolution."""
    if is_capture(env):
        image = capture_image(env)
        return np.roll(image, -(image.shape[1] // 2), axis=1)
    v, u = np.meshgrid((np.arange(height) + 0.5) / height, (np.arange(2 * height) + 0.5) / (2 * height), indexing="ij")
    theta, phi = np.pi * v, 2.0 * np.pi * u
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
    return environment(d, env).astype(np.float32)


def parse_case(text: str) -> tuple[str, float, float]:
    """'ggx:0.3' or 'ggx:0.05x0.3' -> (distribution, alpha_u, alpha_v)."""
    distribution, _, alphas = text.partition(":")
    if distribution not in ("ggx", "beckmann") or not alphas:
        raise ValueError(f"case {text!r}: expected ggx:ALPHA, beckmann:ALPHA or DIST:AUxAV")
    au, _, av = alphas.partition("x")
    return distribution, float(au), float(av or au)


def material(case: str) -> dict:
    distribution, au, av = parse_case(case)
    return {"model": "microfacet", "distribution": distribution, "alpha_u": au, "alpha_v": av,
            "fresnel": {"type": "none"}, "scale": 1.0}  # fmt: skip


def perspective_sensor(mi, camera, size: int, spp: int) -> dict:
    """Mitsuba's sensor for lobeview's ``camera`` (eye, target, up, vertical field of view in
    degrees): a square film of ``size`` pixels with a box filter, ``spp`` independent samples."""
    position, target, up, fov = camera
    return {
        "type": "perspective", "fov": fov, "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(position), target=list(target), up=list(up)),
        "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": spp},
    }  # fmt: skip


def render_mitsuba(case: str, size: int, spp: int, envmap_file: Path) -> np.ndarray:
    try:
        import mitsuba as mi
    except ImportError:
        raise SystemExit("bench.mitsuba needs Mitsuba 3: pip install mitsuba==3.9.1") from None
    mi.set_variant("scalar_rgb")  # llvm_ad_rgb's JIT fails on Debian 12's LLVM 15 (fminimum)
    distribution, au, av = parse_case(case)
    bsdf = {"type": "roughconductor", "distribution": distribution, "material": "none"}
    bsdf.update({"alpha": au} if au == av else {"alpha_u": au, "alpha_v": av})
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},  # the sphere is convex: one bounce
        "sensor": perspective_sensor(mi, CAMERA, size, spp),
        "env": {"type": "envmap", "filename": str(envmap_file)},
        # Pole along +y, as lobeview's uv_sphere: the tangent (anisotropy) frames then agree.
        "sphere": {"type": "sphere", "radius": 1.0, "bsdf": bsdf,
                   "to_world": mi.ScalarTransform4f().rotate(axis=[1, 0, 0], angle=-90)},
    })  # fmt: skip
    return np.array(mi.render(scene), dtype=np.float32)


def mitsuba_key(case: str, size: int, spp: int, version: str, env: str = "sky") -> str:
    """What a Mitsuba render of a case depends on: the case, frame, samples, Mitsuba's version
    and this module's scene (environment, camera, light), hashed for the cache file name."""
    import hashlib

    scene = repr((case, size, spp, version, ENV_HEIGHT, CAMERA, SUN_DIRECTION.tolist(), SUN_RADIANCE, RECTANGLES))
    if env != "sky":  # the sky's keys stay those of the caches written before the option
        scene += repr(env)
    return hashlib.sha1(scene.encode() + mitsuba_equirect(64, env).tobytes()).hexdigest()[:16]


def cached_mitsuba(
    case: str, size: int, spp: int, work: Path, cache: Path | None, version: str, env: str = "sky"
) -> tuple:
    """Mitsuba's image of a case and the seconds it took, read from ``cache`` (a folder, None:
    no cache) when an earlier run rendered the same scene: the path tracer takes minutes per
    case, the lobeview methods seconds, and the table is meant to be rerun after every change to
    a method."""
    from lobeview.core.cache import read_cache_file, write_cache_file

    path = cache / f"mitsuba-{mitsuba_key(case, size, spp, version, env)}.npz" if cache else None

    def read(file: Path):
        with np.load(file) as data:
            image, seconds = data["image"], float(data["seconds"])
        if image.shape != (size, size, 3) or not np.all(np.isfinite(image)):
            raise ValueError(f"image of shape {image.shape}, expected {(size, size, 3)}")
        return image, seconds

    found = read_cache_file(path, read, "Mitsuba render")
    if found is not None:
        return found
    t0 = time.perf_counter()
    image = render_mitsuba(case, size, spp, work / "environment.exr")
    seconds = time.perf_counter() - t0
    if path is not None:
        write_cache_file(path, lambda handle: np.savez(handle, image=image, seconds=seconds))
    return image, seconds


def sun_mirror_normal() -> np.ndarray:
    """The unit sphere's normal (= its point) that mirrors the sun to the camera: it halves the
    angle between the sun and the direction to the camera (fixed point)."""
    position = np.array(CAMERA[0])
    normal = np.array([0.0, 0.0, 1.0])
    for _ in range(64):
        view = (position - normal) / np.linalg.norm(position - normal)
        normal = (view + SUN_DIRECTION) / np.linalg.norm(view + SUN_DIRECTION)
    return normal


def sun_pixel(size: int) -> tuple[int, int]:
    """(row, column) of the pixel where the sphere mirrors the sun to the camera
    (:func:`sun_mirror_normal`)."""
    position = np.array(CAMERA[0])
    normal = sun_mirror_normal()
    focal = 0.5 * size / np.tan(np.radians(0.5 * CAMERA[3]))
    depth = position[2] - normal[2]
    return int(0.5 * size - focal * normal[1] / depth), int(0.5 * size + focal * normal[0] / depth)


def sun_ratios(image: np.ndarray, truth: np.ndarray, size: int) -> tuple[float, float]:
    """The sun's mirror pixel and the 9 x 9 pixels around it, mean over colours, against Mitsuba
    (issue 45: a hole or a halo there is what a plain RMSE over the sphere hides)."""
    row, column = sun_pixel(size)
    window = slice(row - 4, row + 5), slice(column - 4, column + 5)
    return float(image[row, column].mean() / truth[row, column].mean()), float(
        image[window].mean() / truth[window].mean()
    )


def relative_rmse(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    d = image[mask] - reference[mask]
    return float(np.sqrt(np.mean(d**2)) / max(np.sqrt(np.mean(reference[mask] ** 2)), 1e-12))


def run(
    cases,
    methods,
    size: int,
    spp: int,
    work: Path,
    progress=print,
    cache: Path | None = None,
    bright_sources=False,
    supersample: int = 1,
    lod_bias: float | None = None,
    env_name: str = "sky",
) -> dict:
    """``supersample``: the real-time methods render at that many times the size and are averaged
    down (issue 45's protocol: 768 x 768 averaged to 192 x 192), so that they and the two
    box-filtered references integrate the same pixel footprints; 1 shades the pixel centres
    (a sharp reflection's edges then count as the method's error). ``lod_bias``: the real-time
    methods' MIP level bias (None: each method's default; lobe-N's wide lobes add their levels
    on top, materials/patterns.py wide_lobe_footprint_scale)."""
    from lobeview.bench.smith_model import smith_matched
    from lobeview.materials.microfacet import MicrofacetDistribution
    from lobeview.materials.spec import build_bsdf, validate
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PreviewRenderer

    try:
        import mitsuba as mi

        mi.set_variant("scalar_rgb")
        mi.Bitmap(mitsuba_equirect(ENV_HEIGHT, env_name)).write(str(work / "environment.exr"))
        mitsuba_version = mi.__version__
    except ImportError:
        raise SystemExit("bench.mitsuba needs Mitsuba 3: pip install mitsuba==3.9.1") from None
    ctx = create_headless_context()
    if is_capture(env_name):
        env = EnvironmentMap(capture_image(env_name), str(capture_path(env_name)))
    else:
        name = "issue 45 sky" if env_name == "sky" else env_name
        env = EnvironmentMap.from_function(lambda d: environment(d, env_name), height=ENV_HEIGHT, name=name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = PreviewRenderer(
            ctx, env, uv_sphere(1.0), size=(size, size), face_size=256, bright_sources=bright_sources
        )
        fine = size * supersample
        fine_renderer = (
            renderer
            if supersample == 1
            else PreviewRenderer(
                ctx, env, uv_sphere(1.0), size=(fine, fine), face_size=256, bright_sources=bright_sources
            )
        )
    camera = Camera(*CAMERA)
    rows = []
    for case in cases:
        truth, mitsuba_seconds = cached_mitsuba(case, size, spp, work, cache, mitsuba_version, env_name)
        bsdf = build_bsdf(validate(material(case)))
        reference = renderer.render(camera, bsdf, "reference", spp=spp)
        row = {"case": case, "mitsuba seconds": round(mitsuba_seconds, 1),
               "reference": relative_rmse(reference.radiance, truth, reference.mask)}  # fmt: skip
        # Mitsuba's image with lobeview's Smith term (bench/smith_model.py; isotropic lobes), over
        # the sphere's interior: the two renderers without their model difference
        distribution, alpha_u, alpha_v = parse_case(case)
        matched = None
        if alpha_u == alpha_v:
            matched, interior = smith_matched(
                truth, env, MicrofacetDistribution(distribution, alpha_u, alpha_v), CAMERA, reference.mask
            )
            row["smith matched"] = {"reference": relative_rmse(reference.radiance, matched, interior)}
        # Each method against lobeview's own reference too: without the two renderers' model
        # difference (the reference column), which can reorder methods a few tenths apart.
        row["against reference"] = {}
        if env_name == "sky":  # the other environments have no sun
            row["sun"] = {"reference": sun_ratios(reference.radiance, truth, size)}
        for method in methods:
            frame = fine_renderer.render(camera, bsdf, method, spp=1, lod_bias=lod_bias).radiance
            frame = frame.reshape(size, supersample, size, supersample, 3).mean(axis=(1, 3))
            row[method] = relative_rmse(frame, truth, reference.mask)
            if matched is not None:
                row["smith matched"][method] = relative_rmse(frame, matched, interior)
            row["against reference"][method] = relative_rmse(frame, reference.radiance, reference.mask)
            if "sun" in row:
                row["sun"][method] = sun_ratios(frame, truth, size)
        rows.append(row)
        shown = [(k, v) for k, v in row.items() if isinstance(v, float) and k != "mitsuba seconds"]
        progress(f"[mitsuba] {case}: " + ", ".join(f"{k} {100 * v:.1f} %" for k, v in shown))
    renderer.release()
    if fine_renderer is not renderer:
        fine_renderer.release()
    ctx.release()
    return {"rows": rows, "methods": list(methods), "size": size, "spp": spp, "mitsuba": mitsuba_version,
            "bright_sources": bool(bright_sources), "supersample": supersample, "lod_bias": lod_bias, "env": env_name,
            "device": "Mesa llvmpipe (lobeview), Mitsuba scalar_rgb on the CPU"}  # fmt: skip


def markdown(results: dict, stamp: str, command: str) -> str:
    methods = results["methods"]
    lines = [
        f"# lobeview against Mitsuba {results['mitsuba']} ({stamp})",
        "",
        f"`{command}`",
        "",
        f"Preview sphere, {results['size']}x{results['size']} px, box filter "
        f"(real-time methods at {results.get('supersample', 1)}x{results.get('supersample', 1)} points per pixel, "
        "averaged); Mitsuba path tracer at "
        f"{results['spp']} spp (scalar_rgb), lobeview's reference at {results['spp']} samples per lobe; "
        f"{results['device']}; environment {results.get('env', 'sky')}. Relative RMSE (%) over the sphere's "
        "pixels against Mitsuba; the reference "
        "column is the floor (both renderers' noise and model differences). Scene and conventions: "
        "bench/mitsuba.py. Bright sources: "
        + (
            "separated into cap lights (every method but the reference)."
            if results.get("bright_sources")
            else "left in the cube."
        )
        + ("" if results.get("lod_bias") is None else f" LOD bias of the real-time methods: {results['lod_bias']:+g}."),
        "",
        *_table(results["rows"], methods, lambda row, m: f"{100 * row[m]:.1f}"),
    ]
    if methods and all("against reference" in row for row in results["rows"]):
        lines += [
            "",
            f"The same frames against lobeview's reference ({results['spp']} samples per lobe; its noise included, "
            "the model difference to Mitsuba not): the methods' own error, relative RMSE (%):",
            "",
            *_table(results["rows"], methods, _against_reference_cell),
        ]
    if any("smith matched" in row for row in results["rows"]):
        lines += [
            "",
            "Against Mitsuba's image with lobeview's Smith term (Mitsuba 3 shadows with the separable G1(wi) "
            "G1(wo), lobeview with the height-correlated 1 / (1 + Lambda_i + Lambda_o): each pixel times their "
            "ratio under this environment, bench/smith_model.py), over the sphere's interior (without the 2 outer "
            "pixel rings, where the two silhouettes differ); isotropic lobes only. Relative RMSE (%): an "
            "independent renderer without the model difference:",
            "",
            *_table([row for row in results["rows"] if "smith matched" in row], methods, _smith_matched_cell),
        ]
    if all("sun" in row for row in results["rows"]):
        lines += [
            "",
            "The sun's mirror pixel / the 9 x 9 pixels around it against Mitsuba (1 = equal; a hole is below 1):",
            "",
            *_table(results["rows"], methods, lambda row, m: f"{row['sun'][m][0]:.3f} / {row['sun'][m][1]:.3f}"),
        ]
    return "\n".join(lines) + "\n"


def _smith_matched_cell(row, method) -> str:
    return f"{100 * row['smith matched'][method]:.2f}"


def _against_reference_cell(row, method) -> str:
    return "-" if method == "reference" else f"{100 * row['against reference'][method]:.2f}"


def _table(rows, methods, cell) -> list[str]:
    """A Markdown table: one row per case, the reference and each method as ``cell(row, method)``."""
    lines = ["| case | reference | " + " | ".join(methods) + " |", "|---|---|" + "---|" * len(methods)]
    for row in rows:
        lines.append(f"| {row['case']} | " + " | ".join(cell(row, m) for m in ("reference", *methods)) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), help="DIST:ALPHA or DIST:AUxAV (default: all)")
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    parser.add_argument("--size", type=int, default=192, help="frame width and height in pixels (default 192)")
    parser.add_argument("--spp", type=int, default=8192, help="samples per pixel of both references (default 8192)")
    parser.add_argument("--supersample", type=int, default=4, help="real-time methods at this many times the "
                        "size, averaged down (default 4, issue 45's protocol; 1: pixel centres)")  # fmt: skip
    parser.add_argument("--bright-sources", action="store_true", help="separate the sun into a cap light "
                        "(scenes/bright_sources.py) for every lobeview method but the reference")  # fmt: skip
    parser.add_argument("--lod-bias", type=float, help="MIP level bias of the real-time methods (default: each "
                        "method's; lobe-N's lobes wider than alpha 0.3 add up to 1.5 levels on top)")  # fmt: skip
    parser.add_argument("--env", default="sky", help="the environment: issue 45's sky with its sun (default), "
                        "studio (builtin:studio's soft boxes), or an HDR capture: a stem of ../shared/assets/env "
                        "(courtyard, interior, ...) or a path")  # fmt: skip
    parser.add_argument("--no-cache", action="store_true", help="render Mitsuba's images again (default: reuse the "
                        "ones of an earlier run of the same scene from the lobeview cache folder)")  # fmt: skip
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args(argv)
    import tempfile

    from lobeview.core.paths import cache_dir

    for case in args.cases:
        parse_case(case)
    if is_capture(args.env):
        capture_path(args.env)  # an unknown capture stops here, before any rendering
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    with tempfile.TemporaryDirectory(prefix="lobeview-mitsuba-") as work:
        cache = None if args.no_cache else cache_dir() / "mitsuba"
        results = run(
            args.cases,
            args.methods,
            args.size,
            args.spp,
            Path(work),
            cache=cache,
            bright_sources=args.bright_sources,
            supersample=args.supersample,
            lod_bias=args.lod_bias,
            env_name=args.env,
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = "python -m lobeview.bench.mitsuba " + " ".join(argv if argv is not None else __import__("sys").argv[1:])
    (out / f"mitsuba-{stamp}.json").write_text(json.dumps(results, indent=1))
    path = out / f"mitsuba-{stamp}.md"
    path.write_text(markdown(results, stamp, command.strip()))
    print(f"[mitsuba] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
