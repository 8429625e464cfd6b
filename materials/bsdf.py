"""The common BSDF interface: a sum of components, each with its own importance sampler.

Every model in lobeview (thesis model, microfacet conductor, glTF metallic-roughness) is a
:class:`BSDF` made of :class:`Component` terms. The BSDF samples by choosing one component with
probability proportional to its ``selection_weight`` (the first uniform number is reused after
the choice) and its pdf is the matching mixture of the component pdfs, so ``sample``, ``pdf``
and ``eval`` stay consistent by construction (tested: weight == eval * |cos| / pdf).

Conventions (see :mod:`lobeview.materials.vec`): local frame with n = +z; ``wo`` (viewer) must lie
above the surface; renderers flip the frame for double-sided surfaces before calling. For ``wo``
at or below the horizon every method returns zero.
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from typing import NamedTuple

import numpy as np

from .microfacet import MicrofacetDistribution, reflection_jacobian
from .vec import COS_EPSILON, as_dirs, cosine_hemisphere, mirror_z, normalize, reflect


class BSDFSample(NamedTuple):
    """Result of :meth:`BSDF.sample`. ``pdf == 0`` marks a failed sample (for example a
    reflected direction below the horizon); its ``weight`` is then 0 and ``wi`` is finite but
    meaningless."""

    wi: np.ndarray
    weight: np.ndarray  # eval(wi, wo) * |cos theta_i| / pdf, shape (..., 3)
    pdf: np.ndarray


class Component(ABC):
    """One additive term of a BSDF with its own sampler."""

    name: str = "component"
    #: 'reflection' (wi above the surface) or 'transmission' (wi below)
    hemisphere: str = "reflection"

    @property
    @abstractmethod
    def selection_weight(self) -> float:
        """Relative probability of sampling this component (>= 0)."""

    @abstractmethod
    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Value of this term, shape (..., 3)."""

    @abstractmethod
    def pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Density of :meth:`sample_wi` per unit solid angle of wi."""

    @abstractmethod
    def sample_wi(self, u1: np.ndarray, u2: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """A direction distributed with :meth:`pdf` (where that is 0 the sample failed)."""


def _valid_pair(wi: np.ndarray, wo: np.ndarray, transmission: bool) -> np.ndarray:
    above_o = wo[..., 2] > COS_EPSILON
    if transmission:
        return above_o & (wi[..., 2] < -COS_EPSILON)
    return above_o & (wi[..., 2] > COS_EPSILON)


class CosineSampled(Component):
    """A diffuse reflection term, importance-sampled with the cosine-weighted hemisphere (pdf
    cos/pi); ``diffuse_albedo`` is its kd, what a lightmap's irradiance is multiplied by."""

    diffuse_albedo: np.ndarray

    def pdf(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        return np.where(valid, wi[..., 2] / np.pi, 0.0)

    def sample_wi(self, u1, u2, wo):
        return cosine_hemisphere(u1, u2)


class Lambert(CosineSampled):
    """kd / pi, sampled by cosine-weighted hemisphere sampling."""

    name = "diffuse"

    def __init__(self, kd: np.ndarray):
        self.kd = np.asarray(kd, dtype=np.float64)
        self.diffuse_albedo = self.kd

    @property
    def selection_weight(self) -> float:
        return float(np.mean(self.kd))

    def eval(self, wi, wo):
        valid = _valid_pair(wi, wo, False)
        return np.where(valid[..., None], self.kd / np.pi, 0.0)


class HalfVectorLobe(Component):
    """A lobe sampled through the half vector of a microfacet distribution.

    ``pdf`` is the half-vector density D(h) cos(theta_h) / (4 wo.h) (thesis Eq. 4.9), mirrored
    through the surface plane for thin-surface transmission lobes (thesis Eq. 3.5). The
    deterministic lobe patterns (:mod:`lobeview.materials.patterns`) use ``distribution`` and
    :meth:`lobe_pdf` of any such lobe.
    """

    distribution: MicrofacetDistribution
    transmission: bool = False

    @property
    def hemisphere(self) -> str:  # type: ignore[override]
        return "transmission" if self.transmission else "reflection"

    def _reflected_wi(self, wi: np.ndarray) -> np.ndarray:
        """The incident direction as seen by the reflection-lobe formulas."""
        return mirror_z(wi) if self.transmission else wi

    def lobe_pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        valid = _valid_pair(wi, wo, self.transmission)
        wr = self._reflected_wi(wi)
        h = normalize(wr + wo)
        p = self.distribution.pdf_half_vector(h) * reflection_jacobian(wo, h)
        return np.where(valid, p, 0.0)

    def pdf(self, wi, wo):
        return self.lobe_pdf(wi, wo)

    def sample_wi(self, u1, u2, wo):
        # xi1 = 1 - u1 maps [0,1) to the thesis' (0,1] with xi1 = 1 at the lobe centre.
        h = self.distribution.half_vector_from_xi(1.0 - np.asarray(u1, dtype=np.float64), u2)
        return self._reflected_wi(reflect(wo, h))


class BSDF:
    """A sum of components with mixture importance sampling."""

    def __init__(self, components: list[Component], name: str = "bsdf", tangent_rotation: float = 0.0):
        self.components = list(components)
        self.name = name
        # Radians by which the surface's tangent frame turns about the normal before this BSDF's
        # local frame (x = tangent) applies: KHR_materials_anisotropy's rotation.
        self.tangent_rotation = float(tangent_rotation)
        # KHR_materials_volume of a glTF material (thickness, attenuation, ior; materials/spec.py
        # build_bsdf), None for a surface without a volume behind it.
        self.volume: dict | None = None
        weights = np.array([max(c.selection_weight, 0.0) for c in self.components], dtype=float)
        total = weights.sum()
        self.selection_probabilities = weights / total if total > 0 else np.zeros_like(weights)

    def eval(self, wi, wo) -> np.ndarray:
        wi, wo = np.broadcast_arrays(as_dirs(wi), as_dirs(wo))
        out = np.zeros(wi.shape[:-1] + (3,))
        for comp in self.components:
            out = out + comp.eval(wi, wo)
        return out

    def pdf(self, wi, wo) -> np.ndarray:
        wi, wo = np.broadcast_arrays(as_dirs(wi), as_dirs(wo))
        out = np.zeros(wi.shape[:-1])
        for prob, comp in zip(self.selection_probabilities, self.components, strict=True):
            if prob > 0:
                out = out + prob * comp.pdf(wi, wo)
        return out

    def sample(self, u1, u2, wo) -> BSDFSample:
        """Importance-sample wi for the viewer direction ``wo`` from two uniform numbers in
        [0, 1). Returns (wi, weight, pdf); unpacking the first element gives ``wi``."""
        u1 = np.asarray(u1, dtype=np.float64)
        u2 = np.asarray(u2, dtype=np.float64)
        shape = np.broadcast_shapes(u1.shape, u2.shape, np.shape(wo)[:-1])
        u1 = np.broadcast_to(u1, shape)
        u2 = np.broadcast_to(u2, shape)
        wo = np.broadcast_to(as_dirs(wo), shape + (3,))
        wi = np.zeros(shape + (3,))
        wi[..., 2] = 1.0
        if self.selection_probabilities.sum() == 0:
            return BSDFSample(wi, np.zeros(shape + (3,)), np.zeros(shape))
        cdf = np.cumsum(self.selection_probabilities)
        cdf[-1] = 1.0
        index = np.minimum(np.searchsorted(cdf, u1, side="right"), len(cdf) - 1)
        lower = np.concatenate([[0.0], cdf[:-1]])
        own_ok = np.zeros(shape, dtype=bool)
        for c, comp in enumerate(self.components):
            chosen = index == c
            if not np.any(chosen) or self.selection_probabilities[c] == 0:
                continue
            u1_c = np.clip((u1[chosen] - lower[c]) / self.selection_probabilities[c], 0.0, 1.0 - 1e-16)
            wi_c = comp.sample_wi(u1_c, u2[chosen], wo[chosen])
            wi[chosen] = wi_c
            # A sample that failed for its own component (e.g. a reflection below the horizon)
            # stays failed even where another component has density there.
            own_ok[chosen] = comp.pdf(wi_c, wo[chosen]) > 0.0
        pdf = self.pdf(wi, wo)
        f = self.eval(wi, wo)
        ok = own_ok & (pdf > 0.0)
        weight = np.where(ok[..., None], f * np.abs(wi[..., 2:3]) / np.where(ok, pdf, 1.0)[..., None], 0.0)
        return BSDFSample(wi, weight, np.where(ok, pdf, 0.0))

    # -- directional albedo by quadrature -------------------------------------------------------
    def albedo(self, wo, order: int = 128) -> tuple[np.ndarray, np.ndarray]:
        """Directional reflectance and transmittance seen from ``wo`` (a single direction):
        the integrals of f(wi, wo) |cos theta_i| over the upper and lower hemisphere of wi
        (thesis Eq. 2.7, 2.8 by reciprocity), each shape (3,).

        Each component is integrated in the primary-sample space of its own sampler with a
        tensor Gauss-Legendre rule of ``order`` x ``order`` nodes: the integrand
        f |cos| / pdf is smooth there even for near-mirror lobes, which a grid over directions
        cannot resolve.
        """
        reflection, transmission = self.albedo_many(as_dirs(wo).reshape(1, 3), order)
        return reflection[0], transmission[0]

    def albedo_many(self, wos, order: int = 128) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`albedo` for many viewer directions ``wos`` (k, 3) at once: (k, 3) each. One
        vectorised quadrature over (k, order, order) (in chunks that keep arrays near 1e6
        entries): an albedo table of 512 directions costs one call, not 512."""
        wos = as_dirs(wos).reshape(-1, 3)
        totals = {"reflection": np.zeros((len(wos), 3)), "transmission": np.zeros((len(wos), 3))}
        for comp in self.components:
            if hasattr(comp, "albedo_many"):  # its own rule (a tabulated measured BRDF)
                totals[comp.hemisphere] += comp.albedo_many(wos)
                continue
            # A sampler whose map is only roughly proportional to f cos (the Rational BRDF's
            # inverse CDFs) needs a finer rule: its own minimum order, integrand given.
            own = hasattr(comp, "primary_integrand")
            comp_order = max(order, comp.min_quadrature_order) if own else order
            x, w = gauss_legendre_unit(comp_order)
            u1, u2 = np.meshgrid(x, x, indexing="ij")
            quad_w = np.outer(w, w)
            chunk = max(1, 1_000_000 // (comp_order * comp_order))
            for start in range(0, len(wos), chunk):
                wo_b = np.broadcast_to(
                    wos[start : start + chunk, None, None, :], (len(wos[start : start + chunk]), *u1.shape, 3)
                )
                cu1 = np.broadcast_to(u1, wo_b.shape[:-1])
                cu2 = np.broadcast_to(u2, wo_b.shape[:-1])
                if own:
                    integrand = comp.primary_integrand(cu1, cu2, wo_b)
                else:
                    wi = comp.sample_wi(cu1, cu2, wo_b)
                    pdf = comp.pdf(wi, wo_b)
                    ok = pdf > 0.0
                    f = comp.eval(wi, wo_b)
                    integrand = np.where(
                        ok[..., None], f * np.abs(wi[..., 2:3]) / np.where(ok, pdf, 1.0)[..., None], 0.0
                    )
                totals[comp.hemisphere][start : start + chunk] += np.einsum("ij,kijc->kc", quad_w, integrand)
        return totals["reflection"], totals["transmission"]


@functools.lru_cache(maxsize=16)
def gauss_legendre_unit(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights of ``order`` points on [0, 1] (cached: numpy's leggauss
    solves an eigenproblem each call, 2 ms at order 48)."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    return 0.5 * (nodes + 1.0), 0.5 * weights


def diffuse_albedo(bsdf: BSDF) -> np.ndarray:
    """Sum of the BSDF's diffuse kd (Lambert kd, glTF (1 - metallic) baseColor), shape (3,)."""
    total = np.zeros(3)
    for comp in bsdf.components:
        if isinstance(comp, CosineSampled):
            total = total + comp.diffuse_albedo
    return total
