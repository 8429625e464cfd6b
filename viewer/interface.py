"""The contract between the Python renderer and the GLSL shaders, written once.

* :data:`SHADER_CONSTANTS`: every number both sides must agree on (array sizes, the lobe layout
  and its type codes, table sizes, pattern constants). They are injected as ``#define``s into
  every program (viewer/shaders.py), so the shaders hold no copies; a shader that declares one of
  them itself fails to compile (redefinition).
* :data:`LOBE_LAYOUT`: the rows of one packed lobe (``u_lobes``, LOBE_ROWS vec4s per lobe), the
  field each component holds, and the codes of its type/distribution/Fresnel fields; used by
  viewer/material_gpu.py to pack and by shaders/bsdf.glsl ``get_lobe`` to unpack.
* :data:`TEXTURE_UNITS`: the texture unit of every sampler uniform of the shading programs
  (mesh/scene/preview fragment shaders). Every sampler gets its own unit even when unused: two
  samplers of different types on one unit make the draw call fail (GL_INVALID_OPERATION).
* :func:`set_uniform` / :func:`write_uniform`: the only way uniforms are set. A name the program's
  sources do not declare raises :class:`UniformError` (a typo used to be skipped silently); a
  declared uniform the compiler optimised away is skipped; a raw write whose byte size differs
  from the uniform's raises too (a layout mismatch between packer and shader).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import numpy as np

from lobeview.core.methods import MAX_LOBES, MAX_PATTERN, PREFILTER_LOOKUPS, Method
from lobeview.materials.banks import BANKS_AZIMUTHS
from lobeview.materials.blur_stack import BUILD_TAPS, STACK_FACE, STACK_LAYERS, STACK_PAD, stack_sigmas
from lobeview.materials.fitted_pattern import TABLE_ALPHAS, TABLE_VIEWS_DEG
from lobeview.materials.gltf import SHEEN_TABLE_SIZE
from lobeview.materials.lobe_fit import LOBE_SLICES, MAP_LOBES
from lobeview.materials.measured import DEFENSIVE_COSINE
from lobeview.materials.measured import PHI_CELLS as MEASURED_PHI_CELLS
from lobeview.materials.measured import T_CELLS as MEASURED_T_CELLS
from lobeview.materials.measured import THETA_O_BINS as MEASURED_THETA_O_BINS
from lobeview.materials.microfacet import ALPHA_MIN
from lobeview.materials.patterns import (
    ALBEDO_MU,
    ALBEDO_PHI,
    ANISOTROPY_LINE_RATIO,
    GGX_TAIL_AZIMUTHAL,
    GGX_TAIL_FRACTION,
    GGX_TAIL_OUTER_TAN,
    GGX_TAIL_RADIAL,
    GGX_TAIL_SAMPLES,
    LINE_MIN_FOOTPRINT_FRACTION,
    MAX_ELLIPSE_ANGLE,
    WIDE_LOBE_ALPHA,
    WIDE_LOBE_LEVELS_PER_ALPHA,
    WIDE_LOBE_MAX_LEVELS,
    XI_BORDER,
)
from lobeview.materials.prefilter import ANISO_DFG_COS, ANISO_DFG_PHI, ANISO_DFG_ROUGHNESS, ANISO_DFG_STRENGTH
from lobeview.materials.rational import MAX_TERMS as RATIONAL_MAX_TERMS
from lobeview.materials.rational import graded_exponents
from lobeview.materials.rational_brdf import TANGENT_ANCHOR_DEG
from lobeview.materials.rsibr import (
    RSIBR_ALBEDO_SIZE,
    RSIBR_FADE,
    RSIBR_MAX_ALBEDO_RATIO,
    RSIBR_MAX_FACES,
    RSIBR_MAX_VIEWS,
)
from lobeview.scenes.reflection_proxy import MAX_PROXY_PLANES
from lobeview.scenes.scene import ALPHA_MODES as GLTF_ALPHA_MODES
from lobeview.scenes.scene import TEXTURE_SLOTS
from lobeview.scenes.self_visibility import (
    AZIMUTH_TAP,
    HORIZON_MIN_COS,
    HORIZON_SECTORS,
    HORIZON_SOFT_EDGE,
    MAP_HORIZON_SECTORS,
    MAX_FOOTPRINT_RADIUS,
    SELF_LOBE_TILT_MIN,
    SPLIT_SUM_MAX_RADIUS,
    SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN,
    SPLIT_SUM_RADIUS_PER_ALPHA_GGX,
)


class UniformError(KeyError):
    """A uniform name the program does not declare, or a write of the wrong size."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


# -- the packed lobe ---------------------------------------------------------------------------
LOBE_TYPES = {
    "kurt reflection": 0,
    "kurt transmission": 1,
    "microfacet": 2,
    "gltf specular": 3,
    "gltf clearcoat": 4,
    "gltf transmission": 5,
    "rational": 6,  # the Rational BRDF (shaders/rational.glsl); its functions in a storage buffer
    "measured": 7,  # a measured table (shaders/measured.glsl): a 3D texture and a CDF storage buffer
}
DISTRIBUTIONS = {"beckmann": 0, "ggx": 1}
FRESNEL_TYPES = {"none": 0, "schlick": 1, "conductor": 2}


@dataclass(frozen=True)
class LobeField:
    """One slot of the packed lobe: ``names`` are the GLSL ``Lobe`` fields that read it (several
    where lobe types use the slot for different quantities), at ``row`` (a vec4 of ``u_lobes``)
    and ``columns`` (``"x"``, ``"xyz"``...); an ``int`` field is stored as a float and read back
    rounded."""

    names: tuple[str, ...]
    row: int
    columns: str
    kind: str = "float"
    doc: str = ""

    @property
    def glsl_type(self) -> str:
        return "int" if self.kind == "int" else ("float" if len(self.columns) == 1 else f"vec{len(self.columns)}")


#: The packed lobe, written once: material_gpu.pack_lobe packs by it, shaders/lobe_layout.glsl
#: (struct Lobe and get_lobe, generated by lobe_layout_glsl) unpacks by it.
LOBE_LAYOUT = (
    LobeField(("type",), 0, "x", "int", "LOBE_* code"),
    LobeField(("dist",), 0, "y", "int", "DIST_* code"),
    LobeField(("ax",), 0, "z", doc="distribution alpha along the tangent"),
    LobeField(("ay",), 0, "w", doc="distribution alpha along the bitangent"),
    LobeField(("k",), 1, "xyz", doc="ks / kt / scale (glTF specular 1; clearcoat, transmission: factor)"),
    LobeField(("alpha", "specular_weight"), 1, "w", doc="thesis shadowing exponent (Eq. 3.4) | glTF specular weight"),
    LobeField(("r0",), 2, "xyz", doc="Schlick r0 (thesis, microfacet) or the glTF base colour"),
    LobeField(("fresnel",), 2, "w", "int", "FRESNEL_* code"),
    LobeField(("eta", "dielectric_f0"), 3, "xyz", doc="conductor eta | glTF dielectric f0 (KHR ior/specular)"),
    LobeField(("metallic",), 3, "w", doc="glTF metallic"),
    LobeField(("kappa",), 4, "xyz", doc="conductor kappa"),
    LobeField(("coat",), 4, "w", doc="glTF specular/transmission: the clearcoat factor over the lobe"),
)
LOBE_ROWS = 1 + max(field.row for field in LOBE_LAYOUT)
#: Lobe fields the shaders set themselves (not packed): (name, GLSL type, initial value, doc)
LOBE_SHADER_FIELDS = (
    ("coat_cos", "float", "-1.0", "N_c.V of the clearcoat's own normal (scene.frag); < 0: the lobe frame's N.V"),
)
LOBE_FIELDS = {name: field for field in LOBE_LAYOUT for name in field.names}


def pack_lobe(lobe_type: str, **values) -> np.ndarray:
    """One packed lobe, (LOBE_ROWS, 4) float32: ``lobe_type`` (a LOBE_TYPES name) and the
    LOBE_LAYOUT fields by name (``dist``, ``ax``, ``k``, ...); unnamed slots are 0. A name the
    layout lacks, a value of the wrong size, or two names of one slot raise."""
    out = np.zeros((LOBE_ROWS, 4), dtype=np.float32)
    written: dict[int, str] = {}
    for name, value in {"type": LOBE_TYPES[lobe_type], **values}.items():
        field = LOBE_FIELDS.get(name)
        if field is None:
            raise KeyError(f"the packed lobe has no field {name!r}; fields: {sorted(LOBE_FIELDS)}")
        if id(field) in written:
            raise ValueError(f"{name!r} and {written[id(field)]!r} share one slot of the packed lobe")
        written[id(field)] = name
        data = np.ravel(np.asarray(value, dtype=np.float64))
        if data.size != len(field.columns):
            raise ValueError(f"lobe field {name!r} takes {len(field.columns)} values, got {data.size}")
        out[field.row, ["xyzw".index(c) for c in field.columns]] = data
    return out


def unpack_lobe(rows: np.ndarray) -> dict:
    """Every named field of one packed lobe as get_lobe reads it (ints rounded, vectors as
    arrays): the numpy twin of the generated GLSL, for tests."""
    values = {}
    for field in LOBE_LAYOUT:
        data = np.asarray(rows[field.row, ["xyzw".index(c) for c in field.columns]], dtype=np.float32)
        value = int(np.floor(data[0] + 0.5)) if field.kind == "int" else (data if data.size > 1 else float(data[0]))
        values.update(dict.fromkeys(field.names, value))
    return values


def lobe_layout_glsl() -> str:
    """shaders/lobe_layout.glsl, generated from LOBE_LAYOUT (viewer/shaders.py includes it): the
    ``Lobe`` struct and ``get_lobe``, which reads lobe ``i`` out of ``u_lobes``."""
    fields, reads = [], []
    for field in LOBE_LAYOUT:
        docs = field.doc.split(" | ") if len(field.names) > 1 else [field.doc]
        for name, doc in zip(field.names, docs, strict=True):
            fields.append(f"    {field.glsl_type} {name};  // {doc}")
            slot = f"v{field.row}.{field.columns}"
            reads.append(f"    l.{name} = {'int(' + slot + ' + 0.5)' if field.kind == 'int' else slot};")
    for name, glsl_type, initial, doc in LOBE_SHADER_FIELDS:
        fields.append(f"    {glsl_type} {name};  // {doc}")
        reads.append(f"    l.{name} = {initial};")
    rows = [f"    vec4 v{row} = u_lobes[LOBE_ROWS * i + {row}];" for row in range(LOBE_ROWS)]
    return "\n".join(
        [
            "// Generated by viewer/interface.py lobe_layout_glsl from LOBE_LAYOUT: do not edit.",
            "struct Lobe {", *fields, "};", "",
            "#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py",
            "uniform vec4 u_lobes[MAX_LOBES * LOBE_ROWS];",
            "#endif", "",
            "Lobe get_lobe(int i) {", *rows, "    Lobe l;", *reads, "    return l;", "}",
        ]
    )  # fmt: skip


# -- the Rational BRDF's storage buffer ----------------------------------------------------------
RATIONAL_FUNCTIONS = 5  # BRDF R, G, B; inverse CDFs of theta_l (Eq. 8) and dphi (Eq. 9)
RATIONAL_STRIDE = 3 + 2 * RATIONAL_MAX_TERMS  # vec4s per function: header, lower, upper, terms
RATIONAL_MAX_DEGREE = int(graded_exponents(2, RATIONAL_MAX_TERMS).max())  # 2D has the highest degrees
RATIONAL_BINDING = 1  # shader storage binding point (compute shaders use 0)
MEASURED_BINDING = 3  # a measured BRDF's sampler CDFs (object records use 2)

# -- prefiltered lookups -------------------------------------------------------------------------
#: u_lobe_map_mode codes: how each lobe is looked up by the prefiltered methods
LOBE_MAP_MODES = {name: code for code, name in enumerate(PREFILTER_LOOKUPS)}
# Rows of the lobe table per component: the fitted lobes of a lobe map, or the view azimuths of a
# Banks map's albedo table (viewer/prefilter_modes.py lobe_table).
LOBE_TABLE_ROWS = max(MAP_LOBES, BANKS_AZIMUTHS)
CDF_ROW = 1024  # texels per row of the environment CDF texture (viewer/cubemap.py)
PROXY_KINDS = {"planes": 1, "box": 2}  # u_proxy_kind (scenes/reflection_proxy.py)
#: u_alpha_mode codes (glTF alphaMode, scenes/scene.py ALPHA_MODES)
ALPHA_MODES = {mode.lower(): code for code, mode in enumerate(GLTF_ALPHA_MODES)}
#: u_material_maps slots (scenes/scene.py TEXTURE_SLOTS, in that order)
MAP_SLOTS = {slot.replace("_", " "): index for index, slot in enumerate(TEXTURE_SLOTS)}


def _defines_of(prefix: str, codes: dict) -> dict:
    return {f"{prefix}_{name.upper().replace(' ', '_')}": code for name, code in codes.items()}


# Footprint of the direct cube read of a narrow fitted lobe (viewer/prefiltered.py lobe_direct_angle):
# area = LOBE_DIRECT_AREA_PER_MEDIAN2 m^2 for a lobe of median angle m. A box with the variance of a
# Gaussian lobe would be 12 m^2 / (2 ln 2) = 8.66 m^2, but the cube's trilinear reads add their own
# kernel. On the box MIP chain (measured: chrome, preview sphere 128 px, interior HDR) PSNR 31.9 /
# 35.6 / 36.2 / 35.5 / 33.5 / 29.6 dB at 1 / 2 / 3 / 4 / 5.5 / 8.66 m^2 gave 3. The tent chain
# (viewer/mip_chain.py, the default) blurs more per level: 200 px sphere, `prefiltered`, PSNR at
# 1 / 1.5 / 2 / 3 m^2: chrome interior 31.1 / 32.9 / 33.8 / 32.8 (box chain at 3: 32.8), courtyard
# 27.6 / 29.1 / 29.8 / 29.5 (box 28.9); lacquer courtyard 32.7 / 33.6 / 34.0 / 34.0 (box 33.4),
# interior 35.5 / 35.4 / 35.4 / 35.3 (box 36.4: its split-sum base, not this read).
LOBE_DIRECT_AREA_PER_MEDIAN2 = 2.0

SHADER_CONSTANTS: dict = {
    "MAX_LOBES": MAX_LOBES,
    "MAX_PATTERN": MAX_PATTERN,
    "LOBE_ROWS": LOBE_ROWS,
    **_defines_of("LOBE", LOBE_TYPES),
    **_defines_of("DIST", DISTRIBUTIONS),
    **_defines_of("FRESNEL", FRESNEL_TYPES),
    **_defines_of("LOBE_MAP", LOBE_MAP_MODES),
    **_defines_of("PROXY", PROXY_KINDS),
    **_defines_of("ALPHA", ALPHA_MODES),
    **_defines_of("MAP", MAP_SLOTS),
    "MATERIAL_MAPS": len(MAP_SLOTS),
    "SHEEN_TABLE_SIZE": SHEEN_TABLE_SIZE,  # materials/gltf.py: E_s(N.V) entries of u_sheen_albedo
    "ALPHA_MIN": float(ALPHA_MIN),  # materials/microfacet.py: the smallest GGX alpha
    "LOBE_SLICES": LOBE_SLICES,
    "LOBE_TABLE_ROWS": LOBE_TABLE_ROWS,
    "LOBE_DIRECT_AREA_PER_MEDIAN2": LOBE_DIRECT_AREA_PER_MEDIAN2,
    # lobe-N+norm+fit (materials/fitted_pattern.py): the table's nodes, alpha log-spaced by hand
    "FITTED_ALPHAS": len(TABLE_ALPHAS),
    "FITTED_ALPHA_NODES": "float[](" + ", ".join(repr(float(a)) for a in TABLE_ALPHAS) + ")",
    "FITTED_VIEWS": len(TABLE_VIEWS_DEG),
    "FITTED_VIEW_STEP_DEG": float(TABLE_VIEWS_DEG[1] - TABLE_VIEWS_DEG[0]),
    # materials/blur_stack.py: every blur stack (its layout; shaders/blur_stack.comp's taps)
    "BLUR_STACK_FACE": STACK_FACE,
    "BLUR_STACK_PAD": STACK_PAD,
    "BLUR_STACK_LAYERS": STACK_LAYERS,
    "BLUR_STACK_SIGMA0": float(stack_sigmas()[0]),
    "BLUR_STACK_TAPS": BUILD_TAPS,
    # scenes/self_visibility.py: the horizon seen through a lookup's footprint
    "HORIZON_MIN_COS": float(HORIZON_MIN_COS),
    "HORIZON_SECTORS": HORIZON_SECTORS,  # at vertices
    "MAP_HORIZON_SECTORS": MAP_HORIZON_SECTORS,  # in a horizon map (u_horizon_map's layers, 4 each)
    "HORIZON_SOFT_EDGE": float(HORIZON_SOFT_EDGE),
    "AZIMUTH_TAP": float(AZIMUTH_TAP),
    "SELF_LOBE_TILT_MIN": float(SELF_LOBE_TILT_MIN),
    "MAX_FOOTPRINT_RADIUS": float(MAX_FOOTPRINT_RADIUS),
    "SPLIT_SUM_RADIUS_PER_ALPHA_GGX": float(SPLIT_SUM_RADIUS_PER_ALPHA_GGX),
    "SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN": float(SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN),
    "SPLIT_SUM_MAX_RADIUS": float(SPLIT_SUM_MAX_RADIUS),
    "RSIBR_MAX_VIEWS": RSIBR_MAX_VIEWS,  # materials/rsibr.py: views of a once-subdivided icosahedron
    "RSIBR_MAX_FACES": RSIBR_MAX_FACES,
    "RSIBR_FADE": float(RSIBR_FADE),
    "RSIBR_ALBEDO_SIZE": RSIBR_ALBEDO_SIZE,
    "RSIBR_MAX_ALBEDO_RATIO": float(RSIBR_MAX_ALBEDO_RATIO),
    "ALBEDO_PHI": ALBEDO_PHI,
    # normalised lobe-N, textured anisotropic glTF lobes: the anisotropic DFG table's nodes
    "ANISO_DFG_COS": ANISO_DFG_COS,
    "ANISO_DFG_PHI": ANISO_DFG_PHI,
    "ANISO_DFG_ROUGHNESS": ANISO_DFG_ROUGHNESS,
    "ANISO_DFG_STRENGTH": ANISO_DFG_STRENGTH,
    "ALBEDO_MU": ALBEDO_MU,
    "XI_BORDER": float(XI_BORDER),  # Eq. 4.10
    "MAX_ELLIPSE_ANGLE": float(MAX_ELLIPSE_ANGLE),  # Eq. 4.15 clamp
    "WIDE_LOBE_ALPHA": float(WIDE_LOBE_ALPHA),  # materials/patterns.py wide_lobe_footprint_scale
    "WIDE_LOBE_LEVELS_PER_ALPHA": float(WIDE_LOBE_LEVELS_PER_ALPHA),
    "WIDE_LOBE_MAX_LEVELS": float(WIDE_LOBE_MAX_LEVELS),
    "GGX_TAIL_FRACTION": float(GGX_TAIL_FRACTION),  # materials/patterns.py step 7
    "GGX_TAIL_OUTER_TAN": float(GGX_TAIL_OUTER_TAN),
    "GGX_TAIL_SAMPLES": GGX_TAIL_SAMPLES,
    "GGX_TAIL_RADIAL": GGX_TAIL_RADIAL,
    "GGX_TAIL_AZIMUTHAL": GGX_TAIL_AZIMUTHAL,
    "ANISOTROPY_LINE_RATIO": float(ANISOTROPY_LINE_RATIO),  # materials/patterns.py choose_pattern
    "LINE_MIN_FOOTPRINT_FRACTION": float(LINE_MIN_FOOTPRINT_FRACTION),  # ... lobe_sample_area
    "CDF_ROW": CDF_ROW,
    "MAX_PROXY_PLANES": MAX_PROXY_PLANES,
    # shaders/rational.glsl: the storage buffer of a Rational BRDF (material_gpu.pack_rational)
    "RATIONAL_BINDING": RATIONAL_BINDING,
    "RATIONAL_STRIDE": RATIONAL_STRIDE,
    "RATIONAL_MAX_DEGREE": RATIONAL_MAX_DEGREE,
    # lobe-N's lattice anchored in the tangent frame near the normal (materials/rational_brdf.py)
    "TANGENT_ANCHOR_LOW_DEG": TANGENT_ANCHOR_DEG[0],
    "TANGENT_ANCHOR_HIGH_DEG": TANGENT_ANCHOR_DEG[1],
    "RATIONAL_NEWTON_STEPS": 14,  # inverting an inverse CDF (rational_invert): steps in all,
    "RATIONAL_BISECTION_STEPS": 6,  # the first ones bisection, then safeguarded Newton
    # shaders/measured.glsl: a measured BRDF's tabulated sampler (materials/measured.py)
    "MEASURED_BINDING": MEASURED_BINDING,
    "MEASURED_THETA_O_BINS": MEASURED_THETA_O_BINS,
    "MEASURED_T_CELLS": MEASURED_T_CELLS,
    "MEASURED_PHI_CELLS": MEASURED_PHI_CELLS,
    "MEASURED_DEFENSIVE_COSINE": float(DEFENSIVE_COSINE),
}

# -- texture units of the shading programs ---------------------------------------------------------
TEXTURE_UNITS: dict[str, int | tuple[int, ...]] = {
    "u_radiance": 0,  # the object's (or the environment's) radiance cube
    "u_irradiance": 1,  # preview: irradiance cube for the diffuse term
    "u_sobol": 2,
    "u_env_cdf": 3,  # reference: environment importance tables
    "u_env_pdf": 4,
    "u_lightmap": 5,
    "u_material_maps": (6, 20, 21, 22, 23, 34, 35, 36, 37, 38, 39),  # glTF textures by MAP_SLOTS
    "u_albedo": 7,  # normalised lobe-N: the lobes' albedo tables
    "u_split_sum": (8, 9),  # by distribution (DIST_BECKMANN, DIST_GGX)
    "u_dfg": 10,
    "u_lobe_maps": tuple(range(11, 11 + MAX_LOBES)),
    "u_lobe_table": 19,
    "u_mirror_radiance": 24,
    "u_mirror_position": 25,
    "u_mirror_normal": 26,
    "u_through_radiance": 27,
    "u_through_position": 28,
    "u_through_normal": 29,
    "u_plane_point_state": (30, 31),  # previous pass: mirror, see-through
    "u_plane_normal_state": (32, 33),
    "u_rsibr_maps": 40,  # prefiltered-rsibr: the reflection-space maps (viewer/rsibr.py)
    # the background's cube: its own unit, since an object's u_radiance may be another texture of
    # the same cube (viewer/cubemap.py residual, without the bright sources the background shows)
    "u_background": 41,
    "u_dfg_anisotropic": 42,  # normalised lobe-N: (A, B) of anisotropic glTF lobes per pixel
    # multi-drawn lobe-shaded objects: the cube-map array of their face size (viewer/cube_arrays.py;
    # fixed by layout(binding) in the shader: moderngl does not set samplerCubeArray uniforms)
    "u_radiance_array": 43,
    # multi-drawn normalised lobe-N: every material's albedo table, one layer each
    # (viewer/lobe_batches.py AlbedoTableArray; layout(binding) as for the cube-map arrays)
    "u_albedo_array": 44,
    "u_measured_table": 45,  # a measured BRDF's table (shaders/measured.glsl)
    "u_horizon_map": 46,  # the horizons per lightmap texel (scenes/horizon_maps.py)
    "u_fitted_patterns": 47,  # lobe-N+norm+fit: the fitted reads (materials/fitted_pattern.py, viewer/fitted_gpu.py)
    "u_blur_stack": 48,  # lobe-N+norm+fit's coarse reads: the bound cube's blur stack (materials/blur_stack.py)
}


def unit(name: str, index: int = 0) -> int:
    """Texture unit of sampler uniform ``name`` (element ``index`` of a sampler array)."""
    units = TEXTURE_UNITS[name]
    return units[index] if isinstance(units, tuple) else units


def uses_blur_stack(method: Method) -> bool:
    """lobe-N+norm+fit reads its coarse reads from the cube's blur stack (materials/blur_stack.py):
    the variant's BLUR_STACK (the preview, the scene's per-object draws and its multi-draws, which
    read copies from viewer/lobe_batches.py StackArrays; not the mirror buffers)."""
    return method.kind == "lobe" and method.pattern == "fitted"


def method_defines(method: Method) -> dict:
    """The shader variant of a method (viewer/shaders.py adds SHADER_CONSTANTS to every program)."""
    return {
        "METHOD_LOBE": method.kind == "lobe",
        "METHOD_FIS": method.kind == "fis",
        "METHOD_MC": method.kind in ("mc", "reference"),
        "ENV_SAMPLING": method.kind == "reference",
        "LOBE_NORMALIZE": method.kind == "lobe" and method.normalize,
        "LOBE_EQ424": method.kind == "lobe" and method.weighting == "eq4.24",
        "LOBE_FITTED": method.kind == "lobe" and method.pattern == "fitted",
        "METHOD_PREFILTERED": method.kind == "prefiltered",
    }


# -- uniforms ------------------------------------------------------------------------------------
_COMMENTS = re.compile(r"//[^\n]*|/\*.*?\*/", re.DOTALL)
_UNIFORM = re.compile(r"\buniform\b[^;{}()=]*?\b(\w+)\s*(?:\[[^\]]*\])?\s*(?:=[^;]*)?;")  # an initializer too


def declared_uniforms(*sources: str) -> frozenset[str]:
    """Names of the uniforms the GLSL ``sources`` declare (comments ignored)."""
    names = set()
    for source in sources:
        names.update(_UNIFORM.findall(_COMMENTS.sub("", source)))
    return frozenset(names)


def _check_declared(program, name: str) -> None:
    declared = (program.extra or {}).get("declared_uniforms") if hasattr(program, "extra") else None
    if declared is None:
        raise UniformError(f"uniform {name!r}: the program was not built by viewer.shaders.ProgramCache")
    if name not in declared:
        shaders = program.extra.get("sources", "?")
        raise UniformError(f"uniform {name!r} is not declared in {shaders} (misspelt, or a shader lost it)")


def has_uniform(program, name: str) -> bool:
    """Whether this program variant kept uniform ``name`` (a dict lookup: ``name in program``
    walks every member, 2 million steps a frame in the 12-room apartment's mirror passes)."""
    return program.get(name, None) is not None


class UniformWrites:
    """How many uniform values the helpers below sent to GL and how many they skipped because
    the program already held those bytes (issue 18: state uploaded when it changes, not per draw)."""

    def __init__(self):
        self.written = 0
        self.skipped = 0

    def reset(self) -> None:
        self.written = self.skipped = 0


UNIFORM_WRITES = UniformWrites()


def _pack(member, value) -> bytes:
    """``value`` as the bytes moderngl's ``Uniform.value`` setter would write."""
    if member.array_length > 1:
        if member.dimension > 1:
            return b"".join(struct.pack(member.fmt, *row) for row in value)
        return b"".join(struct.pack(member.fmt, item) for item in value)
    if member.dimension > 1:
        return struct.pack(member.fmt, *value)
    return struct.pack(member.fmt, value)


def _shadow(extra: dict) -> dict:
    """The program's uniform name -> bytes it holds (made on first use)."""
    shadow = extra.get("uniform_shadow")
    if shadow is None:
        shadow = extra["uniform_shadow"] = {}
    return shadow


def _store(program, name: str, member, data: bytes) -> None:
    """Write ``data`` to ``member`` unless the program already holds exactly these bytes (a
    shadow of each ProgramCache program's uniform state in ``program.extra``). A uniform written
    here must never be written another way (``program[name] = ...``), or the shadow would hold a
    value GL does not: programs that are set through these helpers are set only through them. A
    :class:`DrawRecorder` collects the write instead."""
    extra = program.extra
    if extra is None:  # a program not made by ProgramCache: no shadow
        member.write(data)
        return
    record = extra.get("record")
    if record is not None:
        record[name] = (member, data)
        return
    shadow = _shadow(extra)
    if shadow.get(name) == data:
        UNIFORM_WRITES.skipped += 1
        return
    member.write(data)
    shadow[name] = data
    UNIFORM_WRITES.written += 1


def set_uniform(program, name: str, value) -> None:
    """Set a declared uniform; skipped where the compiler optimised it out of this variant, and
    where the program holds this value already."""
    member = program.get(name, None)
    if member is not None:
        _store(program, name, member, _pack(member, value))
    else:
        _check_declared(program, name)


def write_uniform(program, name: str, data) -> None:
    """Write raw bytes (arrays of vectors, int arrays): the size must match the declaration."""
    data = np.ascontiguousarray(data).tobytes() if not isinstance(data, bytes | bytearray) else bytes(data)
    member = program.get(name, None)
    if member is None:
        _check_declared(program, name)
        return
    expected = getattr(member, "array_length", 1) * getattr(member, "dimension", 1) * 4
    if len(data) != expected:
        raise UniformError(
            f"uniform {name!r}: {len(data)} bytes written, the shader declares {expected} "
            f"({member.array_length} x {member.dimension} x 4): the packing and the GLSL layout disagree"
        )
    _store(program, name, member, data)


def _bind(program, bind, target) -> None:
    """Call ``bind(target)`` now, and record the call when ``program`` is a :class:`DrawRecorder`."""
    uses = getattr(program, "recorded_uses", None)
    if uses is not None:
        uses.append((bind, target))
    bind(target)


def use_unit(program, resource, unit_index: int) -> None:
    """Bind a texture or sampler object to a texture unit for ``program``'s next draw."""
    _bind(program, resource.use, unit_index)


def bind_storage(program, buffer, binding: int) -> None:
    """Bind a storage buffer for ``program``'s next draw."""
    _bind(program, buffer.bind_to_storage_buffer, binding)


@dataclass(frozen=True)
class DrawRecord:
    """The uniform values and bindings one object's draw state sets, recorded once
    (:class:`DrawRecorder`) and replayed per draw (:func:`replay`)."""

    uniforms: tuple  # (name, (member, bytes)) in the order they were set
    uses: tuple  # (bind method, unit or binding) in the order they were made


class DrawRecorder:
    """Stands in for a ProgramCache program while a renderer sets an object's draw state once:
    the uniform helpers record into it instead of writing, texture and buffer bindings are made
    and recorded. Replaying the record (:func:`replay`) then costs a bytes comparison per uniform
    and one call per binding, instead of rebuilding every value per draw."""

    def __init__(self, program):
        self.program = program
        self.extra = {**program.extra, "record": {}}
        self.recorded_uses: list = []

    def get(self, name: str, default=None):
        return self.program.get(name, default)

    def record(self) -> DrawRecord:
        return DrawRecord(tuple(self.extra["record"].items()), tuple(self.recorded_uses))


def replay(program, record: DrawRecord) -> None:
    """Set what ``record`` holds on ``program``: uniform bytes it does not hold yet, every binding
    (:func:`_store` inlined: this loop runs for every uniform of every draw)."""
    shadow = _shadow(program.extra)
    written = 0
    for name, (member, data) in record.uniforms:
        if shadow.get(name) != data:
            member.write(data)
            shadow[name] = data
            written += 1
    UNIFORM_WRITES.written += written
    UNIFORM_WRITES.skipped += len(record.uniforms) - written
    for bind, target in record.uses:
        bind(target)


def bind_sampler(program, name: str, texture, index: int | None = None) -> None:
    """Bind ``texture`` to the unit of sampler ``name`` (of its element ``index``)."""
    use_unit(program, texture, unit(name, index or 0))
    if index is None:
        units = TEXTURE_UNITS[name]
        set_uniform(program, name, list(units) if isinstance(units, tuple) else units)
