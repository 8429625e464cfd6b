"""Anisotropic prefiltered environment maps with the Banks model (seed 001, section 5.3).

Banks' fibre model, with the seed's sharpness parameter s in [0, 1), is

    f(v, l) = max(0, sqrt(1 - (l.t)^2) sqrt(1 - (v.t)^2) - (l.t)(v.t) - s) / (1 - s)^2

(the positive part is implied: the bracket is a cosine, negative away from the highlight).
Writing l.t = cos(psi) (psi = angle between l and the fibre direction t) and v.t = sin(a_v),
the bracket is cos(pi/2 - psi + a_v) = sin(psi - a_v): a *ring* around t, peaking on the cone
l.t = -v.t that holds the mirror direction of v (n.t = 0). Without the self-shadowing term n.l
(which the seed drops to stay three-dimensional) the kernel depends on l only through l.t, so
it is radially symmetric around t, and the prefiltered map

    L_banks(t, v.t) = integral K_{v.t}(angle(l, t)) L(l) dl

is a 3D texture indexed by the direction t and v.t (seed Eq. for L_banks, without n.l). It
is computed with the radially symmetric prefilter of the lobe maps (viewer/prefiltered.py).

lobeview renders a component with it as  E(wo) L_banks(t, v.t)  with the kernel normalised to
unit mass per slice and E the component's true directional albedo, tabulated over the view
elevation and azimuth (anisotropic albedo depends on both): the energy rescaling of Kautz &
McCool 3.1 applied to Banks' shape. The fibre runs along the tangent axis of the smaller
roughness (microfacet normals of a fibre are perpendicular to it), and s is fitted to the
component by least squares over a set of views (:func:`fit_banks`).

What the model cannot do (seed 5.3): it reflects light from the whole cone, also from behind
the surface and far along the cone where the true lobe has faded (its spread along the cone
is unlimited); the committed bench tables measure what that costs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from .bsdf import BSDF, Component
from .lobe_fit import LUMINANCE, component_key, is_isotropic, polar_grid, slice_cosines, slice_values
from .prefilter import RadialProfile

BANKS_SLICES = 24  # map slices over a_v = asin(|v.t|) in [0, pi/2]
BANKS_AZIMUTHS = 8  # energy table: view azimuths 0 .. pi/2 (microfacet albedo is symmetric)
BANKS_S_MAX = 1.0 - 1e-4
_PSI = np.linspace(0.0, np.pi, 4097)
# Fit views: elevations and azimuths (from the fibre axis) where the least squares look.
_FIT_COS = (0.3, 0.55, 0.8, 0.97)
_FIT_PHI = (0.0, np.pi / 6, np.pi / 3, np.pi / 2)
_GRID_THETA = (np.arange(256) + 0.5) / 256 * np.pi
_GRID_PHI = (np.arange(512) + 0.5) / 512 * 2.0 * np.pi


def banks_kernel(cos_lt, cos_vt, s: float) -> np.ndarray:
    """Unnormalised Banks term max(0, sqrt(1-lt^2) sqrt(1-vt^2) - lt vt - s) / (1-s)^2."""
    lt = np.clip(cos_lt, -1.0, 1.0)
    vt = np.clip(cos_vt, -1.0, 1.0)
    value = np.sqrt(1.0 - lt * lt) * np.sqrt(1.0 - vt * vt) - lt * vt - s
    return np.maximum(value, 0.0) / (1.0 - s) ** 2


def slice_angles(slices: int = BANKS_SLICES) -> np.ndarray:
    """a_v = asin(v.t) of the map slices, uniform in the angle (the ring moves with a_v)."""
    return np.linspace(0.0, 0.5 * np.pi, slices)


def banks_profile(cos_vt: float, s: float) -> RadialProfile:
    """Unit-mass radial profile around t of the Banks kernel for one value of v.t."""
    return RadialProfile.from_values(_PSI, banks_kernel(np.cos(_PSI), cos_vt, s))


def fibre_axis(component: Component) -> int:
    """0 (tangent x) or 1 (bitangent y): the axis of the smaller roughness."""
    d = component.distribution
    return 0 if d.alpha_x <= d.alpha_y else 1


def view_direction(cos_theta_o: float, phi: float, axis: int) -> np.ndarray:
    """wo at elevation cos_theta_o and azimuth phi measured from the fibre axis."""
    sin_o = np.sqrt(max(1.0 - cos_theta_o**2, 0.0))
    along, across = sin_o * np.cos(phi), sin_o * np.sin(phi)
    return np.array([along, across, cos_theta_o]) if axis == 0 else np.array([across, along, cos_theta_o])


def _albedo(component: Component, wo: np.ndarray) -> np.ndarray:
    reflection, transmission = BSDF([component]).albedo(wo, order=96)
    return transmission if component.transmission else reflection


@dataclass
class BanksFit:
    axis: int  # fibre axis in the shading frame (0 = tangent, 1 = bitangent)
    s: float  # Banks sharpness
    profiles: list  # RadialProfile per slice (a_v = slice_angles())
    energy: np.ndarray  # (len(slice_cosines()), BANKS_AZIMUTHS, 3) albedo over (cos theta_o, phi)
    error: float  # relative RMS of the approximation over the fit views (luminance)
    mode: str = "banks"

    def energy_at(self, cos_theta_o: float, phi: float) -> np.ndarray:
        """Bilinear in (sqrt cos theta_o, |phi| folded into [0, pi/2]), as the shader does."""
        rows = self.energy.shape[0]
        x = np.sqrt(np.clip(cos_theta_o, 0.0, 1.0)) * (rows - 1)
        folded = abs(np.arctan2(np.sin(phi), np.cos(phi)))
        folded = min(folded, np.pi - folded)
        y = folded / (0.5 * np.pi) * (BANKS_AZIMUTHS - 1)
        x0, y0 = min(int(x), rows - 2), min(int(y), BANKS_AZIMUTHS - 2)
        fx, fy = x - x0, y - y0
        e = self.energy
        return (1 - fx) * ((1 - fy) * e[x0, y0] + fy * e[x0, y0 + 1]) + fx * (
            (1 - fy) * e[x0 + 1, y0] + fy * e[x0 + 1, y0 + 1]
        )


def _fit_s(component: Component, axis: int) -> tuple[float, float]:
    """s minimising the summed squared error of E(wo) K(l) against f cos over the fit views,
    relative to the summed squared slice (luminance)."""
    # A uniform grid over the whole sphere (the ring lies anywhere, not near one axis).
    dirs, weights = polar_grid(np.array([0.0, 0.0, 1.0]), _GRID_THETA, _GRID_PHI)
    dirs, weights = dirs.reshape(-1, 3), weights.reshape(-1)
    t = np.eye(3)[axis]
    cases = []
    for c in _FIT_COS:
        for phi in _FIT_PHI:
            wo = view_direction(c, phi, axis)
            g = slice_values(component, wo, dirs) @ LUMINANCE
            cases.append((float(wo @ t), g, float(_albedo(component, wo) @ LUMINANCE)))
    total = sum(np.sum(weights * g * g) for _, g, _ in cases)
    cos_lt = dirs @ t

    def error(log_gap):
        s = 1.0 - np.exp(log_gap)
        squared = 0.0
        for cos_vt, g, energy in cases:
            kernel = banks_kernel(cos_lt, cos_vt, s)
            mass = np.sum(weights * kernel)
            approximation = energy * kernel / mass if mass > 0 else 0.0 * kernel
            squared += np.sum(weights * (g - approximation) ** 2)
        return squared / total

    result = minimize_scalar(error, bounds=(np.log(1.0 - BANKS_S_MAX), 0.0), method="bounded", options={"xatol": 1e-3})
    return float(1.0 - np.exp(result.x)), float(np.sqrt(result.fun))


def energy_table(component: Component, axis: int) -> np.ndarray:
    """Directional albedo over (cos theta_o = slice_cosines(), phi = 0 .. pi/2 from the fibre)."""
    cosines = slice_cosines()
    phis = np.linspace(0.0, 0.5 * np.pi, BANKS_AZIMUTHS)
    table = np.zeros((len(cosines), BANKS_AZIMUTHS, 3))
    for i, c in enumerate(cosines):
        for j, phi in enumerate(phis):
            if c > 0.0:
                table[i, j] = _albedo(component, view_direction(c, phi, axis))
    return table


_FITS: dict[str, BanksFit] = {}


def fit_banks(component: Component) -> BanksFit:
    """Banks map parameters of an anisotropic specular component (cached by its parameters).
    Isotropic components have no fibre direction: that is an error (the renderer gives them
    lobe maps instead)."""
    if getattr(component, "distribution", None) is None or is_isotropic(component):
        raise ValueError("the Banks map needs an anisotropic microfacet lobe (alpha_x != alpha_y)")
    key = component_key(component)
    if key not in _FITS:
        axis = fibre_axis(component)
        s, error = _fit_s(component, axis)
        profiles = [banks_profile(np.sin(a), s) for a in slice_angles()]
        _FITS[key] = BanksFit(axis, s, profiles, energy_table(component, axis), error)
    return _FITS[key]
