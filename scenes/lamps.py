"""KHR_lights_punctual lamps as live lights of the view-dependent shading (issue 39 item 5).

The lightmap bake already gives a lamp's diffuse light (scenes/baker.py lamp_irradiance, with
exact shadows). Its reflection in glossy surfaces needs a source with an area: a punctual lamp
reflected by a mirror would be a point no pixel sees. So for the lobes a point or spot lamp is a
sphere of radius ``LAMP_RADIUS`` (scene units; the size of a bulb) around its position, and a
directional lamp a disc of the sun's angular radius ``DIRECTIONAL_ANGULAR_RADIUS``, with the
radiance that gives the extension's intensity:

- point / spot: a uniformly bright sphere of radius r and radiance L has intensity I = pi r^2 L in
  every direction, so L = colour x intensity / (pi r^2); seen from a point at distance d it is a
  spherical cap of angular radius asin(r / d) whose irradiance at normal incidence is
  pi L (r / d)^2 = I / d^2, the extension's (exactly, not only far away). The range window and the
  spot cone of lamp_irradiance multiply L, evaluated at the shading point as the bake does.
- directional: L = colour x intensity / (pi sin^2 delta), irradiance pi L sin^2 delta = E.

Each shading point integrates its lobes over these caps by the deterministic cap integrator of
the bright sources (materials/cap_lights.py integrate_cap_light; GLSL shaders/cap_lights.glsl
cap_integral) in every method, the reference included (the cube maps and mirror buffers never
hold lamps, so nothing is counted twice).

Shadows: per object, not per pixel. :func:`lamp_visibility` casts rays from up to
``VISIBILITY_POINTS`` of the object's vertices to each lamp; the fraction that reaches it scales
the lamp for the whole object (a lamp in the next room lights nothing here; a half-shadowed
floor shows its highlight at half strength everywhere: a documented approximation)."""

from __future__ import annotations

import math

import numpy as np

from lobeview.materials.cap_lights import CapLight
from lobeview.scenes.baker import range_window, spot_factor  # the bake's own definitions

LAMP_RADIUS = 0.05  # scene units (metres in glTF): a point or spot lamp's sphere for its reflections
DIRECTIONAL_ANGULAR_RADIUS = math.radians(0.265)  # the sun's
MAX_LAMPS = 16  # lamps with live reflections per scene (more: the brightest, the rest baked only)
VISIBILITY_POINTS = 16  # vertices per object whose rays to each lamp decide its visibility
SHADOW_OFFSET = 1e-4  # of the scene's extent: ray origins leave the surface along the normal


def lamp_cap(light, point, radius: float = LAMP_RADIUS) -> CapLight | None:
    """The cap of directions (world space) in which ``light`` is seen from ``point``, with its
    radiance (module docstring); None inside a lamp's sphere or where its light is zero."""
    colour = np.asarray(light.colour, dtype=np.float64) * float(light.intensity)
    if light.type == "directional":
        sin_r = math.sin(DIRECTIONAL_ANGULAR_RADIUS)
        direction = -np.asarray(light.direction, dtype=np.float64)
        return CapLight(direction, math.cos(DIRECTIONAL_ANGULAR_RADIUS), colour / (math.pi * sin_r * sin_r))
    to_lamp = np.asarray(light.position, dtype=np.float64) - np.asarray(point, dtype=np.float64)
    distance = float(np.linalg.norm(to_lamp))
    if distance <= radius:
        return None
    axis = to_lamp / distance
    scale = float(range_window(light, distance)) * float(
        spot_factor(light, -float(axis @ np.asarray(light.direction, np.float64)))
    )
    if scale <= 0.0 or not np.any(colour > 0.0):
        return None
    sin_r = radius / distance
    return CapLight(axis, math.sqrt(1.0 - sin_r * sin_r), colour * scale / (math.pi * radius * radius))


def live_lamps(lights: list) -> list:
    """The lamps that get live reflections: all of them up to MAX_LAMPS, else the MAX_LAMPS of
    highest intensity (luminance of colour x intensity)."""
    if len(lights) <= MAX_LAMPS:
        return list(lights)

    def strength(light) -> float:
        r, g, b = np.asarray(light.colour, dtype=np.float64) * float(light.intensity)
        return 0.2126 * r + 0.7152 * g + 0.0722 * b

    return sorted(lights, key=strength, reverse=True)[:MAX_LAMPS]


def visibility_points(obj, count: int = VISIBILITY_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """(points, normals): up to ``count`` of the object's vertices, evenly strided through its
    vertex list (deterministic), with their normals."""
    positions = np.asarray(obj.mesh.positions, dtype=np.float64)
    normals = np.asarray(obj.mesh.normals, dtype=np.float64)
    if len(positions) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    picks = np.unique(np.linspace(0, len(positions) - 1, min(count, len(positions))).round().astype(np.int64))
    return positions[picks], normals[picks]


def lamp_visibility(scene, lights: list, intersector=None) -> np.ndarray:
    """(objects, lamps) fraction of each object's visibility points from which each lamp is not
    blocked by the scene's geometry (thin transmissive panes let light through, alpha-masked
    cut-outs too: the bake's ray caster, scenes/baker.py). A point on the lamp's far side of its
    own surface counts as blocked (the surface itself faces away)."""
    out = np.zeros((len(scene.objects), len(lights)))
    if not lights or not scene.objects:
        return out
    if intersector is None:
        from lobeview.scenes.baker import scene_intersector

        intersector = scene_intersector(scene)
    low, high = scene.bounds
    offset = SHADOW_OFFSET * max(float(np.max(high - low)), 1e-9)
    for o, obj in enumerate(scene.objects):
        points, normals = visibility_points(obj)
        if len(points) == 0:
            continue
        for k, light in enumerate(lights):
            if light.type == "directional":
                direction = np.broadcast_to(-np.asarray(light.direction, np.float64), points.shape)
                distance = np.full(len(points), np.inf)
            else:
                to_lamp = np.asarray(light.position, np.float64)[None, :] - points
                distance = np.linalg.norm(to_lamp, axis=1)
                direction = to_lamp / np.maximum(distance, 1e-30)[:, None]
            facing = np.sum(normals * direction, axis=1)
            # Leave the surface on the lamp's side (double-sided surfaces: the side facing it).
            origins = points + np.sign(np.where(facing == 0.0, 1.0, facing))[:, None] * normals * offset
            first = intersector.intersects_first(origins, np.ascontiguousarray(direction))
            blocked = first >= 0
            if np.any(blocked) and np.any(np.isfinite(distance)):
                hits = intersector.hit_points(origins[blocked], direction[blocked], first[blocked])
                hit_distance = np.linalg.norm(hits - origins[blocked], axis=1)
                blocked[np.flatnonzero(blocked)] = hit_distance < distance[blocked] - offset
            out[o, k] = float(np.count_nonzero(~blocked)) / len(points)
    return out
