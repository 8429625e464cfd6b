"""The in-memory scene: world-space triangle meshes with materials and lightmaps, cameras.

Static scenes only (walkthroughs): node transforms are applied at load time, so every
:class:`SceneObject` holds world-space geometry.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .meshes import Mesh


@dataclass
class Lightmap:
    """Linear irradiance E (W/m^2-like units, RGB) over TEXCOORD_``tex_coord``."""

    image: np.ndarray  # (H, W, 3) float32, row 0 = v 0 (glTF: top of the image)
    tex_coord: int = 1
    intensity: float = 1.0
    source: str = ""


# glTF sampler enums (OpenGL values, as the specification uses them).
REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT = 10497, 33071, 33648
NEAREST, LINEAR = 9728, 9729
NEAREST_MIPMAP_NEAREST, LINEAR_MIPMAP_NEAREST, NEAREST_MIPMAP_LINEAR, LINEAR_MIPMAP_LINEAR = 9984, 9985, 9986, 9987
WRAP_MODES = (REPEAT, CLAMP_TO_EDGE, MIRRORED_REPEAT)
MAG_FILTERS = (NEAREST, LINEAR)
MIN_FILTERS = (
    NEAREST,
    LINEAR,
    NEAREST_MIPMAP_NEAREST,
    LINEAR_MIPMAP_NEAREST,
    NEAREST_MIPMAP_LINEAR,
    LINEAR_MIPMAP_LINEAR,
)

# The texture slots of a glTF material (core specification 3.9) in the order shaders bind them.
TEXTURE_SLOTS = (
    "base_color",
    "metallic_roughness",
    "normal",
    "occlusion",
    "emissive",
    # KHR material extensions' textures (gltf_loader.EXTENSION_SLOTS says which texture fills
    # which channel): anisotropy (RG direction, B strength), clearcoat (R factor, G roughness),
    # the clearcoat's normal map, specular (RGB colour, A factor), transmission (R), sheen colour.
    "anisotropy",
    "clearcoat",
    "clearcoat_normal",
    "specular",
    "transmission",
    "sheen_color",
)
# sRGB-encoded colour (alpha linear); the others hold linear data
COLOUR_SLOTS = ("base_color", "emissive", "specular", "sheen_color")
ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")  # glTF alphaMode, in the order of the shaders' codes


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1), values in [0, 1]."""
    values = np.asarray(values, dtype=np.float32)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4).astype(np.float32)


@dataclass
class TextureSlot:
    """One glTF ``textureInfo``: the image, which UV set, its sampler and KHR_texture_transform.

    ``image`` is what the file stores: (H, W, 4) uint8 (sRGB-encoded when ``srgb``, as glTF's
    colour textures are; the GPU decodes it before filtering with an SRGB8_ALPHA8 texture), or
    float32 (H, W, 3|4) linear values for generated scenes. Row 0 is v = 0, the top of the image
    (glTF's UV origin)."""

    image: np.ndarray
    srgb: bool = False
    tex_coord: int = 0
    wrap_s: int = REPEAT
    wrap_t: int = REPEAT
    mag_filter: int = LINEAR
    min_filter: int = LINEAR_MIPMAP_LINEAR
    transform: np.ndarray = field(default_factory=lambda: np.eye(3))  # uv' = (T @ [u, v, 1])[:2]
    source: str = ""
    # linear()'s result for the image it was made from (the baker samples a mask per ray batch).
    _linear: tuple | None = field(default=None, repr=False, compare=False)

    def linear(self) -> np.ndarray:
        """(H, W, 4) float32 linear values (sRGB decoded, alpha linear; alpha 1 if absent);
        decoded once per image and srgb flag (read-only result)."""
        if self._linear is not None and self._linear[0] is self.image and self._linear[1] == self.srgb:
            return self._linear[2]
        values = self._decode()
        values.setflags(write=False)
        self._linear = (self.image, self.srgb, values)
        return values

    def _decode(self) -> np.ndarray:
        image = self.image
        if image.dtype == np.uint8:
            values = image.astype(np.float32) / 255.0
            if self.srgb:
                values[..., :3] = srgb_to_linear(values[..., :3])
        else:
            values = image.astype(np.float32)
        if values.shape[-1] == 3:
            values = np.concatenate([values, np.ones(values.shape[:-1] + (1,), np.float32)], axis=-1)
        return values

    def key(self) -> bytes:
        """Everything that decides what the slot looks like (cube-map cache keys)."""
        import hashlib

        h = hashlib.sha256(np.ascontiguousarray(self.image).tobytes())
        h.update(repr((self.image.shape, str(self.image.dtype), self.srgb, self.tex_coord, self.wrap_s,
                       self.wrap_t, self.mag_filter, self.min_filter)).encode())  # fmt: skip
        h.update(np.asarray(self.transform, np.float64).tobytes())
        return h.digest()


@dataclass
class SceneMaterial:
    """A material of the scene: the BSDF description plus glTF's per-pixel inputs.

    For the ``gltf`` model the textures act as the specification says (Appendix B): base colour
    (RGBA) x factor, metallic (B) and roughness (G) x factors, a tangent-space normal map scaled
    by ``normal_scale``, occlusion on the indirect diffuse by ``occlusion_strength``, emission x
    the emissive texture; the KHR extensions' textures multiply their factors (anisotropy
    direction and strength, clearcoat factor and roughness, the clearcoat's own normal map,
    specular colour and factor, transmission, sheen colour). For the other models the base-colour
    texture multiplies kd."""

    name: str
    desc: dict  # validated material description (lobeview.materials.spec)
    base_color_texture: np.ndarray | None = None  # generated scenes: (H, W, 3) linear, multiplies kd
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))  # emitted radiance
    lightmap: Lightmap | None = None
    double_sided: bool = False
    textures: dict = field(default_factory=dict)  # slot name (TEXTURE_SLOTS) -> TextureSlot
    base_alpha: float = 1.0  # baseColorFactor's alpha
    alpha_mode: str = "OPAQUE"  # OPAQUE, MASK (alpha_cutoff) or BLEND
    alpha_cutoff: float = 0.5
    normal_scale: float = 1.0
    occlusion_strength: float = 1.0
    clearcoat_normal_scale: float = 1.0  # KHR_materials_clearcoat's clearcoatNormalTexture.scale

    def __post_init__(self):
        if self.base_color_texture is not None and "base_color" not in self.textures:
            self.textures["base_color"] = TextureSlot(np.asarray(self.base_color_texture, np.float32), source=self.name)

    def texture(self, slot: str) -> TextureSlot | None:
        return self.textures.get(slot)


@dataclass
class SceneObject:
    name: str
    mesh: Mesh  # world space
    material: int
    uv1: np.ndarray | None = None  # (V, 2) lightmap coordinates
    reflection_proxy: object | None = None  # scenes.reflection_proxy.ReflectionProxy (None: plain lookup)
    planar_reflector: bool | str = "auto"  # mirror pass: True, False or "auto" (scenes/planar_mirror.py)
    # Where a loaded object came from, so that `lobeview bake` can write the input file back with
    # only the lightmap added: (node, mesh, primitive) indices of the glTF and whether the node's
    # transform mirrors (the loader then reversed the triangles' winding). None: generated.
    origin: tuple[int, int, int, bool] | None = None
    # After a lightmap unwrap: the loaded vertex each vertex of ``mesh`` copies (xatlas splits
    # vertices along chart seams). None: the vertices are the file's, one to one.
    vertex_map: np.ndarray | None = None
    # Mesh units to world units (the cube root of the node transform's |determinant|): a
    # KHR_materials_volume thickness is given in the mesh's units (materials/volume.py).
    volume_scale: float = 1.0
    # (V, 4) visibility cones against the object itself (scenes/self_visibility.py), traced on
    # first use; None: not yet.
    self_visibility: np.ndarray | None = None


@dataclass
class SceneCamera:
    name: str
    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_y: float


LIGHT_TYPES = ("point", "spot", "directional")  # KHR_lights_punctual


@dataclass
class PunctualLight:
    """A KHR_lights_punctual lamp in world space. ``intensity`` x ``colour`` is the radiant
    intensity of point and spot lamps (the extension's candela) and the irradiance at normal
    incidence of directional ones (its lux), in the environment's units: one candela is one
    unit, as the Khronos Sample Viewer takes it."""

    name: str
    type: str  # one of LIGHT_TYPES
    colour: np.ndarray  # linear RGB
    intensity: float
    position: np.ndarray  # world space (unused by directional lamps)
    direction: np.ndarray  # unit vector the lamp shines along (its node's -Z)
    range: float | None = None  # None: infinite (point and spot lamps)
    inner_cone: float = 0.0  # spot lamps, radians
    outer_cone: float = np.pi / 4


@dataclass
class Scene:
    objects: list[SceneObject]
    materials: list[SceneMaterial]
    cameras: list[SceneCamera] = field(default_factory=list)
    source: str = ""
    warnings: list[str] = field(default_factory=list)
    lights: list[PunctualLight] = field(default_factory=list)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lows = [o.mesh.positions.min(axis=0) for o in self.objects]
        highs = [o.mesh.positions.max(axis=0) for o in self.objects]
        return np.min(lows, axis=0), np.max(highs, axis=0)
