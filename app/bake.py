"""``lobeview bake SCENE``: bake (or re-bake) lightmaps for a glTF scene.

Objects without TEXCOORD_1 are unwrapped with xatlas (all objects into one atlas when any is
missing); every material gets a MOZ_lightmap extension pointing at the baked EXR. Writes
``SCENE_baked.glb`` + ``SCENE_baked_lightmap.exr`` next to the input unless ``--out`` says
otherwise.
"""

from __future__ import annotations

import time
from pathlib import Path

from lobeview.app.options import add_trust_arguments, check_environment_option, trust_limits


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
    p.add_argument("--out", help="output .glb (default: SCENE_baked.glb beside the input)")
    add_trust_arguments(p)


def run(args) -> int:
    from lobeview.scenes.baker import bake_lightmap
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import unwrap_lightmap_uvs
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.gltf_writer import write_glb

    for name in ("resolution", "rays", "bounces"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be at least 1")
    if not 16 <= args.resolution <= 8192:
        raise ValueError("--resolution must be in [16, 8192]")
    check_environment_option(args.env)
    limits = trust_limits(args)
    t0 = time.perf_counter()
    source = Path(args.scene)
    scene = load_gltf(source, limits)
    if any(obj.uv1 is None for obj in scene.objects):
        print(f"unwrapping {len(scene.objects)} objects into one {args.resolution}^2 lightmap atlas (xatlas)")
        scene = unwrap_lightmap_uvs(scene, args.resolution)
    lightmap = bake_lightmap(
        scene,
        load_environment(args.env),
        args.resolution,
        args.rays,
        args.bounces,
        light_samples=args.light_samples,
    )
    out = Path(args.out) if args.out else source.with_name(source.stem + "_baked.glb")
    write_glb(scene, out, lightmap, lightmap_name=out.stem + "_lightmap.exr")
    print(f"wrote {out} and {out.stem}_lightmap.exr in {time.perf_counter() - t0:.1f} s")
    return 0
