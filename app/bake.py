"""``lobeview bake SCENE``: bake (or re-bake) lightmaps for a glTF scene.

The scene is baked into one shared atlas over TEXCOORD_1: the file's own coordinates when every
baked object has them and they do not overlap, else a new xatlas unwrap of all objects (uniform
texel density over the scene's real extent; said so). The output is the input glTF unchanged
except for the lightmap (scenes/baked_gltf.py): one self-contained ``SCENE_baked.glb`` in the
current folder unless ``--out`` names another, with the atlas embedded as an EXR image, or
written beside it with ``--external-lightmap``. The input's folder is never written to.
"""

from __future__ import annotations

import time
from pathlib import Path

from lobeview.app.options import add_trust_arguments, check_environment_option, trust_limits
from lobeview.core.errors import check_output_folder


def add_arguments(p) -> None:
    p.add_argument("scene", help="glTF scene (.gltf/.glb)")
    p.add_argument(
        "--env",
        default="builtin:overcast",
        help="environment lighting the scene from outside (default builtin:overcast)",
    )
    p.add_argument("--resolution", type=int, default=512, help="lightmap atlas size in texels (default 512)")
    p.add_argument("--rays", type=int, default=128, help="hemisphere rays per texel and bounce (default 128)")
    p.add_argument("--bounces", type=int, default=3, help="diffuse bounces (default 3)")
    p.add_argument(
        "--light-samples",
        type=int,
        default=32,
        help="shadow rays per texel towards emissive surfaces (default 32)",
    )
    p.add_argument(
        "--env-samples",
        type=int,
        default=32,
        help="importance samples of the environment per texel, combined with the rays by MIS (default 32; 0: off)",
    )
    p.add_argument("--out", help="output .glb (default: SCENE_baked.glb in the current folder)")
    p.add_argument(
        "--external-lightmap",
        action="store_true",
        help="write the lightmap as OUT_lightmap.exr beside the .glb instead of embedding it",
    )
    add_trust_arguments(p)


def run(args) -> int:
    from lobeview.scenes.gltf_bake import BakeSettings, bake_gltf

    settings = BakeSettings(args.resolution, args.rays, args.bounces, args.light_samples, args.env_samples)
    settings.check()
    check_environment_option(args.env)
    limits = trust_limits(args)
    t0 = time.perf_counter()
    source = Path(args.scene)
    out = Path(args.out) if args.out else Path.cwd() / (source.stem + "_baked.glb")
    _check_writable(out)
    written = bake_gltf(source, args.env, out, limits, settings, external_lightmap=args.external_lightmap)
    print(f"wrote {' and '.join(str(p) for p in written)} in {time.perf_counter() - t0:.1f} s")
    return 0


def _check_writable(out: Path) -> None:
    """Refuse an output that cannot be written before an hour of baking, not after it."""
    if out.suffix.lower() != ".glb":
        raise ValueError(f"--out {out}: the baked scene is a .glb file")
    check_output_folder(out)
    folder = out.parent if str(out.parent) else Path(".")
    try:
        probe = folder / f".{out.name}.lobeview-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        reason = exc.strerror or exc
        raise ValueError(f"cannot write to {folder} ({reason}); name a writable place with --out") from None
