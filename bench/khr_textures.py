"""The KHR material extensions' textures on a generated glTF, through the real loader and
renderer (issue 16): a brushed-metal disc (KHR_materials_anisotropy with a circular direction
texture), a clear-coated dark blue panel (clearcoatTexture stripes, a clearcoatRoughnessTexture
gradient, a ribbed clearcoatNormalTexture) and a dark glossy dielectric whose
specularColorTexture tints its reflections with a hue gradient. The figure puts each beside the
same scene with the extension textures removed (factors only).

    python -m lobeview.bench.khr_textures [--env builtin:studio] [--size 960x320] [--method lobe-15]
        [--keep-gltf FOLDER] [--out bench/figures/gltf-khr-textures.png]

The glTF is written to a temporary folder (``--keep-gltf`` keeps a copy: a test asset for other
viewers). Prints what it renders and where the figure went.
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import tempfile
from pathlib import Path

import numpy as np

from lobeview.scenes.scene import TEXTURE_SLOTS

from .textures import untextured

SIZE = 256  # texels per side of every generated texture
EXTENSION_SLOTS = set(TEXTURE_SLOTS[5:])  # the KHR extensions' slots (scenes/scene.py)


def _png(pixels: np.ndarray) -> str:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(buffer, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode()


def _texel_grid() -> tuple[np.ndarray, np.ndarray]:
    """(x, y) in [-1, 1] of every texel centre; row 0 is v = 0, the top (y = +1)."""
    centres = (np.arange(SIZE) + 0.5) / SIZE
    u, v = np.meshgrid(centres, centres)
    return 2.0 * u - 1.0, 1.0 - 2.0 * v


def _rgba(channels: list) -> np.ndarray:
    out = np.full((SIZE, SIZE, 4), 255, np.uint8)
    for index, values in enumerate(channels):
        out[..., index] = np.round(np.clip(values, 0.0, 1.0) * 255)
    return out


def textures() -> dict[str, np.ndarray]:
    """The generated images (uint8 RGBA)."""
    x, y = _texel_grid()
    radius = np.maximum(np.hypot(x, y), 1e-6)
    # Circular brushing: the direction (-y, x) / r in the glTF tangent frame, whose tangent is
    # +x (u) and whose bitangent is -y (v grows downwards): components (-y, -x) / r.
    anisotropy = _rgba([0.5 - 0.5 * y / radius, 0.5 - 0.5 * x / radius, np.ones_like(x)])
    stripes = (np.floor((x + 1.0) * 3.0) % 2 == 0).astype(float)  # six vertical bands, coated or not
    coat = _rgba([stripes, np.zeros_like(x), np.zeros_like(x)])
    coat_roughness = _rgba([np.zeros_like(x), 0.5 - 0.5 * y, np.zeros_like(x)])  # smooth at the top
    # Horizontal ribs in the coat only: the normal tilted along the bitangent by a sine.
    tilt = 0.45 * np.sin(y * np.pi * 8.0)
    length = np.sqrt(1.0 + tilt**2)
    coat_normal = _rgba([np.full_like(x, 0.5), 0.5 + 0.5 * tilt / length, 0.5 + 0.5 / length])
    hue = (x + 1.0) / 2.0
    rainbow = np.stack([np.clip(np.abs(hue * 6.0 - 3.0) - 1.0, 0, 1), np.clip(2.0 - np.abs(hue * 6.0 - 2.0), 0, 1),
                        np.clip(2.0 - np.abs(hue * 6.0 - 4.0), 0, 1)])  # fmt: skip
    specular_colour = _rgba(list(rainbow ** (1 / 2.2)))  # sRGB-encoded
    return {
        "anisotropy": anisotropy,
        "coat": coat,
        "coat_roughness": coat_roughness,
        "coat_normal": coat_normal,
        "specular_colour": specular_colour,
    }


def _square(centre_x: float, disc: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, UVs and indices of a 2 x 2 square (or the disc inscribed in it) facing +z."""
    if disc:
        angles = np.linspace(0.0, 2.0 * np.pi, 97)[:-1]
        ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        local = np.concatenate([[[0.0, 0.0]], ring])
        count = len(angles)
        indices = np.array([[0, 1 + i, 1 + (i + 1) % count] for i in range(count)], np.uint16).reshape(-1)
    else:
        local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        indices = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    positions = np.concatenate([local + [centre_x, 0.0], np.zeros((len(local), 1))], axis=1).astype(np.float32)
    uvs = np.stack([(local[:, 0] + 1.0) / 2.0, (1.0 - local[:, 1]) / 2.0], axis=1).astype(np.float32)
    return positions, uvs, indices


def write_gltf(folder: Path) -> Path:
    """KhrTextureTest.gltf (buffers and images embedded as data URIs) in ``folder``."""
    images = textures()
    names = list(images)
    materials = [
        {
            "name": "brushed disc",
            "pbrMetallicRoughness": {"baseColorFactor": [0.95, 0.93, 0.88, 1], "metallicFactor": 1.0,
                                     "roughnessFactor": 0.35},
            "extensions": {"KHR_materials_anisotropy": {"anisotropyStrength": 0.9,
                                                        "anisotropyTexture": {"index": names.index("anisotropy")}}},
        },
        {
            "name": "striped clearcoat",
            "pbrMetallicRoughness": {"baseColorFactor": [0.013, 0.022, 0.11, 1], "metallicFactor": 0.0,
                                     "roughnessFactor": 0.6},
            "extensions": {"KHR_materials_clearcoat": {
                "clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.4,
                "clearcoatTexture": {"index": names.index("coat")},
                "clearcoatRoughnessTexture": {"index": names.index("coat_roughness")},
                "clearcoatNormalTexture": {"index": names.index("coat_normal"), "scale": 1.0}}},
        },
        {
            "name": "tinted specular",
            "pbrMetallicRoughness": {"baseColorFactor": [0.02, 0.02, 0.02, 1], "metallicFactor": 0.0,
                                     "roughnessFactor": 0.2},
            "extensions": {"KHR_materials_specular": {
                "specularColorFactor": [6.0, 6.0, 6.0],
                "specularColorTexture": {"index": names.index("specular_colour")}}},
        },
    ]  # fmt: skip
    blob = b""
    views, accessors, meshes, nodes = [], [], [], []
    for index, centre in enumerate((-2.3, 0.0, 2.3)):
        positions, uvs, indices = _square(centre, disc=index == 0)
        primitive = {}
        for key, data, kind in (("POSITION", positions, "VEC3"), ("TEXCOORD_0", uvs, "VEC2")):
            views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes})
            accessor = {"bufferView": len(views) - 1, "componentType": 5126, "count": len(data), "type": kind}
            if key == "POSITION":
                accessor.update(min=positions.min(axis=0).tolist(), max=positions.max(axis=0).tolist())
            accessors.append(accessor)
            primitive[key] = len(accessors) - 1
            blob += data.tobytes()
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": indices.nbytes})
        accessors.append({"bufferView": len(views) - 1, "componentType": 5123, "count": len(indices), "type": "SCALAR"})
        blob += indices.tobytes() + b"\0" * (-indices.nbytes % 4)
        meshes.append({"primitives": [{"attributes": primitive, "indices": len(accessors) - 1, "material": index}]})
        nodes.append({"mesh": index, "name": materials[index]["name"]})
    gltf = {
        "asset": {"version": "2.0", "generator": "lobeview bench/khr_textures.py"},
        "extensionsUsed": ["KHR_materials_anisotropy", "KHR_materials_clearcoat", "KHR_materials_specular"],
        "buffers": [
            {"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
        ],  # fmt: skip
        "bufferViews": views,
        "accessors": accessors,
        "images": [{"uri": _png(images[name]), "name": name} for name in names],
        "samplers": [{"wrapS": 33071, "wrapT": 33071}],
        "textures": [{"source": i, "sampler": 0} for i in range(len(names))],
        "materials": materials,
        "meshes": meshes,
        "nodes": nodes,
        "scenes": [{"nodes": list(range(len(nodes)))}],
    }
    path = folder / "KhrTextureTest.gltf"
    path.write_text(json.dumps(gltf))
    return path


def render_figure(gltf: Path, env_spec: str, size: tuple[int, int], method: str, out: Path) -> dict:
    import warnings

    from PIL import Image

    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings
    from lobeview.viewer.tonemap import tonemap

    scene = load_gltf(gltf)
    for obj in scene.objects:
        obj.planar_reflector = False  # the cube-map path for all three (no mirror passes)
    env = load_environment(env_spec)
    camera = Camera(position=(0.0, 0.6, 7.2), target=(0.0, 0.0, 0.0), fov_y=26.0)
    ctx = create_headless_context()
    rows, stats = [], {}
    factors_only = untextured(scene, EXTENSION_SLOTS)
    for label, variant in (("factors only", factors_only), ("with the extension textures", scene)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no usable lightmap": lit by the environment, as intended
            renderer = SceneRenderer(
                ctx, variant, env, size=size, progress=False, settings=RenderSettings(cube_face_size=128)
            )
        result = renderer.render(camera, method)
        renderer.release()
        if not np.all(np.isfinite(result.radiance)) or result.invalid.any():
            raise RuntimeError(f"{label}: non-finite pixels")
        stats[label] = float(result.radiance[result.mask].mean())
        rows.append(tonemap(result.radiance))
    ctx.release()
    image = np.concatenate([rows[0], np.full((4, size[0], 3), 1.0), rows[1]], axis=0)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)).save(out)
    return stats


def main(argv=None) -> int:
    from lobeview.core.errors import parse_size

    p = argparse.ArgumentParser(prog="python -m lobeview.bench.khr_textures", description=__doc__.split("\n\n")[0])
    p.add_argument("--env", default="builtin:studio", help="environment (default builtin:studio)")
    p.add_argument("--size", default="960x320", help="size of each row (default 960x320)")
    p.add_argument("--method", default="lobe-15", help="method (default lobe-15)")
    p.add_argument("--keep-gltf", default=None, help="also write KhrTextureTest.gltf into this folder")
    p.add_argument("--out", default="bench/figures/gltf-khr-textures.png", help="the figure (PNG)")
    args = p.parse_args(argv)
    size = parse_size(args.size)
    with tempfile.TemporaryDirectory(prefix="lobeview-khr-") as folder:
        gltf = write_gltf(Path(folder))
        if args.keep_gltf:
            Path(args.keep_gltf).mkdir(parents=True, exist_ok=True)
            kept = Path(args.keep_gltf) / gltf.name
            kept.write_text(gltf.read_text())
            print(f"wrote {kept}")
        print(f"rendering {gltf.name} ({args.method}, {size[0]}x{size[1]} per row, {args.env}) ...", flush=True)
        stats = render_figure(gltf, args.env, size, args.method, Path(args.out))
    for label, mean in stats.items():
        print(f"  {label}: mean radiance {mean:.4f}")
    print(f"wrote {args.out} (top: factors only; bottom: with the extension textures)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
