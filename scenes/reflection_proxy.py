"""Reflected-geometry correction for cube maps (thesis 4.4.1, and the parallax-corrected /
box-projected cube maps of game engines).

A cube map holds the scene as seen from one point C (the object's bounding-box centre); a
secondary ray from a surface point P in direction w is looked up as if it started at C, so what
it shows is shifted by P - C (Fig. 4.4). With a proxy of the surrounding geometry the ray is
intersected with the proxy at H = P + t w and the cube map is read toward H - C instead (Fig.
4.5): geometry that lies on the proxy (floor, walls, ceiling) is then reflected where a ray
tracer would show it; everything else is sheared (Fig. 4.6), so the correction is chosen per
object and off by default.

Proxies:
- ``planes``: up to MAX_PROXY_PLANES user planes n.x + d = 0 (the thesis' bounding planes);
  the nearest hit in front of P wins; rays that hit none keep their direction.
- ``box``: an axis-aligned box seen from inside (parallax-corrected cube maps): the exit point.

The solid angle a sample covers changes with the lookup distance: seen from C a footprint at H
subtends (|H - P| / |H - C|)^2 times its solid angle from P, i.e. the MIP level moves by
log2(|H - P| / |H - C|) (lod = 0.5 log2 of the solid angle), which :func:`corrected_directions`
returns with the directions.

Scene files set it per node: ``extras: {"lobeview": {"reflection_proxy": {"type": "planes",
"planes": [[0, 1, 0, 0]]}}}`` or ``{"type": "box", "min": [...], "max": [...]}``, or the
automatic forms ``{"type": "floor"}`` (the plane y = scene minimum) and ``{"type": "room"}``
(the scene's bounding box).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

MAX_PROXY_PLANES = 6
PROXY_KINDS = ("none", "planes", "box")


class ProxyError(ValueError):
    pass


@dataclass(frozen=True)
class ReflectionProxy:
    kind: str  # 'planes' or 'box'
    planes: np.ndarray = None  # (K, 4): unit normal n and d with n.x + d = 0
    box_min: np.ndarray = None
    box_max: np.ndarray = None

    @classmethod
    def from_planes(cls, planes) -> ReflectionProxy:
        planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
        if not 1 <= len(planes) <= MAX_PROXY_PLANES:
            raise ProxyError(f"reflection proxy: 1 to {MAX_PROXY_PLANES} planes, got {len(planes)}")
        if not np.all(np.isfinite(planes)):
            raise ProxyError("reflection proxy: plane coefficients must be finite")
        norms = np.linalg.norm(planes[:, :3], axis=1)
        if np.any(norms < 1e-9):
            raise ProxyError("reflection proxy: a plane has a zero normal")
        return cls("planes", planes=planes / norms[:, None])

    @classmethod
    def from_box(cls, box_min, box_max) -> ReflectionProxy:
        lo, hi = np.asarray(box_min, np.float64).reshape(3), np.asarray(box_max, np.float64).reshape(3)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
            raise ProxyError(f"reflection proxy: box needs finite min < max, got {lo.tolist()} .. {hi.tolist()}")
        return cls("box", box_min=lo, box_max=hi)

    @classmethod
    def from_description(cls, desc: dict, scene_bounds) -> ReflectionProxy | None:
        """A node's ``reflection_proxy`` extras (module docstring); None for type 'none'."""
        if not isinstance(desc, dict) or "type" not in desc:
            raise ProxyError(f"reflection proxy: expected an object with a 'type', got {desc!r}")
        kind = desc["type"]
        lo, hi = (np.asarray(b, np.float64) for b in scene_bounds)
        if kind == "none":
            return None
        if kind == "planes":
            return cls.from_planes(desc.get("planes", []))
        if kind == "box":
            return cls.from_box(desc.get("min"), desc.get("max"))
        if kind == "floor":
            return cls.from_planes([[0.0, 1.0, 0.0, -lo[1]]])
        if kind == "room":
            return cls.from_box(lo, hi)
        raise ProxyError(f"reflection proxy: unknown type {kind!r}; use planes, box, floor, room or none")

    def to_description(self) -> dict:
        """The node-extras form (written by scenes/gltf_writer.py)."""
        if self.kind == "planes":
            return {"type": "planes", "planes": self.planes.tolist()}
        return {"type": "box", "min": self.box_min.tolist(), "max": self.box_max.tolist()}

    def hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance t > 0 along each ray to the proxy (inf where it misses)."""
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        d = np.asarray(directions, np.float64).reshape(-1, 3)
        if self.kind == "planes":
            n, dist = self.planes[:, :3], self.planes[:, 3]
            denom = d @ n.T  # (R, K)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -(o @ n.T + dist) / denom
            t = np.where((np.abs(denom) > 1e-12) & (t > 1e-6), t, np.inf)
            return t.min(axis=1)
        # Box seen from inside: the exit distance, min over axes of the far slab.
        with np.errstate(divide="ignore", invalid="ignore"):
            far = np.where(d > 0, (self.box_max - o) / d, np.where(d < 0, (self.box_min - o) / d, np.inf))
        t = far.min(axis=1)
        return np.where(t > 1e-6, t, np.inf)

    def corrected_directions(self, points, directions, centre) -> tuple[np.ndarray, np.ndarray]:
        """(lookup directions toward H - C, MIP-level offsets log2(|H - P| / |H - C|)); rays that
        miss keep their direction and offset 0."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        d = np.asarray(directions, np.float64).reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        t = self.hit_distance(p, d)
        hit = np.isfinite(t)
        out = d.copy()
        offset = np.zeros(len(d))
        h = p[hit] + t[hit, None] * d[hit]
        to_hit = h - np.asarray(centre, np.float64)
        length = np.linalg.norm(to_hit, axis=1)
        good = length > 1e-9
        idx = np.flatnonzero(hit)[good]
        out[idx] = to_hit[good] / length[good, None]
        offset[idx] = np.log2(np.maximum(t[idx], 1e-9) / length[good])
        return out, offset

    def padded_planes(self) -> np.ndarray:
        """(MAX_PROXY_PLANES, 4) float32: the planes (n, d), zero rows after the last."""
        planes = np.zeros((MAX_PROXY_PLANES, 4), np.float32)
        if self.kind == "planes":
            planes[: len(self.planes)] = self.planes
        return planes


def object_proxy(extras, scene_bounds, name: str) -> ReflectionProxy | None:
    """The proxy in a node's ``extras.lobeview.reflection_proxy``; a bad one is warned about and
    ignored (the object keeps the plain cube-map lookup)."""
    if not isinstance(extras, dict):
        return None
    custom = extras.get("lobeview")
    if not isinstance(custom, dict) or "reflection_proxy" not in custom:
        return None
    try:
        return ReflectionProxy.from_description(custom["reflection_proxy"], scene_bounds)
    except (ProxyError, TypeError, ValueError) as exc:
        warnings.warn(f"node {name!r}: {exc}; using the plain cube-map lookup", stacklevel=2)
        return None
