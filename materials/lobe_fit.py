"""Kautz & McCool lobe fitting (seed 000, section 3): radially symmetric approximations of a
BRDF lobe, one per sampled view elevation, for prefiltered environment maps.

The function approximated is the lobe's slice  g(wi) = f(wi, wo) |cos theta_i|  for fixed wo
(the seed fits f and approximates n.l by n.r, Eq. 2; fitting the cosine-weighted slice avoids
that approximation). Modes:

* ``lobe``   (3.1): per elevation the peak direction (searched in the plane of incidence, where
  an isotropic lobe peaks), the mean of the profile curves around it, rescaled to the true
  directional albedo; rendered from a 3D map (direction x cos theta_o).
* ``lobe2d`` (3.2): one average shape for every elevation and a weight k(theta_o) (the true
  albedo); a 2D map, so the sharpening at glancing angles is lost.
* ``phong``  (Heidrich & Seidel, seed 001 section 4): a cos^n lobe around the mirror direction
  with n matched to the average shape's median angle, weighted by the true albedo.
* ``multi``  (3.3, 5.3): greedy fitting with minimum profiles per elevation
  (:func:`fit_multi_lobe`), the lobes matched across elevations by their axes (the seed's
  "consistent and coherent selection"), the sum rescaled to the true albedo; one 3D map per
  fitted lobe, rendered with one lookup per lobe (:func:`fit_lobe_maps`).

Anisotropic lobes are fitted through their isotropic equivalent (alpha = sqrt(ax ay)) and scaled
to their own albedo averaged over the view azimuth; the method assumes isotropy (seed 000, 3.1),
so brushed metals lose their stretched highlights (use lobe-N for them).
"""

from __future__ import annotations

import copy
import hashlib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from lobeview.core.cache import DAMAGED_CACHE_ERRORS, write_cache_file
from lobeview.core.progress import timed_step

from .bsdf import BSDF, Component
from .microfacet import MicrofacetDistribution
from .prefilter import RadialProfile, cumulative_radial_mass, phong_profile

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
LOBE_SLICES = 16  # view elevations, uniform in cos(theta_o) from 0 to 1 (the seed used 16)
MIN_COS_O = 0.02  # the grazing slice is fitted at this cosine (wo on the horizon is degenerate)
FIT_MODES = ("lobe", "lobe2d", "phong", "multi")
MAP_LOBES = 4  # fitted lobes per component in the 'multi' mode

_PSI = np.pi * (np.arange(161) / 160.0) ** 2  # radial nodes, dense near the axis
_BETA = (np.arange(64) + 0.5) / 64 * 2.0 * np.pi


def slice_cosines(slices: int = LOBE_SLICES) -> np.ndarray:
    """View elevations of the slices: uniform in sqrt(cos theta_o), dense near grazing where the
    albedo (the slices' energy, interpolated linearly between them) changes fastest. Linear
    spacing overshot the white furnace 37x at grazing pixels (m = 1e-4, alpha = 1, r0 = 0;
    found by `lobeview bench --stress`)."""
    return np.linspace(0.0, 1.0, slices) ** 2


def slice_coordinate(cos_theta_o, slices: int = LOBE_SLICES):
    """Continuous slice index of a view elevation (shaders/integrate.glsl does the same)."""
    return np.sqrt(np.clip(cos_theta_o, 0.0, 1.0)) * (slices - 1)


def is_isotropic(component: Component) -> bool:
    d = getattr(component, "distribution", None)
    return d is None or abs(d.alpha_x - d.alpha_y) <= 1e-9 * max(d.alpha_x, d.alpha_y)


def isotropic_equivalent(component: Component) -> Component:
    """The component with its microfacet distribution made isotropic at alpha = sqrt(ax ay)."""
    if is_isotropic(component):
        return component
    d = component.distribution
    alpha = float(np.sqrt(d.alpha_x * d.alpha_y))
    twin = copy.copy(component)
    twin.distribution = MicrofacetDistribution(d.kind, alpha, alpha)
    return twin


def _frame(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t = np.cross(helper, axis)
    t /= np.linalg.norm(t)
    return t, np.cross(axis, t)


def polar_grid(axis: np.ndarray, psi: np.ndarray = _PSI, beta: np.ndarray = _BETA):
    """Directions (len(psi), len(beta), 3) around ``axis`` and their solid-angle weights."""
    t, b = _frame(axis)
    sp, cp = np.sin(psi)[:, None, None], np.cos(psi)[:, None, None]
    ring = np.cos(beta)[None, :, None] * t + np.sin(beta)[None, :, None] * b
    dirs = cp * axis + sp * ring
    dpsi = np.gradient(psi)
    weights = (np.sin(psi) * dpsi)[:, None] * np.full(len(beta), 2.0 * np.pi / len(beta))[None, :]
    return dirs, weights


def _wo(cos_theta_o: float) -> np.ndarray:
    c = max(float(cos_theta_o), MIN_COS_O)
    return np.array([np.sqrt(1.0 - c * c), 0.0, c])


def _in_plane(t: float) -> np.ndarray:
    """Direction at polar angle t in the plane of incidence, on the mirror side (t in [0, pi]:
    t < pi/2 above the surface, t > pi/2 below; the mirror direction of wo is t = theta_o)."""
    return np.array([-np.sin(t), 0.0, np.cos(t)])


def slice_values(component: Component, wo: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """g(wi) = f(wi, wo) |cos theta_i| (RGB), the function a lobe approximates."""
    f = component.eval(wi, np.broadcast_to(wo, wi.shape))
    return f * np.abs(wi[..., 2:3])


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMINANCE


def _mirror_axis(component: Component, wo: np.ndarray) -> np.ndarray:
    axis = np.array([-wo[0], -wo[1], wo[2]])
    return axis * np.array([1.0, 1.0, -1.0]) if component.transmission else axis


def find_peak(component: Component, wo: np.ndarray) -> float:
    """Polar angle t of the maximum of the slice in the plane of incidence (seed 000, 3.1)."""
    theta_o = np.arccos(wo[2])
    start = np.pi - theta_o if component.transmission else theta_o
    ts = np.clip(start + np.linspace(-1.2, 1.2, 481), 0.0, np.pi)
    values = _luminance(slice_values(component, wo, np.stack([_in_plane(t) for t in ts])))
    best = int(np.argmax(values))
    lo, hi = ts[max(best - 1, 0)], ts[min(best + 1, len(ts) - 1)]
    if hi <= lo:
        return float(ts[best])
    res = minimize_scalar(
        lambda t: -_luminance(slice_values(component, wo, _in_plane(t)[None]))[0],
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-7},
    )
    return float(res.x) if -res.fun >= values[best] else float(ts[best])


def mean_profile_values(component: Component, wo: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """Mean of the profile curves around the peak (luminance), on the radial nodes _PSI."""
    dirs, _ = polar_grid(peak)
    return _luminance(slice_values(component, wo, dirs)).mean(axis=1)


def directional_energy(component: Component, wo: np.ndarray) -> np.ndarray:
    """Directional albedo of the lobe; for an anisotropic lobe the mean over the view azimuth
    (an isotropic map cannot follow the azimuth, but its energy stays the true one on average)."""
    return directional_energies(component, np.asarray(wo, dtype=np.float64).reshape(1, 3))[0]


def directional_energies(component: Component, wos: np.ndarray) -> np.ndarray:
    """:func:`directional_energy` of many viewer directions (k, 3) -> (k, 3), in one vectorised
    quadrature (BSDF.albedo_many): a map's 16 slices x 8 azimuths cost one call, not 128."""
    wos = np.asarray(wos, dtype=np.float64).reshape(-1, 3)
    azimuths = (0.0,) if is_isotropic(component) else np.arange(8) * np.pi / 8
    c, s = np.cos(azimuths), np.sin(azimuths)
    rotated = np.stack(
        [c[:, None] * wos[None, :, 0] - s[:, None] * wos[None, :, 1],
         s[:, None] * wos[None, :, 0] + c[:, None] * wos[None, :, 1],
         np.broadcast_to(wos[None, :, 2], (len(azimuths), len(wos)))],
        axis=-1,
    )  # fmt: skip
    reflection, transmission = BSDF([component]).albedo_many(rotated.reshape(-1, 3), order=128)
    energy = transmission if component.transmission else reflection
    return energy.reshape(len(azimuths), len(wos), 3).mean(axis=0)


def relative_rms(component: Component, wo: np.ndarray, approximation) -> float:
    """Relative RMS error of an approximation of the slice (luminance) over the whole sphere:
    sqrt(integral (g - a)^2 / integral g^2), on a polar grid around the mirror direction."""
    dirs, weights = polar_grid(_mirror_axis(component, wo))
    g = _luminance(slice_values(component, wo, dirs))
    a = approximation(dirs)
    return float(np.sqrt(np.sum(weights * (g - a) ** 2) / max(np.sum(weights * g * g), 1e-300)))


@dataclass
class LobeMapFit:
    """A fitted lobe over the view elevations cos(theta_o) = slice_cosines(S)."""

    mode: str
    cos_theta_o: np.ndarray  # (S,)
    peak_theta: np.ndarray  # (S,) polar angle t of the lobe axis in the plane of incidence
    profiles: list  # RadialProfile per slice ('lobe') or one for all ('lobe2d', 'phong')
    energy: np.ndarray  # (S, 3) directional albedo the lobe is scaled to
    error: np.ndarray  # (S,) relative RMS of the approximation over the slice
    isotropic_approximation: bool  # the component was anisotropic and fitted isotropically
    phong_exponent: float | None = None
    axes: np.ndarray | None = None  # (S, 3) lobe axes when not in the plane of incidence (multi)
    transmission: bool = False  # the component's lobe lies below the surface

    def profile(self, slice_index: int) -> RadialProfile:
        return self.profiles[slice_index if len(self.profiles) > 1 else 0]

    def axis(self, slice_index: int) -> np.ndarray:
        """Lobe axis in the local frame for wo in the x-z plane (mirror azimuth = -x)."""
        if self.axes is not None:
            return self.axes[slice_index]
        return _in_plane(self.peak_theta[slice_index])

    def local_axes(self) -> np.ndarray:
        """(S, 3): :meth:`axis` of every slice."""
        return np.stack([self.axis(s) for s in range(len(self.cos_theta_o))])

    def mirror_relative_axes(self) -> np.ndarray:
        """(S, 3): each slice's axis in the frame of that slice's mirror direction m (straight
        through for transmission), as (a.e, a.y, a.m) with e = dm/dtheta_o in the plane of
        incidence: what the renderer's lobe table holds. Interpolating these between slices
        and rebuilding with the pixel's own mirror frame (:func:`axis_from_mirror_relative`) keeps
        a mirror-like lobe on its mirror direction; interpolating the axes themselves put it up to
        7 deg off between the coarse slices near normal incidence (chrome, prefiltered: relRMSE 0.50)."""
        out = np.empty((len(self.cos_theta_o), 3))
        for s, c in enumerate(self.cos_theta_o):
            m, e = _mirror_frame(float(c), self.transmission)
            a = self.axis(s)
            out[s] = (a @ e, a[1], a @ m)
        return out


def _mirror_frame(cos_theta_o: float, transmission: bool) -> tuple[np.ndarray, np.ndarray]:
    """Mirror direction m of wo = (sin, 0, cos) (straight through for transmission) and e = dm/dtheta_o."""
    sin = np.sqrt(max(1.0 - cos_theta_o * cos_theta_o, 0.0))
    if transmission:
        return np.array([-sin, 0.0, -cos_theta_o]), np.array([-cos_theta_o, 0.0, sin])
    return np.array([-sin, 0.0, cos_theta_o]), np.array([-cos_theta_o, 0.0, -sin])


def axis_from_mirror_relative(relative: np.ndarray, cos_theta_o: float, transmission: bool) -> np.ndarray:
    """The axis (wo at azimuth 0) of mirror-relative coordinates (:meth:`LobeMapFit.mirror_relative_axes`,
    typically interpolated between slices) at the view elevation ``cos_theta_o``: the numpy twin of
    shaders/prefiltered.glsl's reconstruction."""
    m, e = _mirror_frame(cos_theta_o, transmission)
    a = relative[0] * e + np.array([0.0, relative[1], 0.0]) + relative[2] * m
    return a / np.linalg.norm(a)


def _interp_profiles(profiles: list) -> RadialProfile:
    """Average of unit-mass shapes on the common radial nodes (seed 000, 3.2)."""
    return RadialProfile.from_values(_PSI, np.mean([p(_PSI) for p in profiles], axis=0))


def phong_exponent_for(profile: RadialProfile) -> float:
    """Exponent n of cos^n with the same median angle (mass of cos^n within psi: 1 - cos^(n+1))."""
    c = np.cos(min(profile.median_angle, 1.5))
    return float(max(np.log(0.5) / np.log(c) - 1.0, 0.0))


def _fit(component: Component, mode: str, slices: int) -> LobeMapFit:
    anisotropic = not is_isotropic(component)
    comp = isotropic_equivalent(component)
    cosines = slice_cosines(slices)
    peaks, shapes = [], []
    for c in cosines:
        wo = _wo(c)
        t = find_peak(comp, wo)
        peaks.append(t)
        values = mean_profile_values(comp, wo, _in_plane(t))
        shapes.append(RadialProfile.from_values(_PSI, values) if np.any(values > 0) else None)
    shapes = _fill_empty_slices(shapes)
    peaks = np.array(peaks)
    energies = directional_energies(component, np.array([_wo(c) for c in cosines]))
    exponent = None
    if mode == "lobe2d":
        shapes = [_interp_profiles(shapes)]
    elif mode == "phong":
        exponent = phong_exponent_for(_interp_profiles(shapes))
        shapes = [phong_profile(exponent)]
        theta_o = np.arccos(np.maximum(cosines, MIN_COS_O))
        peaks = np.pi - theta_o if comp.transmission else theta_o
    errors = []
    for s, c in enumerate(cosines):
        wo = _wo(c)
        axis = _in_plane(peaks[s])
        shape = shapes[s if len(shapes) > 1 else 0]
        scale = float(energies[s] @ LUMINANCE)
        errors.append(
            relative_rms(comp, wo, lambda d, shape=shape, axis=axis, scale=scale: scale * shape.of_cosine(d @ axis))
        )
    return LobeMapFit(
        mode, cosines, peaks, shapes, energies, np.array(errors), anisotropic, exponent,
        transmission=bool(comp.transmission),
    )  # fmt: skip


def _fill_empty_slices(shapes: list) -> list:
    """Slices where the lobe vanishes (r0 = 0 at normal incidence, or a spike narrower than the
    radial grid) have no shape: they take the nearest slice's (their energy is ~0 anyway); if no
    slice has one, the narrowest profile the grid holds. Found by `lobeview bench --stress`
    (m = 1e-4, r0 = 0 raised and stopped the renderer)."""
    valid = [i for i, p in enumerate(shapes) if p is not None]
    if not valid:
        narrowest = RadialProfile.from_values(_PSI, (_PSI <= _PSI[1]).astype(float))
        return [narrowest] * len(shapes)
    return [p if p is not None else shapes[min(valid, key=lambda j, i=i: abs(j - i))] for i, p in enumerate(shapes)]


def component_key(component: Component) -> str:
    items = {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else repr(v)) for k, v in vars(component).items()}
    return f"{type(component).__name__}:{sorted(items.items())}"


_FITS: dict[str, list] = {}
_MAX_CACHED_FITS = 64


def fit_lobe_map(component: Component, mode: str = "lobe", slices: int = LOBE_SLICES) -> LobeMapFit:
    """Fit one specular component (reflection or transmission lobe) for a single-lobe
    prefiltered mode ('lobe', 'lobe2d', 'phong')."""
    if mode == "multi":
        raise ValueError("the 'multi' mode fits several lobes: use fit_lobe_maps")
    return fit_lobe_maps(component, mode, slices)[0]


def fit_lobe_maps(component: Component, mode: str = "lobe", slices: int = LOBE_SLICES, directory=None) -> list:
    """The fitted lobes (LobeMapFit each, one 3D map each) of one specular component: one for
    'lobe', 'lobe2d' and 'phong', MAP_LOBES for 'multi'. Fits (0.05-1.5 s each) are cached by the
    component's parameters, not its identity, so a rebuilt material is not fitted again: in
    memory, and on disk under ``directory``/lobe_fits (default: core/paths.py's cache folder), so
    that a second start of a scene with `prefiltered` does not fit again."""
    if mode not in FIT_MODES:
        raise ValueError(f"unknown lobe-map mode {mode!r}; use one of {FIT_MODES}")
    key = f"{component_key(component)}|{mode}|{slices}"
    if key not in _FITS:
        if len(_FITS) >= _MAX_CACHED_FITS:
            _FITS.pop(next(iter(_FITS)))  # oldest first
        path = _fit_cache_path(key, directory)
        fits = _load_fits(path, slices)
        if fits is None:
            with timed_step("prefilter", f"{mode} fit of a {type(component).__name__} lobe (cached afterwards)"):
                fits = _fit_multi(component, slices) if mode == "multi" else [_fit(component, mode, slices)]
            _save_fits(path, fits)
        _FITS[key] = fits
    return _FITS[key]


# Lobe-map fits cached on disk: bump when the fit or the LobeMapFit layout changes.
FIT_CACHE_VERSION = 1


def _fit_cache_path(key: str, directory) -> Path:
    from lobeview.core.paths import cache_dir

    digest = hashlib.sha256(f"{FIT_CACHE_VERSION}|{key}".encode()).hexdigest()[:24]
    return Path(directory or cache_dir()) / "lobe_fits" / f"fit-v{FIT_CACHE_VERSION}-{digest}.npz"


def _save_fits(path: Path, fits: list) -> None:
    arrays = {"count": np.array(len(fits))}
    for j, f in enumerate(fits):
        arrays.update({
            f"{j}_mode": np.array(f.mode), f"{j}_cos": f.cos_theta_o, f"{j}_peak": f.peak_theta,
            f"{j}_energy": f.energy, f"{j}_error": f.error,
            f"{j}_flags": np.array([f.isotropic_approximation, f.transmission]),
            f"{j}_phong": np.array(np.nan if f.phong_exponent is None else f.phong_exponent),
            f"{j}_profiles": np.array(len(f.profiles)),
        })  # fmt: skip
        if f.axes is not None:
            arrays[f"{j}_axes"] = f.axes
        for i, p in enumerate(f.profiles):
            arrays[f"{j}_p{i}"] = np.stack([p.psi, p.density, p.radial_mass])
    write_cache_file(path, lambda handle: np.savez(handle, **arrays))  # read-only cache: refit next time


def _load_fits(path: Path, slices: int) -> list | None:
    """The cached fits, or None (absent; damaged or inconsistent: warned, refitted)."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            fits = []
            for j in range(int(data["count"])):
                energy, error = data[f"{j}_energy"], data[f"{j}_error"]
                cosines, peaks = data[f"{j}_cos"], data[f"{j}_peak"]
                count = int(data[f"{j}_profiles"])
                profiles = [RadialProfile(*data[f"{j}_p{i}"]) for i in range(count)]
                axes = data[f"{j}_axes"] if f"{j}_axes" in data.files else None
                isotropic_approximation, transmission = (bool(x) for x in data[f"{j}_flags"])
                phong = float(data[f"{j}_phong"])
                shapes_ok = (
                    cosines.shape == (slices,) and peaks.shape == (slices,) and energy.shape == (slices, 3)
                    and error.shape == (slices,) and count in (1, slices)
                    and (axes is None or axes.shape == (slices, 3))
                    and all(p.psi.ndim == 1 and p.psi.shape == p.density.shape == p.radial_mass.shape for p in profiles)
                )  # fmt: skip
                values = [cosines, peaks, energy, *(p.density for p in profiles)]
                if not shapes_ok or not all(np.all(np.isfinite(v)) for v in values) or energy.min() < 0.0:
                    raise ValueError("inconsistent shapes or values")
                fits.append(
                    LobeMapFit(
                        str(data[f"{j}_mode"]), cosines, peaks, profiles, energy, error, isotropic_approximation,
                        None if np.isnan(phong) else phong, axes, transmission,
                    )
                )  # fmt: skip
            return fits if fits else None
    except DAMAGED_CACHE_ERRORS as exc:
        warnings.warn(f"{path}: unusable cached lobe-map fit ({exc}); fitting again", stacklevel=3)
        return None


# -- greedy multi-lobe fitting (seed 000, 3.3) --------------------------------------------------
@dataclass
class MultiLobeFit:
    axes: list  # lobe axes (3,)
    profiles: list  # (len(_PSI),) minimum-profile values (unnormalised, luminance)
    errors: list  # relative RMS after 1, 2, ... lobes


def fit_multi_lobe(component: Component, cos_theta_o: float, lobes: int = 8, last_mean: bool = False) -> MultiLobeFit:
    """Greedy fitting with minimum profiles at one view elevation: find the maximum of what is
    left, take around it the smallest profile curve (so the residual never goes negative),
    subtract, repeat. Lobes may sit anywhere (not only in the plane of incidence).

    ``last_mean``: the last lobe takes the *mean* profile of the residual around its maximum
    (section 3.1's averaging) instead of the minimum: it carries all the energy the minimum
    profiles left (the mean over azimuth around any axis keeps the integral), which at grazing
    views is most of it (4 minimum profiles hold 6-10 % of the albedo at cos theta_o = 0.004)."""
    comp = isotropic_equivalent(component)
    wo = _wo(cos_theta_o)
    search_dirs, _ = polar_grid(_mirror_axis(comp, wo))
    search_dirs = search_dirs.reshape(-1, 3)
    axes, profiles, errors = [], [], []

    def approximation(d):
        total = np.zeros(d.shape[:-1])
        for axis, prof in zip(axes, profiles, strict=True):
            total = total + np.interp(np.arccos(np.clip(d @ axis, -1.0, 1.0)), _PSI, prof, right=0.0)
        return total

    def residual(d):
        return _luminance(slice_values(comp, wo, d)) - approximation(d)

    for index in range(lobes):
        r = residual(search_dirs)
        axis = search_dirs[int(np.argmax(r))]
        dirs, _ = polar_grid(axis)
        rings = np.maximum(residual(dirs), 0.0)
        axes.append(axis)
        profiles.append(rings.mean(axis=1) if last_mean and index == lobes - 1 else rings.min(axis=1))
        errors.append(relative_rms(comp, wo, approximation))
    return MultiLobeFit(axes, profiles, errors)


def _match_lobes(previous: list, axes: list, masses: list) -> list:
    """Order of this elevation's lobes that follows the previous elevation's (by the angle
    between axes; a lobe without mass matches anything): the seed's clustering of lobes with
    similar offsets into one map (Figure 5)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.zeros((len(previous), len(axes)))
    for i, a in enumerate(previous):
        for j, b in enumerate(axes):
            cost[i, j] = np.arccos(np.clip(a @ b, -1.0, 1.0)) if masses[j] > 0.0 else 0.5
    rows, cols = linear_sum_assignment(cost)
    return [int(c) for _, c in sorted(zip(rows, cols, strict=True))]


def _fit_multi(component: Component, slices: int, lobes: int = MAP_LOBES) -> list:
    """'multi' mode: greedy minimum-profile lobes per elevation plus a last lobe with the mean
    profile of the remainder (fit_multi_lobe(last_mean=True)), matched across elevations from
    grazing to normal incidence, each elevation's sum rescaled to the
    true directional albedo (section 3.1's energy rescaling, shared in proportion to the lobes'
    masses). Returns one LobeMapFit per lobe; every lobe carries the combined error."""
    anisotropic = not is_isotropic(component)
    comp = isotropic_equivalent(component)
    cosines = slice_cosines(slices)
    per_slice = []  # (axes, profile values, masses) in matched order
    previous = None
    for c in cosines:
        fit = fit_multi_lobe(comp, c, lobes, last_mean=True)
        masses = [float(cumulative_radial_mass(_PSI, p)[-1]) for p in fit.profiles]
        # The last lobe (the mean profile of the remainder) keeps its block; the minimum-profile
        # lobes are matched among themselves.
        order = list(range(lobes))
        if previous is not None and lobes > 2:
            order = _match_lobes(previous[:-1], fit.axes[:-1], masses[:-1]) + [lobes - 1]
        axes = [fit.axes[j] for j in order]
        per_slice.append((axes, [fit.profiles[j] for j in order], [masses[j] for j in order]))
        # an empty lobe keeps the previous elevation's axis for the next match
        previous = [
            a if m > 0.0 or previous is None else previous[k]
            for k, (a, m) in enumerate(zip(axes, per_slice[-1][2], strict=True))
        ]
    energies = directional_energies(component, np.array([_wo(c) for c in cosines]))
    total = np.array([max(sum(masses), 1e-300) for _, _, masses in per_slice])
    fits = []
    for j in range(lobes):
        shapes = [
            RadialProfile.from_values(_PSI, values[j]) if masses[j] > 0.0 else None for _, values, masses in per_slice
        ]
        shapes = _fill_empty_slices(shapes)
        share = np.array([masses[j] for _, _, masses in per_slice]) / total
        axes = np.array([axes[j] for axes, _, _ in per_slice])
        fits.append(
            LobeMapFit(
                "multi",
                cosines,
                np.arccos(np.clip(axes[:, 2], -1, 1)),
                shapes,
                energies * share[:, None],
                np.zeros(len(cosines)),
                anisotropic,
                axes=axes,
                transmission=bool(comp.transmission),
            )
        )
    errors = []
    for s, c in enumerate(cosines):
        terms = [(float(f.energy[s] @ LUMINANCE), f.profiles[s], f.axes[s]) for f in fits]
        errors.append(
            relative_rms(comp, _wo(c), lambda d, terms=terms: sum(e * p.of_cosine(d @ a) for e, p, a in terms))
        )
    for f in fits:
        f.error = np.array(errors)
    return fits
