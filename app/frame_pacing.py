"""Frame pacing for the walkthrough window (issue 41): the render scale that holds a target frame
time while the view changes, and wall-clock motion from held keys.

While the camera moves (or a material, the method, an option changes) the window renders the
real-time frame at a reduced resolution chosen by :class:`RenderScale` and upsamples it to the
window (bilinear: the accumulation pass samples the smaller radiance target with a linear
filter). Once nothing has changed for ``REST_DELAY_S`` it renders one frame at full resolution,
then refines it (viewer/refinement.py). A headless ``lobeview shot`` never goes through here: its
images are unchanged.

The controller models a frame interval as ``overhead + pass * (scale / measured_scale)^2`` (the
shading cost grows with the pixel count, the rest does not) and picks the finest scale of
``RENDER_SCALES`` whose predicted interval fits the target, moving to a finer one only with a
margin (``FINER_MARGIN``) so that it does not flicker between two sizes, whose every change
reallocates the frame's targets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

DEFAULT_TARGET_FPS = 15.0
# Pixel count falls by ~0.7 per step, 1 to 1/100 of the window's pixels.
RENDER_SCALES = (1.0, 0.84, 0.71, 0.6, 0.5, 0.42, 0.35, 0.3, 0.25, 0.21, 0.18, 0.15, 0.125, 0.1)
REST_DELAY_S = 0.3  # unchanged this long: the full-resolution frame, then refinement
FINER_MARGIN = 0.8  # a finer scale only where it is predicted within 80 % of the target
# Motion follows wall-clock time; only a stall longer than this (a window drag, a cube-map
# refresh, the full-resolution frame at rest) is cut, so that the camera does not jump.
MOTION_STALL_CAP_S = 1.0


def scaled_size(size, scale: float) -> tuple[int, int]:
    """``size`` (w, h) times ``scale``, at least one pixel each way."""
    return max(1, round(size[0] * scale)), max(1, round(size[1] * scale))


def target_frame_seconds(target_fps: float) -> float | None:
    """The frame interval to hold for ``--target-fps`` (None for 0: always full resolution)."""
    if not math.isfinite(target_fps) or target_fps < 0:
        raise ValueError(f"--target-fps must be 0 (off) or a positive number of frames a second, not {target_fps}")
    return None if target_fps == 0 else 1.0 / target_fps


class RenderScale:
    """The scale of the frames rendered while the view changes. ``target_s``: the frame interval
    to hold (None: always 1). ``observe`` after each such frame; ``scale`` for the next one."""

    def __init__(self, target_s: float | None, scales=RENDER_SCALES):
        self.target_s = target_s
        self.scales = tuple(scales)
        self.level = 0

    @property
    def scale(self) -> float:
        return 1.0 if self.target_s is None else self.scales[self.level]

    def predicted_interval(self, scale: float, measured_scale: float, pass_s: float, interval_s: float) -> float:
        overhead = max(interval_s - pass_s, 0.0)
        return overhead + pass_s * (scale / measured_scale) ** 2

    def observe(self, measured_scale: float, pass_s: float, interval_s: float) -> float:
        """A frame at ``measured_scale`` took ``pass_s`` to render, ``interval_s`` from its start
        to the next frame's: choose the next scale (returned)."""
        if self.target_s is None or not (pass_s >= 0 and interval_s > 0):
            return self.scale
        chosen = len(self.scales) - 1  # nothing fits: the coarsest
        for level, scale in enumerate(self.scales):
            limit = self.target_s if level >= self.level else FINER_MARGIN * self.target_s
            if self.predicted_interval(scale, measured_scale, pass_s, interval_s) <= limit:
                chosen = level
                break
        # One step finer per frame at most: a fast frame after a stall is no reason to jump up.
        self.level = max(chosen, self.level - 1)
        return self.scale


@dataclass
class HeldKeys:
    """How long each key was held since the last ``take``, from press and release times: a key
    released between two slow frames still moves the camera by the time it was down."""

    down_since: dict = field(default_factory=dict)
    released_for: dict = field(default_factory=dict)  # seconds held and already released
    last_take: float | None = None

    def press(self, key, now: float) -> None:
        self.down_since.setdefault(key, now)

    def release(self, key, now: float) -> None:
        since = self.down_since.pop(key, None)
        if since is not None:
            start = since if self.last_take is None else max(since, self.last_take)
            self.released_for[key] = self.released_for.get(key, 0.0) + max(now - start, 0.0)

    def is_down(self, key) -> bool:
        return key in self.down_since

    def take(self, now: float) -> dict:
        """{key: seconds held since the previous take}, each at most MOTION_STALL_CAP_S."""
        held = dict(self.released_for)
        for key, since in self.down_since.items():
            start = since if self.last_take is None else max(since, self.last_take)
            held[key] = held.get(key, 0.0) + max(now - start, 0.0)
        self.released_for.clear()
        self.last_take = now
        return {key: min(seconds, MOTION_STALL_CAP_S) for key, seconds in held.items() if seconds > 0}

    def clear(self) -> None:
        self.down_since.clear()
        self.released_for.clear()
