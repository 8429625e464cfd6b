"""Procedural environments that ship with lobeview (no files needed): ``builtin:studio`` (grey
studio with soft boxes, a strip and a rim light) and ``builtin:sky`` (clear sky with a sun of
radiance ~2e4, the case that stresses sampling) and ``builtin:overcast`` (CIE overcast sky, the
demo scene's daylight). All in the orientation of envmap.py."""

from __future__ import annotations

import numpy as np

from .envmap import EnvironmentMap


def _disc(d, axis, cos_radius, softness):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    c = np.sum(d * axis, axis=-1)
    return np.clip((c - cos_radius) / softness, 0.0, 1.0)[..., None]


def studio(d: np.ndarray) -> np.ndarray:
    """Photo studio: grey backdrop and floor, two soft boxes above and behind the camera, a
    strip light on the left and a small rim light behind the object."""
    up = d[..., 1:2]
    backdrop = 0.05 + 0.04 * np.clip(up + 0.3, 0.0, 1.0)
    floor = np.where(up < -0.05, 0.12 + 0.06 * np.clip(-up, 0.0, 1.0), 0.0)
    key = 30.0 * _disc(d, [0.55, 0.6, 0.58], np.cos(np.radians(11)), 0.004) * [1.0, 0.97, 0.92]
    fill = 10.0 * _disc(d, [-0.6, 0.45, 0.66], np.cos(np.radians(16)), 0.01) * [0.9, 0.95, 1.0]
    strip = 6.0 * _disc(d, [-1.0, 0.1, -0.1], np.cos(np.radians(6)), 0.003) * [1.0, 1.0, 1.0]
    rim = 12.0 * _disc(d, [0.25, 0.35, -0.9], np.cos(np.radians(4)), 0.002) * [1.0, 0.9, 0.8]
    return backdrop + floor + key + fill + strip + rim


def sky(d: np.ndarray) -> np.ndarray:
    up = d[..., 1:2]
    zenith = np.array([0.25, 0.45, 0.9])
    horizon = np.array([0.8, 0.85, 0.9])
    sky_col = np.where(up > 0, horizon + (zenith - horizon) * np.sqrt(np.clip(up, 0, 1)), 0.0)
    ground = np.where(up <= 0, [0.25, 0.22, 0.18] * (0.6 + 0.4 * np.exp(up * 4)), 0.0)
    sun = 2.0e4 * _disc(d, [0.4, 0.55, -0.73], np.cos(np.radians(0.6)), 1e-5) * [1.0, 0.95, 0.85]
    return 1.5 * sky_col + ground + sun


def overcast(d: np.ndarray) -> np.ndarray:
    """CIE standard overcast sky, L(theta) = Lz (1 + 2 cos(theta)) / 3 with Lz = 3, over a grey
    ground of radiance 0.35: soft daylight with no sun, what the demo scene's window shows."""
    up = d[..., 1:2]
    sky_col = 3.0 * (1.0 + 2.0 * np.clip(up, 0.0, 1.0)) / 3.0 * np.array([0.95, 0.98, 1.0])
    ground = np.array([0.35, 0.33, 0.3]) * (0.7 + 0.3 * np.exp(4.0 * np.minimum(up, 0.0)))
    return np.where(up > 0, sky_col, ground)


BUILTIN = {"studio": studio, "sky": sky, "overcast": overcast}


def load_environment(spec: str) -> EnvironmentMap:
    """``builtin:NAME`` or a path to an equirectangular .exr / .hdr."""
    if spec.startswith("builtin:"):
        name = spec.split(":", 1)[1]
        if name not in BUILTIN:
            raise ValueError(f"unknown built-in environment {name!r}; use one of {sorted(BUILTIN)}")
        return EnvironmentMap.from_function(BUILTIN[name], height=512, name=spec)
    return EnvironmentMap.load(spec)
