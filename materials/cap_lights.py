"""Bright sources as area lights on the sphere of directions, and their exact integration against
any lobe (issue 39, steps 1-2; numpy reference of shaders/cap_lights.glsl).

A :class:`CapLight` is a spherical cap of uniform radiance, or with a soft edge (its radiance
falling linearly in cos(angle) to zero at the rim: a soft box): what scenes/bright_sources.py
takes out of a radiance cube or an environment map where a few texels carry most of the energy
far above their surroundings (a sun, a window, a softbox), so that the cube left behind is smooth
enough for the frame's method and the source itself is integrated exactly.

Integration (:func:`integrate_cap_light`): the outgoing radiance of one lobe under one light,
    L_o = integral over the cap of f(wi, wo) cos(theta_i) L dwi,
(L the cap's radiance times its edge profile) by deterministic multiple importance sampling of
two strategies, both on the golden-ratio lattice
(materials/patterns.py lattice_xi): M points uniform over the cap (pdf 1 / Omega) and K points
from the lobe's own sampler (pdf p), combined with the balance heuristic (Veach 1997, Eq. 9.10):
    L_o = sum_i f cos L / (M / Omega + K p(x_i))  +  sum_j [y_j in cap] f cos L / (M / Omega + K p(y_j)).
Each term is bounded where either density is large, so the sum is accurate both for a lobe much
wider than the cap (the cap points see a nearly constant f: a sun on a rough metal) and for a lobe
much narrower than the cap (the lobe points all fall inside: a mirror reflecting a window), and
it converges to the integral for any lobe with a sampler and a pdf (every Component of
materials/bsdf.py: microfacet, thesis, glTF, Rational), Fresnel and shadowing included because it
evaluates the lobe itself. LTC (Heitz et al. 2016) would need fitted tables per lobe family; this
needs none, at the price of M + K BSDF evaluations per light and lobe. Tested against brute-force
quadrature over the cap (tests/test_cap_lights.py).

Where the cap is at most as wide as the lobe (q < GAUSS_BELOW below), that sum is a lottery: a
deterministic lattice puts 0, 1 or 2 of the lobe's points into a small cap, each carrying a fixed
share of the result. There the cap alone is integrated by a product Gauss rule
(:func:`gauss_cap_integral`: Gauss-Legendre in the profile's area fraction times equally spaced
azimuths, 1-24 points by q), which is exact for an integrand polynomial in the cap's
coordinates and converges fast for one smooth across it: a lobe at least as wide as the cap is.

What a light costs per pixel and lobe (each point a BSDF evaluation): nothing where the cap lies
below the lobe's horizon (:func:`cap_below_horizon`, about half the lights of a curved object's
pixels) or where a Beckmann tail holds nothing over it (:func:`cap_negligible`); where a cap is
farther from a GGX lobe's peak than the lobe is wide, the rule its distance asks for
(:func:`cap_peak_distance`, TAIL_GAUSS_RULES): the tail is smooth on that scale, so a light far
off the highlight takes 1-4 points, not up to 24.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bsdf import gauss_legendre_unit
from .patterns import GOLDEN_LATTICE_STEP, LATTICE_U2_START, lattice_xi

CAP_POINTS = 8  # cap points per light and lobe of a lobe without a width (Rational, measured)
LOBE_POINTS = 8  # ... and lobe points
# Soft-edged caps (soft boxes) of such lobes take twice as many: with 8 + 8 the deterministic
# sum's error showed as blotches inside the boxes' reflections (builtin:studio, fifteenth session).
SOFT_CAP_POINTS = 16
SOFT_LOBE_POINTS = 16
MIN_VIEW_COSINE = 0.1
# A lobe no wider than the cap (q >= NARROW_FROM, q = the cap's radius / the lobe's width
# 2 atan(2 sqrt(ax ay)) cos(theta_o): reflected lobes narrow towards grazing views; chrome in a
# soft box) takes NARROW_LOBE_POINTS lobe points and NARROW_CAP_POINTS cap points combined by the
# power heuristic (Veach 1997, Eq. 9.13, beta = 2): inside a uniform cap f cos / p is nearly
# constant over the lobe's samples, while with the balance heuristic each of 8 cap points that
# lands in the lobe's core added up to 1/8 of its albedo (-9 / +12 % from pixel to pixel, chrome
# under builtin:studio; 1 % with these). The cap points stay for the lobe's tail where its core
# misses the cap. From q = 1 (was 2, with 8 + 8 points by the balance heuristic between 1 and 2:
# 150 random caps with q in 1-2 at 7.9 % / 12 % error at the 95th percentile / worst, 3.8 / 9.6 %
# with these 8 + 16; narrower caps take the Gauss rule below).
NARROW_FROM = 1.0
NARROW_LOBE_POINTS = 16
NARROW_CAP_POINTS = 8
# A cap not much wider than the lobe (q < GAUSS_BELOW) is integrated over the cap alone by a
# product Gauss rule (:func:`gauss_cap_rule`): Gauss-Legendre nodes in the profile's area fraction
# (a function smooth across the cap is smooth in it, the axis included) times equally spaced
# azimuths. The two-strategy lattice sum above was a lottery there: whether 0, 1 or 2 of a lobe's
# 8 lattice points land inside a 4-degree cap moved a GGX 0.15 highlight by -10 to +34 % (gold under
# the studio capture), and 400 random caps of 0.2-25 degrees on GGX / Beckmann 0.01-0.5 lobes put
# its 95th-percentile error at 8.5 % for q in 0.2-0.35, 5-8 % up to q = 2 (relative to the value
# with the cap on the lobe's peak). The rule's rings x azimuths by q, the fewest points whose
# error on those caps is <= 0.6 % at the 95th percentile and <= 1 % at worst (azimuths count more
# than rings: 3 x 8 equals 4 x 8 up to q = 1; docs/measurements.md). Beyond q = 1 a Gauss rule
# of 24 points is no better than the two-strategy sum (6 against 7.6 %): the NARROW_* sum.
# One point on the axis up to q = 0.05 (second order in q: 0.17 / 0.35 % there, 0.63 / 0.96 up
# to 0.1, against a 3 x 16 rule).
GAUSS_RULES = ((0.05, 1, 1), (0.2, 1, 4), (0.35, 2, 6), (0.6, 3, 6), (1.0, 3, 8))
GAUSS_BELOW = GAUSS_RULES[-1][0]  # = NARROW_FROM: every cap of a lobe with a width has a rule
# A cap farther from a GGX lobe's peak than the lobe's width sees only the tail, smooth on the
# scale of that distance (:func:`cap_peak_distance`; q over the distance): there each rule holds
# to larger q. Measured on random caps in that regime (error relative to the cap's own value,
# 95th percentile / worst): 1 x 4 points 0.84 / 1.4 % up to q = 0.34 (1.5 % at 0.3-0.45),
# 2 x 6 0.67 / 0.93 % up to 0.68, 3 x 8 0.38 / 0.91 % up to 1 (3 x 6 no better than 2 x 6 there;
# docs/measurements.md, forty-first session).
TAIL_GAUSS_RULES = ((0.05, 1, 1), (0.3, 1, 4), (0.6, 2, 6), (1.0, 3, 8))
GAUSS_RINGS = 3  # Gauss-Legendre rules of 1-3 nodes (shaders/cap_lights.glsl gauss_node)
# Below MIN_VIEW_COSINE q stops growing while the reflected lobe still narrows and stretches
# along the plane of incidence: there the rule's azimuths double. Measured (12 caps around the
# mirror direction, error relative to the largest value): GGX 0.05 under a 1-degree cap at
# cos theta_o 0.05 / 0.03, 3 x 8 points 14 / 31 % at worst, 3 x 16 3.0 / 10 %; GGX 0.02 under
# 0.5 degrees 19 / 37 -> 5.9 / 13 %; GGX 0.15 under 2 degrees 3.9 / 7.2 -> 0.6 / 2.0 % (the medians
# at most 2 % either way; docs/measurements.md, thirty-seventh session).
GRAZING_AZIMUTH_FACTOR = 2


@dataclass(frozen=True)
class CapLight:
    """A spherical cap of directions around the unit vector ``direction`` with angular radius
    acos(``cos_radius``) and ``radiance`` (RGB): an area light at infinity. ``inner_fraction`` f
    gives it a soft edge: with u = (1 - cos angle) / (1 - cos_radius), the cap's share of solid
    angle from its axis, the radiance is ``radiance`` for u <= f and falls linearly to 0 at u = 1
    (linear in cos(angle), as builtin:studio's soft boxes are made); f = 1: uniform."""

    direction: np.ndarray
    cos_radius: float
    radiance: np.ndarray
    inner_fraction: float = 1.0

    def __post_init__(self):
        direction = np.asarray(self.direction, dtype=np.float64).reshape(3)
        length = float(np.linalg.norm(direction))
        if not np.isfinite(length) or length == 0.0:
            raise ValueError(f"a cap light needs a finite, non-zero direction, got {self.direction}")
        if not -1.0 < self.cos_radius < 1.0:
            raise ValueError(f"a cap light's cos(radius) must lie in (-1, 1), got {self.cos_radius}")
        radiance = np.asarray(self.radiance, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(radiance)) or np.any(radiance < 0.0):
            raise ValueError(f"a cap light's radiance must be finite and >= 0, got {radiance}")
        if not 0.0 <= self.inner_fraction <= 1.0:
            raise ValueError(f"a cap light's inner fraction must lie in [0, 1], got {self.inner_fraction}")
        object.__setattr__(self, "direction", direction / length)
        object.__setattr__(self, "radiance", radiance)
        object.__setattr__(self, "inner_fraction", float(self.inner_fraction))

    @property
    def solid_angle(self) -> float:
        return float(2.0 * np.pi * (1.0 - self.cos_radius))

    @property
    def radius(self) -> float:
        """Angular radius in radians."""
        return float(np.arccos(self.cos_radius))

    @property
    def lit_solid_angle(self) -> float:
        """The integral of the edge profile over the cap: solid_angle (1 + f) / 2."""
        return self.solid_angle * 0.5 * (1.0 + self.inner_fraction)

    @property
    def power(self) -> np.ndarray:
        """The integral of its radiance over directions (RGB): what it took out of the cube."""
        return self.radiance * self.lit_solid_angle

    def profile(self, directions: np.ndarray) -> np.ndarray:
        """The edge profile (0 outside the cap, 1 inside its uniform core) at ``directions``."""
        return edge_profile(
            (1.0 - np.asarray(directions) @ self.direction) / (1.0 - self.cos_radius), self.inner_fraction
        )

    def contains(self, directions: np.ndarray) -> np.ndarray:
        return np.asarray(directions) @ self.direction >= self.cos_radius

    def frame(self) -> np.ndarray:
        """3x3 with columns t, b, direction: an orthonormal frame around the cap's axis."""
        axis = self.direction
        helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        t = np.cross(helper, axis)
        t /= np.linalg.norm(t)
        return np.stack([t, np.cross(axis, t), axis], axis=1)

    def points(self, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
        """Directions uniform in solid angle over the cap for (u1, u2) in [0, 1)^2:
        cos(angle from the axis) = 1 - u1 (1 - cos_radius), azimuth 2 pi u2."""
        cos_t = 1.0 - np.asarray(u1) * (1.0 - self.cos_radius)
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        phi = 2.0 * np.pi * np.asarray(u2)
        local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
        return local @ self.frame().T


def edge_profile(u: np.ndarray, inner_fraction: float) -> np.ndarray:
    """A cap's radiance profile at u = (1 - cos angle) / (1 - cos radius) (shaders/cap_lights.glsl
    cap_edge_profile): 1 up to ``inner_fraction``, then linear to 0 at u = 1, 0 beyond."""
    u = np.asarray(u, dtype=np.float64)
    ramp = np.clip((1.0 - u) / max(1.0 - inner_fraction, 1e-12), 0.0, 1.0)
    return np.where(u <= inner_fraction, 1.0, ramp)


def profile_area_fraction(xi: np.ndarray, inner_fraction: float) -> np.ndarray:
    """The area fraction u (the ``points`` coordinate u1) at which a share ``xi`` of the edge
    profile's integral lies nearer the axis: the inverse of its CDF, C(u) = u / A for u <= f and
    (f + t - t^2 / (2 w)) / A beyond, t = u - f, w = 1 - f, A = (1 + f) / 2. f = 1: u = xi."""
    xi = np.asarray(xi, dtype=np.float64)
    f = float(inner_fraction)
    s = xi * 0.5 * (1.0 + f)
    w = max(1.0 - f, 1e-300)
    ramp = f + w * (1.0 - np.sqrt(np.maximum(1.0 - 2.0 * (s - f) / w, 0.0)))
    return np.where(s <= f, s, ramp)


def symmetric_cap_xi(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n cap points (u1: cap area fraction from the axis, u2: azimuth fraction) symmetric about
    the axis: one on the axis when n is odd, then antipodal pairs, pair j at u1 = (j + 1/2) / pairs
    and the golden-ratio azimuth frac(1/4 + j / golden ratio), its partner half a turn away. A
    symmetric set cancels the first-order error of a lobe whose value changes across the cap;
    the golden-ratio lattice alone put 3 points' centroid off the axis and skewed a lamp's
    highlight by half a pixel (8 % against Mitsuba on a GGX 0.15 floor, bench/lamps.py)."""
    if n < 1:
        raise ValueError(f"a cap needs at least one point, got n = {n}")
    pairs = n // 2
    j = np.arange(pairs, dtype=np.float64)
    radial = (j + 0.5) / max(pairs, 1)
    azimuth = (LATTICE_U2_START + j * GOLDEN_LATTICE_STEP) % 1.0
    u1 = np.stack([radial, radial], axis=1).ravel()
    u2 = np.stack([azimuth, (azimuth + 0.5) % 1.0], axis=1).ravel()
    if n % 2:
        u1, u2 = np.concatenate([[0.0], u1]), np.concatenate([[0.0], u2])
    return u1, u2


def cap_xi(cap_points: int, lobe_points: int) -> tuple[np.ndarray, np.ndarray]:
    """The cap points: symmetric about the axis (:func:`symmetric_cap_xi`) where no lobe points
    are taken (the cap is small against the lobe, so f changes smoothly across it and its
    gradient is the error to cancel), else the golden-ratio lattice, whose distinct radii and
    azimuths cover a cap that a narrower lobe lights only in part (there the symmetric pairs
    were 31 % low: a 5-degree cap 10 degrees off a GGX 0.01 lobe); one point: the axis."""
    if lobe_points == 0 or cap_points == 1:
        return symmetric_cap_xi(cap_points)
    return lattice_xi(cap_points)


def lobe_width(lobe) -> float | None:
    """A microfacet lobe's width 2 atan(2 sqrt(ax ay)) (radians); None for lobes without one."""
    distribution = getattr(lobe, "distribution", None)
    if distribution is None or getattr(lobe, "sampled_pattern", False):
        return None
    return float(2.0 * np.arctan(2.0 * np.sqrt(distribution.alpha_x * distribution.alpha_y)))


def cap_width_ratio(lobe, light: CapLight, cos_theta_o: float, distance: float = 0.0) -> float | None:
    """q: the cap's angular radius over the lobe's width (:func:`lobe_width`) times cos(theta_o)
    (reflected lobes narrow towards grazing views), or over ``distance`` cos(theta_o) where that
    is larger (a cap that far from the lobe's peak sees only its tail, which varies on the scale
    of the distance: :func:`cap_peak_distance`); None for lobes without a microfacet width."""
    width = lobe_width(lobe)
    if width is None:
        return None
    return light.radius / max(max(width, distance) * max(cos_theta_o, MIN_VIEW_COSINE), 1e-6)


def _reflected_axis(lobe, light: CapLight, frame: np.ndarray) -> np.ndarray:
    """The cap's axis in the lobe's local frame as its reflection formulas see it (a transmission
    lobe's mirrored below the surface, materials/bsdf.py Component.reflected)."""
    axis = light.direction @ frame  # world -> local (frame is orthonormal)
    return axis * np.array([1.0, 1.0, -1.0]) if getattr(lobe, "transmission", False) else axis


def cap_below_horizon(lobe, light: CapLight, frame: np.ndarray | None = None) -> bool:
    """Whether the whole cap lies below the lobe's (reflected) horizon, where every lobe is 0: its
    integral is exactly 0 and costs nothing (half the lights of a curved object's pixels)."""
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    sin_radius = np.sqrt(max(1.0 - light.cos_radius**2, 0.0))
    return bool(_reflected_axis(lobe, light, frame)[2] <= -sin_radius)


def _peak_distance(lobe, wo: np.ndarray, light: CapLight, frame: np.ndarray) -> tuple[float, float]:
    """(the angle from the lobe's peak, the mirror direction of ``wo``, to the cap's nearest
    direction (0 where the cap holds the peak), the reflected axis' cosine to the normal)."""
    axis = _reflected_axis(lobe, light, frame)
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    peak = np.array([-wo[0], -wo[1], wo[2]]) / max(float(np.linalg.norm(wo)), 1e-300)
    return max(float(np.arccos(np.clip(axis @ peak, -1.0, 1.0))) - light.radius, 0.0), float(axis[2])


def cap_peak_distance(lobe, wo: np.ndarray, light: CapLight, frame: np.ndarray | None = None) -> float:
    """The distance that sets a GGX lobe's Gauss rule (:func:`cap_width_ratio`): the angle from
    the lobe's peak to the cap's nearest direction, where the tail seen over the cap varies on
    that scale (D ~ theta_h^-4), or the cap's gap above the horizon where that is smaller (f cos
    falls to 0 there: caps 4-6 degrees above it were 2.6-5.4 % off by the peak distance alone);
    0 where the cap reaches below the horizon (the integrand's kink there needs the rule the
    lobe's width asks for) and for other lobes (a Beckmann tail,
    exp(-tan^2 theta_h / alpha^2), varies faster the farther it is: :func:`cap_negligible`).
    Measured on 250 random caps of 0.2-25 degrees 0-120 degrees off the peak whose rule the
    distance changes (GGX alpha 0.005-0.5, views 0-85 degrees, contributions above 1e-6 of the
    cap's value on the peak): the rule chosen with the distance (and TAIL_GAUSS_RULES) is within
    0.30 % of a 300 x 600 midpoint rule at the 95th percentile and 0.91 % at worst, at 7.3 points
    per cap instead of 17.1 (docs/measurements.md, "What a light costs a frame")."""
    distribution = getattr(lobe, "distribution", None)
    if distribution is None or distribution.kind != "ggx":
        return 0.0
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    distance, axis_cos = _peak_distance(lobe, wo, light, frame)
    # the cap's gap above the horizon, where f cos falls to 0 on that scale
    above_horizon = float(np.arcsin(np.clip(axis_cos, -1.0, 1.0))) - light.radius
    return min(distance, above_horizon) if above_horizon > 0.0 else 0.0


# A Beckmann lobe's tail is exp(-tan^2 theta_h / alpha^2) of its peak; where that is below e^-40
# (4e-18) over the whole cap, the light adds nothing a float can hold. Every direction of the cap
# is at least the cap's peak distance d from the mirror direction, and the half vector at least
# d / 2 from the normal (reflection about h doubles angles at most: |d wi| <= 2 |d h|).
BECKMANN_NEGLIGIBLE_EXPONENT = 40.0


def cap_negligible(lobe, wo: np.ndarray, light: CapLight, frame: np.ndarray | None = None) -> bool:
    """Whether a Beckmann lobe's tail is below e^-BECKMANN_NEGLIGIBLE_EXPONENT of its peak over
    the whole cap (then its integral is skipped)."""
    distribution = getattr(lobe, "distribution", None)
    if distribution is None or distribution.kind != "beckmann" or getattr(lobe, "sampled_pattern", False):
        return False
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    distance, _ = _peak_distance(lobe, wo, light, frame)
    widest = max(distribution.alpha_x, distribution.alpha_y)
    return bool(np.tan(min(0.5 * distance, 0.5 * np.pi - 1e-9)) ** 2 > BECKMANN_NEGLIGIBLE_EXPONENT * widest**2)


def gauss_cap_rule(lobe, light: CapLight, cos_theta_o: float = 1.0, distance: float = 0.0) -> tuple[int, int] | None:
    """(rings, azimuths) of the product Gauss rule for ``lobe`` under ``light`` (GAUSS_RULES, or
    TAIL_GAUSS_RULES where ``distance`` exceeds the lobe's width), or
    None where the cap is wide against the lobe (q >= GAUSS_BELOW) or the lobe has no width: the
    two-strategy sum (:func:`cap_point_counts`) integrates those. ``distance``: the cap's from the
    lobe's peak (:func:`cap_peak_distance`)."""
    ratio = cap_width_ratio(lobe, light, cos_theta_o, distance)
    if ratio is None:
        return None
    for below, rings, azimuths in TAIL_GAUSS_RULES if distance > lobe_width(lobe) else GAUSS_RULES:
        if ratio < below:
            grazing = cos_theta_o < MIN_VIEW_COSINE and azimuths > 1
            return rings, azimuths * (GRAZING_AZIMUTH_FACTOR if grazing else 1)
    return None


def gauss_cap_integral(lobe, wo: np.ndarray, light: CapLight, rings: int, azimuths: int, frame=None) -> np.ndarray:
    """The cap integral by the product Gauss rule: nodes at the profile's area fractions of the
    Gauss-Legendre points (so the points follow the edge profile, as the two-strategy sum's cap
    points do), azimuths (j + 1/2) / azimuths, each point weighted by the lit solid angle times
    its ring's weight over ``azimuths``; a rule of one point takes the axis."""
    if not 1 <= rings <= GAUSS_RINGS:
        raise ValueError(f"the cap's Gauss rule has 1-{GAUSS_RINGS} rings, got {rings}")
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    nodes, weights = gauss_legendre_unit(rings)
    # A single point lies on the axis (the symmetric rule for a cap tiny against the lobe).
    nodes = np.zeros(1) if rings * azimuths == 1 else nodes
    u1 = np.repeat(profile_area_fraction(nodes, light.inner_fraction), azimuths)
    u2 = np.tile((np.arange(azimuths) + 0.5) / azimuths, rings)
    wi = light.points(u1, u2) @ frame
    f = np.asarray(lobe.eval(wi, np.broadcast_to(wo, wi.shape)), dtype=np.float64)
    weight = np.repeat(weights, azimuths) / azimuths * np.abs(wi[:, 2])
    f = np.where(np.isfinite(f), f, 0.0)
    return np.sum(f * weight[:, None], axis=0) * light.lit_solid_angle * light.radiance


def cap_point_counts(lobe, light: CapLight, cos_theta_o: float = 1.0) -> tuple[int, int, bool]:
    """(cap points, lobe points, power heuristic) of the two-strategy sum for ``lobe`` under
    ``light`` seen at cos(theta_o): NARROW_* by the power heuristic for a lobe with a microfacet
    width (the sum integrates caps with q >= NARROW_FROM; narrower ones take the Gauss rule), all
    points by the balance heuristic for lobes without one (the Rational BRDF, measured tables)."""
    ratio = cap_width_ratio(lobe, light, cos_theta_o)
    if ratio is None:
        soft = light.inner_fraction < 1.0
        return (SOFT_CAP_POINTS, SOFT_LOBE_POINTS, False) if soft else (CAP_POINTS, LOBE_POINTS, False)
    return NARROW_CAP_POINTS, NARROW_LOBE_POINTS, True


def integrate_cap_light(
    lobe,
    wo: np.ndarray,
    light: CapLight,
    frame: np.ndarray | None = None,
    cap_points: int | None = None,
    lobe_points: int | None = None,
    power: bool = False,
) -> np.ndarray:
    """Outgoing radiance (RGB) of ``lobe`` (a BSDF Component: eval, pdf, sample_wi) toward the
    local direction ``wo`` under ``light`` (world space), by the two-strategy deterministic MIS
    of the module docstring, with :func:`cap_point_counts` points unless both counts are given;
    without counts, a cap not much wider than the lobe, or far enough from its peak, takes the
    product Gauss rule instead (:func:`gauss_cap_rule`), and a cap below the horizon costs
    nothing.
    ``frame`` (3x3, columns tangent, bitangent, normal in world space; None: the identity) takes
    local directions to world space. A single cap point lies on the axis. ``power``: the power
    heuristic instead of the balance heuristic (where the counts are given)."""
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    if wo[2] <= 0.0 or cap_below_horizon(lobe, light, frame) or cap_negligible(lobe, wo, light, frame):
        return np.zeros(3)
    if cap_points is None or lobe_points is None:
        rule = gauss_cap_rule(lobe, light, float(wo[2]), cap_peak_distance(lobe, wo, light, frame))
        if rule is not None:
            return gauss_cap_integral(lobe, wo, light, *rule, frame=frame)
        cap_points, lobe_points, power = cap_point_counts(lobe, light, float(wo[2]))
    # The cap points follow the edge profile (density M profile / lit solid angle): a soft cap's
    # single point on the axis then carries the lit solid angle, not the whole cap's.
    cap_density = cap_points / light.lit_solid_angle
    total = np.zeros(3)
    if cap_points > 0:
        u1, u2 = cap_xi(cap_points, lobe_points)
        u1 = profile_area_fraction(u1, light.inner_fraction)
        wi = light.points(u1, u2) @ frame  # world -> local (frame is orthonormal)
        total += _weighted_sum(
            lobe, wi, wo, cap_density, lobe_points, light.radiance, edge_profile(u1, light.inner_fraction), power, True
        )
    if lobe_points > 0:
        u1, u2 = lattice_xi(lobe_points)
        wi = lobe.sample_wi(u1, u2, np.broadcast_to(wo, (lobe_points, 3)))
        profile = light.profile(wi @ frame.T)  # 0 outside the cap
        total += _weighted_sum(lobe, wi, wo, cap_density, lobe_points, light.radiance, profile, power, False)
    return total


def _weighted_sum(lobe, wi, wo, cap_density, lobe_points, radiance, profile, power, cap_strategy) -> np.ndarray:
    """One strategy's share: the sum over ``wi`` of h f cos L / (a + b) with a = M h / Omega_lit,
    b = K p(wi) (balance heuristic), or h f cos L a' / (a^2 + b^2) with a' = a for the cap's
    points and b for the lobe's (power heuristic); h the edge profile (0 outside the cap)."""
    wo_b = np.broadcast_to(wo, wi.shape)
    f = np.asarray(lobe.eval(wi, wo_b), dtype=np.float64)
    p = np.asarray(lobe.pdf(wi, wo_b), dtype=np.float64)
    cos_i = np.abs(wi[:, 2])
    if power:
        a, b = cap_density * profile, lobe_points * p
        denominator = (a * a + b * b) / np.maximum(np.where(cap_strategy, a, b), 1e-300)
    else:
        denominator = cap_density * profile + lobe_points * p
    ok = (profile > 0.0) & np.isfinite(f).all(-1) & (denominator > 0.0)
    weight = np.where(ok, profile * cos_i / np.where(ok, denominator, 1.0), 0.0)
    return np.sum(f * weight[:, None], axis=0) * radiance


def brute_force_cap_light(lobe, wo: np.ndarray, light: CapLight, frame=None, rings: int = 400) -> np.ndarray:
    """The same integral by a dense midpoint rule over the cap in (cos angle, azimuth), rings x
    2 rings cells of equal solid angle: the independent check of :func:`integrate_cap_light`."""
    frame = np.eye(3) if frame is None else np.asarray(frame, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64).reshape(3)
    u1 = (np.arange(rings) + 0.5) / rings
    u2 = (np.arange(2 * rings) + 0.5) / (2 * rings)
    a, b = np.meshgrid(u1, u2, indexing="ij")
    wi = light.points(a.ravel(), b.ravel()) @ frame
    f = np.asarray(lobe.eval(wi, np.broadcast_to(wo, wi.shape)), dtype=np.float64)
    cell = light.solid_angle / len(wi)
    weight = np.abs(wi[:, 2]) * edge_profile(a.ravel(), light.inner_fraction)
    return np.sum(f * weight[:, None], axis=0) * cell * light.radiance


# Footprint-aware lights (issue 39 item 3): a source narrower than what one pixel reflects (a sun
# on a mirror sphere, a distant lamp) is hit by a pixel centre or missed, so its energy in the
# image is a lottery (a mirror sphere under a 0.5-degree sun kept 40 % of the image's light). The
# lights are integrated against the lobe widened by the pixel's footprint instead: across one
# pixel the reflected direction r moves by dr/dx, dr/dy and the half vector (the slope the
# distribution reads) by half that, |dn| = |dr| / 2. Any normalised widening keeps the source's
# energy on average over where it lies; to keep it wherever it lies, the widened lobe must be
# wide enough that its values at pixel centres sum to its integral (at the box filter's own
# variance, alpha^2 = 2 |dn|^2 / 12, the sum ranges 0.58-2.16 with the source's position), and
# no wider than that, because a wide GGX's tail spreads energy over the curved surface where the
# pixels' slope steps are not even (+3 to +10 % on a mirror sphere with alpha one slope step).
# Measured (tests/test_footprint_lights.py): alpha^2 = 2/3 of a slope step squared sums to
# 0.94-1.08 on the slope plane and keeps a sub-pixel sun's energy on a mirror sphere within
# 1-5 %, so
#     alpha'^2 = alpha^2 + (|dn_x|^2 + |dn_y|^2) / 3 = alpha^2 + (|dr_x|^2 + |dr_y|^2) / 12,
# the lights' highlight spread over two to three pixels, as a point-sampled image must.
# A cap wider than the footprint needs none of it: its reflection already covers pixels, and the
# widened lobe's tails only smear its edge over neighbours (chrome under builtin:studio's 11-degree
# soft box: pixels beside the box's reflection 5x the backdrop, +10 % over the whole upper half).
# The widening is scaled by |dr|^2 / (|dr|^2 + rho^2), rho^2 ~ 2 (1 - cos rho) the cap's angular
# radius squared: ~1 for a 0.5-degree sun on a 128-pixel sphere, 0.1 for that soft box.
FOOTPRINT_DIVISOR = 12.0  # alpha^2 gains (|dr_x|^2 + |dr_y|^2) / FOOTPRINT_DIVISOR
MAX_FOOTPRINT_ALPHA2 = 0.1  # at silhouettes r turns fast: at most alpha 0.32 is added


def footprint_alpha2(dr_dx, dr_dy, one_minus_cos: float = 0.0) -> np.ndarray:
    """What one pixel's footprint adds to a lobe's alpha^2 for a light of 1 - cos(radius) =
    ``one_minus_cos`` (0: a point), from the derivatives of the reflected direction across the
    pixel (shaders/cap_lights.glsl footprint_alpha2 and footprint_lobe)."""
    dr_dx, dr_dy = np.asarray(dr_dx, dtype=np.float64), np.asarray(dr_dy, dtype=np.float64)
    total = np.sum(dr_dx * dr_dx, axis=-1) + np.sum(dr_dy * dr_dy, axis=-1)
    widening = np.minimum(total / FOOTPRINT_DIVISOR, MAX_FOOTPRINT_ALPHA2)
    return widening * total / np.maximum(total + 2.0 * one_minus_cos, 1e-300)


def widened_alphas(alpha_x, alpha_y, footprint) -> tuple[np.ndarray, np.ndarray]:
    """A lobe's alphas widened by a pixel's ``footprint`` (footprint_alpha2)."""
    return np.sqrt(np.square(alpha_x) + footprint), np.sqrt(np.square(alpha_y) + footprint)
