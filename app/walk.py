"""The viewer's walkthrough camera: yaw/pitch from mouse drags, W/A/S/D/Q/E motion at a speed
set by the wheel, and an orbit mode around a centre."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lobeview.viewer.camera import Camera


def walk_speed_for(bounds) -> float:
    """Walking speed for a scene: crossing its largest extent in four seconds (1.5 m/s in
    a 6 m room), so a scene authored in millimetres or kilometres walks like one in metres."""
    extent = float(np.max(np.asarray(bounds[1], float) - np.asarray(bounds[0], float)))
    return max(0.25 * extent, 1e-6)


@dataclass
class WalkCamera:
    position: np.ndarray
    yaw: float  # radians, 0 looks down -Z
    pitch: float
    fov_y: float = 60.0
    speed: float = 1.5  # m/s
    orbit: bool = False
    orbit_centre: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_camera(cls, camera: Camera) -> WalkCamera:
        pos = np.asarray(camera.position, dtype=np.float64)
        d = np.asarray(camera.target, dtype=np.float64) - pos
        d /= np.linalg.norm(d)
        return cls(
            pos,
            math.atan2(d[0], -d[2]),
            math.asin(np.clip(d[1], -1, 1)),
            camera.fov_y,
            orbit_centre=np.asarray(camera.target, float),
        )

    def forward(self) -> np.ndarray:
        cp = math.cos(self.pitch)
        return np.array([math.sin(self.yaw) * cp, math.sin(self.pitch), -math.cos(self.yaw) * cp])

    def camera(self) -> Camera:
        return Camera(tuple(self.position), tuple(self.position + self.forward()), (0.0, 1.0, 0.0), self.fov_y)

    def look(self, dx: float, dy: float) -> None:
        self.yaw += dx * 0.004
        self.pitch = float(np.clip(self.pitch - dy * 0.004, -1.5, 1.5))
        if self.orbit:
            distance = np.linalg.norm(self.position - self.orbit_centre)
            self.position = self.orbit_centre - self.forward() * distance

    def move(self, direction: np.ndarray, dt: float) -> None:
        f = self.forward()
        right = np.cross(f, [0.0, 1.0, 0.0])
        right /= max(np.linalg.norm(right), 1e-9)
        step = (direction[0] * right + direction[1] * np.array([0.0, 1.0, 0.0]) + direction[2] * f) * self.speed * dt
        self.position = self.position + step
