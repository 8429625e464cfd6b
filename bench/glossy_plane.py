"""A glossy square floor as glTF, for the Cycles bench: 2 m wide in the xz plane (y up), one
material (base colour, roughness, metallic 0) with an optional constant normal map tilted
towards +x. lobeview draws such a plane from its mirror pass (a planar reflector); the bench
compares it with Cycles under the white sky and a sunny capture (docs/measurements.md "A glossy
floor's mirror pass under the sun").

    python -m lobeview.bench.glossy_plane OUT.gltf [--tilt 30] [--roughness 0.4] [--base 0.0]
    python -m lobeview.bench.cycles --cases OUT.gltf --envs white garden

The file is self-contained (buffer and texture as data URIs) and about 2 KB.
"""

from __future__ import annotations

import argparse
import base64
import json
from pathlib import Path

import numpy as np

from .khr_textures import _png as png_data_uri

NORMAL_MAP_TEXELS = 8  # a constant map: any size samples the same


def normal_map_texel(tilt_deg: float) -> np.ndarray:
    """The tangent-space normal tilted by ``tilt_deg`` towards the tangent (+x), as 8-bit RGB
    (glTF: n / 2 + 1 / 2)."""
    tilt = np.radians(tilt_deg)
    return np.round((np.array([np.sin(tilt), 0.0, np.cos(tilt)]) * 0.5 + 0.5) * 255).astype(np.uint8)


def plane_gltf(tilt_deg: float | None, roughness: float, base: float) -> dict:
    """The glTF document of the floor; ``tilt_deg`` None: no normal map."""
    positions = np.array([[-1, 0, 1], [1, 0, 1], [1, 0, -1], [-1, 0, -1]], np.float32)
    normals = np.tile(np.array([0, 1, 0], np.float32), (4, 1))
    tangents = np.tile(np.array([1, 0, 0, 1], np.float32), (4, 1))
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    indices = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    parts = [positions, normals, tangents, uvs, indices]
    blob = b"".join(part.tobytes() for part in parts)
    offsets = np.cumsum([0] + [part.nbytes for part in parts[:-1]]).tolist()
    kinds = [("VEC3", 5126), ("VEC3", 5126), ("VEC4", 5126), ("VEC2", 5126), ("SCALAR", 5123)]
    accessors = [
        {"bufferView": i, "componentType": component, "count": len(part), "type": kind}
        for i, (part, (kind, component)) in enumerate(zip(parts, kinds, strict=True))
    ]
    accessors[0].update(min=[-1.0, 0.0, -1.0], max=[1.0, 0.0, 1.0])
    material = {
        "name": "floor",
        "pbrMetallicRoughness": {
            "baseColorFactor": [base, base, base, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": roughness,
        },
    }
    document = {
        "asset": {"version": "2.0", "generator": "lobeview bench/glossy_plane.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "floor"}],
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3},
                        "indices": 4,
                        "material": 0,
                    }
                ]
            }
        ],
        "materials": [material],
        "buffers": [
            {"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": offset, "byteLength": part.nbytes}
            for offset, part in zip(offsets, parts, strict=True)
        ],
        "accessors": accessors,
    }
    if tilt_deg is not None:
        image = np.empty((NORMAL_MAP_TEXELS, NORMAL_MAP_TEXELS, 3), np.uint8)
        image[...] = normal_map_texel(tilt_deg)
        material["normalTexture"] = {"index": 0}
        document["textures"] = [{"source": 0, "sampler": 0}]
        document["samplers"] = [{"magFilter": 9729, "minFilter": 9729}]
        document["images"] = [{"uri": png_data_uri(image)}]
    return document


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m lobeview.bench.glossy_plane", description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="the .gltf to write")
    parser.add_argument("--tilt", type=float, default=None, help="normal map tilt in degrees (default: no map)")
    parser.add_argument("--roughness", type=float, default=0.4, help="glTF roughness (default 0.4: alpha 0.16)")
    parser.add_argument("--base", type=float, default=0.0, help="grey base colour (default 0: specular only)")
    args = parser.parse_args(argv)
    if not 0.0 <= args.roughness <= 1.0 or not 0.0 <= args.base <= 1.0:
        parser.error("--roughness and --base lie in [0, 1]")
    if args.tilt is not None and not -90.0 < args.tilt < 90.0:
        parser.error("--tilt lies strictly between -90 and 90 degrees")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(plane_gltf(args.tilt, args.roughness, args.base)))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
