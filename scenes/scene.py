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


@dataclass
class SceneMaterial:
    name: str
    desc: dict  # validated material description (lobeview.materials.spec)
    base_color_texture: np.ndarray | None = None  # (H, W, 3) linear, multiplies kd
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))  # emitted radiance
    lightmap: Lightmap | None = None
    double_sided: bool = False


@dataclass
class SceneObject:
    name: str
    mesh: Mesh  # world space
    material: int
    uv1: np.ndarray | None = None  # (V, 2) lightmap coordinates
    reflection_proxy: object | None = None  # scenes.reflection_proxy.ReflectionProxy (None: plain lookup)
    planar_reflector: bool | str = "auto"  # mirror pass: True, False or "auto" (scenes/planar_mirror.py)


@dataclass
class SceneCamera:
    name: str
    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_y: float


@dataclass
class Scene:
    objects: list[SceneObject]
    materials: list[SceneMaterial]
    cameras: list[SceneCamera] = field(default_factory=list)
    source: str = ""
    warnings: list[str] = field(default_factory=list)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lows = [o.mesh.positions.min(axis=0) for o in self.objects]
        highs = [o.mesh.positions.max(axis=0) for o in self.objects]
        return np.min(lows, axis=0), np.max(highs, axis=0)
