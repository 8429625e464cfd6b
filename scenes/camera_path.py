"""Recorded camera paths (``lobeview view --path FILE``, ``lobeview bench walkthrough``): key
frames of eye position and look-at target at given times, interpolated by a cubic Hermite spline
with Catmull-Rom velocities in time (C1, passes through every key, eases in and out at the ends)
so that a walkthrough is smooth and exactly repeatable.

File format (JSON, untrusted: sizes and values are checked before use)::

    {"fov_y": 60, "keys": [{"t": 0.0, "position": [x, y, z], "target": [x, y, z]}, ...]}

``t`` in seconds, strictly increasing from 0; at least 2 and at most MAX_KEYS keys; the up vector
is +Y (the walkthrough convention of the built-in scenes and the viewer's walk mode).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .scene import SceneCamera

MAX_KEYS = 10_000
MAX_PATH_BYTES = 4 << 20


class CameraPathError(ValueError):
    pass


@dataclass
class CameraPath:
    times: np.ndarray  # (K,) seconds, strictly increasing, times[0] == 0
    positions: np.ndarray  # (K, 3)
    targets: np.ndarray  # (K, 3)
    fov_y: float = 60.0

    def __post_init__(self):
        self.times = np.asarray(self.times, np.float64).reshape(-1)
        self.positions = np.asarray(self.positions, np.float64).reshape(-1, 3)
        self.targets = np.asarray(self.targets, np.float64).reshape(-1, 3)
        k = len(self.times)
        if not 2 <= k <= MAX_KEYS:
            raise CameraPathError(f"camera path: 2 to {MAX_KEYS} keys, got {k}")
        if len(self.positions) != k or len(self.targets) != k:
            raise CameraPathError("camera path: every key needs a time, a position and a target")
        for name, values in (("t", self.times), ("position", self.positions), ("target", self.targets)):
            if not np.all(np.isfinite(values)):
                raise CameraPathError(f"camera path: every key's {name} must be finite")
        if self.times[0] != 0.0 or np.any(np.diff(self.times) <= 0):
            raise CameraPathError("camera path: key times must start at 0 and increase strictly")
        gaze = self.targets - self.positions
        if np.any(np.linalg.norm(gaze, axis=1) < 1e-6):
            raise CameraPathError("camera path: a key's target equals its position")
        horizontal = np.linalg.norm(gaze[:, [0, 2]], axis=1) / np.linalg.norm(gaze, axis=1)
        if np.any(horizontal < 1e-3):
            raise CameraPathError("camera path: a key looks straight up or down (the up vector is +Y)")
        if not (np.isfinite(self.fov_y) and 1.0 <= self.fov_y <= 170.0):
            raise CameraPathError(f"camera path: fov_y must be in [1, 170] degrees, got {self.fov_y}")

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def _velocity(self, values: np.ndarray, i: int) -> np.ndarray:
        """Catmull-Rom velocity at key ``i`` in time (finite difference over its neighbours' times);
        zero at the end keys, so the camera eases in and out instead of overshooting."""
        if i == 0 or i == len(values) - 1:
            return np.zeros(values.shape[1])
        return (values[i + 1] - values[i - 1]) / (self.times[i + 1] - self.times[i - 1])

    def _spline(self, values: np.ndarray, t: float) -> np.ndarray:
        """Cubic Hermite between the keys around ``t`` with Catmull-Rom velocities: C1 in time, so
        speed is continuous through a key however unevenly the keys are spaced (a tangent per
        key index would overshoot before a long segment)."""
        t = float(np.clip(t, 0.0, self.duration))
        i = int(np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2))
        dt = self.times[i + 1] - self.times[i]
        s = (t - self.times[i]) / dt
        s2, s3 = s * s, s * s * s
        h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        return (
            h00 * values[i]
            + h10 * dt * self._velocity(values, i)
            + h01 * values[i + 1]
            + h11 * dt * self._velocity(values, i + 1)
        )

    def camera_at(self, t: float) -> SceneCamera:
        """The camera at ``t`` seconds (clamped to the path); viewer.camera.Camera.from_scene_camera
        makes it a render camera."""
        position = self._spline(self.positions, t)
        target = self._spline(self.targets, t)
        if np.linalg.norm(target - position) < 1e-6:  # the spline can pass a target through its eye
            target = position + (self.targets[-1] - self.positions[-1])
        return SceneCamera(f"path t={t:.2f}", position, target, np.array([0.0, 1.0, 0.0]), self.fov_y)

    def frame_times(self, frames: int) -> np.ndarray:
        """``frames`` times spread evenly over the path, both ends included."""
        if frames < 1:
            raise CameraPathError(f"camera path: at least one frame, got {frames}")
        return np.linspace(0.0, self.duration, frames) if frames > 1 else np.zeros(1)

    def to_json(self) -> dict:
        keys = [
            {
                "t": round(float(t), 4),
                "position": [round(float(x), 4) for x in p],
                "target": [round(float(x), 4) for x in q],
            }
            for t, p, q in zip(self.times, self.positions, self.targets, strict=True)
        ]
        return {"fov_y": self.fov_y, "keys": keys}

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_json(), indent=1) + "\n")
        return path

    @classmethod
    def from_json(cls, data, source: str = "camera path") -> CameraPath:
        if not isinstance(data, dict) or not isinstance(data.get("keys"), list):
            raise CameraPathError(f"{source}: expected an object with a 'keys' list")
        keys = data["keys"]
        if not 2 <= len(keys) <= MAX_KEYS:
            raise CameraPathError(f"{source}: 2 to {MAX_KEYS} keys, got {len(keys)}")
        times, positions, targets = [], [], []
        for n, key in enumerate(keys):
            try:
                times.append(float(key["t"]))
                positions.append([float(x) for x in key["position"]])
                targets.append([float(x) for x in key["target"]])
            except (KeyError, TypeError, ValueError):
                raise CameraPathError(
                    f"{source}: key {n} needs 't' (seconds), 'position' and 'target' ([x, y, z] numbers)"
                ) from None
            if len(positions[-1]) != 3 or len(targets[-1]) != 3:
                raise CameraPathError(f"{source}: key {n}: position and target need 3 numbers")
        try:
            fov = float(data.get("fov_y", 60.0))
        except (TypeError, ValueError):
            raise CameraPathError(f"{source}: fov_y must be a number") from None
        try:
            return cls(np.array(times), np.array(positions), np.array(targets), fov)
        except CameraPathError as exc:
            raise CameraPathError(str(exc).replace("camera path", source, 1)) from None

    @classmethod
    def load(cls, path: str | Path) -> CameraPath:
        from lobeview.core.jsonio import JSONInputError, read_json_file

        path = Path(path)
        try:
            data = read_json_file(path, "camera path", MAX_PATH_BYTES)
        except JSONInputError as exc:
            raise CameraPathError(str(exc)) from None
        return cls.from_json(data, f"camera path {path}")
