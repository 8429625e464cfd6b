"""glTF material textures per pixel in numpy: the reference twin of shaders/material_maps.glsl
and of the per-pixel material in shaders/scene.frag (core specification 3.9 and Appendix B).

- :func:`sample_slot`: a texture slot at UV coordinates as the GPU samples MIP level 0: the
  slot's UV set, KHR_texture_transform, wrap mode per axis (repeat, clamp-to-edge, mirrored
  repeat folded into [0, 1] and then repeated, as the shader does), nearest or bilinear filter
  between texel centres, sRGB decoded per texel before filtering (an SRGB8_ALPHA8 texture).
- :func:`texel_material`: base colour (RGBA x factor), metallic (B) and roughness (G) x factors,
  the tangent-space normal, occlusion and emission of a material at UV coordinates, and the KHR
  extensions' factors times their textures (:func:`extension_texels`).
- :func:`mapped_normal`: the normal map in the interpolated tangent frame.
- :func:`lightmap_tilt_share`: how much of a baked irradiance a normal-mapped point receives.
- :func:`pixel_bsdf`: the glTF BSDF of one pixel's parameters (materials/gltf.py).
"""

from __future__ import annotations

import numpy as np

from lobeview.materials.spec import GLTF_BSDF_KEYS

from .scene import CLAMP_TO_EDGE, MIRRORED_REPEAT, NEAREST, SceneMaterial, TextureSlot


def transformed_uv(slot: TextureSlot, uv0: np.ndarray, uv1: np.ndarray | None = None) -> np.ndarray:
    """(N, 2) coordinates of the slot: its UV set through its KHR_texture_transform matrix."""
    uv = np.asarray(uv1 if slot.tex_coord == 1 and uv1 is not None else uv0, dtype=np.float64).reshape(-1, 2)
    homogeneous = np.concatenate([uv, np.ones((len(uv), 1))], axis=1)
    return (homogeneous @ np.asarray(slot.transform, dtype=np.float64).T)[:, :2]


def _fold(coordinate: np.ndarray, wrap: int) -> np.ndarray:
    if wrap == MIRRORED_REPEAT:
        t = coordinate - 2.0 * np.floor(0.5 * coordinate)
        return np.where(t > 1.0, 2.0 - t, t)
    return coordinate


def _texel_index(index: np.ndarray, size: int, wrap: int) -> np.ndarray:
    if wrap == CLAMP_TO_EDGE:
        return np.clip(index, 0, size - 1)
    return np.mod(index, size)  # repeat (mirrored repeat is folded before, then repeats)


def sample_slot(slot: TextureSlot, uv0: np.ndarray, uv1: np.ndarray | None = None) -> np.ndarray:
    """(N, 4) linear RGBA of the slot at the given vertex coordinates (MIP level 0)."""
    texels = slot.linear()  # float32, decoded once per slot; only the gathered texels widen
    height, width = texels.shape[:2]
    uv = transformed_uv(slot, uv0, uv1)
    u, v = _fold(uv[:, 0], slot.wrap_s), _fold(uv[:, 1], slot.wrap_t)
    x, y = u * width - 0.5, v * height - 0.5
    if slot.mag_filter == NEAREST:
        xi = _texel_index(np.floor(x + 0.5).astype(np.int64), width, slot.wrap_s)
        yi = _texel_index(np.floor(y + 0.5).astype(np.int64), height, slot.wrap_t)
        return texels[yi, xi].astype(np.float64)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    xa, xb = _texel_index(x0, width, slot.wrap_s), _texel_index(x0 + 1, width, slot.wrap_s)
    ya, yb = _texel_index(y0, height, slot.wrap_t), _texel_index(y0 + 1, height, slot.wrap_t)

    def texel(row, col):
        return texels[row, col].astype(np.float64)

    top = texel(ya, xa) * (1 - fx) + texel(ya, xb) * fx
    bottom = texel(yb, xa) * (1 - fx) + texel(yb, xb) * fx
    return top * (1 - fy) + bottom * fy


def texel_material(material: SceneMaterial, uv0: np.ndarray, uv1: np.ndarray | None = None) -> dict:
    """Per-pixel inputs of ``material`` at (N, 2) coordinates, as shaders/scene.frag computes them:
    base_color (N, 3), coverage (N,), metallic, roughness (N,), normal_texel (N, 3) or None,
    occlusion (N,), emission (N, 3)."""
    count = len(np.asarray(uv0).reshape(-1, 2))
    ones = np.ones((count, 4))

    def texel(name, absent=ones):
        slot = material.texture(name)
        return sample_slot(slot, uv0, uv1) if slot is not None else absent

    desc = material.desc
    gltf_model = desc["model"] == "gltf"
    base_texel = texel("base_color")
    mr_texel = texel("metallic_roughness")
    factor = np.asarray(desc["base_color"] if gltf_model else [1.0, 1.0, 1.0], dtype=np.float64)
    coverage = (
        np.ones(count) if material.alpha_mode == "OPAQUE" else np.clip(material.base_alpha * base_texel[:, 3], 0, 1)
    )
    occlusion = texel("occlusion")[:, 0]
    return {
        "gltf_model": gltf_model,
        "base_color": factor * base_texel[:, :3],
        "base_texel": base_texel[:, :3],
        "coverage": coverage,
        "metallic": np.clip(float(desc.get("metallic", 0.0)) * mr_texel[:, 2], 0, 1),
        "roughness": np.clip(float(desc.get("roughness", 1.0)) * mr_texel[:, 1], 0, 1),
        "normal_texel": texel("normal")[:, :3] if material.texture("normal") is not None else None,
        "occlusion": 1.0 + material.occlusion_strength * (occlusion - 1.0),
        "emission": np.asarray(material.emission, dtype=np.float64) * texel("emissive")[:, :3],
        # KHR_materials_* factors times their textures, per pixel: gltf_bsdf's keyword arguments.
        "extensions": extension_texels(material, texel, count) if gltf_model else {},
        "coat_normal_texel": (
            texel("clearcoat_normal")[:, :3] if gltf_model and material.texture("clearcoat_normal") else None
        ),
    }


def extension_texels(material: SceneMaterial, texel, count: int) -> dict:
    """The KHR extensions' factors at ``count`` pixels (arrays with a leading pixel axis), each
    times its texture as the extension specifies (shaders/scene.frag): anisotropy strength x B and
    rotation + the direction atan2(G, R) of the RG texel in [-1, 1]; clearcoat x R, clearcoat
    roughness x G; specular colour x RGB (sRGB) and specular x A; transmission x R; sheen colour x
    RGB (sRGB). ``texel(slot, absent)`` samples a slot."""
    desc = material.desc
    out = {k: np.repeat(np.asarray(desc[k], np.float64)[None], count, axis=0) for k in GLTF_BSDF_KEYS if k in desc}
    if material.texture("anisotropy") is not None:
        values = texel("anisotropy")
        direction = 2.0 * values[:, :2] - 1.0
        turned = np.sum(direction**2, axis=1) > 1e-12
        angle = np.where(turned, np.arctan2(direction[:, 1], direction[:, 0]), 0.0)
        out["anisotropy"] = float(desc.get("anisotropy", 0.0)) * values[:, 2]
        out["anisotropy_rotation"] = float(desc.get("anisotropy_rotation", 0.0)) + angle
    if material.texture("clearcoat") is not None:
        coat = texel("clearcoat")
        out["clearcoat"] = float(desc.get("clearcoat", 0.0)) * coat[:, 0]
        out["clearcoat_roughness"] = float(desc.get("clearcoat_roughness", 0.0)) * coat[:, 1]
    if material.texture("specular") is not None:
        values = texel("specular")
        out["specular"] = float(desc.get("specular", 1.0)) * values[:, 3]
        out["specular_color"] = np.asarray(desc.get("specular_color", [1.0, 1.0, 1.0]), np.float64) * values[:, :3]
    if material.texture("transmission") is not None:
        out["transmission"] = float(desc.get("transmission", 0.0)) * texel("transmission")[:, 0]
    if material.texture("sheen_color") is not None:
        sheen = np.asarray(desc.get("sheen_color", [0.0, 0.0, 0.0]), np.float64)
        out["sheen_color"] = sheen * texel("sheen_color")[:, :3]
    return out


def mapped_normal(frame: np.ndarray, normal_texel: np.ndarray, scale: float) -> np.ndarray:
    """Normal-mapped world normal (spec 3.9.3): ``frame`` (3, 3) columns tangent, bitangent
    (with handedness), normal; n = normalize((2 t - 1) (scale, scale, 1)) in that frame."""
    n = (2.0 * np.asarray(normal_texel, dtype=np.float64) - 1.0) * np.array([scale, scale, 1.0])
    length = np.linalg.norm(n)
    if not length > 1e-6:
        return frame[:, 2]
    world = frame @ (n / length)
    return world / np.linalg.norm(world)


def lightmap_tilt_share(mapped: np.ndarray, lightmap_normal: np.ndarray) -> np.ndarray:
    """The share of a baked irradiance that reaches a normal-mapped point: (1 + cos tilt) / 2,
    tilt the angle between the mapped normal and the normal the bake integrated around (the
    interpolated vertex normal, scenes/baker.py).

    The bake holds E = int_H L(w) (w.n) dw over the hemisphere H above the surface. A mapped
    normal n' leans part of its cosine lobe below the surface, where a path tracer's rays meet
    the object itself: under radiance uniform over H, int_H max(0, w.n') dw = pi (1 + n.n') / 2
    (the view factor of a plane tilted by theta to a half space), so E' = E (1 + cos theta) / 2.
    Without directional data in the lightmap, that is the whole correction: a tilt towards a
    brighter part of the sky is first order in theta and cancels over a bump's two slopes, the
    lost horizon is second order and darkens both (issue 40: ClearCoatTest's ribbed normal map
    9 % brighter than Cycles with the bake alone). Shapes (..., 3) -> (...)."""
    cos_tilt = np.sum(np.asarray(mapped, np.float64) * np.asarray(lightmap_normal, np.float64), axis=-1)
    return 0.5 * (1.0 + np.clip(cos_tilt, -1.0, 1.0))


def pixel_bsdf(parameters: dict, k: int, coat_cos: float | None = None):
    """The glTF BSDF of pixel ``k`` of :func:`texel_material`'s output (gltf model only);
    ``coat_cos``: N_c.V of the clearcoat's own normal at that pixel (gltf_bsdf)."""
    from lobeview.materials.gltf import gltf_bsdf

    extensions = {key: value[k] for key, value in parameters.get("extensions", {}).items()}
    extensions = {key: value.tolist() if np.ndim(value) else float(value) for key, value in extensions.items()}
    return gltf_bsdf(
        parameters["base_color"][k],
        float(parameters["metallic"][k]),
        float(parameters["roughness"][k]),
        coat_cos=coat_cos,
        **extensions,
    )
