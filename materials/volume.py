"""Thick transmission (KHR_materials_volume, issue 40 item 4): where light that a glTF
transmission lobe sees through a volume comes from. Numpy reference of shaders/volume.glsl.

glTF gives a volume's thickness beneath each surface point (thicknessFactor, in the mesh's
units), not the shape behind it; real-time renderers assume a local shape of that thickness.
lobeview uses two (the sphere and plane models of Unity HDRP's refraction, blended):

- **sphere**: the volume is the sphere tangent to the surface at P with diameter d (centre
  P - n d / 2). The view ray refracts in (Snell, index ior), crosses the chord s = d cos(theta_t)
  and refracts out at Q = P + s t; by the sphere's symmetry it leaves at the angle it entered, so
  there is never total internal reflection. Exact for a glass ball whose thickness is its
  diameter (a bulb, a marble): the image behind it is inverted, as through a real ball lens.
- **slab**: the volume is a plate of thickness d parallel to the tangent plane: the ray leaves
  parallel to the view ray (-V), shifted, after s = d / cos(theta_t) inside. A window pane.

Which: by the ratio of the thickness to the object's middle bounding-box extent (the second
largest side: a pane's width, a ball's diameter), slab below 0.25, sphere above 0.75, the exit
directions and points blended between (smoothstep), so a thickness texture never makes a seam.

The transmission lobe (materials/gltf.py GltfTransmission, thin-walled: centred on -V) is turned
by the rotation that takes -V to the exit direction, so every method integrates the same lobe
around where the light really comes from, read from the exit point (reflection proxies); its
roughness is kept (a rough surface's two refractions widen the real lobe; not modelled). The
light is attenuated along the path (Beer-Lambert, the extension's attenuationColor^(s /
attenuationDistance)) and by the exit interface (1 - specular max F(theta), the same Fresnel the
lobe takes at the entry, equal there by the symmetry of both models). Inside a plate the light
bounces between the faces (both at that angle) and leaves parallel to the single passes: summed
(incoherently) it adds (1 - F)^2 a^2 / (1 - F^2 a^2) to the front face's reflection F and divides
the transmission by 1 - F^2 a^2 (a: one crossing's attenuation; :func:`slab_gains`), weighted by
the plate's share. Light reflected inside the ball is not followed (it leaves in other
directions; the ball loses ~4 % of its light against a path tracer)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The gltf model's KHR_materials_volume keys (materials/spec.py): the object's, not the BSDF's.
VOLUME_KEYS = ("thickness", "attenuation_color", "attenuation_distance")
# Thickness / middle extent: the slab model up to the first, the sphere model from the second.
SPHERE_RATIO_LOW, SPHERE_RATIO_HIGH = 0.25, 0.75
MIN_COS_VIEW = 1e-4  # N.V floor (normal maps turn some normals away from the viewer)


@dataclass
class VolumePath:
    """Per point: the direction the light leaves the volume towards (unit, world), the exit point
    relative to the entry point, the length of the path inside, the plate model's share and the
    plate's crossing length (for :func:`slab_gains`)."""

    exit_direction: np.ndarray
    exit_offset: np.ndarray
    length: np.ndarray
    slab_weight: np.ndarray
    slab_length: np.ndarray


def volume_of(desc: dict) -> dict | None:
    """A material description's volume (a gltf material with a thickness > 0): its thickness (mesh
    units), ior, and attenuation colour and distance where given; None: thin-walled."""
    if desc.get("model") != "gltf" or not desc.get("thickness", 0.0) > 0.0:
        return None
    return {k: desc[k] for k in VOLUME_KEYS if k in desc} | {"ior": desc.get("ior", 1.5)}


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def _normalize(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def effective_ior(ior) -> np.ndarray:
    """The index the ray bends by: glTF's ior, where 0 (the extensions' infinite index: f0 = 1, a
    mirror that transmits nothing) and values below 1 bend nothing."""
    ior = np.asarray(ior, dtype=np.float64)
    return np.where(ior >= 1.0, ior, 1.0)


def sphere_weight(thickness, extent) -> np.ndarray:
    """The sphere model's share (smoothstep of thickness / middle extent between the ratios)."""
    ratio = np.asarray(thickness, dtype=np.float64) / np.maximum(np.asarray(extent, dtype=np.float64), 1e-30)
    x = np.clip((ratio - SPHERE_RATIO_LOW) / (SPHERE_RATIO_HIGH - SPHERE_RATIO_LOW), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def volume_path(view, normal, ior, thickness, extent) -> VolumePath:
    """The path of the ray that enters at a point with outward unit ``normal`` seen from unit
    ``view`` (towards the viewer), through a volume of ``thickness`` (world units, > 0) in an
    object whose middle extent is ``extent`` (arrays broadcast; last axis xyz)."""
    view, normal = np.broadcast_arrays(np.asarray(view, np.float64), np.asarray(normal, np.float64))
    eta = effective_ior(ior)[..., None]
    d = np.asarray(thickness, dtype=np.float64)[..., None]
    cos_i = np.clip(_dot(view, normal), MIN_COS_VIEW, 1.0)[..., None]
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    inside = -view / eta + (cos_i / eta - cos_t) * normal  # refracted into the volume (unit)
    # Sphere: chord s = d cos_t, exit normal (Q - C) / r = 2 cos_t t + n, refraction out.
    chord = d * cos_t
    exit_normal = 2.0 * cos_t * inside + normal
    sphere_exit = _normalize(eta * inside - (eta * cos_t - cos_i) * exit_normal)
    # Slab: out parallel to the view ray after d / cos_t inside.
    slab_length = d / np.maximum(cos_t, 1e-6)
    w = sphere_weight(thickness, extent)[..., None]
    direction = _normalize((1.0 - w) * (-view) + w * sphere_exit)
    length = (1.0 - w) * slab_length + w * chord
    return VolumePath(direction, length * inside, length[..., 0], 1.0 - w[..., 0], slab_length[..., 0])


def bend_rotation(source, target) -> np.ndarray:
    """The rotation (..., 3, 3) taking unit ``source`` to unit ``target`` about their common
    normal (Rodrigues; identity where they coincide). ``source`` = -V and ``target`` the exit
    direction are never opposite (the exit leaves through the far side)."""
    source, target = np.broadcast_arrays(np.asarray(source, np.float64), np.asarray(target, np.float64))
    axis = np.cross(source, target)
    c = _dot(source, target)[..., None, None]
    k = np.zeros(axis.shape + (3,))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axis[..., 2], -axis[..., 1], axis[..., 0]
    return np.eye(3) + k + (k @ k) / np.maximum(1.0 + c, 1e-12)


def attenuation(length, attenuation_color, attenuation_distance) -> np.ndarray:
    """Beer-Lambert over ``length``: attenuationColor^(length / attenuationDistance) per channel
    (the extension's definition); an infinite distance (None) attenuates nothing."""
    length = np.asarray(length, dtype=np.float64)[..., None]
    if attenuation_distance is None or not np.isfinite(attenuation_distance):
        return np.ones(length.shape[:-1] + (3,))
    colour = np.maximum(np.asarray(attenuation_color, dtype=np.float64), 1e-30)
    return np.exp(np.log(colour) * length / float(attenuation_distance))


def exit_transmittance(cos_view, dielectric_f0, specular_weight) -> np.ndarray:
    """1 - specular max F(cos): what the exit interface lets through (Schlick at the outside
    angle, which both models give the exit the entry's; the entry's own factor is the lobe's)."""
    cos_view = np.clip(np.asarray(cos_view, dtype=np.float64), MIN_COS_VIEW, 1.0)
    f0 = np.max(np.asarray(dielectric_f0, dtype=np.float64))
    fresnel = f0 + (1.0 - f0) * (1.0 - cos_view) ** 5
    return 1.0 - float(specular_weight) * fresnel


def slab_gains(fresnel, crossing) -> tuple[np.ndarray, np.ndarray]:
    """A plate's interreflections, summed incoherently: (gain on the front reflection F, gain on
    the single-pass transmission (1 - F)^2 a) for the faces' reflectance ``fresnel`` F and one
    crossing's attenuation ``crossing`` a (per channel): 1 + (1 - F)^2 a^2 / (1 - F^2 a^2) and
    1 / (1 - F^2 a^2), the geometric series of the bounces."""
    f = np.asarray(fresnel, dtype=np.float64)[..., None]
    a = np.asarray(crossing, dtype=np.float64)
    denominator = 1.0 - f * f * a * a
    return 1.0 + (1.0 - f) ** 2 * a * a / denominator, 1.0 / denominator


def volume_factors(
    path: VolumePath,
    cos_view,
    dielectric_f0,
    specular_weight,
    attenuation_color=(1.0, 1.0, 1.0),
    attenuation_distance=None,
) -> tuple[np.ndarray, np.ndarray]:
    """(what the volume lets through to the turned transmission lobe, the gain on the reflection
    lobe), per channel: the path's attenuation x the exit's transmittance x the plate's
    transmission gain, and the plate's reflection gain, each weighted by the plate's share
    (shaders/volume.glsl volume_shading)."""
    exit_t = np.asarray(exit_transmittance(cos_view, dielectric_f0, specular_weight), dtype=np.float64)
    crossing = attenuation(path.slab_length, attenuation_color, attenuation_distance)
    reflection_gain, transmission_gain = slab_gains(1.0 - exit_t, crossing)
    plate = np.asarray(path.slab_weight, dtype=np.float64)[..., None]
    transmitted = attenuation(path.length, attenuation_color, attenuation_distance) * exit_t[..., None]
    return transmitted * (1.0 + plate * (transmission_gain - 1.0)), 1.0 + plate * (reflection_gain - 1.0)
