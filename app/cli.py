"""The ``lobeview`` command line.

``lobeview material list|show|plot``, ``lobeview shot`` (scenes, the demo, object preview),
``lobeview view`` (the window), ``lobeview bench``, ``lobeview bake``, ``lobeview fit`` and
``lobeview measure`` (measured materials).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from lobeview import __version__
from lobeview.app.bench import BenchError
from lobeview.app.shot import ShotError
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import MaterialError, build_bsdf, load_material
from lobeview.materials.vec import direction_from_angles_deg
from lobeview.scenes.gltf_loader import GltfError
from lobeview.scenes.hdrio import HDRImageError
from lobeview.scenes.meshes import MeshError
from lobeview.viewer.context import HeadlessContextError

SHOW_ANGLES_DEG = (0.0, 30.0, 60.0, 80.0)


def _rgb(values) -> str:
    return "(" + ", ".join(f"{v:.4f}" for v in values) + ")"


def _albedo_table(desc: dict) -> list[dict]:
    bsdf = build_bsdf(desc)
    rows = []
    for theta in SHOW_ANGLES_DEG:
        r, t = bsdf.albedo(direction_from_angles_deg(theta, 0.0), order=160)
        rows.append({"theta_deg": theta, "reflectance": r.tolist(), "transmittance": t.tolist()})
    return rows


def cmd_material_list(args) -> int:
    width = max(len(name) for name in PRESETS)
    for name, desc in PRESETS.items():
        print(f"{name:<{width}}  {desc['model']:<10}  {desc.get('description', '')}")
    return 0


def cmd_material_show(args) -> int:
    desc = load_material(args.material)
    rows = _albedo_table(desc)
    if args.json:
        print(json.dumps({"material": desc, "albedo": rows}, indent=2))
        return 0
    name = args.material if args.material in PRESETS else desc.get("name", args.material)
    print(f"material: {name}")
    if "description" in desc:
        print(f"  {desc['description']}")
    print(f"model: {desc['model']}")
    for key, value in desc.items():
        if key in ("model", "name", "description"):
            continue
        if isinstance(value, list) and value and isinstance(value[0], dict):
            for i, lobe in enumerate(value):
                params = "  ".join(f"{k}={v}" for k, v in lobe.items())
                print(f"  {key}[{i}]: {params}")
        else:
            print(f"  {key}: {value}")
    print()
    print("directional albedo seen from viewing angle theta (azimuth 0, along the tangent):")
    header = f"  {'theta':>6}  {'reflectance (R, G, B)':<26}  {'transmittance (R, G, B)':<26}"
    print(header + "  total(mean)")
    for row in rows:
        total = float(np.mean(np.add(row["reflectance"], row["transmittance"])))
        print(
            f"  {row['theta_deg']:>5.0f}°  {_rgb(row['reflectance']):<26}  "
            f"{_rgb(row['transmittance']):<26}  {total:.4f}"
        )
    return 0


def cmd_material_plot(args) -> int:
    from lobeview.materials.plot import plot_material

    desc = load_material(args.material)
    title = args.material if args.material in PRESETS else desc.get("name", "material")
    if "description" in desc:
        title = f"{title}: {desc['description']}"
    out = plot_material(build_bsdf(desc), title, args.output)
    print(f"wrote {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lobeview",
        description="Real-time walkthroughs of light-mapped glTF scenes with glossy materials.",
    )
    parser.add_argument("--version", action="version", version=f"lobeview {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    material = sub.add_parser("material", help="inspect the material library and presets")
    msub = material.add_subparsers(dest="material_command", required=True)
    p = msub.add_parser("list", help="list the material presets")
    p.set_defaults(func=cmd_material_list)
    p = msub.add_parser("show", help="print a material's parameters and directional albedo")
    p.add_argument("material", help="preset name, JSON file or inline JSON object")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_material_show)
    p = msub.add_parser("plot", help="draw the material's lobes to a PNG")
    p.add_argument("material", help="preset name, JSON file or inline JSON object")
    p.add_argument("-o", "--output", default="lobe.png", help="output PNG (default: lobe.png)")
    p.set_defaults(func=cmd_material_plot)
    from lobeview.app import bake, bench, fit, shot, view

    p = sub.add_parser("fit", help="fit the thesis material model to a measurement (CSV, MERL, virtual)")
    fit.add_fit_arguments(p)
    p.set_defaults(func=fit.cmd_fit)
    p = sub.add_parser("measure", help="write a virtual goniophotometer measurement (CSV) or MERL table of a material")
    fit.add_measure_arguments(p)
    p.set_defaults(func=fit.cmd_measure)

    p = sub.add_parser("shot", help="render a headless screenshot of a scene or an object preview")
    shot.add_arguments(p)
    p.set_defaults(func=shot.run)
    p = sub.add_parser("view", help="open the interactive walkthrough window")
    view.add_arguments(p)
    p.set_defaults(func=view.run)
    p = sub.add_parser(
        "bench", help="time against error for every method (--quick: a few minutes); stress, mirrors, report"
    )
    bench.add_arguments(p)
    p.set_defaults(func=bench.run)
    p = sub.add_parser("bake", help="bake lightmaps for a glTF scene")
    bake.add_arguments(p)
    p.set_defaults(func=bake.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (
        MaterialError,
        ShotError,
        BenchError,
        HDRImageError,
        MeshError,
        HeadlessContextError,
        GltfError,
    ) as exc:
        print(f"lobeview: error: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:  # bad option values (method, environment name, ...)
        print(f"lobeview: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader of our output went away (`lobeview material list | head`): not an error.
        # Point stdout at devnull so the interpreter's final flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        print(f"lobeview: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
