"""Thick glass (KHR_materials_volume, issue 40 item 4) against Mitsuba 3: a glass ball, a tinted
glass ball and a tilted glass plate under a real HDR capture, rendered by lobeview thin-walled
(the volume ignored, as before) and thick (materials/volume.py) and by Mitsuba's path tracer
with a smooth dielectric (exact Fresnel, every internal bounce, an absorbing interior medium for
the tint).

    pip install mitsuba==3.9.1   # not a lobeview dependency; the scalar_rgb variant is used
    .venv/bin/python -m lobeview.bench.volume [--size 96] [--spp 256] [--env FILE]

Same camera (vertical field of view, box pixel filter: lobeview renders 4 x 4 points per pixel
and averages them), the same environment (Mitsuba's map is lobeview's sampled at Mitsuba's texel
directions, so no convention can differ), the same geometry (the plate as an OBJ of lobeview's
mesh). Error: relative RMSE over the object's pixels whose 3 x 3 neighbourhood is all object, and
the mean ratio. What differs by design: lobeview's glTF dielectric has Schlick's Fresnel (f0
0.04), a GGX reflection at alpha 1e-4 and no light reflected inside the volume."""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from lobeview.core.paths import shared_assets_dir

CAMERA = ((0.3, 0.4, 2.6), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 30.0)  # eye, target, up, vertical fov
METHODS = ("lobe-7", "prefiltered", "reference")
IOR = 1.5
BALL_RADIUS = 0.5
PLATE = ((0.0, 0.0, 0.0), (1.0, 1.0, 0.08), 35.0)  # centre, size, turned about +y (degrees)
TINT = ([0.9, 0.55, 0.25], 0.6)  # attenuationColor, attenuationDistance
CASES = ("ball", "tinted ball", "plate")


def _glass(thickness: float | None, tint=None) -> dict:
    desc = {"model": "gltf", "base_color": [1, 1, 1], "metallic": 0, "roughness": 0.0, "transmission": 1.0,
            "ior": IOR}  # fmt: skip
    if thickness:
        desc["thickness"] = thickness
        if tint is not None:
            desc["attenuation_color"], desc["attenuation_distance"] = tint
    return desc


def _mesh(case: str):
    from lobeview.scenes.meshes import box_mesh, uv_sphere

    if case == "plate":
        centre, size, turn = PLATE
        return box_mesh(centre, size, turn), PLATE[1][2]
    return uv_sphere(BALL_RADIUS, 128, 256), 2 * BALL_RADIUS


def render_lobeview(case: str, thick: bool, environment, size: int, spp: int) -> dict[str, np.ndarray]:
    """Each method's image (size x size, box-filtered from 4 x 4 points) and the object mask."""
    from lobeview.materials.spec import validate
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    mesh, thickness = _mesh(case)
    desc = _glass(thickness if thick else None, TINT if case == "tinted ball" else None)
    scene = Scene([SceneObject(case, mesh, 0, None)], [SceneMaterial("glass", validate(desc))])
    ctx = create_headless_context()
    out = {}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # no lightmap: the irradiance fallback is warned
            renderer = SceneRenderer(ctx, scene, environment, size=(4 * size, 4 * size), progress=False,
                                     settings=RenderSettings())  # fmt: skip
        camera = Camera(*CAMERA)
        try:
            for method in METHODS:
                frame = renderer.render(camera, method, spp=max(1, spp // 16) if method == "reference" else 1)
                out[method] = frame.radiance.reshape(size, 4, size, 4, 3).mean(axis=(1, 3))
                out["mask"] = frame.mask.reshape(size, 4, size, 4).all(axis=(1, 3))
        finally:
            renderer.release()
    finally:
        ctx.release()
    return out


def mitsuba_environment(environment, path: Path) -> Path:
    """lobeview's map sampled at the texel directions of Mitsuba's equirectangular convention
    (u = atan2(x, -z) / 2 pi, +y up), written as an EXR."""
    from lobeview.scenes.hdrio import write_hdr_image

    height = environment.height
    v, u = np.meshgrid((np.arange(height) + 0.5) / height, (np.arange(2 * height) + 0.5) / (2 * height), indexing="ij")
    theta, phi = np.pi * v, 2.0 * np.pi * u
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
    return write_hdr_image(path, environment.lookup(d).astype(np.float32))


def _write_obj(mesh, path: Path) -> Path:
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in mesh.positions]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.indices.reshape(-1, 3)]
    path.write_text("\n".join(lines) + "\n")
    return path


def render_mitsuba(case: str, envmap: Path, size: int, spp: int, work: Path) -> np.ndarray:
    try:
        import mitsuba as mi
    except ImportError:
        raise SystemExit("bench.volume needs Mitsuba 3: pip install mitsuba==3.9.1") from None
    from .mitsuba import perspective_sensor

    mi.set_variant("scalar_rgb")  # llvm_ad_rgb's JIT fails on Debian 12's LLVM 15
    bsdf = {"type": "dielectric", "int_ior": IOR, "ext_ior": 1.0}
    if case == "plate":
        shape = {"type": "obj", "filename": str(_write_obj(_mesh(case)[0], work / "plate.obj")), "face_normals": True}
    else:
        shape = {"type": "sphere", "radius": BALL_RADIUS}
    shape["bsdf"] = bsdf
    if case == "tinted ball":
        colour, distance = TINT
        sigma = -np.log(np.asarray(colour)) / distance  # Beer-Lambert: colour^(x / distance) = exp(-sigma x)
        # An RGB texture is a reflectance (<= 1) in Mitsuba: the extinction as colour x scale.
        shape["interior"] = {"type": "homogeneous", "albedo": 0.0, "scale": float(sigma.max()),
                             "sigma_t": {"type": "rgb", "value": (sigma / sigma.max()).tolist()}}  # fmt: skip
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": 24},
        "sensor": perspective_sensor(mi, CAMERA, size, spp),
        "env": {"type": "envmap", "filename": str(envmap)},
        "glass": shape,
    })  # fmt: skip
    return np.array(mi.render(scene), dtype=np.float32)


def _inner(mask: np.ndarray) -> np.ndarray:
    """Pixels whose 3 x 3 neighbourhood is all object (a silhouette pixel mixes object and sky)."""
    padded = np.pad(mask, 1)
    return np.all([padded[1 + dy : mask.shape[0] + 1 + dy, 1 + dx : mask.shape[1] + 1 + dx]
                   for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    from lobeview.scenes.envmap import EnvironmentMap

    from .report import write_image_rows, write_markdown_report

    here = Path(__file__).resolve().parent
    assets = shared_assets_dir()
    default_env = assets / "env" / "polyhaven_1k" / "chinese_garden_1k.hdr" if assets else None
    p = argparse.ArgumentParser(prog="python -m lobeview.bench.volume", description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=96, help="image side in pixels (default 96)")
    p.add_argument("--spp", type=int, default=256, help="Mitsuba's and lobeview's reference samples per pixel")
    p.add_argument("--env", default=str(default_env) if default_env else None, help="equirectangular HDR")
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    p.add_argument("--clamp", type=float, default=50.0,
                   help="radiance ceiling applied to the map for both renderers (default 50: the garden's sun, "
                        "7.9e4, would make both renderers' noise on its one-pixel image through the glass the "
                        "whole error; 0: none)")  # fmt: skip
    args = p.parse_args(argv)
    if not args.env:
        raise SystemExit("--env: no HDR given and ../shared/assets is not there")
    environment = EnvironmentMap.load(args.env)
    if args.clamp > 0:
        environment = EnvironmentMap(np.minimum(environment.image, args.clamp), environment.name)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    rows, figure_rows = [], []
    with tempfile.TemporaryDirectory(prefix="lobeview-volume-") as folder:
        envmap = mitsuba_environment(environment, Path(folder) / "env.exr")
        for case in args.cases:
            t0 = time.perf_counter()
            truth = render_mitsuba(case, envmap, args.size, args.spp, Path(folder))
            print(f"{case}: Mitsuba {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
            images = {}
            for thick in (False, True):
                rendered = render_lobeview(case, thick, environment, args.size, args.spp)
                mask = _inner(rendered.pop("mask"))
                norm = float(np.sqrt(np.mean(truth[mask] ** 2)))
                for method, image in rendered.items():
                    error = float(np.sqrt(np.mean((image[mask] - truth[mask]) ** 2))) / norm
                    ratio = float(image[mask].mean() / truth[mask].mean())
                    rows.append((case, "thick" if thick else "thin-walled", method, error, ratio))
                    images[(thick, method)] = image
            error_x4 = np.clip(4 * np.abs(images[(True, "lobe-7")] - truth), 0, None)
            figure_rows.append(np.concatenate([truth, images[(False, "lobe-7")], images[(True, "lobe-7")], error_x4],
                                              axis=1))  # fmt: skip
    tonemapped = [np.clip(row / (1.0 + row), 0.0, 1.0) ** (1 / 2.2) for row in figure_rows]
    figure = write_image_rows(here / "figures", f"volume-{stamp}.png", tonemapped)
    lines = [
        f"# Thick glass against Mitsuba 3 ({stamp})",
        "",
        # the command as it pastes: --env only where it is not the default (../shared's garden)
        f"`python -m lobeview.bench.volume --size {args.size} --spp {args.spp}"
        f"{'' if args.env == p.get_default('env') else f' --env {args.env}'} --clamp {args.clamp:g}"
        f"{'' if args.cases == list(CASES) else ' --cases ' + ' '.join(repr(c) for c in args.cases)}`",
        "",
        f"{args.size}x{args.size} px, box filter (lobeview 4x4 points per pixel), Mitsuba 3 volpath {args.spp} spp "
        f"(scalar_rgb), lobeview's reference {max(1, args.spp // 16)} passes per point; Mesa llvmpipe. Glass: ior "
        f"{IOR}, smooth; ball radius {BALL_RADIUS} (thickness = its diameter); tinted ball: attenuationColor "
        f"{TINT[0]} at {TINT[1]}; plate {PLATE[1]} turned {PLATE[2]} deg (thickness {PLATE[1][2]}). The map's "
        f"radiance clamped at {args.clamp:g} for both (0: not clamped). Object pixels whose 3x3 neighbourhood is all "
        "object.",
        "",
        "| case | volume | method | rel-RMSE | mean / Mitsuba's |",
        "|---|---|---|---|---|",
        *[f"| {c} | {v} | {m} | {100 * e:.1f} % | {r:.3f} |" for c, v, m, e, r in rows],
        "",
        f"Figure: {figure.relative_to(here)} (per case: Mitsuba | thin-walled lobe-7 | thick lobe-7 | |thick - "
        "Mitsuba| x4).",
    ]
    write_markdown_report(here / "results", f"volume-{stamp}.md", lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
