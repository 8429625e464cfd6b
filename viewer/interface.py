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

from lobeview.core.methods import MAX_LOBES, MAX_PATTERN, Method
from lobeview.materials.banks import BANKS_AZIMUTHS
from lobeview.materials.gltf import SHEEN_TABLE_SIZE
from lobeview.materials.lobe_fit import LOBE_SLICES, MAP_LOBES
from lobeview.materials.microfacet import ALPHA_MIN
from lobeview.materials.patterns import (
    ALBEDO_MU,
    ALBEDO_PHI,
    ANISOTROPY_LINE_RATIO,
    GGX_TAIL_FRACTION,
    GGX_TAIL_MEDIAN_TAN,
    GGX_TAIL_OUTER_TAN,
    GGX_TAIL_SAMPLES,
    MAX_ELLIPSE_ANGLE,
    XI_BORDER,
)
from lobeview.materials.rational import MAX_TERMS as RATIONAL_MAX_TERMS
from lobeview.materials.rational import graded_exponents
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
}
DISTRIBUTIONS = {"beckmann": 0, "ggx": 1}
FRESNEL_TYPES = {"none": 0, "schlick": 1, "conductor": 2}
#: (x, y, z, w) of each vec4 row of a packed lobe, as shaders/bsdf.glsl get_lobe reads them
LOBE_LAYOUT = (
    ("type", "distribution", "alpha_x", "alpha_y"),
    # ks / kt / scale (glTF specular: 1, clearcoat and transmission: their factor); thesis
    # shadowing exponent or glTF KHR_materials_specular's weight
    ("k.r", "k.g", "k.b", "alpha | specular_weight"),
    ("r0.r", "r0.g", "r0.b", "fresnel"),  # Schlick r0, or the glTF base colour
    ("eta.r | f0.r", "eta.g | f0.g", "eta.b | f0.b", "metallic"),  # glTF: the dielectric f0
    ("kappa.r", "kappa.g", "kappa.b", "coat"),  # glTF specular/transmission: the clearcoat over it
)
LOBE_ROWS = len(LOBE_LAYOUT)

# -- the Rational BRDF's storage buffer ----------------------------------------------------------
RATIONAL_FUNCTIONS = 5  # BRDF R, G, B; inverse CDFs of theta_l (Eq. 8) and dphi (Eq. 9)
RATIONAL_STRIDE = 3 + 2 * RATIONAL_MAX_TERMS  # vec4s per function: header, lower, upper, terms
RATIONAL_MAX_DEGREE = int(graded_exponents(2, RATIONAL_MAX_TERMS).max())  # 2D has the highest degrees
RATIONAL_BINDING = 1  # shader storage binding point (compute shaders use 0)

# -- prefiltered lookups -------------------------------------------------------------------------
#: u_lobe_map_mode codes: how each lobe is looked up by the prefiltered methods
LOBE_MAP_MODES = {"splitsum": 0, "lobes": 1, "banks": 2}
# Rows of the lobe table per component: the fitted lobes of a lobe map, or the view azimuths of a
# Banks map's albedo table (render_base.lobe_table).
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
    "RSIBR_MAX_VIEWS": RSIBR_MAX_VIEWS,  # materials/rsibr.py: views of a once-subdivided icosahedron
    "RSIBR_MAX_FACES": RSIBR_MAX_FACES,
    "RSIBR_FADE": float(RSIBR_FADE),
    "RSIBR_ALBEDO_SIZE": RSIBR_ALBEDO_SIZE,
    "RSIBR_MAX_ALBEDO_RATIO": float(RSIBR_MAX_ALBEDO_RATIO),
    "ALBEDO_PHI": ALBEDO_PHI,
    "ALBEDO_MU": ALBEDO_MU,
    "XI_BORDER": float(XI_BORDER),  # Eq. 4.10
    "MAX_ELLIPSE_ANGLE": float(MAX_ELLIPSE_ANGLE),  # Eq. 4.15 clamp
    "GGX_TAIL_FRACTION": float(GGX_TAIL_FRACTION),  # materials/patterns.py step 7
    "GGX_TAIL_MEDIAN_TAN": float(GGX_TAIL_MEDIAN_TAN),
    "GGX_TAIL_OUTER_TAN": float(GGX_TAIL_OUTER_TAN),
    "GGX_TAIL_SAMPLES": GGX_TAIL_SAMPLES,
    "ANISOTROPY_LINE_RATIO": float(ANISOTROPY_LINE_RATIO),  # materials/patterns.py choose_pattern
    "CDF_ROW": CDF_ROW,
    "MAX_PROXY_PLANES": MAX_PROXY_PLANES,
    # shaders/rational.glsl: the storage buffer of a Rational BRDF (material_gpu.pack_rational)
    "RATIONAL_BINDING": RATIONAL_BINDING,
    "RATIONAL_STRIDE": RATIONAL_STRIDE,
    "RATIONAL_MAX_DEGREE": RATIONAL_MAX_DEGREE,
    "RATIONAL_NEWTON_STEPS": 14,  # inverting an inverse CDF (rational_invert): steps in all,
    "RATIONAL_BISECTION_STEPS": 6,  # the first ones bisection, then safeguarded Newton
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
}


def unit(name: str, index: int = 0) -> int:
    """Texture unit of sampler uniform ``name`` (element ``index`` of a sampler array)."""
    units = TEXTURE_UNITS[name]
    return units[index] if isinstance(units, tuple) else units


def method_defines(method: Method) -> dict:
    """The shader variant of a method (viewer/shaders.py adds SHADER_CONSTANTS to every program)."""
    return {
        "METHOD_LOBE": method.kind == "lobe",
        "METHOD_FIS": method.kind == "fis",
        "METHOD_MC": method.kind in ("mc", "reference"),
        "ENV_SAMPLING": method.kind == "reference",
        "LOBE_NORMALIZE": method.kind == "lobe" and method.normalize,
        "LOBE_EQ424": method.kind == "lobe" and method.weighting == "eq4.24",
        "METHOD_PREFILTERED": method.kind == "prefiltered",
    }


# -- uniforms ------------------------------------------------------------------------------------
_COMMENTS = re.compile(r"//[^\n]*|/\*.*?\*/", re.DOTALL)
_UNIFORM = re.compile(r"\buniform\b[^;{}()]*?\b(\w+)\s*(?:\[[^\]]*\])?\s*;")


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
