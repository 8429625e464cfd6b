"""Packing a numpy-reference BSDF into the uniforms of shaders/bsdf.glsl, and the per-lobe
deterministic patterns for lobe-N."""

from __future__ import annotations

import hashlib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lobeview.core.cache import DAMAGED_CACHE_ERRORS, BoundedCache, write_cache_file
from lobeview.core.methods import MAX_LOBES, MAX_PATTERN
from lobeview.core.paths import cache_dir
from lobeview.core.progress import timed_step
from lobeview.materials.bsdf import BSDF, CosineSampled, diffuse_albedo
from lobeview.materials.conductor import MicrofacetReflection
from lobeview.materials.gltf import (
    COAT_F0,
    SHEEN_TABLE_SIZE,
    BaseLayers,
    GltfClearcoat,
    GltfDiffuse,
    GltfSpecular,
    GltfTransmission,
)
from lobeview.materials.measured import MeasuredLobe
from lobeview.materials.patterns import (
    ALBEDO_MU,
    ALBEDO_PHI,
    AlbedoTable,
    choose_pattern,
    lattice_xi,
    pattern_xi,
)
from lobeview.materials.rational import graded_exponents
from lobeview.materials.rational_brdf import RationalLobe
from lobeview.materials.thesis import KurtLobe

from .interface import DISTRIBUTIONS, FRESNEL_TYPES, LOBE_ROWS, RATIONAL_FUNCTIONS, RATIONAL_STRIDE, pack_lobe

ALBEDO_TABLES_KEPT = 256  # albedo tables of distinct lobes kept in memory (slider edits make new ones)
# Albedo tables cached on disk: bump when a lobe's eval or the table's layout changes.
ALBEDO_CACHE_VERSION = 1


@dataclass
class PackedMaterial:
    kd: np.ndarray
    gltf_diffuse: bool
    lobes: np.ndarray  # (MAX_LOBES * LOBE_ROWS, 4) float32, interface.LOBE_LAYOUT
    lobe_count: int
    lobe_distributions: list
    lobe_components: list
    tangent_rotation: float = 0.0  # BSDF.tangent_rotation (KHR_materials_anisotropy), radians
    # The glTF diffuse's weight (shaders/bsdf.glsl diffuse_weight): 1 - specular max(F_d(f0)),
    # times 1 - clearcoat F_c(N.V) (KHR_materials_specular/_ior/_clearcoat).
    dielectric_f0: tuple = (0.04, 0.04, 0.04)
    specular_weight: float = 1.0
    clearcoat: float = 0.0
    transmission: float = 0.0  # KHR_materials_transmission: the diffuse keeps 1 - transmission
    # KHR_materials_sheen (approximated, materials/gltf.py GltfSheen): colour and E_s(N.V) table.
    sheen_color: tuple = (0.0, 0.0, 0.0)
    sheen_table: tuple = (0.0,) * SHEEN_TABLE_SIZE
    # The Rational BRDF's storage buffer (pack_rational), None without a rational lobe.
    rational: np.ndarray | None = None
    # A measured BRDF (materials/measured.py): its lobe, whose table and CDFs the shader reads.
    measured: MeasuredLobe | None = None

    @property
    def has_diffuse(self) -> bool:
        """Whether the diffuse-like terms (kd, and the sheen lit like it) need the irradiance."""
        return bool(np.any(self.kd > 0) or any(c > 0 for c in self.sheen_color))

    @property
    def has_rational(self) -> bool:
        """Whether the program needs shaders/rational.glsl (the HAS_RATIONAL variant)."""
        return self.rational is not None

    @property
    def has_measured(self) -> bool:
        """Whether the program needs shaders/measured.glsl (the HAS_MEASURED variant)."""
        return self.measured is not None

    @property
    def draws_alone(self) -> bool:
        """A Rational or measured BRDF: its buffers are bound per object, outside the multi-draws."""
        return self.rational is not None or self.measured is not None

    @property
    def lobes_key(self) -> tuple:
        """Everything that determines what is derived from the specular lobes (albedo tables,
        lobe fits): the one lobe-identity key of the renderers' per-material textures and of the
        albedo tables. The preview packs its
        material anew every frame, so an id() key would miss (and grow) on every frame."""
        return tuple(_lobe_key(comp) for comp in self.lobe_components)


def pack_material(bsdf: BSDF) -> PackedMaterial:
    kd = diffuse_albedo(bsdf)
    gltf_diffuse = any(isinstance(comp, GltfDiffuse) for comp in bsdf.components)
    rows = []
    dists = []
    components = []
    for comp in bsdf.components:
        if isinstance(comp, CosineSampled):
            continue
        d = comp.distribution
        shape = {"dist": DISTRIBUTIONS[d.kind], "ax": d.alpha_x, "ay": d.alpha_y}
        if isinstance(comp, KurtLobe):
            kind = "kurt transmission" if comp.transmission else "kurt reflection"
            row = pack_lobe(kind, **shape, k=comp.k, alpha=comp.alpha, r0=comp.r0, fresnel=FRESNEL_TYPES["schlick"])
        elif isinstance(comp, (GltfSpecular, GltfTransmission)):
            # The glTF base lobes: scale 1 (specular) or the transmission factor, the specular
            # weight, base colour, dielectric f0, metallic and the clearcoat over them.
            transmission = isinstance(comp, GltfTransmission)
            scale = comp.amount if transmission else 1.0
            row = pack_lobe(
                "gltf transmission" if transmission else "gltf specular", **shape, k=(scale, scale, scale),
                specular_weight=comp.specular, r0=comp.base_color, dielectric_f0=comp.f0, metallic=comp.metallic,
                coat=comp.layers.coat,
            )  # fmt: skip
        elif isinstance(comp, GltfClearcoat):
            row = pack_lobe(
                "gltf clearcoat", **shape, k=comp.scale, r0=(COAT_F0,) * 3, fresnel=FRESNEL_TYPES["schlick"]
            )
        elif isinstance(comp, RationalLobe):
            # The proxy distribution places lobe-N's pattern; the functions go to a storage
            # buffer (one rational lobe per material: its data are per material, not per lobe).
            # k.r holds the largest theta_l of the fit (radians).
            if any(isinstance(c, RationalLobe) for c in components):
                raise ValueError("a material has at most one rational lobe")
            row = pack_lobe("rational", **shape, k=(np.radians(comp.theta_max_deg), 0.0, 0.0))
        elif isinstance(comp, MeasuredLobe):
            # The proxy distribution places lobe-N's cap lights and prefiltered lookups; the
            # table and its CDFs are the material's (one measured lobe per material).
            if any(isinstance(c, MeasuredLobe) for c in components):
                raise ValueError("a material has at most one measured lobe")
            row = pack_lobe("measured", **shape)
        elif isinstance(comp, MicrofacetReflection):
            fr = comp.fresnel
            row = pack_lobe(
                "microfacet", **shape, k=comp.scale, r0=fr.r0, fresnel=FRESNEL_TYPES[fr.kind], eta=fr.eta, kappa=fr.k
            )
        else:
            raise TypeError(f"no GPU version of BSDF component {type(comp).__name__}")
        rows.append(row)
        dists.append(d)
        components.append(comp)
    if len(rows) > MAX_LOBES:
        raise ValueError(f"material has {len(rows)} lobes; the renderer supports {MAX_LOBES}")
    lobes = np.zeros((MAX_LOBES * LOBE_ROWS, 4), dtype=np.float32)
    if rows:
        lobes[: len(rows) * LOBE_ROWS] = np.concatenate(rows)
    diffuse = next((comp for comp in bsdf.components if isinstance(comp, GltfDiffuse)), None)
    extra = {}
    if diffuse is not None:
        layers = diffuse.layers
        extra = dict(dielectric_f0=tuple(map(float, diffuse.f0)), specular_weight=diffuse.specular,
                     clearcoat=layers.coat, transmission=diffuse.transmission,
                     sheen_color=tuple(map(float, layers.sheen_color)),
                     sheen_table=tuple(map(float, layers.sheen_table)))  # fmt: skip
    rational = next((pack_rational(c) for c in components if isinstance(c, RationalLobe)), None)
    measured = next((c for c in components if isinstance(c, MeasuredLobe)), None)
    return PackedMaterial(
        kd.astype(np.float32), gltf_diffuse, lobes, len(rows), dists, components, float(bsdf.tangent_rotation),
        rational=rational, measured=measured, **extra
    )  # fmt: skip


def pack_rational(lobe: RationalLobe) -> np.ndarray:
    """(RATIONAL_FUNCTIONS * RATIONAL_STRIDE, 4) float32, shaders/rational.glsl's layout: per
    function a header (counts), the domain's lower and upper corners, then (coefficient,
    exponents) per numerator and denominator term. A grey fit's one function fills R, G and B."""
    functions = list(lobe.functions)
    if len(functions) == 1:
        functions = functions * 3
    functions += [lobe.sampling.theta, lobe.sampling.phi]
    out = np.zeros((RATIONAL_FUNCTIONS * RATIONAL_STRIDE, 4), dtype=np.float32)
    for f, fn in enumerate(functions):
        base = f * RATIONAL_STRIDE
        n_num, n_den = fn.counts
        out[base] = (n_num, n_den, 0, 0)
        out[base + 1, : fn.dimension] = fn.lower
        out[base + 2, : fn.dimension] = fn.upper
        row = base + 3
        for coefficients in (fn.numerator, fn.denominator):
            exponents = graded_exponents(fn.dimension, len(coefficients))
            out[row : row + len(coefficients), 0] = coefficients
            out[row : row + len(coefficients), 1 : 1 + fn.dimension] = exponents
            row += len(coefficients)
    return out


_ALBEDO_TABLES = BoundedCache(ALBEDO_TABLES_KEPT)


def _lobe_key(comp) -> tuple:
    """Everything that determines a lobe's albedo (its packed uniforms)."""
    return (type(comp).__name__, *pack_material_row_key(comp))


def pack_material_row_key(comp) -> tuple:
    values = []
    for name in ("k", "r0", "alpha", "transmission", "scale", "base_color", "metallic", "f0", "specular", "layers",
                 "amount"):  # fmt: skip
        v = getattr(comp, name, None)
        if isinstance(v, BaseLayers):
            v = (v.coat, *v.sheen_color, v.sheen_roughness)
        values.append(None if v is None else tuple(np.atleast_1d(np.asarray(v, float)).tolist()))
    if isinstance(comp, (RationalLobe, MeasuredLobe)):
        values.append(comp.cache_key)
    fresnel = getattr(comp, "fresnel", None)
    if fresnel is not None:
        values.append((fresnel.kind, *fresnel.r0, *fresnel.eta, *fresnel.k))
    d = comp.distribution
    return (d.kind, d.alpha_x, d.alpha_y, *values)


def albedo_texture_data(material: PackedMaterial, directory: Path | None = None) -> np.ndarray:
    """(MAX_LOBES * (ALBEDO_PHI + 1), ALBEDO_MU, 3) float32: each lobe's AlbedoTable stacked
    (shaders/integrate.glsl, LOBE_NORMALIZE). Tables are cached by lobe parameters."""
    data = np.zeros((MAX_LOBES * (ALBEDO_PHI + 1), ALBEDO_MU, 3), dtype=np.float32)
    rows = ALBEDO_PHI + 1
    for i, comp in enumerate(material.lobe_components):
        data[i * rows : (i + 1) * rows] = albedo_table_for(comp, directory).values
    return data


def albedo_table_for(comp, directory: Path | None = None) -> AlbedoTable:
    """The lobe's AlbedoTable: from memory, else from ``directory``/albedo (the cache folder,
    default core/paths.py's; a second start of a scene then costs nothing), else built (0.05 s isotropic,
    ~1.3 s anisotropic) and saved there."""
    key = _lobe_key(comp)
    return _ALBEDO_TABLES.get(key, lambda: _load_or_build_albedo_table(comp, key, directory))


def _albedo_cache_path(key: tuple, directory: Path | None) -> Path:
    digest = hashlib.sha256(repr((ALBEDO_CACHE_VERSION, ALBEDO_PHI, ALBEDO_MU, key)).encode()).hexdigest()[:24]
    return Path(directory or cache_dir()) / "albedo" / f"albedo-v{ALBEDO_CACHE_VERSION}-{digest}.npy"


def _load_or_build_albedo_table(comp, key: tuple, directory: Path | None) -> AlbedoTable:
    path = _albedo_cache_path(key, directory)
    shape = (ALBEDO_PHI + 1, ALBEDO_MU, 3)
    try:
        values = np.load(path, allow_pickle=False)
        if values.shape == shape and values.dtype == np.float64 and np.all(np.isfinite(values)) and values.min() >= 0:
            return AlbedoTable(values)
        warnings.warn(f"{path}: not an albedo table of shape {shape}; rebuilding it", stacklevel=2)
    except FileNotFoundError:
        pass
    except DAMAGED_CACHE_ERRORS as exc:  # a damaged cache file is rebuilt, never trusted
        warnings.warn(f"{path}: unreadable cached albedo table ({exc}); rebuilding it", stacklevel=2)
    with timed_step("albedo", f"normalisation table of a {type(comp).__name__} lobe (cached afterwards)"):
        table = AlbedoTable.build(comp)
    write_cache_file(path, lambda handle: np.save(handle, table.values))  # read-only cache: rebuild next time
    return table


def pack_patterns(material: PackedMaterial, n: int, planar: bool = False, pattern: str = "auto") -> np.ndarray:
    """(MAX_LOBES * MAX_PATTERN, 2) pattern coordinates of each lobe's ring (or, with ``pattern``
    'auto', its double ring from DOUBLE_RING_MIN_SAMPLES on), or
    with ``planar`` the multi-ring pattern of thesis 4.5.3 for objects shaded from a mirror
    buffer. The line
    patterns of strongly anisotropic lobes (:func:`lobeview.materials.patterns.choose_pattern`)
    are chosen and placed per pixel by shaders/integrate.glsl lobe_pattern_xi, since a roughness
    or anisotropy texture changes a lobe's anisotropy from pixel to pixel. A lobe sampled through
    its own inverse CDFs (``sampled_pattern``: the Rational BRDF) gets the lattice of
    :func:`lobeview.materials.patterns.lattice_xi` instead (integrate.glsl integrate_sampled_lobe)."""
    if not 1 <= n <= MAX_PATTERN:
        raise ValueError(f"lobe-N supports 1 <= N <= {MAX_PATTERN}, got {n}")
    out = np.zeros((MAX_LOBES * MAX_PATTERN, 2), dtype=np.float32)
    lattice = np.stack(lattice_xi(n), -1)
    for i, comp in enumerate(material.lobe_components):
        if getattr(comp, "sampled_pattern", False):
            out[i * MAX_PATTERN : i * MAX_PATTERN + n] = lattice
            continue
        # Ring or double ring by the lobe's widest roughness (isotropic here: the line patterns are the
        # shader's, per pixel); a roughness texture can only widen it (materials/gltf.py).
        dist = getattr(comp, "distribution", None)
        alpha = max(float(dist.alpha_x), float(dist.alpha_y)) if dist is not None else 1.0
        out[i * MAX_PATTERN : i * MAX_PATTERN + n] = np.stack(
            pattern_xi(n, choose_pattern(alpha, alpha, planar, n, pattern)), -1
        )
    return out
