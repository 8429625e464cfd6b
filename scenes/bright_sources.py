"""Bright-source separation (issue 39, step 1; numpy reference): the few regions of a radiance
map that carry most of its energy far above their surroundings become cap lights
(materials/cap_lights.py), and the map keeps their surroundings' level in their place.

Method, on any set of texels (directions, solid angles, RGB radiance: a cube map's faces or an
equirectangular environment map):
  1. threshold: luminance above BRIGHT_FACTOR times the map's median luminance (median by solid
     angle: robust to the sources themselves, which cover a tiny part of the sphere);
  2. regions: connected sets of such texels (neighbours within NEIGHBOUR_TEXELS texel widths of
     each other, found with a k-d tree on the directions, so regions run across cube faces and
     the equirectangular seam);
  3. per region, the surroundings' level B: the per-channel median radiance of the texels that
     are below the threshold and within SURROUND_TEXELS texel widths of the region's cap;
  4. the light is what lies above B: per texel and channel max(L - B, 0). The map without
     sources keeps min(L, B) there; the residual instead loses the light's cap drawn into its
     texels (:func:`rasterised_cap`), so it keeps, signed, how the source differs from a uniform
     cap (see :class:`Separation`). Either map plus the lights' power is the map before, exactly
     (nothing twice, nothing lost: tests/test_cap_lights.py checks it to 1e-4);
  5. the region becomes a cap around its energy-weighted mean direction, as wide as the removed
     energy's median spread (the energy-weighted median of 1 - cos about that axis, half a uniform
     cap's 1 - cos radius: a sun in its glow gets the sun's size), holding the excess of the
     region's texels inside it with uniform radiance; what the region holds beyond that core (a
     sun's glow, a soft box's corners) becomes a second light, a cone about the same axis with
     the same power and mean spread (:func:`glow_light`), where it holds at least
     MIN_LIGHT_SHARE of the map's energy and a light is left (else it stays in the map). The
     decisions below take the region's extent from the mean of 1 - cos; regions holding less than
     MIN_LIGHT_SHARE of the map's energy, regions whose peak is less than MIN_CONTRAST times
     their surroundings, regions whose cap's radiance is less than MIN_SOURCE_FACTOR times the
     map's median (a bright patch of sky between walls), and regions whose cap would be wider than
     MAX_LIGHT_SOLID_ANGLE (their structure matters), and regions wider than 2 degrees and more
     than MAX_ELONGATION times longer than wide (a band of city lights: a cap would be a disc),
     stay in the map; at most MAX_LIGHTS of the strongest are taken;
  6. a uniform region (a soft box, a disc lamp: the excess inside its cap varies by at most
     MAX_UNIFORM_VARIATION) becomes a soft-edged cap instead (:func:`soft_light`): its ramp, below
     the threshold, joins it, its surroundings are measured beyond the ramp, and the cap's rim and
     inner fraction come from the removed energy and its first moment about the axis, given the
     region's plateau (:func:`soft_cap_shape`). Up to
     MAX_UNIFORM_LIGHT_SOLID_ANGLE: a uniform region has no structure for the map to keep.
Debevec's median-cut (2005) places lights where the energy is but does not remove them; the
threshold-and-region scheme is the "light extraction" of production engines, with the removal
made conservative.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lobeview.core.cube_layout import equirect_direction, face_directions, texel_solid_angles
from lobeview.materials.cap_lights import CapLight, edge_profile
from lobeview.materials.lobe_fit import LUMINANCE

BRIGHT_FACTOR = 50.0  # a source is at least this many times the map's median luminance
MIN_LIGHT_SHARE = 0.005  # ... and holds at least this share of the map's energy
MAX_LIGHTS = 8
NEIGHBOUR_TEXELS = 1.5  # texels of a region lie within this many texel widths of each other
SURROUND_TEXELS = 4.0  # the surroundings: this many texel widths around the region's cap
# ... and its brightest texel at least this many times its surroundings' level (the sources that
# patterns and tail lookups miss are 1e2-1e5 times brighter than what is around them; a sunlit
# wall 20 times brighter than the sky beside it is structure that a sharp reflection shows).
MIN_CONTRAST = 100.0
# A light is a uniform cap: a bright region wider than this (10 degrees of radius) would lose the
# structure a sharp reflection shows (a sky or a sunlit wall), so it stays in the map.
MAX_LIGHT_SOLID_ANGLE = 2.0 * np.pi * (1.0 - np.cos(np.radians(10.0)))
# ... and a hard cap's radiance (the removed power over its solid angle) is at least this many
# times the map's median luminance: a region only 100x its map's median is a patch of bright sky
# between dark walls or trees, which the MIP-filtered reads see as they see the rest of the map,
# while its cap, a uniform disc, loses the patch's shape. Measured on the 11 captures of
# ../shared/assets/env (`lobeview bench light`, 4 x 4 points per pixel, against the 2048-sample
# reference): without courtyard's two caps (4.0 / 4.7 degrees, 132x / 91x the median) and forest's
# 7.1-degree cap (143x) the metals gain (lobe-7+norm+fit on miro5 6.0 -> 3.0 % and 15.6 -> 3.8 %,
# GGX 0.05 under forest 13.5 -> 3.0 %), but the wide lobes under forest lose (frosted glass 4.3 ->
# 9.8 %, the glTF plastic 7.5 -> 14.2 %: their grazing rim reads the patch from the map, where the
# cap's integral was exact); lobe-7's summed error over the 14 cells 105 -> 85. Every source the
# caps are for, suns, windows, lamps and soft boxes, is 640x-360 000x (interior's 1.9-degree
# window the faintest). Which a lobe wants depends on its width against the light's (not built).
MIN_SOURCE_FACTOR = 300.0
# The residual keeps a hard light's shape beyond its cap (see Separation) where the cap is at least
# this many texel widths in radius. Below, the shape is the texels' pixelation of a sun (its core
# in one texel, the drawn cap's ramp over the next): a near-mirror reads that signed detail at one
# point per pixel while its cap integral is widened by the pixel's footprint (cap_lights.py
# footprint_alpha2), and the two disagree by up to the cap's radiance: black pixels in a sun's
# highlight (GGX 0.01 under sunrise.exr, whose 1.03-degree sun is 2.3 texels of a 256^2 cube).
SHAPE_FROM_TEXELS = 3.0
# ... and only where its cap is drawn over the source itself: a cap whose solid angle lies for more
# than MAX_UNBACKED_SHARE over texels UNBACKED_CONTRAST times darker than its radiance is not the
# source's shape, and the residual keeps the source whole (the cube without sources still loses it
# as that disc, where the single lookups of prefiltered maps want it: the strip kept in both maps
# took prefiltered gold 1.9 -> 5.4 %). studio.exr's strip light (12 x 1.5 degrees in a glow that
# makes its elongation 2.99, under MAX_ELONGATION) became a 6-degree disc lying for 0.39-0.44 of
# its solid angle (128^2-512^2 cubes) over a backdrop 1400x darker, and the residual held that
# disc negative: where a pixel's cap integral (the lobe widened by its footprint, GGX's long tail)
# and its MIP-filtered residual reads (compact kernels) do not cancel to a fraction of the
# backdrop, the lobe's sum is clamped at 0: a near-mirror (GGX 0.01, 160 px, one point per pixel)
# showed 45 pixels with a channel at 0 along the strip's reflection, kept whole 1. At 4 x 4 points
# per pixel (`lobeview bench light`, docs/measurements.md) no conductor case moved by more than
# 0.1 but alanod (3.3 -> 4.0 %); frosted glass 1.4 -> 2.1, the red plastic 1.6 -> 2.3. Every
# round source of the 11 captures lies at most 0.21 over such texels (night.exr's lamps in their
# glows at 512^2), studio's round lamps 0.02: the strip is the only source kept whole.
MAX_UNBACKED_SHARE = 0.3
UNBACKED_CONTRAST = 100.0
# A uniform region (6.): builtin:studio's key and fill soft boxes (11 and 16 degrees, a ramp over
# their outer 1.3 and 2.2 degrees) stayed in the map, the key too wide, the fill's contrast
# measured against its own ramp; in a glossy floor's GGX tail the four tail lookups read them 2.5x
# too bright (tests/test_cap_lights.py, the glossy floor).
MAX_UNIFORM_VARIATION = 0.25  # coefficient of variation of the excess, weighted by solid angle
MAX_UNIFORM_LIGHT_SOLID_ANGLE = 2.0 * np.pi * (1.0 - np.cos(np.radians(25.0)))
SOFT_EDGE_FLOOR = 0.01  # a ramp texel's excess is at least this share of the region's median excess
RAMP_FALL = 0.1  # a soft edge goes on while each ring's median luminance falls by this share or more
RAMP_REACH = 1.5  # ... out to at most this many times the region's extent
# A soft box has a flat top and a ramp: a fitted inner fraction below this is a bright core in a
# glow (a real capture's lamps and sun), which keeps the hard cap of step 5 (the sun's size).
MIN_SOFT_INNER_FRACTION = 0.3


# A region much longer than wide (its energy's spread along its major axis over its minor, in the
# plane tangent at its centre) would become a round cap: a mirror would show a disc where the
# capture has a band. Such a region stays in the map where its cap is wider than 2 degrees
# (narrower ones are below what most lobes resolve).
MAX_ELONGATION = 3.5
ELONGATED_FROM_SOLID_ANGLE = 2.0 * np.pi * (1.0 - np.cos(np.radians(2.0)))


def elongation(directions: np.ndarray, weights: np.ndarray, centre: np.ndarray) -> float:
    """sqrt of the ratio of the major to the minor eigenvalue of the ``weights``-weighted
    covariance of ``directions`` projected (gnomonically) on the plane tangent at ``centre``."""
    helper = np.array([0.0, 1.0, 0.0]) if abs(centre[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t = np.cross(helper, centre)
    t /= np.linalg.norm(t)
    b = np.cross(centre, t)
    depth = np.maximum(directions @ centre, 1e-6)
    plane = np.stack([directions @ t, directions @ b], axis=1) / depth[:, None]
    if len(plane) < 3 or float(np.sum(weights)) <= 0.0:
        return 1.0
    mean = np.average(plane, axis=0, weights=weights)
    covariance = np.cov((plane - mean).T, aweights=weights)
    low, high = np.linalg.eigvalsh(covariance)
    return float(np.sqrt(high / max(low, 1e-30)))


@dataclass
class Separation:
    """Lights taken out of a map, and the map without them (same layout as the input), twice:
    ``residual`` lost each hard light's cap as drawn into its texels (signed: what the map holds
    beyond the uniform cap, a sun's core brighter than the cap, its glow darker), for the methods
    that read the map by lobe-sized footprints (lobe-N, fis-N: a footprint wider than the source
    reads about zero, a narrower one the source's real shape); ``without_sources`` has each
    source's texels at their surroundings' level (>= 0), for single lookups of prefiltered maps,
    whose finest levels would show the signed detail as it is. A source whose cap is not its
    shape (a strip light: MAX_UNBACKED_SHARE) stays whole in ``residual`` and is a light of
    ``without_sources`` only (``kept_whole``), and so is a glow's cone drawn over texels far darker
    than it (a soft box's corners: ``residual`` keeps them as they are); every other cone
    ``residual`` loses as drawn, signed. ``without_sources`` plus ``lights`` and ``residual`` plus
    ``residual_lights`` are the map's power (to 1e-4; tests/test_cap_lights.py)."""

    lights: list[CapLight]
    residual: np.ndarray
    threshold: float  # luminance above which texels were candidates
    regions: list[np.ndarray] = field(default_factory=list)  # texel indices of each light (flattened)
    without_sources: np.ndarray | None = None  # None: no lights, the map itself (``residual``)
    # how many lights ``residual`` loses as drawn, keeping their source's shape beyond them, signed:
    # caps of SHAPE_FROM_TEXELS texels or more and the glows' cones (0: ``residual`` is >= 0)
    shapes_kept: int = 0
    # the lights (indices into ``lights``) whose texels ``residual`` keeps whole: a source whose cap
    # is not its shape (MAX_UNBACKED_SHARE) and a cone drawn over texels far darker than it; only
    # the single lookups of ``without_sources`` use them
    kept_whole: list[int] = field(default_factory=list)

    def __post_init__(self):
        if self.without_sources is None:
            self.without_sources = self.residual

    @property
    def light_power(self) -> np.ndarray:
        """The lights' total power (RGB), what left ``without_sources``."""
        return np.sum([light.power for light in self.lights], axis=0) if self.lights else np.zeros(3)

    @property
    def residual_lights(self) -> list[CapLight]:
        """The lights ``residual`` lost: all but those it keeps whole."""
        return [light for k, light in enumerate(self.lights) if k not in self.kept_whole]

    @property
    def residual_light_power(self) -> np.ndarray:
        """The power (RGB) that left ``residual``."""
        lights = self.residual_lights
        return np.sum([light.power for light in lights], axis=0) if lights else np.zeros(3)


def cube_texels(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions (6, S, S, 3) and solid angles (6, S, S) of a cube map's texels
    (core/cube_layout.py: rows are t, columns s)."""
    size = faces.shape[1]
    directions = np.stack([face_directions(face, size) for face in range(6)])
    solid = texel_solid_angles(size).T  # [row t, column s]; symmetric anyway
    return directions, np.broadcast_to(solid, (6, size, size))


def equirect_texels(height: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions (H, 2H, 3) and exact solid angles (H, 2H) of an equirectangular map's texels."""
    width = 2 * height
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    uu, vv = np.meshgrid(u, v)
    directions = equirect_direction(uu, vv)
    band = (
        2.0
        * np.pi
        / width
        * (np.cos(np.pi * np.arange(height) / height) - np.cos(np.pi * (np.arange(height) + 1) / height))
    )
    return directions, np.broadcast_to(band[:, None], (height, width))


def separate_cube(faces: np.ndarray, **options) -> Separation:
    """:func:`separate` on the six faces (6, S, S, 3) of a radiance cube."""
    faces = np.asarray(faces)
    if faces.ndim != 4 or faces.shape[0] != 6 or faces.shape[1] != faces.shape[2] or faces.shape[3] < 3:
        raise ValueError(f"a cube map's faces have shape (6, S, S, 3), got {faces.shape}")
    directions, solid = cube_texels(faces)
    # A cube texel at a face's centre spans 2 / S radians: the widest on the cube.
    return separate(directions, solid, faces[..., :3], 2.0 / faces.shape[1], **options)


def separate_equirect(image: np.ndarray, **options) -> Separation:
    """:func:`separate` on an equirectangular map (H, 2H, 3)."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[1] != 2 * image.shape[0] or image.shape[2] < 3:
        raise ValueError(f"an equirectangular map has shape (H, 2H, 3), got {image.shape}")
    directions, solid = equirect_texels(image.shape[0])
    return separate(directions, solid, image[..., :3], np.pi / image.shape[0], **options)


def rasterised_cap(
    dirs, omega, centre, cos_radius, power, texel_angle, inner_fraction=1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The cap of ``power`` (RGB) around ``centre`` drawn into texels (``dirs``, ``omega``): each
    texel's covered share, a ramp one texel wide across the rim, times the cap's edge profile at
    the texel's centre (``inner_fraction`` < 1: materials/cap_lights.py edge_profile), scaled so
    that the texels carry exactly ``power``. Returns the texels it touches (indices into
    ``dirs``) and their radiance."""
    radius = float(np.arccos(np.clip(cos_radius, -1.0, 1.0)))
    cos_angle = np.clip(dirs @ centre, -1.0, 1.0)
    angle = np.arccos(cos_angle)
    coverage = np.clip((radius - angle) / texel_angle + 0.5, 0.0, 1.0)
    if inner_fraction < 1.0:
        coverage *= edge_profile(np.minimum((1.0 - cos_angle) / (1.0 - cos_radius), 1.0), inner_fraction)
    touched = np.flatnonzero(coverage > 0.0)
    if len(touched) == 0:  # a cap far below a texel: the nearest texel holds it
        touched = np.array([int(np.argmin(angle))])
        coverage[touched] = 1.0
    weight = coverage[touched] * omega[touched]
    radiance = np.outer(weight / float(np.sum(weight)) / omega[touched], power)
    return touched, radiance


def unbacked_share(dirs, omega, luminance, centre, cos_radius, radiance) -> float:
    """The share of a cap's solid angle (texels ``dirs``, ``omega`` near it, their map
    ``luminance``) over which the map is darker than UNBACKED_CONTRAST times less than the cap's
    ``radiance`` (RGB): where the cap is drawn over the source's dark surroundings."""
    inside = dirs @ centre >= cos_radius
    if not inside.any():
        return 0.0
    dark = inside & (luminance * UNBACKED_CONTRAST < float(np.asarray(radiance) @ LUMINANCE))
    return float(np.sum(omega[dark]) / np.sum(omega[inside]))


def energy_median_spread(energy: np.ndarray, cos_to_axis: np.ndarray) -> float:
    """The ``energy``-weighted median of 1 - cos(angle to the axis) over a region's texels: half
    a uniform cap's 1 - cos(radius), as the mean is, but robust to a glow's far tail."""
    one_minus_cos = 1.0 - np.clip(cos_to_axis, -1.0, 1.0)
    order = np.argsort(one_minus_cos)
    cumulative = np.cumsum(energy[order])
    if cumulative[-1] <= 0.0:
        return 0.0
    return float(one_minus_cos[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def excess_variation(excess: np.ndarray, omega: np.ndarray, cos_to_axis: np.ndarray, cos_radius: float) -> float:
    """Coefficient of variation (weighted by solid angle) of a region's excess luminance over its
    texels inside the cap of ``cos_radius`` about its axis (``cos_to_axis``: each texel's cosine to
    it); inf with fewer than two texels there or no excess."""
    inside = cos_to_axis >= cos_radius
    if np.count_nonzero(inside) < 2:
        return float("inf")
    values, weights = excess[inside], omega[inside]
    mean = float(np.average(values, weights=weights))
    if mean <= 0.0:
        return float("inf")
    return float(np.sqrt(np.average((values - mean) ** 2, weights=weights)) / mean)


def soft_cap_shape(energy: float, first_moment: float, plateau: float) -> tuple[float, float]:
    """(1 - cos rim, inner fraction f) of the soft-edged cap (materials/cap_lights.py
    edge_profile) with the plateau radiance ``plateau`` that holds ``energy`` = integral of L dw
    and ``first_moment`` = integral of L (1 - cos) dw about its axis. With b = 1 - cos rim and the
    profile 1 up to u = f b, linear to 0 at u = b (u = 1 - cos):
        energy = pi plateau b (1 + f),   first_moment = pi plateau b^2 (1 + f + f^2) / 3,
    so with P = energy / (pi plateau), 3 first_moment / (energy P) = (1 + f + f^2) / (1 + f)^2,
    which falls from 1 (f = 0, a cone) to 3/4 (f = 1, uniform): f solves the quadratic
    (1 - q) f^2 + (1 - 2 q) f + (1 - q) = 0, q that ratio; b = P / (1 + f). The rim comes from
    the energy, not from the farthest texel: a texel centre lies up to half a texel inside it."""
    extent = energy / (np.pi * plateau)
    q = float(np.clip(3.0 * first_moment / (energy * extent), 0.75, 1.0))
    if q >= 1.0:
        f = 0.0
    else:
        a, b = 1.0 - q, 1.0 - 2.0 * q  # a f^2 + b f + a = 0, the root in [0, 1]
        f = float(min((-b - np.sqrt(max(b * b - 4.0 * a * a, 0.0))) / (2.0 * a), 1.0))
    return extent / (1.0 + f), max(f, 0.0)


def glow_light(dirs, omega, excess, centre, core_cos_radius, min_power) -> CapLight | None:
    """What a hard source holds beyond its core's cap (texels ``dirs``, ``omega`` and their RGB
    ``excess``: a sun's glow, a soft box's corners) as a cone about the core's axis (``centre``):
    a soft-edged cap with inner fraction 0, its radiance falling linearly in cos from the axis to 0
    at the rim, which holds energy pi L b and first moment pi L b^2 / 3 about the axis (b = 1 - cos
    rim; soft_cap_shape with f = 0), so b is 3 times the excess' energy-weighted mean of 1 - cos:
    exact in power and mean spread, for the lobes wider than the core, which read the glow's
    integral, not its shape. None where it carries less than ``min_power`` (luminance: the glow
    stays in the map) or would be wider than MAX_UNIFORM_LIGHT_SOLID_ANGLE."""
    power = np.sum(excess * omega[:, None], axis=0)
    energy = excess @ LUMINANCE * omega
    if float(power @ LUMINANCE) < min_power or float(np.sum(energy)) <= 0.0:
        return None
    mean_spread = float(np.sum(energy * (1.0 - np.clip(dirs @ centre, -1.0, 1.0))) / float(np.sum(energy)))
    rim = max(3.0 * mean_spread, 1.0 - core_cos_radius)
    if 2.0 * np.pi * rim > MAX_UNIFORM_LIGHT_SOLID_ANGLE:
        return None
    light = CapLight(centre, 1.0 - rim, np.ones(3), 0.0)
    return CapLight(centre, 1.0 - rim, power / light.lit_solid_angle, 0.0)


@dataclass
class SoftLight:
    """A uniform region as a soft-edged cap (step 6): the light, the texels it takes (its region
    and its ramp) and what each of them loses."""

    light: CapLight
    texels: np.ndarray
    excess: np.ndarray


def ramp_end(dirs, luminance, centre, extent, texel_angle, all_tree) -> float:
    """How far (a chord from ``centre``) a uniform region's soft edge reaches below the threshold:
    out from the region's ``extent`` in rings one texel wide, until a ring's median luminance
    falls by less than RAMP_FALL from the ring before (the ramp has ended; at most RAMP_REACH
    times the extent). The ramp's width is the light's, not a number of texels: builtin:studio's
    fill ramps over 2.2 degrees, 9 texels of a 256^2 cube and 2 of a 64^2 one."""
    reach = extent * RAMP_REACH + texel_angle
    near = np.asarray(all_tree.query_ball_point(centre, reach), dtype=int)
    distance = np.linalg.norm(dirs[near] - centre, axis=1)
    previous = float(np.median(luminance[near[distance <= extent]]))
    edge = extent
    while edge + texel_angle <= reach:
        ring = near[(distance > edge) & (distance <= edge + texel_angle)]
        if len(ring) == 0:
            break
        level = float(np.median(luminance[ring]))
        if level > (1.0 - RAMP_FALL) * previous:
            break
        previous, edge = level, edge + texel_angle
    return edge + texel_angle


def soft_light(dirs, omega, light_in, luminance, region, centre, extent, threshold, texel_angle, all_tree):
    """Step 6 for one uniform region, or None where it is not far enough above its surroundings.
    The surroundings are measured in the SURROUND_TEXELS wide ring beyond the ramp (:func:`ramp_end`):
    a soft edge fills the ring next to the region (builtin:studio's fill, a 2-degree ramp: 3x that
    ring's level, 117x the next one's). The ramp is every texel up to its end whose excess over
    that level is at least SOFT_EDGE_FLOOR of the region's."""
    first = ramp_end(dirs, luminance, centre, extent, texel_angle, all_tree)
    inner = np.asarray(all_tree.query_ball_point(centre, first), dtype=int)
    ring = np.setdiff1d(
        np.asarray(all_tree.query_ball_point(centre, first + SURROUND_TEXELS * texel_angle), int), inner
    )
    ring = ring[luminance[ring] <= threshold]
    if len(ring) == 0:
        return None
    level = np.median(light_in[ring], axis=0)
    if float(luminance[region].max()) < MIN_CONTRAST * float(level @ LUMINANCE):
        return None
    excess_luminance = np.maximum(luminance[inner] - float(level @ LUMINANCE), 0.0)
    floor = SOFT_EDGE_FLOOR * float(np.median(luminance[region] - float(level @ LUMINANCE)))
    texels = np.union1d(inner[excess_luminance >= floor], region)
    excess = np.maximum(light_in[texels] - level, 0.0)
    removed = excess @ LUMINANCE * omega[texels]
    energy = float(np.sum(removed))
    plateau = float(np.percentile(excess[np.isin(texels, region)] @ LUMINANCE, 90.0))
    if energy <= 0.0 or plateau <= 0.0:
        return None
    first_moment = float(np.sum(removed * (1.0 - np.clip(dirs[texels] @ centre, -1.0, 1.0))))
    one_minus_cos, inner_fraction = soft_cap_shape(energy, first_moment, plateau)
    if inner_fraction < MIN_SOFT_INNER_FRACTION or 2.0 * np.pi * one_minus_cos > MAX_UNIFORM_LIGHT_SOLID_ANGLE:
        return None
    light = CapLight(centre, 1.0 - one_minus_cos, np.ones(3), inner_fraction)
    power = np.sum(excess * omega[texels, None], axis=0)
    return SoftLight(
        CapLight(centre, 1.0 - one_minus_cos, power / light.lit_solid_angle, inner_fraction), texels, excess
    )


def separate(
    directions: np.ndarray,
    solid_angles: np.ndarray,
    radiance: np.ndarray,
    texel_angle: float,
    bright_factor: float = BRIGHT_FACTOR,
    min_share: float = MIN_LIGHT_SHARE,
    max_lights: int = MAX_LIGHTS,
) -> Separation:
    """Steps 1-5 of the module docstring on texels of any layout: ``directions`` (..., 3) unit
    vectors, ``solid_angles`` (...), ``radiance`` (..., 3) finite and >= 0 (scenes/hdrio.py
    sanitises what it reads), ``texel_angle`` the widest texel's angular size in radians."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    shape = radiance.shape
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    omega = np.asarray(solid_angles, dtype=np.float64).reshape(-1)
    light_in = np.asarray(radiance, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(light_in)) or np.any(light_in < 0.0):
        raise ValueError("bright-source separation needs finite radiance >= 0 (sanitise the map first)")
    residual = light_in.copy()
    without_sources = light_in.copy()
    luminance = light_in @ LUMINANCE
    order = np.argsort(luminance)
    cumulative = np.cumsum(omega[order])
    median = float(luminance[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])
    total_energy = float(np.sum(luminance * omega))
    threshold = bright_factor * max(median, 1e-6 * float(luminance.max(initial=0.0)), 1e-12)
    hot = np.flatnonzero(luminance > threshold)
    if len(hot) == 0 or total_energy <= 0.0:
        return Separation([], residual.reshape(shape).astype(radiance.dtype), threshold)

    # 2. regions: hot texels within NEIGHBOUR_TEXELS texel widths (chord ~ angle) are joined
    tree = cKDTree(dirs[hot])
    pairs = tree.query_pairs(NEIGHBOUR_TEXELS * texel_angle, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(hot), len(hot)))
    count, labels = connected_components(graph, directed=False)
    regions = [hot[labels == k] for k in range(count)]
    regions.sort(key=lambda idx: -float(np.sum(luminance[idx] * omega[idx])))

    all_tree = cKDTree(dirs)
    lights, kept = [], []
    shapes_kept = 0
    kept_whole: list[int] = []
    taken = np.zeros(len(dirs), bool)  # texels another light already took (soft edges reach out)
    for region in regions:
        if len(lights) == max_lights:
            break
        weights = luminance[region] * omega[region]
        centre = np.sum(dirs[region] * weights[:, None], axis=0)
        centre /= max(np.linalg.norm(centre), 1e-300)
        # 3. the surroundings: non-hot texels within SURROUND_TEXELS of the region's extent
        extent = float(np.max(np.linalg.norm(dirs[region] - centre, axis=1)))
        near = np.asarray(all_tree.query_ball_point(centre, extent + SURROUND_TEXELS * texel_angle), dtype=int)
        near = near[luminance[near] <= threshold]
        background = np.median(light_in[near], axis=0) if len(near) else np.zeros(3)
        # 4. what lies above the surroundings leaves the map
        excess = np.maximum(light_in[region] - background, 0.0)
        power = np.sum(excess * omega[region, None], axis=0)
        if float(power @ LUMINANCE) < min_share * total_energy:
            continue
        # 5. a cap carrying that power, as wide as the removed energy is spread: for a uniform
        # cap the energy-weighted mean of 1 - cos(angle to the axis) is (1 - cos r) / 2, so a
        # sun inside its glow becomes a cap of the sun's size, not of the glow's
        removed = excess @ LUMINANCE * omega[region]
        spread = float(np.sum(removed * (1.0 - dirs[region] @ centre)) / max(float(np.sum(removed)), 1e-300))
        region_omega = float(np.sum(omega[region]))
        cap_omega = min(max(4.0 * np.pi * spread, float(np.min(omega[region]))), region_omega)
        cos_radius = 1.0 - cap_omega / (2.0 * np.pi)
        # 6. a uniform region: a soft-edged cap with its ramp
        if excess_variation(removed / omega[region], omega[region], dirs[region] @ centre, cos_radius) <= (
            MAX_UNIFORM_VARIATION
        ):
            soft = soft_light(
                dirs, omega, light_in, luminance, region, centre, extent, threshold, texel_angle, all_tree
            )
            if soft is not None and not taken[soft.texels].any():
                residual[soft.texels] = light_in[soft.texels] - soft.excess
                without_sources[soft.texels] = residual[soft.texels]
                taken[soft.texels] = True
                lights.append(soft.light)
                kept.append(soft.texels)
                continue
        if float(luminance[region].max()) < MIN_CONTRAST * float(background @ LUMINANCE):
            continue  # bright, but not far above its surroundings: structure, not a source
        if float(power @ LUMINANCE) / cap_omega < MIN_SOURCE_FACTOR * median:
            continue  # a bright patch of the map (sky between walls), not a source: its shape stays
        if cap_omega > MAX_LIGHT_SOLID_ANGLE or taken[region].any():
            continue  # a wide bright region keeps its structure in the map
        if cap_omega > ELONGATED_FROM_SOLID_ANGLE and elongation(dirs[region], removed, centre) > MAX_ELONGATION:
            continue  # a band (a horizon's city lights) is no cap: the map keeps its shape
        # the light is the source's core: a cap of the energy's median spread (equal to the mean's
        # for a uniform cap, but blind to a glow's far tail, which the mean weighs by its angle
        # squared; the decisions above keep the mean's extent, or a clipped sun's uniform core
        # would pass step 6 as a soft box) over the region's texels within it (half a texel of
        # slack); what the region holds beyond (a glow, a soft box's corners) is a second light,
        # a cone about the same axis (glow_light). sunrise.exr's sun holds 95 % of its excess
        # within 0.6 degrees; the mean made it one 1.03-degree cap, too flat for a 1-4-degree lobe.
        # At least a texel in radius: a sun smaller than a texel is a texel in the cube and in the
        # reference reading it (city.exr's and chinese_garden's suns as 0.32-degree caps at 256^2:
        # miro5 5.9 -> 7.5 and 4.3 -> 5.8 %; a texel, 0.45 degrees: 5.6 % under city.exr)
        median_omega = 4.0 * np.pi * energy_median_spread(removed, dirs[region] @ centre)
        texel_omega = 2.0 * np.pi * (1.0 - np.cos(texel_angle))  # a cap a texel in radius
        cap_omega = min(cap_omega, max(median_omega, texel_omega))
        cos_radius = 1.0 - cap_omega / (2.0 * np.pi)
        in_core = dirs[region] @ centre >= np.cos(min(np.arccos(cos_radius) + 0.5 * texel_angle, np.pi))
        if not in_core.any():
            in_core = removed == removed.max()
        core, halo = region[in_core], region[~in_core]
        power = np.sum(excess[in_core] * omega[core, None], axis=0)
        glow = None
        if len(halo) and len(lights) + 2 <= max_lights:
            glow = glow_light(dirs[halo], omega[halo], excess[~in_core], centre, cos_radius, min_share * total_energy)
        source = region if glow is not None else core  # the texels whose excess the lights carry
        # the map keeps the source's shape beyond its cap: it loses the cap as drawn into its
        # texels (signed; the methods that read it by lobe-sized footprints see the sun's core in
        # its glow, a soft box's corners), and, for single lookups, a copy loses the excess the
        # lights carry (a cap narrower than SHAPE_FROM_TEXELS texels has no shape the map resolves)
        keeps_shape = np.arccos(cos_radius) >= SHAPE_FROM_TEXELS * texel_angle
        whole = False  # the residual keeps the source as it is (its cap is not its shape)
        if keeps_shape:
            near_cap = np.asarray(
                all_tree.query_ball_point(centre, np.sqrt(2.0 * (1.0 - cos_radius)) + texel_angle), dtype=int
            )
            share = unbacked_share(
                dirs[near_cap], omega[near_cap], luminance[near_cap], centre, cos_radius, power / cap_omega
            )
            whole = share > MAX_UNBACKED_SHARE
        without_sources[source] = light_in[source] - (excess if glow is not None else excess[in_core])
        new_lights = [CapLight(centre, cos_radius, power / cap_omega)] + ([glow] if glow is not None else [])
        if whole:
            kept_whole.extend(range(len(lights), len(lights) + len(new_lights)))
        elif keeps_shape:
            drawn, in_map = rasterised_cap(dirs[near_cap], omega[near_cap], centre, cos_radius, power, texel_angle)
            residual[near_cap[drawn]] -= in_map
            shapes_kept += 1
        else:
            residual[core] = without_sources[core]
        if glow is not None and not whole:
            # the residual keeps the glow's shape beyond its cone: it loses the cone as drawn
            # (signed), so a lobe narrower than the glow reads the glow as it is and a wider one
            # the cone's exact integral; a cone drawn over texels far darker than it (a soft box's
            # corners, the sky between them) is no shape of them: the residual keeps them whole
            reach = np.sqrt(2.0 * (1.0 - glow.cos_radius)) + texel_angle
            near = np.asarray(all_tree.query_ball_point(centre, reach), dtype=int)
            mean_radiance = glow.power / glow.solid_angle
            if unbacked_share(dirs[near], omega[near], luminance[near], centre, glow.cos_radius, mean_radiance) > (
                MAX_UNBACKED_SHARE
            ):
                kept_whole.append(len(lights) + 1)
            else:
                drawn, in_map = rasterised_cap(
                    dirs[near], omega[near], centre, glow.cos_radius, glow.power, texel_angle, glow.inner_fraction
                )
                residual[near[drawn]] -= in_map
                shapes_kept += 1
        taken[source] = True
        lights.extend(new_lights)
        kept.extend([core, halo][: len(new_lights)])
    return Separation(
        lights,
        residual.reshape(shape).astype(radiance.dtype),
        threshold,
        kept,
        without_sources.reshape(shape).astype(radiance.dtype),
        shapes_kept,
        kept_whole,
    )
