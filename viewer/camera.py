"""Pinhole camera: look-at view and OpenGL perspective projection (right-handed, +Y up,
looking down -Z in view space, as glTF cameras)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.stats import qmc


def look_at(eye, target, up) -> np.ndarray:
    """The view matrix of a camera at ``eye`` looking at ``target`` (a new array each call; the
    matrix is made once per distinct camera: a frame asks for it in every mirror pass)."""
    key = tuple(float(x) for v in (eye, target, up) for x in np.ravel(v))
    if len(key) != 9:
        raise ValueError("look_at takes three 3-vectors")
    return _look_at(key).copy()


@lru_cache(maxsize=64)
def _look_at(key: tuple) -> np.ndarray:
    eye, target, up = (np.array(key[k : k + 3], dtype=np.float64) for k in (0, 3, 6))
    forward = target - eye
    if np.linalg.norm(forward) < 1e-12:
        raise ValueError("camera position and target coincide")
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("camera up vector is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0] = f / aspect
    proj[1, 1] = f
    proj[2, 2] = (far + near) / (near - far)
    proj[2, 3] = 2.0 * far * near / (near - far)
    proj[3, 2] = -1.0
    return proj


PIXEL_OFFSET_TABLE = 4096  # sub-pixel offsets tabulated at once; later passes wrap (pixel_offset)
# Toroidal shifts of the offset sequence per stream: stream 0 starts at the pixel centre, stream 1
# (the refinement's second half, viewer/refinement.py) is the same sequence moved by the R2
# sequence's generator, so that its positions differ from stream 0's at every index.
PIXEL_OFFSET_SHIFTS = ((0.5, 0.5), (0.5 + 0.7548776662466927, 0.5 + 0.5698402909980532))


@lru_cache(maxsize=1)
def _halton_points() -> np.ndarray:
    return qmc.Halton(d=2, scramble=False).random(PIXEL_OFFSET_TABLE)


def pixel_offset(pass_index: int, stream: int = 0) -> tuple[float, float]:
    """The sub-pixel position of pass ``pass_index`` of a box-filtered pixel integral, in pixels
    from the pixel centre, in [-0.5, 0.5)^2 (x right, y up). The Halton (2, 3) points toroidally
    shifted (a Cranley-Patterson shift keeps their discrepancy), so any prefix of passes is
    stratified over the pixel; stream 0's pass 0 is the centre (its G-buffer is the point-sampled
    one)."""
    point = _halton_points()[int(pass_index) % PIXEL_OFFSET_TABLE] + PIXEL_OFFSET_SHIFTS[stream]
    x, y = np.mod(point, 1.0) - 0.5
    return float(x), float(y)


def jittered(view_projection: np.ndarray, offset_px, size) -> np.ndarray:
    """``view_projection`` moved by ``offset_px`` pixels in the image plane of a ``size`` = (W, H)
    frame: x_ndc += 2 dx / W, i.e. x_clip += (2 dx / W) w_clip (and y alike)."""
    shift = np.eye(4)
    shift[0, 3] = 2.0 * float(offset_px[0]) / float(size[0])
    shift[1, 3] = 2.0 * float(offset_px[1]) / float(size[1])
    return shift @ view_projection


def box_corners(box_min, box_max) -> np.ndarray:
    """The 8 corners (8, 3) of an axis-aligned box."""
    lo, hi = np.asarray(box_min, dtype=np.float64), np.asarray(box_max, dtype=np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def outside_frustum(corners: np.ndarray, view_projection: np.ndarray) -> bool:
    """Whether points (the corners of a convex volume) lie wholly outside one clip plane of
    ``view_projection``: then nothing of the volume can reach the image. Each plane (x <= w,
    -w <= x, and y, z alike) is a linear function of the homogeneous point, so the test holds for
    corners behind the eye (w < 0) and for oblique near planes too. Conservative: a volume that
    crosses a frustum edge outside every single plane's half-space is kept."""
    return bool(outside_frustum_many(np.asarray(corners, dtype=np.float64)[None], view_projection)[0])


def outside_frustum_many(corners: np.ndarray, view_projection: np.ndarray) -> np.ndarray:
    """:func:`outside_frustum` of many volumes at once: ``corners`` (n, k, 3) -> (n,) bool (one
    matrix product per pass instead of one per object)."""
    corners = np.asarray(corners, dtype=np.float64)
    view_projection = np.asarray(view_projection, dtype=np.float64)
    clip = corners @ view_projection[:, :3].T + view_projection[:, 3]
    w = clip[..., 3:4]
    above = np.all(clip[..., :3] > w, axis=1)
    below = np.all(clip[..., :3] < -w, axis=1)
    return np.any(above | below, axis=-1)


def outside_frustum_boxes(box_min: np.ndarray, box_max: np.ndarray, view_projection: np.ndarray) -> np.ndarray:
    """:func:`outside_frustum_many` of axis-aligned boxes (n, 3) and (n, 3) -> (n,) bool, without
    their corners: a clip plane's linear function p . (x, 1) is largest over a box at
    p . centre + |p_xyz| . half-size, so the box lies wholly outside it when that is negative
    (the same test as the corners', in one (n, 6) product: several times faster per pass)."""
    low = np.asarray(box_min, dtype=np.float64)
    high = np.asarray(box_max, dtype=np.float64)
    view_projection = np.asarray(view_projection, dtype=np.float64)
    # Inside means w - x_i >= 0 and w + x_i >= 0 for x_i = x, y, z: six rows of the matrix.
    planes = np.concatenate([view_projection[3] - view_projection[:3], view_projection[3] + view_projection[:3]])
    largest = 0.5 * (low + high) @ planes[:, :3].T + planes[:, 3] + 0.5 * (high - low) @ np.abs(planes[:, :3]).T
    return np.any(largest < 0.0, axis=1)


DEPTH_RANGE_RATIO = 5000.0  # far / near kept by fit_clip_planes: 24-bit depth resolves ~far/1e4 at far


def fit_clip_planes(position, bounds_min, bounds_max) -> tuple[float, float]:
    """Near and far planes that hold a scene of any scale (millimetres to kilometres).

    ``far`` covers every point of the scene's bounding box seen from ``position`` and from its
    mirror image in any plane through the box (mirror passes reuse the projection): for the box
    centre c and half-diagonal h, |e - c| + 3 h. ``near`` is half the distance to the box when the
    camera is outside it, and never closer than far / DEPTH_RANGE_RATIO, which keeps the 24-bit
    depth buffer's resolution at about far / 1e4 at the far end."""
    eye = np.asarray(position, dtype=np.float64)
    low, high = np.asarray(bounds_min, dtype=np.float64), np.asarray(bounds_max, dtype=np.float64)
    centre, half_diagonal = 0.5 * (low + high), 0.5 * float(np.linalg.norm(high - low))
    half_diagonal = max(half_diagonal, 1e-6 * max(float(np.max(np.abs(centre))), 1.0), 1e-9)
    far = 1.01 * (float(np.linalg.norm(eye - centre)) + 3.0 * half_diagonal)
    outside = float(np.linalg.norm(eye - np.clip(eye, low, high)))
    near = max(0.5 * outside, far / DEPTH_RANGE_RATIO)
    return near, far


@dataclass
class Camera:
    position: tuple = (0.0, 0.0, 3.0)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov_y: float = 40.0
    near: float = 0.05
    far: float = 200.0

    @classmethod
    def from_scene_camera(cls, camera) -> Camera:
        """A render camera from a scene's camera (scenes.scene.SceneCamera, a path's camera_at)."""
        return cls(tuple(camera.position), tuple(camera.target), tuple(camera.up), camera.fov_y)

    def fitted_to(self, bounds) -> Camera:
        """This camera with near/far planes fitted to a scene's (min, max) bounds."""
        near, far = fit_clip_planes(self.position, *bounds)
        return replace(self, near=near, far=far)

    def view(self) -> np.ndarray:
        return look_at(self.position, self.target, self.up)

    def view_projection(self, aspect: float) -> np.ndarray:
        return perspective(self.fov_y, aspect, self.near, self.far) @ self.view()

    def describe(self) -> str:
        """The ``lobeview shot`` flags that reproduce this camera, as ``--flag=value`` (a vector
        such as ``-0.01,0.98,-0.18`` after a space would be taken for an option)."""

        def fmt(v):
            return ",".join(f"{x:.9g}" for x in v)

        return f"--camera={fmt(self.position)} --target={fmt(self.target)} --up={fmt(self.up)} --fov={self.fov_y:.9g}"
