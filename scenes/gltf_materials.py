"""glTF materials (issue 16; scenes/gltf_loader.py reads the rest of the file): metallic-roughness
factors and textures with their samplers and KHR_texture_transform, the KHR_materials_*
extensions lobeview maps onto its gltf model (with their per-pixel textures), MOZ_lightmap, and a
thesis-model material in ``extras.lobeview``. Values outside a documented range are clamped with
a warning; missing textures fall back to the factors (gltf_loader.FALLBACKS)."""

from __future__ import annotations

import dataclasses
import json
import types

import numpy as np

from lobeview.core.errors import quoted
from lobeview.core.trust import UntrustedReferenceError, read_reference
from lobeview.materials.spec import RANGES, MaterialError, resolve_material_files, validate

from .gltf_common import FALLBACKS, GltfError, _index, _warn
from .hdrio import sanitize_radiance
from .scene import (
    ALPHA_MODES,
    COLOUR_SLOTS,
    MAG_FILTERS,
    MIN_FILTERS,
    WRAP_MODES,
    Lightmap,
    SceneMaterial,
    TextureSlot,
)

# glTF material extensions lobeview maps onto the gltf model: extension -> {glTF field: (desc
# key, default, (low, high))}; their textures are read per pixel (EXTENSION_SLOTS).
GLTF_MODEL_EXTENSIONS = {
    "KHR_materials_anisotropy": {
        "anisotropyStrength": ("anisotropy", 0.0, (0.0, 1.0)),
        "anisotropyRotation": ("anisotropy_rotation", 0.0, None),
    },
    "KHR_materials_ior": {"ior": ("ior", 1.5, None)},
    "KHR_materials_specular": {
        "specularFactor": ("specular", 1.0, (0.0, 1.0)),
        "specularColorFactor": ("specular_color", [1.0, 1.0, 1.0], (0.0, 10.0)),
    },
    "KHR_materials_clearcoat": {
        "clearcoatFactor": ("clearcoat", 0.0, (0.0, 1.0)),
        "clearcoatRoughnessFactor": ("clearcoat_roughness", 0.0, (0.0, 1.0)),
    },
    "KHR_materials_transmission": {"transmissionFactor": ("transmission", 0.0, (0.0, 1.0))},
    "KHR_materials_sheen": {
        "sheenColorFactor": ("sheen_color", [0.0, 0.0, 0.0], (0.0, 1.0)),
        "sheenRoughnessFactor": ("sheen_roughness", 0.0, (0.0, 1.0)),
    },
    # KHR_materials_volume: read by _volume (a thickness of 0 is thin-walled, attenuationDistance
    # is infinite unless given).
    "KHR_materials_volume": {},
}
# Material extensions read here (the rest are warned as ignored).
MATERIAL_EXTENSIONS_USED = {"MOZ_lightmap", "KHR_materials_emissive_strength", *GLTF_MODEL_EXTENSIONS}
# The extensions' textures lobeview reads per pixel: extension -> {glTF field: (slot of
# scene.TEXTURE_SLOTS, the channels the extension reads from it)}. Two textures that share a slot
# (clearcoat factor R + roughness G; specular colour RGB + factor A) are combined channel-wise
# (_extension_slot); the factors multiply the texels as each extension specifies.
EXTENSION_SLOTS = {
    "KHR_materials_anisotropy": {"anisotropyTexture": ("anisotropy", (0, 1, 2))},
    "KHR_materials_clearcoat": {
        "clearcoatTexture": ("clearcoat", (0,)),
        "clearcoatRoughnessTexture": ("clearcoat", (1,)),
        "clearcoatNormalTexture": ("clearcoat_normal", (0, 1, 2)),
    },
    "KHR_materials_specular": {
        "specularColorTexture": ("specular", (0, 1, 2)),
        "specularTexture": ("specular", (3,)),
    },
    "KHR_materials_transmission": {"transmissionTexture": ("transmission", (0,))},
    "KHR_materials_sheen": {"sheenColorTexture": ("sheen_color", (0, 1, 2))},
}
# Extension textures that are read but not honoured (warned: the factor applies uniformly).
EXTENSION_TEXTURES_UNUSED = {
    "KHR_materials_sheen": ("sheenRoughnessTexture",),  # the E_s table is per material roughness
    "KHR_materials_volume": ("thicknessTexture",),  # the thickness factor applies uniformly
}


def _texture_transform(info, where: str, scene_warnings: list) -> tuple[np.ndarray, int | None]:
    """KHR_texture_transform of a textureInfo: the 3x3 UV matrix translation x rotation x scale
    (the extension's definition) and its texCoord override (None: the textureInfo's)."""
    extension = (getattr(info, "extensions", None) or {}).get("KHR_texture_transform")
    if extension is None:
        return np.eye(3), None
    try:
        offset = np.asarray(extension.get("offset", [0.0, 0.0]), dtype=np.float64).reshape(2)
        rotation = float(extension.get("rotation", 0.0))
        scale = np.asarray(extension.get("scale", [1.0, 1.0]), dtype=np.float64).reshape(2)
        tex_coord = extension.get("texCoord")
        if not (np.all(np.isfinite(offset)) and np.isfinite(rotation) and np.all(np.isfinite(scale))):
            raise ValueError("non-finite value")
    except (TypeError, ValueError, AttributeError) as exc:
        _warn(scene_warnings, f"{where}: KHR_texture_transform unreadable ({exc}); ignored")
        return np.eye(3), None
    c, s = np.cos(rotation), np.sin(rotation)
    translation = np.array([[1.0, 0.0, offset[0]], [0.0, 1.0, offset[1]], [0.0, 0.0, 1.0]])
    rotate = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return translation @ rotate @ np.diag([scale[0], scale[1], 1.0]), tex_coord


def _texture_slot(reader, info, slot: str, material: str, scene_warnings: list, fallback: str):
    """A material's textureInfo as a :class:`TextureSlot`, or None (warned) when unusable."""
    if info is None:
        return None
    where = f"{reader.path}: material {material!r}: {slot.replace('_', ' ')} texture"
    image = reader.image(info.index, stored=True)
    if image is None:
        _warn(scene_warnings, f"{where} missing or unusable ({reader.last_image_problem}); {fallback}")
        return None
    out = TextureSlot(image, srgb=slot in COLOUR_SLOTS and image.dtype == np.uint8, source=where)
    texture = reader.gltf.textures[info.index]
    if texture.sampler is not None:
        try:
            sampler = _index(reader.gltf.samplers, texture.sampler, "sampler", reader.path)
        except GltfError as exc:
            _warn(scene_warnings, f"{where}: {exc}; default sampler (repeat, trilinear)")
            sampler = None
        if sampler is not None:
            # A missing or invalid value keeps the TextureSlot default (repeat, trilinear).
            for attribute, field, allowed in (
                ("wrapS", "wrap_s", WRAP_MODES),
                ("wrapT", "wrap_t", WRAP_MODES),
                ("magFilter", "mag_filter", MAG_FILTERS),
                ("minFilter", "min_filter", MIN_FILTERS),
            ):
                value = getattr(sampler, attribute)
                if value is not None and value not in allowed:
                    _warn(scene_warnings, f"{where}: sampler {attribute} {value!r} is not a glTF value; default used")
                elif value is not None:
                    setattr(out, field, int(value))
    transform, override = _texture_transform(info, where, scene_warnings)
    out.transform = transform
    tex_coord = override if override is not None else (info.texCoord or 0)
    if not isinstance(tex_coord, int) or tex_coord not in (0, 1):
        _warn(scene_warnings, f"{where}: texCoord {tex_coord!r} (lobeview reads TEXCOORD_0 and _1); TEXCOORD_0 used")
        tex_coord = 0
    out.tex_coord = tex_coord
    return out


def _checked_number(value, default, limits, label: str, scene_warnings: list):
    """A glTF number or array of ``default``'s shape (None: absent, ``default``): a value of
    another shape or type, or not finite, is unusable (warned, ``default`` used); one outside
    ``limits`` (low, high; None: any) is clamped with a warning. Returns a float or a list.
    docs/guide.md "glTF numbers" lists every number the loader checks."""
    if value is None:  # absent: the specification's default
        return default if isinstance(default, float) else list(default)
    try:
        if isinstance(value, bool):
            raise TypeError
        array = np.asarray(value, dtype=np.float64)
        if array.shape != np.shape(default) or not np.all(np.isfinite(array)):
            raise ValueError
    except (TypeError, ValueError):
        _warn(scene_warnings, f"{label} {quoted(value)} is unusable; {default} used")
        array = np.asarray(default, dtype=np.float64)
    if limits is not None and (np.any(array < limits[0]) or np.any(array > limits[1])):
        _warn(scene_warnings, f"{label} {array.tolist()} clamped to {list(limits)}")
        array = np.clip(array, *limits)
    return array.tolist() if array.ndim else float(array)


def _model_extensions(mat, where: str, scene_warnings: list) -> dict:
    """KHR_materials_anisotropy/_ior/_specular/_clearcoat/_transmission/_sheen as the gltf
    model's optional keys (materials/spec.py GLTF_EXTENSION_KEYS). Out-of-range factors are
    clamped with a warning; the textures are read by _extension_textures."""
    out: dict = {}
    for extension, fields in GLTF_MODEL_EXTENSIONS.items():
        data = (mat.extensions or {}).get(extension)
        if data is None:
            continue
        if not isinstance(data, dict):
            _warn(scene_warnings, f"{where}: {extension} is not an object; ignored")
            continue
        for field, (key, default, limits) in fields.items():
            value = _checked_number(
                data.get(field, default), default, limits, f"{where}: {extension}.{field}", scene_warnings
            )
            out[key] = value
        unused = [name for name in EXTENSION_TEXTURES_UNUSED.get(extension, ()) if data.get(name) is not None]
        if unused:
            _warn(
                scene_warnings,
                f"{where}: {extension} {', '.join(unused)} not used yet; its factor applies uniformly",
            )
    out.update(_volume(mat, where, scene_warnings))
    if "anisotropy_rotation" in out:
        out["anisotropy_rotation"] = float(np.remainder(out["anisotropy_rotation"] + np.pi, 2 * np.pi) - np.pi)
    ior = out.get("ior")
    if ior is not None and not (ior == 0.0 or 1.0 <= ior <= 10.0):
        _warn(scene_warnings, f"{where}: KHR_materials_ior ior {ior} is neither 0 nor in [1, 10]; 1.5 used")
        out["ior"] = 1.5
    return out


def _volume(mat, where: str, scene_warnings: list) -> dict:
    """KHR_materials_volume as the gltf model's thickness / attenuation keys (materials/volume.py):
    thicknessFactor (mesh units, 0: thin-walled, then nothing is kept), attenuationColor and a
    finite attenuationDistance (absent: the spec's infinity, no attenuation)."""
    volume = (mat.extensions or {}).get("KHR_materials_volume")
    if not isinstance(volume, dict):
        return {}
    label = f"{where}: KHR_materials_volume"
    thickness = _checked_number(volume.get("thicknessFactor", 0.0), 0.0, RANGES["thickness"],
                                f"{label}.thicknessFactor", scene_warnings)  # fmt: skip
    if thickness <= 0.0:
        return {}
    out = {"thickness": thickness}
    colour = _checked_number(volume.get("attenuationColor"), [1.0, 1.0, 1.0], RANGES["attenuation_color"],
                             f"{label}.attenuationColor", scene_warnings)  # fmt: skip
    distance = volume.get("attenuationDistance")
    if distance is not None:
        checked = _checked_number(distance, 0.0, None, f"{label}.attenuationDistance", scene_warnings)
        low, high = RANGES["attenuation_distance"]
        if low <= checked <= high:
            out["attenuation_distance"], out["attenuation_color"] = checked, colour
        else:
            _warn(scene_warnings, f"{label}.attenuationDistance {quoted(distance)} is not in (0, 1e30]; "
                  "no attenuation")  # fmt: skip
    return out


def _texture_info(value, where: str, scene_warnings: list):
    """An extension's textureInfo (a JSON object) as the attributes _texture_slot reads."""
    if value is None:
        return None
    index = value.get("index") if isinstance(value, dict) else None
    if not isinstance(index, int) or isinstance(index, bool):
        _warn(scene_warnings, f"{where} is not a textureInfo with an integer index; its factor applies uniformly")
        return None
    return types.SimpleNamespace(
        index=index,
        texCoord=value.get("texCoord", 0),
        extensions=value.get("extensions") if isinstance(value.get("extensions"), dict) else None,
        scale=value.get("scale", 1.0),
    )


def _same_sampling(a: TextureSlot, b: TextureSlot) -> bool:
    return (a.tex_coord, a.wrap_s, a.wrap_t, a.mag_filter, a.min_filter) == (
        b.tex_coord, b.wrap_s, b.wrap_t, b.mag_filter, b.min_filter
    ) and np.array_equal(a.transform, b.transform)  # fmt: skip


def _extension_slot(slot: str, parts: list, where: str, scene_warnings: list) -> TextureSlot:
    """One slot from the extension textures that fill it: ``parts`` = [(TextureSlot, channels,
    glTF field)]. A texture that is the slot's only source and the same image for every channel
    is used as it is; otherwise the channels are copied into one image whose other channels
    are 1 (the texel that leaves the factor unchanged). A texture of another size, UV set,
    transform or sampler than the first cannot share its slot: warned, its factor applies."""
    first = parts[0][0]
    shared = all(
        _same_sampling(part[0], first) and (part[0].image is first.image or np.array_equal(part[0].image, first.image))
        for part in parts
    )
    if shared and (len(parts) > 1 or slot not in ("clearcoat", "specular")):
        return first
    as_uint8 = all(part[0].image.dtype == np.uint8 for part in parts)
    height, width = first.image.shape[:2]
    combined = np.full((height, width, 4), 255 if as_uint8 else 1.0, np.uint8 if as_uint8 else np.float32)
    for texture, channels, field_name in parts:
        if texture.image.shape[:2] != (height, width) or not _same_sampling(texture, first):
            _warn(
                scene_warnings,
                f"{where}: {field_name} differs from {parts[0][2]} in size, UV set, transform or sampler and "
                "cannot share its slot; its factor applies uniformly",
            )
            continue
        # uint8 images are RGBA as stored (Reader.image(stored=True)); others decode to linear RGBA.
        values = texture.image if as_uint8 else texture.linear()
        combined[..., list(channels)] = values[..., list(channels)]
    return dataclasses.replace(first, image=combined, srgb=as_uint8 and slot in COLOUR_SLOTS)


def _extension_textures(reader, mat, name: str, out: SceneMaterial, scene_warnings: list) -> None:
    """The KHR material extensions' textures (EXTENSION_SLOTS) as per-pixel slots of ``out``."""
    gathered: dict[str, list] = {}
    for extension, fields in EXTENSION_SLOTS.items():
        data = (mat.extensions or {}).get(extension)
        if not isinstance(data, dict):
            continue
        for field_name, (slot, channels) in fields.items():
            where = f"{reader.path}: material {name!r}: {extension}.{field_name}"
            info = _texture_info(data.get(field_name), where, scene_warnings)
            texture = _texture_slot(reader, info, slot, name, scene_warnings, "its factor applies uniformly")
            if texture is None:
                continue
            gathered.setdefault(slot, []).append((texture, channels, field_name))
            if field_name == "clearcoatNormalTexture":
                out.clearcoat_normal_scale = _checked_number(
                    1.0 if info.scale is None else info.scale, 1.0, None, f"{where}.scale", scene_warnings
                )
    for slot, parts in gathered.items():
        where = f"{reader.path}: material {name!r}: {slot.replace('_', ' ')} texture"
        out.textures[slot] = _extension_slot(slot, parts, where, scene_warnings)


def _custom_material(reader, custom) -> dict:
    """``extras.lobeview`` of a material: a preset name, a material object, or the name of a JSON
    file in the scene's folder (never a path outside it: the scene file is untrusted)."""
    from lobeview.materials.presets import PRESETS

    if isinstance(custom, dict):
        # A measured table is named relative to the scene's folder, like every scene reference.
        return resolve_material_files(validate(custom), reader.path.parent, reader.limits)
    if not isinstance(custom, str):
        raise MaterialError(f"extras.lobeview must be a preset name, a material object or a JSON file, not {custom!r}")
    if custom in PRESETS:
        return validate(PRESETS[custom])
    try:
        text = read_reference(reader.path.parent, custom, f"{reader.path}: material file", reader.limits)
    except FileNotFoundError:
        names = ", ".join(sorted(PRESETS))
        raise MaterialError(f"{custom!r} is neither a preset name ({names}) nor a file in the scene's folder") from None
    except UntrustedReferenceError as exc:
        raise MaterialError(str(exc)) from None
    try:
        return resolve_material_files(validate(json.loads(text)), reader.path.parent, reader.limits)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise MaterialError(f"material file {custom!r} is not valid JSON: {exc}") from None


def _material(reader, index: int | None, scene_warnings: list) -> SceneMaterial:
    gltf = reader.gltf
    path = reader.path
    if index is None:
        return SceneMaterial(
            "default",
            validate({"model": "gltf", "base_color": [0.8, 0.8, 0.8], "metallic": 0.0, "roughness": 1.0}),
        )
    mat = gltf.materials[index]
    name = mat.name or f"material{index}"
    pbr = mat.pbrMetallicRoughness
    extras = mat.extras or {}
    custom = extras.get("lobeview") if isinstance(extras, dict) else None
    where = f"{path}: material {name!r}"
    raw_base = getattr(pbr, "baseColorFactor", None) if pbr else None
    base_factor = _checked_number(
        [1.0, 1.0, 1.0, 1.0] if raw_base is None else raw_base, [1.0, 1.0, 1.0, 1.0], (0.0, 1.0),
        f"{where}: baseColorFactor", scene_warnings,
    )  # fmt: skip
    try:
        if custom is not None:
            desc = _custom_material(reader, custom)
        else:
            desc = validate(
                {
                    "model": "gltf",
                    "base_color": base_factor[:3],
                    "metallic": _checked_number(
                        getattr(pbr, "metallicFactor", None) if pbr else None, 1.0, (0.0, 1.0),
                        f"{where}: metallicFactor", scene_warnings,
                    ),
                    "roughness": _checked_number(
                        getattr(pbr, "roughnessFactor", None) if pbr else None, 1.0, (0.0, 1.0),
                        f"{where}: roughnessFactor", scene_warnings,
                    ),
                    **_model_extensions(mat, where, scene_warnings),
                }
            )  # fmt: skip
    except MaterialError as exc:
        raise GltfError(f"{path}: material {name!r}: {exc}") from None
    out = SceneMaterial(name, desc, double_sided=bool(mat.doubleSided))
    gltf_model = desc["model"] == "gltf"
    out.base_alpha = float(base_factor[3])
    mode = mat.alphaMode or "OPAQUE"
    if mode not in ALPHA_MODES:
        _warn(scene_warnings, f"{path}: material {name!r}: alphaMode {mode!r} is not a glTF mode; OPAQUE used")
        mode = "OPAQUE"
    out.alpha_mode = mode
    cutoff = 0.5 if mat.alphaCutoff is None else mat.alphaCutoff
    if not (isinstance(cutoff, (int, float)) and np.isfinite(cutoff) and cutoff >= 0):
        _warn(scene_warnings, f"{path}: material {name!r}: alphaCutoff {cutoff!r} is invalid; 0.5 used")
        cutoff = 0.5
    out.alpha_cutoff = float(cutoff)
    slots = {
        "base_color": (pbr.baseColorTexture if pbr else None, FALLBACKS["missing image"]),
        "metallic_roughness": (
            (pbr.metallicRoughnessTexture if pbr else None) if gltf_model else None,
            "metallic and roughness factors only",
        ),
        "normal": (mat.normalTexture, FALLBACKS["missing normal map"]),
        "occlusion": (mat.occlusionTexture, FALLBACKS["missing occlusion map"]),
        "emissive": (mat.emissiveTexture, "the emissive factor alone"),
    }
    if not gltf_model and pbr is not None and pbr.metallicRoughnessTexture is not None:
        _warn(
            scene_warnings,
            f"{path}: material {name!r}: metallicRoughnessTexture ignored (extras.lobeview replaces the glTF BRDF)",
        )
    if not gltf_model:  # the glTF model's extensions have nothing to act on
        for extension in sorted(set(mat.extensions or {}) & set(GLTF_MODEL_EXTENSIONS)):
            _warn(
                scene_warnings,
                f"{path}: material {name!r}: {extension} ignored (extras.lobeview replaces the glTF BRDF)",
            )
    for slot, (info, fallback) in slots.items():
        texture = _texture_slot(reader, info, slot, name, scene_warnings, fallback)
        if texture is not None:
            out.textures[slot] = texture
    if gltf_model:
        _extension_textures(reader, mat, name, out, scene_warnings)
    if mat.normalTexture is not None and "normal" in out.textures:
        scale = getattr(mat.normalTexture, "scale", None)
        out.normal_scale = _checked_number(
            1.0 if scale is None else scale, 1.0, None, f"{where}: normalTexture.scale", scene_warnings
        )
    if mat.occlusionTexture is not None and "occlusion" in out.textures:
        strength = getattr(mat.occlusionTexture, "strength", None)
        out.occlusion_strength = _checked_number(
            1.0 if strength is None else strength,
            1.0,
            (0.0, 1.0),
            f"{where}: occlusionTexture.strength",
            scene_warnings,
        )
    # Material extensions lobeview does not honour yet: said once per material, never dropped silently.
    for extension in sorted(set(mat.extensions or {}) - MATERIAL_EXTENSIONS_USED):
        _warn(
            scene_warnings,
            f"{path}: material {name!r}: {extension} is not supported yet; the material renders without it"
            " (docs/guide.md: glTF support)",
        )
    out.emission = _emission(mat, f"{path}: material {name!r}", scene_warnings)
    lightmap_ext = (mat.extensions or {}).get("MOZ_lightmap")
    if lightmap_ext is not None and not isinstance(lightmap_ext, dict):
        _warn(scene_warnings, f"{path}: material {name!r}: MOZ_lightmap {quoted(lightmap_ext)} is no object; ignored")
        lightmap_ext = None
    if lightmap_ext is not None:
        image = reader.image(lightmap_ext.get("index", -1))
        if image is None:
            _warn(
                scene_warnings,
                f"{path}: material {name!r}: lightmap image missing or unusable ({reader.last_image_problem}); "
                + FALLBACKS["missing lightmap"],
            )
        else:
            if id(image) not in reader.sanitized:  # once per image, however many materials share it
                reader.sanitized[id(image)] = (image, sanitize_radiance(image, f"{path}: lightmap of {name!r}")[0])
            clean = reader.sanitized[id(image)][1]
            where = f"{path}: material {name!r}: MOZ_lightmap"
            tex_coord = lightmap_ext.get("texCoord", 1)
            if isinstance(tex_coord, bool) or tex_coord not in (0, 1):
                _warn(scene_warnings, f"{where} texCoord {quoted(tex_coord)} is not 0 or 1; TEXCOORD_1 used")
                tex_coord = 1
            intensity = lightmap_ext.get("intensity", 1.0)
            if not _is_number(intensity) or not np.isfinite(intensity) or intensity < 0:
                # a negative intensity rendered negative radiance without a word (issue 43)
                _warn(scene_warnings, f"{where} intensity {quoted(intensity)} is not a finite number >= 0; 1 used")
                intensity = 1.0
            out.lightmap = Lightmap(clean, tex_coord=int(tex_coord), intensity=float(intensity), source=name)
    return out


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _emission(mat, where: str, scene_warnings: list) -> np.ndarray:
    """emissiveFactor (3 numbers in [0, 1]) times KHR_materials_emissive_strength (a number >= 0),
    validated: another length or a non-finite value is warned and gives no emission (it reached
    the shaders' uniform packing as a struct.error, issue 43), values outside their range are
    clamped with a warning."""
    raw = mat.emissiveFactor if mat.emissiveFactor is not None else [0.0, 0.0, 0.0]
    if not (isinstance(raw, (list, tuple)) and len(raw) == 3 and all(_is_number(v) for v in raw)) or not all(
        np.isfinite(v) for v in raw
    ):
        _warn(scene_warnings, f"{where}: emissiveFactor {quoted(raw)} is not 3 finite numbers; no emission")
        return np.zeros(3)
    emissive = np.asarray(raw, dtype=np.float64)
    if np.any((emissive < 0) | (emissive > 1)):
        _warn(scene_warnings, f"{where}: emissiveFactor {quoted(raw)} clamped to [0, 1]")
        emissive = np.clip(emissive, 0.0, 1.0)
    extension = (mat.extensions or {}).get("KHR_materials_emissive_strength", {})
    strength = extension.get("emissiveStrength", 1.0) if isinstance(extension, dict) else None
    if not _is_number(strength) or not np.isfinite(strength) or strength < 0:
        _warn(scene_warnings, f"{where}: emissiveStrength {quoted(strength)} is not a finite number >= 0; 1 used")
        strength = 1.0
    return emissive * float(strength)
