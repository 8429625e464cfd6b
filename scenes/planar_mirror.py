"""Planar reflectors and the mirror pass (thesis 4.5): the numpy reference of what
viewer/mirror_pass.py and shaders/integrate.glsl (``MIRROR``) do on the GPU.

A large glossy plane (floor, table top, wall) cannot use one cube map: what it reflects changes
across it (Fig. 4.25). Each frame the scene is rendered from the camera mirrored about the plane
(Diefenbach et al. 1997) into a *mirror buffer* holding radiance (with a MIP chain built every
frame), world position and normal. A surface point P of the plane finds the radiance arriving
from its mirror direction w_r at its own screen position in that buffer (Fig. 4.26); other
directions w_i of its lobes are mapped into the buffer by the two-step tangent-plane projection
of 4.5.2:

  1. intersect the ray P + t w_i with the tangent plane of P_R, the surface point the buffer
     shows at P's own position (a point at infinity, i.e. the environment, if the buffer shows
     the environment there or the plane is missed);
  2. project that point P_I into the mirror camera;
  3. intersect the ray again with the tangent plane of what the buffer shows *there*, project
     the new P_I and read the radiance at that position (the second step removes the
     discontinuities of Fig. 4.30-4.31 at depth edges).

Filtering (4.5.3): each sample reads the radiance MIP level whose texels cover its share of the
lobe. lobeview maps that share, the solid angle Omega_s of Eq. 4.14 / N, through the tangent
plane found for the sample into buffer pixels (the local Jacobian of the projection; the thesis
projects the lobe's extreme directions to an ellipse once per pixel and divides its area by N):

  pixels = Omega_s * (t^2 / |n . w_i|) * (|n . v'| / r'^2) * f^2 / cos^3(alpha)

with t the distance P -> P_I, n the tangent-plane normal, v' and r' the direction and distance
from the mirror camera to P_I, f the focal length in pixels and alpha the angle of v' off the
mirror camera's axis (Omega_s * f^2 / cos^3 alpha for the environment at infinity); lod =
0.5 log2(pixels) + bias.

The mirror camera uses an oblique near plane (Lengyel 2005) equal to the reflector's plane, so
nothing behind the reflector leaks into the buffer.

Which objects are planar reflectors: node ``extras.lobeview.planar_reflector`` = true (force:
any planar mesh with view-dependent lobes), false (never) or "auto" (default): the mesh lies in a
plane within PLANAR_TOLERANCE of the scene size, spans
at least MIN_REFLECTOR_FRACTION of the scene's diagonal, and its lobes are no wider than
MAX_MIRROR_ROUGHNESS (wider lobes reach geometry the mirror camera does not see, Fig. 4.27: such
an object keeps its cube map and the scene analysis says why).

Transmission lobes of a thin pane (the thesis' Kurt transmission, Eq. 3.5: the transmitted
direction is the reflected one mirrored through the plane) read a second, *see-through* buffer:
the scene behind the plane rendered from the camera itself with the same oblique near plane. The
straight-through direction of P then reads P's own pixel, and other directions go through the same
two-step projection. The thesis renders only reflections this way; this is the same construction
with the identity in place of the reflection.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

PLANAR_TOLERANCE = 1e-4  # max distance of a vertex from the fitted plane / scene diagonal
MIN_REFLECTOR_FRACTION = 0.2  # reflector diagonal / scene diagonal for automatic detection
MAX_MIRROR_ROUGHNESS = 0.3  # Beckmann m / GGX alpha (larger of the two axes) of the widest lobe


class ReflectorError(ValueError):
    pass


@dataclass(frozen=True)
class PlanarReflector:
    """A planar reflector: its plane n.x + d = 0 with n toward the side it is seen from (the
    mean of the mesh normals), its bounding box for frustum culling, and which buffers its lobes
    read: the mirror buffer (reflection lobes) and the see-through buffer (transmission lobes of
    a thin pane: the scene behind the plane, rendered from the camera itself)."""

    plane: np.ndarray  # (4,)
    box_min: np.ndarray
    box_max: np.ndarray
    reflection: bool = True
    transmission: bool = False

    @property
    def passes(self) -> tuple[str, ...]:
        """The buffers drawn for it each frame: 'mirror' and/or 'see-through'."""
        return ("mirror",) * self.reflection + ("see-through",) * self.transmission

    def side(self, points) -> np.ndarray:
        """Signed distance of points (..., 3) from the plane (> 0 on the front side)."""
        return np.asarray(points, dtype=np.float64) @ self.plane[:3] + self.plane[3]

    def reflection_matrix(self) -> np.ndarray:
        return reflection_matrix(self.plane)

    def corners(self) -> np.ndarray:
        lo, hi = self.box_min, self.box_max
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def fit_plane(positions: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane through points: (plane (4,), max |distance|). The normal is the
    singular vector of the smallest singular value of the centred points."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p) < 3:
        raise ReflectorError("a plane needs at least three vertices")
    centre = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - centre, full_matrices=False)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        raise ReflectorError("degenerate mesh: its vertices are collinear")
    n = vt[2]
    plane = np.append(n, -n @ centre)
    return plane, float(np.max(np.abs(p @ n + plane[3])))


def planar_reflector(mesh, scene_diagonal: float) -> PlanarReflector | None:
    """The reflector of a mesh if it lies in a plane (within PLANAR_TOLERANCE * scene_diagonal),
    else None. The normal faces where the mesh normals point on average."""
    try:
        plane, deviation = fit_plane(mesh.positions)
    except ReflectorError:
        return None
    if deviation > PLANAR_TOLERANCE * max(scene_diagonal, 1e-9):
        return None
    mean_normal = np.asarray(mesh.normals, dtype=np.float64).mean(axis=0)
    if mean_normal @ plane[:3] < 0.0:
        plane = -plane
    positions = np.asarray(mesh.positions, dtype=np.float64)
    return PlanarReflector(plane, positions.min(axis=0), positions.max(axis=0))


def reflector_mode(extras, name: str):
    """The node's ``extras.lobeview.planar_reflector``: 'auto' (default), True or False; anything
    else is warned about and treated as 'auto'."""
    if not isinstance(extras, dict) or not isinstance(extras.get("lobeview"), dict):
        return "auto"
    value = extras["lobeview"].get("planar_reflector", "auto")
    if isinstance(value, bool) or value == "auto":
        return value
    warnings.warn(
        f'node {name!r}: planar_reflector must be true, false or "auto", got {value!r}; using "auto"',
        stacklevel=2,
    )
    return "auto"


def reflector_decision(mesh, lobes, scene_diagonal: float, mode="auto") -> tuple[PlanarReflector | None, str]:
    """(reflector or None, the reason the scene analysis prints). ``lobes`` are the object's
    view-dependent lobes (materials.patterns.specular_lobes)."""
    if mode is False:
        return None, "off (extras)"
    if not lobes:
        return None, "-"
    reflector = planar_reflector(mesh, scene_diagonal)
    if reflector is None:
        return None, "no: not planar" if mode is True else "-"
    transmits = [getattr(lobe, "transmission", False) for lobe in lobes]
    reflector = replace(reflector, reflection=not all(transmits), transmission=any(transmits))
    what = " + ".join(f"{name} pass" for name in reflector.passes)
    if mode is True:
        return reflector, f"{what} (extras)"
    diagonal = float(np.linalg.norm(reflector.box_max - reflector.box_min))
    if diagonal < MIN_REFLECTOR_FRACTION * scene_diagonal:
        return None, f"no: small plane ({diagonal:.2f} m < {MIN_REFLECTOR_FRACTION:g} x scene)"
    widest = max(max(lobe.distribution.alpha_x, lobe.distribution.alpha_y) for lobe in lobes)
    if widest > MAX_MIRROR_ROUGHNESS:
        return None, f"cube map: lobes too wide for a mirror pass (roughness {widest:.2f} > {MAX_MIRROR_ROUGHNESS:g})"
    return reflector, what


def reflector_arrays(reflectors: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(planes (n, 4), box minima (n, 3), box maxima (n, 3)) of ``reflectors``: what the frame's
    per-reflector tests (viewer/mirror_pass.py ReflectorLayout, reflector_max_view_angles,
    mirror_scissors) take in one numpy pass."""
    planes = np.array([reflector.plane for reflector in reflectors], dtype=np.float64).reshape(-1, 4)
    low = np.array([reflector.box_min for reflector in reflectors], dtype=np.float64).reshape(-1, 3)
    high = np.array([reflector.box_max for reflector in reflectors], dtype=np.float64).reshape(-1, 3)
    return planes, low, high


def coplanar_groups(reflectors: dict, scene_diagonal: float, tolerance: float = PLANAR_TOLERANCE) -> list[tuple]:
    """Reflectors that can share one mirror pass (thesis 4.5: a mirror render per plane, not per
    object): the same plane seen from the same side (normals within ``tolerance`` radians, offsets
    within ``tolerance`` * ``scene_diagonal``, the flatness a reflector itself may have: the shared
    buffer's image then moves by at most twice that) and the same passes. ``reflectors``: index ->
    PlanarReflector; returns tuples of indices, each ascending, in the order of their first index.
    The floors of an apartment's rooms share one pass instead of one each."""
    distance = tolerance * max(float(scene_diagonal), 1e-9)
    cos_tolerance = np.cos(tolerance)
    groups: list[list[int]] = []
    for index in sorted(reflectors):
        reflector = reflectors[index]
        for group in groups:
            first = reflectors[group[0]]
            if (
                first.passes == reflector.passes
                and float(first.plane[:3] @ reflector.plane[:3]) >= cos_tolerance
                and abs(float(first.plane[3] - reflector.plane[3])) <= distance
            ):
                group.append(index)
                break
        else:
            groups.append([index])
    return [tuple(group) for group in groups]


# -- the mirror camera ---------------------------------------------------------------------------
def reflection_matrix(plane) -> np.ndarray:
    """4x4 reflection about the plane n.x + d = 0 (n unit): x' = x - 2 (n.x + d) n."""
    plane = np.asarray(plane, dtype=np.float64)
    n, d = plane[:3], plane[3]
    m = np.eye(4)
    m[:3, :3] -= 2.0 * np.outer(n, n)
    m[:3, 3] = -2.0 * d * n
    return m


def oblique_projection(projection: np.ndarray, clip_plane_eye: np.ndarray) -> np.ndarray:
    """Lengyel's oblique near plane: ``projection`` with its near plane replaced by the plane
    (a, b, c, d) given in eye space (the camera on its negative side); everything on the
    negative side then falls outside the depth range. Only the third row changes, so pixel
    positions are those of the plain projection."""
    c = np.asarray(clip_plane_eye, dtype=np.float64)
    p = np.array(projection, dtype=np.float64)
    q = np.linalg.inv(p) @ np.array([np.sign(c[0]), np.sign(c[1]), 1.0, 1.0])
    scaled = c * (2.0 / (c @ q))
    p[2] = scaled - p[3]
    return p


@dataclass(frozen=True)
class MirrorCamera:
    """The mirrored camera of one frame: ``view`` = camera view @ reflection (world -> mirror
    eye), ``projection`` (oblique), ``plain_projection`` (for the environment background) and the
    buffer ``size`` (W, H)."""

    view: np.ndarray
    projection: np.ndarray
    plain_projection: np.ndarray
    size: tuple[int, int]
    position: np.ndarray  # C', the mirrored camera position

    @property
    def view_projection(self) -> np.ndarray:
        return self.projection @ self.view

    @property
    def plain_view_projection(self) -> np.ndarray:
        """World -> clip with the plain projection: buffer positions (same x, y, w rows as the
        oblique one) and the environment background."""
        return self.plain_projection @ self.view

    @property
    def focal_pixels(self) -> float:
        """Pixels per unit of tan(angle) at the image centre (vertical)."""
        return 0.5 * self.size[1] * float(self.plain_projection[1, 1])

    def uv(self, points_h: np.ndarray) -> np.ndarray:
        """Buffer coordinates in [0, 1]^2 (v up, OpenGL) of homogeneous world points (..., 4)
        (w = 0: directions, i.e. points at infinity), clamped to the buffer."""
        clip = np.asarray(points_h, dtype=np.float64) @ self.plain_view_projection.T
        w = np.maximum(clip[..., 3], 1e-6)
        return np.clip(clip[..., :2] / w[..., None] * 0.5 + 0.5, 0.0, 1.0)


def mirror_camera(
    view: np.ndarray, projection: np.ndarray, reflector: PlanarReflector, size, see_through: bool = False
) -> MirrorCamera:
    """The mirrored camera of the reflector, or with ``see_through`` the camera itself: the
    see-through buffer of a transmitting pane holds the scene behind the plane as the camera sees
    it, so a thin pane's straight-through direction reads the pixel under P, as the mirror direction
    does in the mirror buffer. Either way the plane is the oblique near plane, oriented so that the
    camera's side of it is cut away."""
    r = np.eye(4) if see_through else reflector.reflection_matrix()
    mirror_view = np.asarray(view, dtype=np.float64) @ r
    # The reflector's plane in the buffer camera's eye space, oriented so that camera is on its
    # negative side: plane_eye = inverse(view)^T plane_world.
    plane_eye = np.linalg.inv(mirror_view).T @ reflector.plane
    if plane_eye[3] > 0.0:
        plane_eye = -plane_eye
    eye = np.linalg.inv(mirror_view)[:3, 3]
    return MirrorCamera(mirror_view, oblique_projection(projection, plane_eye), np.array(projection), tuple(size), eye)


# -- scissored passes (issue 18) ----------------------------------------------------------------
# lobe-N's lookups of a reflector's pixels read its buffer near the reflector's own image: the
# sample directions deviate at most ``angle`` from the mirror direction, and C' -> hit is a
# positive combination of the mirror direction and the sample's, so the read lies within that
# angle of the pixel's own position seen from C'. Each read is a trilinear MIP lookup whose level
# comes from the sample's solid angle through the hit's tangent plane; SCISSOR_LOD_SLACK levels
# allow for that Jacobian (grazing hits). The pass is drawn only inside the reflector's screen
# rectangle grown by that reach; everything else holds the environment (drawn everywhere).
SCISSOR_LOD_SLACK = 0.0
SCISSOR_MAX_ANGLE = np.radians(80.0)  # a reach beyond this off the buffer's axis: no scissor


# Mirror buffers at the resolution their lobes read (issue 42: on a GPU the apartment's frame is
# its mirror passes, bench/results/walkthrough-20261128-052454.md). A lookup of solid angle Omega
# at an environment hit reads MIP level 0.5 log2(Omega f^2 / cos^3) + bias of a buffer of focal
# length f pixels (shaders/incident.glsl buffer_incident), so with Omega no smaller than the lobes'
# finest lookup it never reads below L_env = 0.5 log2(Omega_min) + log2 f + bias, and a buffer
# halved k times shows at its level 0 what the full one shows at level k. Geometry nearer to the
# plane than to the eye is read finer (the footprint scales by about (t / d)^2 in pixels: contact
# reflections stay sharp on rough floors): MIRROR_CONTACT_MARGIN_LEVELS of the finest level are
# kept, i.e. points within about 2^-margin of the eye's distance from where they touch the plane
# read coarser than the full buffer would give them. Views up to MIRROR_FOOTPRINT_MAX_VIEW_ANGLE
# count that the camera sees the reflector at (reflector_max_view_angle: a floor is seen at grazing
# angles far off, where the lobe's footprint shrinks, 7x from 75 to 88 degrees).
MIRROR_CONTACT_MARGIN_LEVELS = 3.0
MIRROR_MAX_COARSE_LEVELS = 2  # buffers at 1/2 or 1/4 of the mirror scale at most
MIRROR_VIEW_ANGLE_STEP = np.radians(2.0)  # view-angle bounds rounded up to this (a cache key)
MIRROR_FOOTPRINT_MAX_VIEW_ANGLE = np.radians(89.0)


def mirror_view_angle_bounds() -> np.ndarray:
    """Every value reflector_max_view_angle returns: multiples of MIRROR_VIEW_ANGLE_STEP below
    MIRROR_FOOTPRINT_MAX_VIEW_ANGLE, then that cap (radians, ascending)."""
    steps = int(np.ceil(MIRROR_FOOTPRINT_MAX_VIEW_ANGLE / MIRROR_VIEW_ANGLE_STEP - 1e-9))
    multiples = np.arange(steps) * MIRROR_VIEW_ANGLE_STEP
    return np.append(multiples[multiples < MIRROR_FOOTPRINT_MAX_VIEW_ANGLE], MIRROR_FOOTPRINT_MAX_VIEW_ANGLE)


def reflector_max_view_angle(reflector: PlanarReflector, eye) -> float:
    """An upper bound of the angle between the reflector's normal and the direction to ``eye`` over
    its surface, rounded up to MIRROR_VIEW_ANGLE_STEP (at most MIRROR_FOOTPRINT_MAX_VIEW_ANGLE):
    at a point x of the plane cos(theta) = h / |eye - x| with h the eye's distance from the
    plane, and no point of the reflector lies farther from the eye than its farthest box corner."""
    return float(reflector_max_view_angles([reflector], eye)[0])


def reflector_max_view_angles(reflectors: list, eye) -> np.ndarray:
    """:func:`reflector_max_view_angle` of many reflectors at once (one numpy pass a frame, not
    one per reflector); the farthest box corner is |eye - x| with each coordinate at the box's
    farther face."""
    eye = np.asarray(eye, dtype=np.float64)
    if not reflectors:
        return np.zeros(0)
    planes, low, high = reflector_arrays(reflectors)
    height = np.abs(planes[:, :3] @ eye + planes[:, 3])
    farthest = np.linalg.norm(np.maximum(np.abs(eye - low), np.abs(eye - high)), axis=1)
    angle = np.arccos(np.clip(height / np.maximum(farthest, 1e-30), 0.0, 1.0))
    steps = np.ceil(angle / MIRROR_VIEW_ANGLE_STEP - 1e-9) * MIRROR_VIEW_ANGLE_STEP
    return np.minimum(steps, MIRROR_FOOTPRINT_MAX_VIEW_ANGLE)


def mirror_buffer_levels(
    sample_solid_angle: float | None,
    focal_px: float,
    lod_bias: float,
    margin_levels: float = MIRROR_CONTACT_MARGIN_LEVELS,
    max_levels: int = MIRROR_MAX_COARSE_LEVELS,
) -> int:
    """How many times a reflector's mirror buffers may be halved (0 .. ``max_levels``): its
    lookups' finest solid angle ``sample_solid_angle`` (materials/lobe_spread.py
    finest_sample_solid_angle; None: unknown, 0) at an environment hit reads level
    0.5 log2(Omega) + log2(focal_px) + lod_bias of the full buffer; ``margin_levels`` of it are kept
    for geometry near the plane (see above)."""
    if sample_solid_angle is None or not sample_solid_angle > 0 or not focal_px > 0:
        return 0
    finest_level = 0.5 * np.log2(sample_solid_angle) + np.log2(focal_px) + lod_bias
    return int(np.clip(np.floor(finest_level - margin_levels), 0, max_levels))


def box_screen_rect(corners: np.ndarray, view_projection: np.ndarray, size) -> tuple[float, float, float, float] | None:
    """Pixel rectangle (x0, y0, x1, y1), OpenGL rows (y up), of a box's image, its part behind
    the eye clipped away (edges crossing w = 0 cut there); None when nothing of it lies in front."""
    corners = np.asarray(corners, dtype=np.float64)
    clip = np.concatenate([corners, np.ones((len(corners), 1))], axis=1) @ np.asarray(view_projection).T
    near = 1e-6
    points = [c for c in clip if c[3] > near]
    for i in range(len(corners)):  # box edges: corners differing in one coordinate
        for j in range(i + 1, len(corners)):
            if np.count_nonzero(corners[i] != corners[j]) != 1:
                continue
            wi, wj = clip[i, 3], clip[j, 3]
            if (wi > near) != (wj > near):
                t = (near - wi) / (wj - wi)
                points.append(clip[i] + t * (clip[j] - clip[i]))
    if not points:
        return None
    points = np.array(points)
    ndc = points[:, :2] / points[:, 3:4]
    width, height = size
    xy = (np.clip(ndc, -1e6, 1e6) * 0.5 + 0.5) * np.array([width, height], dtype=np.float64)
    return float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max())


# The 12 edges of a box given by box_corners' order (corner 4 ix + 2 iy + iz): corners whose
# indices differ in one bit. A box flat in an axis repeats corners; its edges are then the same
# points twice (box_screen_rect's pairwise test finds the same ones).
BOX_EDGES = np.array([(i, i | bit) for bit in (4, 2, 1) for i in range(8) if not i & bit])


def box_screen_rects(box_min: np.ndarray, box_max: np.ndarray, view_projection: np.ndarray, size) -> np.ndarray:
    """:func:`box_screen_rect` of many axis-aligned boxes (m, 3) at once: (m, 4) rows (x0, y0, x1,
    y1), NaN where nothing of a box lies in front of the eye."""
    low = np.asarray(box_min, dtype=np.float64).reshape(-1, 3)
    high = np.asarray(box_max, dtype=np.float64).reshape(-1, 3)
    bits = (np.arange(8)[:, None] >> np.array([2, 1, 0])) & 1  # corner k's (ix, iy, iz)
    corners = np.where(bits[None] == 1, high[:, None], low[:, None])  # (m, 8, 3)
    clip = corners @ np.asarray(view_projection, dtype=np.float64)[:, :3].T + np.asarray(view_projection)[:, 3]
    near = 1e-6
    a, b = clip[:, BOX_EDGES[:, 0]], clip[:, BOX_EDGES[:, 1]]  # (m, 12, 4)
    crossing = (a[..., 3] > near) != (b[..., 3] > near)
    t = np.where(crossing, (near - a[..., 3]) / np.where(crossing, b[..., 3] - a[..., 3], 1.0), 0.0)
    cut = a + t[..., None] * (b - a)
    points = np.concatenate([clip, cut], axis=1)  # (m, 20, 4)
    usable = np.concatenate([clip[..., 3] > near, crossing], axis=1)
    w = np.where(usable, points[..., 3], 1.0)
    width, height = size
    xy = (np.clip(points[..., :2] / w[..., None], -1e6, 1e6) * 0.5 + 0.5) * np.array([width, height], dtype=np.float64)
    lowest = np.where(usable[..., None], xy, np.inf).min(axis=1)
    highest = np.where(usable[..., None], xy, -np.inf).max(axis=1)
    rects = np.concatenate([lowest, highest], axis=1)
    rects[~usable.any(axis=1)] = np.nan
    return rects


def mirror_scissor(
    reflector: PlanarReflector, camera: MirrorCamera, spread: tuple[float, float] | None, lod_bias: float
) -> tuple[int, int, int, int] | None:
    """The buffer region (x, y, width, height; OpenGL rows) that lobe-N's lookups of the
    reflector's pixels can read, from its lobes' ``spread`` (materials/lobe_spread.py:
    largest angle off the mirror direction, largest lookup solid angle); None: the whole buffer
    (no bound: unknown spread, the region reaches the buffer's edges or too far off-axis)."""
    return mirror_scissors([reflector], camera, [spread], lod_bias)[0]


def mirror_scissors(reflectors: list, camera: MirrorCamera, spreads: list, lod_bias: float) -> list:
    """:func:`mirror_scissor` of several reflectors read from one buffer (the members of a plane's
    shared pass), in one numpy pass."""
    out: list = [None] * len(reflectors)
    bounded = [k for k, spread in enumerate(spreads) if spread is not None]
    if not bounded:
        return out
    width, height = camera.size
    _, low, high = reflector_arrays([reflectors[k] for k in bounded])
    rects = box_screen_rects(low, high, camera.plain_view_projection, camera.size)
    seen = ~np.isnan(rects[:, 0])
    x0, y0, x1, y1 = np.clip(np.where(seen[:, None], rects, 0.0), 0.0, [width, height, width, height]).T
    angle, solid_angle = np.array([spreads[k] for k in bounded], dtype=np.float64).T
    focal = camera.focal_pixels
    # Largest off-axis angle of the rectangle, and how far the reach carries beyond it.
    corner_x = np.maximum(np.abs(x0 - width / 2.0), np.abs(x1 - width / 2.0))
    corner_y = np.maximum(np.abs(y0 - height / 2.0), np.abs(y1 - height / 2.0))
    off_axis = np.arctan(np.hypot(corner_x, corner_y) / focal)
    outer = off_axis + angle
    near_axis = outer < SCISSOR_MAX_ANGLE
    cos_outer = np.cos(np.where(near_axis, outer, 0.0))
    # Gnomonic projection: at most 1 / cos^2 pixels per radian along the way (radially).
    reach = focal * angle / cos_outer**2
    lod = 0.5 * np.log2(np.maximum(solid_angle * focal**2 / cos_outer**3, 1e-30)) + lod_bias + SCISSOR_LOD_SLACK
    # A bilinear read at level L uses the texel holding it and the neighbour nearer to it: pixels
    # up to 1.5 texels (of 2^ceil(L) pixels at the coarser of the two trilinear levels) away.
    reach = reach + 1.5 * 2.0 ** np.ceil(np.maximum(lod, 0.0)) + 1.0
    left = np.maximum(np.floor(x0 - reach), 0.0)
    bottom = np.maximum(np.floor(y0 - reach), 0.0)
    right = np.minimum(np.ceil(x1 + reach), width)
    top = np.minimum(np.ceil(y1 + reach), height)
    keep = seen & near_axis & (right > left) & (top > bottom) & ((right - left) * (top - bottom) < width * height)
    for row, k in enumerate(bounded):
        if keep[row]:
            out[k] = (int(left[row]), int(bottom[row]), int(right[row] - left[row]), int(top[row] - bottom[row]))
    return out


# -- sampling the buffer (4.5.2-4.5.3) -----------------------------------------------------------
@dataclass
class MirrorBuffers:
    """What one mirror pass produced, rows in OpenGL order (row 0 = v 0, the bottom)."""

    camera: MirrorCamera
    radiance: np.ndarray  # (H, W, 3)
    position: np.ndarray  # (H, W, 4): world xyz, w = 1 geometry, 0 environment
    normal: np.ndarray  # (H, W, 3)

    def texel(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        width, height = self.camera.size
        x = np.clip((uv[..., 0] * width).astype(int), 0, width - 1)
        y = np.clip((uv[..., 1] * height).astype(int), 0, height - 1)
        return y, x

    def radiance_bilinear(self, uv: np.ndarray) -> np.ndarray:
        """Level-0 bilinear lookup with clamp-to-edge, as a linearly filtered texture."""
        height, width = self.radiance.shape[:2]
        x = uv[..., 0] * width - 0.5
        y = uv[..., 1] * height - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = (x - x0)[..., None], (y - y0)[..., None]
        xs = np.clip([x0, x0 + 1], 0, width - 1)
        ys = np.clip([y0, y0 + 1], 0, height - 1)
        img = self.radiance
        top = img[ys[0], xs[0]] * (1 - fx) + img[ys[0], xs[1]] * fx
        bottom = img[ys[1], xs[0]] * (1 - fx) + img[ys[1], xs[1]] * fx
        return top * (1 - fy) + bottom * fy


def intersect_tangent_plane(p: np.ndarray, wi: np.ndarray, surface: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Homogeneous hit (..., 4) of rays p + t wi with the planes through surface[..., :3] with
    ``normal``; a direction (w = 0) where the buffer shows the environment (surface w < 0.5),
    the ray is parallel to the plane or the hit lies behind p."""
    p = np.broadcast_to(p, wi.shape)
    denom = np.sum(wi * normal, axis=-1)
    safe = np.where(np.abs(denom) < 1e-6, 1.0, denom)
    t = np.sum((surface[..., :3] - p) * normal, axis=-1) / safe
    ok = (surface[..., 3] >= 0.5) & (np.abs(denom) >= 1e-6) & (t > 0.0)
    hit = np.concatenate([p + t[..., None] * wi, np.ones(wi.shape[:-1] + (1,))], axis=-1)
    direction = np.concatenate([wi, np.zeros(wi.shape[:-1] + (1,))], axis=-1)
    return np.where(ok[..., None], hit, direction)


def project_samples(buffers: MirrorBuffers, p: np.ndarray, wi: np.ndarray, second_step: bool = True):
    """The two-step projection of 4.5.2 for sample directions ``wi`` (..., 3, unit, world) at the
    plane point ``p``: (uv (..., 2), hit (..., 4), tangent-plane normal (..., 3))."""
    p = np.asarray(p, dtype=np.float64)
    wi = np.asarray(wi, dtype=np.float64)
    own = buffers.camera.uv(np.append(p, 1.0))
    y, x = buffers.texel(own)
    surface = np.broadcast_to(buffers.position[y, x], wi.shape[:-1] + (4,))
    normal = np.broadcast_to(buffers.normal[y, x], wi.shape)
    hit = intersect_tangent_plane(p, wi, surface, normal)
    uv = buffers.camera.uv(hit)
    if second_step:
        y, x = buffers.texel(uv)
        surface, normal = buffers.position[y, x], buffers.normal[y, x]
        hit = intersect_tangent_plane(p, wi, surface, normal)
        uv = buffers.camera.uv(hit)
    return uv, hit, normal


@dataclass
class TangentPlaneAverage:
    """The averaged tangent plane of Fig. 4.46b at one pixel during progressive refinement: the
    running sums of the hit points and plane normals that the pixel's samples found so far (the
    shader keeps them, per buffer, in float targets across passes). The first step of the next sample
    intersects this plane instead of P_R's, so the projection changes smoothly from pixel to pixel
    across depth edges instead of jumping with P_R, and blur edges fade softly."""

    point_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))
    normal_sum: np.ndarray = field(default_factory=lambda: np.zeros(3))
    count: int = 0

    def plane(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(point, unit normal) of the averaged plane, None before the first geometry hit or where
        the normals cancel."""
        length = np.linalg.norm(self.normal_sum)
        if self.count == 0 or length < 1e-6:
            return None
        return self.point_sum / self.count, self.normal_sum / length

    def add(self, hit: np.ndarray, normal: np.ndarray) -> None:
        if hit[3] > 0.5:  # the environment has no plane
            self.point_sum = self.point_sum + hit[:3]
            self.normal_sum = self.normal_sum + normal
            self.count += 1


def project_samples_averaged(buffers: MirrorBuffers, p: np.ndarray, wi: np.ndarray, average: TangentPlaneAverage):
    """Progressive refinement's projection (Fig. 4.46b): directions ``wi`` (K, 3) in the order they
    are taken; the first step of each uses ``average``'s plane (P_R's before the first geometry
    hit, or where the ray misses it), followed by the second step of project_samples and one more
    such step, and the plane found last is added to ``average``. The averaged plane lies further
    from the true hit than P_R's near depth edges; measured against a ray tracer (``lobeview bench
    --mirrors``), averaging lowers the error of rough floors only with the third step. Returns
    (uv (K, 2), hit (K, 4), normal (K, 3))."""
    p = np.asarray(p, dtype=np.float64)
    wi = np.asarray(wi, dtype=np.float64).reshape(-1, 3)
    own_y, own_x = buffers.texel(buffers.camera.uv(np.append(p, 1.0)))
    uvs, hits, normals = [], [], []
    for direction in wi:
        hit = None
        plane = average.plane()
        if plane is not None:
            point, normal = plane
            hit = intersect_tangent_plane(p, direction, np.append(point, 1.0), normal)
            if hit[3] < 0.5:
                hit = None  # parallel or behind: P_R's plane as without averaging
        if hit is None:
            hit = intersect_tangent_plane(p, direction, buffers.position[own_y, own_x], buffers.normal[own_y, own_x])
        for _ in range(2):  # the second step of project_samples, then a third (see the docstring)
            y, x = buffers.texel(buffers.camera.uv(hit))
            normal = buffers.normal[y, x]
            hit = intersect_tangent_plane(p, direction, buffers.position[y, x], normal)
        average.add(hit, normal)
        uvs.append(buffers.camera.uv(hit))
        hits.append(hit)
        normals.append(normal)
    return np.array(uvs), np.array(hits), np.array(normals)


def sample_pixels(camera: MirrorCamera, p, wi, hit, normal, solid_angle) -> np.ndarray:
    """Buffer pixels covered by a sample of ``solid_angle`` around ``wi`` that hit the tangent
    plane (``normal``) at ``hit`` (w = 0: the environment), by the Jacobian in the docstring."""
    p = np.asarray(p, dtype=np.float64)
    eye = hit @ camera.view.T  # mirror eye space (w = 0 stays a direction)
    distance = np.linalg.norm(eye[..., :3], axis=-1)
    cos_alpha = np.maximum(-eye[..., 2] / np.maximum(distance, 1e-30), 1e-3)
    angular = solid_angle * camera.focal_pixels**2 / cos_alpha**3
    at_infinity = hit[..., 3] < 0.5
    t = np.linalg.norm(hit[..., :3] - p, axis=-1)
    to_hit = (hit[..., :3] - camera.position) / np.maximum(distance, 1e-30)[..., None]
    cos_in = np.maximum(np.abs(np.sum(normal * wi, axis=-1)), 1e-3)
    cos_out = np.abs(np.sum(normal * to_hit, axis=-1))
    scale = np.where(at_infinity, 1.0, t * t / cos_in * cos_out / np.maximum(distance, 1e-30) ** 2)
    return angular * scale
