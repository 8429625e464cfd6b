"""Per-object draw state in one storage buffer (issue 42, GPU-driven drawing): the uniforms an
object's draw of the diffuse scene program sets (viewer/scene_shading.py object_state and the
packed material's diffuse terms) become one std430 record per object, read in shaders/scene.frag
as ``g_object_records[v_object]`` by programs with OBJECT_RECORDS. One multi-draw then draws
every object that binds the same textures.

The layout is written once here: :data:`OBJECT_RECORD_FIELDS` gives each uniform's GLSL type;
:func:`object_records_glsl` generates the struct, the buffer and one ``#define u_name`` per field
(the shader code reads the uniforms' names unchanged), and :func:`pack_object_record` places the
exact bytes the per-object path would send to each uniform (recorded by viewer/interface.py
DrawRecorder) at the field's std430 offset, so both paths shade with bit-identical values."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lobeview.core.methods import MAX_LOBES, MAX_PATTERN
from lobeview.scenes.bright_sources import MAX_LIGHTS as MAX_CAP_LIGHTS
from lobeview.scenes.lamps import MAX_LAMPS
from lobeview.scenes.reflection_proxy import MAX_PROXY_PLANES

from .interface import LOBE_ROWS, SHADER_CONSTANTS, TEXTURE_UNITS

OBJECT_RECORDS_BINDING = 2  # storage binding (RATIONAL_BINDING is 1; compute shaders use 0)


@dataclass(frozen=True)
class RecordField:
    uniform: str  # the uniform the field replaces (u_ prefix)
    glsl_type: str  # float, int, vec3, vec4, ivec2, mat3
    length: int = 0  # array length (0: not an array); a SHADER_CONSTANTS name is resolved

    @property
    def member(self) -> str:
        return self.uniform.removeprefix("u_")


#: Every uniform an object sets in the diffuse scene program (no SPECULAR), in std430 order.
OBJECT_RECORD_FIELDS = (
    RecordField("u_base_color_factor", "vec4"),
    RecordField("u_emission", "vec3"),
    RecordField("u_object_id", "float"),
    RecordField("u_kd", "vec3"),
    RecordField("u_gltf_diffuse", "float"),
    RecordField("u_dielectric_f0", "vec3"),
    RecordField("u_specular_weight", "float"),
    RecordField("u_sheen_color", "vec3"),
    RecordField("u_clearcoat", "float"),
    RecordField("u_specular_f0_raw", "vec3"),
    RecordField("u_transmission", "float"),
    RecordField("u_metallic_factor", "float"),
    RecordField("u_roughness_factor", "float"),
    RecordField("u_anisotropy", "float"),
    RecordField("u_normal_scale", "float"),
    RecordField("u_occlusion_strength", "float"),
    RecordField("u_clearcoat_roughness", "float"),
    RecordField("u_clearcoat_normal_scale", "float"),
    RecordField("u_alpha_cutoff", "float"),
    RecordField("u_lightmap_intensity", "float"),
    RecordField("u_tangent_rotation", "float"),
    RecordField("u_gltf_model", "int"),
    RecordField("u_alpha_mode", "int"),
    RecordField("u_lightmap_texcoord", "int"),
    RecordField("u_has_horizon_map", "int"),
    RecordField("u_horizon_map_uv", "int"),
    RecordField("u_map_texcoord", "int", "MATERIAL_MAPS"),
    RecordField("u_map_mirrored", "ivec2", "MATERIAL_MAPS"),
    RecordField("u_map_transform", "mat3", "MATERIAL_MAPS"),
    RecordField("u_sheen_albedo", "float", "SHEEN_TABLE_SIZE"),
    RecordField("u_lamp_visibility", "float", MAX_LAMPS),  # scenes/lamps.py: how much of it each lamp reaches
)

#: What a lobe-shaded object (SPECULAR; methods lobe-N and fis-N, viewer/lobe_batches.py) sets
#: beyond the diffuse fields, appended after them so both kinds share the diffuse offsets: its
#: lobes and patterns, the cube's size and bright-source lights, its reflection proxy, and the
#: layer of its cube map in the cube-map array of its face size (viewer/cube_arrays.py).
LOBE_RECORD_FIELDS = (
    RecordField("u_lobe_count", "int"),
    RecordField("u_albedo_per_pixel", "int"),
    RecordField("u_face_size", "float"),
    RecordField("u_cube_layer", "float"),
    RecordField("u_albedo_layer", "float"),  # normalised lobe-N: the layer of its albedo table
    RecordField("u_stack_layer", "float"),  # lobe-N+norm+fit: its blur stack's first layer in the group's array
    RecordField("u_has_blur_stack", "int"),  # 0: no stack (no fitted lobe, or not built yet): the chain
    RecordField("u_cap_light_count", "int"),
    RecordField("u_signed_residual", "int"),  # 1: its residual keeps a source's shape (cap_lights.glsl)
    RecordField("u_proxy_kind", "int"),
    RecordField("u_proxy_plane_count", "int"),
    RecordField("u_cube_centre", "vec3"),
    RecordField("u_proxy_box_min", "vec3"),
    RecordField("u_proxy_box_max", "vec3"),
    RecordField("u_volume", "vec4"),  # KHR_materials_volume (shaders/volume.glsl)
    RecordField("u_volume_attenuation", "vec3"),
    RecordField("u_lobes", "vec4", MAX_LOBES * LOBE_ROWS),
    RecordField("u_pattern", "vec2", MAX_LOBES * MAX_PATTERN),
    RecordField("u_cap_light_axis", "vec4", MAX_CAP_LIGHTS),
    RecordField("u_cap_light_radiance", "vec4", MAX_CAP_LIGHTS),
    RecordField("u_proxy_planes", "vec4", MAX_PROXY_PLANES),
)

# std430 (GL 4.5 spec 7.6.2.2): base alignment and size in bytes; the stride of an array of
# scalars or two-vectors is their size (no rounding to 16 as in std140), of three-vectors 16;
# mat3 is three vec3 columns, each aligned to 16.
_ALIGN = {"float": 4, "int": 4, "ivec2": 8, "vec2": 8, "vec3": 16, "vec4": 16, "mat3": 16}
_SIZE = {"float": 4, "int": 4, "ivec2": 8, "vec2": 8, "vec3": 12, "vec4": 16, "mat3": 48}
# Types whose std430 elements are padded beyond moderngl's tight packing: (floats sent, floats stored).
_PADDED = {"mat3": (3, 4), "vec3": (3, 4)}


def _length(field: RecordField) -> int:
    length = field.length
    return int(SHADER_CONSTANTS[length]) if isinstance(length, str) else int(length)


def _stride(field: RecordField) -> int:
    """Bytes per array element (the field's size where it is not an array)."""
    if _length(field) and field.glsl_type == "vec3":
        return 16
    return _SIZE[field.glsl_type]


class RecordLayout:
    """The std430 layout of a record made of ``fields``: each uniform's offset, the record's size
    (a multiple of 16: a struct's alignment is its largest member's), and the packing."""

    def __init__(self, fields: tuple[RecordField, ...]):
        self.fields = fields
        self.offsets: dict[str, tuple[int, RecordField]] = {}
        offset = 0
        for field in fields:
            align = _ALIGN[field.glsl_type]
            offset = (offset + align - 1) // align * align
            self.offsets[field.uniform] = (offset, field)
            offset += _stride(field) * max(_length(field), 1)
        self.size = (offset + 15) // 16 * 16
        self.uniforms = frozenset(self.offsets)

    def pack(self, uniforms: dict[str, bytes]) -> bytes:
        """One object's record from the bytes each uniform would be sent as (moderngl's packing:
        arrays tight, mat3 as 9 floats column by column); a field absent from ``uniforms`` (a
        uniform the compiler dropped from the per-object program: unread) stays 0."""
        out = bytearray(self.size)
        for name, data in uniforms.items():
            entry = self.offsets.get(name)
            if entry is None:
                continue
            offset, field = entry
            count = max(_length(field), 1)
            expected = (36 if field.glsl_type == "mat3" else _SIZE[field.glsl_type]) * count  # mat3 sent tight
            if len(data) != expected:
                raise ValueError(f"{name}: {len(data)} bytes for a {field.glsl_type} field of {expected}")
            padded = _PADDED.get(field.glsl_type)
            if padded is not None and (field.glsl_type == "mat3" or count > 1):
                sent, stored = padded
                rows = np.frombuffer(data, dtype=np.float32).reshape(-1, sent)
                wide = np.zeros((len(rows), stored), dtype=np.float32)
                wide[:, :sent] = rows
                data = wide.tobytes()
            out[offset : offset + len(data)] = data
        return bytes(out)


DIFFUSE_RECORDS = RecordLayout(OBJECT_RECORD_FIELDS)
LOBE_RECORDS = RecordLayout(OBJECT_RECORD_FIELDS + LOBE_RECORD_FIELDS)
# The diffuse layout under its earlier names (object_batches, tests).
RECORD_OFFSETS, RECORD_SIZE, RECORD_UNIFORMS = DIFFUSE_RECORDS.offsets, DIFFUSE_RECORDS.size, DIFFUSE_RECORDS.uniforms
pack_object_record = DIFFUSE_RECORDS.pack


def _members(fields) -> list[str]:
    return [f"    {f.glsl_type} {f.member}{f'[{f.length}]' if f.length else ''};" for f in fields]


def _defines(fields) -> list[str]:
    return [f"#define {f.uniform} g_object_records[v_object].{f.member}" for f in fields]


def object_records_glsl() -> str:
    """shaders/object_records.glsl (viewer/shaders.py GENERATED_SOURCES): with OBJECT_RECORDS,
    the record struct, the buffer of every object's record, the object index ``v_object`` (flat,
    from the vertex shader's per-draw attribute) and ``#define u_name`` for each field; with
    SPECULAR too (OBJECT_LOBE_RECORDS), the lobe fields and the cube-map array the radiance is
    read from (``RADIANCE_LOD``; shaders/integrate.glsl defines it on the object's own cube
    otherwise), the albedo-table array (``ALBEDO_AT``; patterns.glsl's default reads the
    material's own table) and the blur-stack array (lobe-N+norm+fit); without OBJECT_RECORDS,
    nothing (the uniforms are declared where they were)."""
    return "\n".join(
        [
            "// Generated by viewer/object_records.py object_records_glsl: do not edit.",
            "#if defined(OBJECT_RECORDS)",
            "#if defined(SPECULAR)",
            "#define OBJECT_LOBE_RECORDS",
            "#endif",
            "flat in uint v_object;",
            "struct ObjectRecord {", *_members(OBJECT_RECORD_FIELDS),
            "#if defined(OBJECT_LOBE_RECORDS)", *_members(LOBE_RECORD_FIELDS), "#endif",
            "};",
            f"layout(std430, binding = {OBJECT_RECORDS_BINDING}) readonly buffer ObjectRecords {{",
            "    ObjectRecord g_object_records[];",
            "};",
            *_defines(OBJECT_RECORD_FIELDS),
            "#if defined(OBJECT_LOBE_RECORDS)",
            *_defines(LOBE_RECORD_FIELDS),
            "// The object's cube map: its layer of the array of its face size (viewer/cube_arrays.py).",
            f"layout(binding = {TEXTURE_UNITS['u_radiance_array']}) uniform samplerCubeArray u_radiance_array;",
            "#define RADIANCE_LOD(dir, lod) textureLod(u_radiance_array, vec4(dir, u_cube_layer), lod)",
            "// Normalised lobe-N: the material's albedo table, its layer of one array for every material",
            "// (viewer/lobe_batches.py AlbedoTableArray; shaders/patterns.glsl reads it through ALBEDO_AT).",
            f"layout(binding = {TEXTURE_UNITS['u_albedo_array']}) uniform sampler2DArray u_albedo_array;",
            "#define ALBEDO_AT(uv) textureLod(u_albedo_array, vec3(uv, u_albedo_layer), 0.0)",
            "// lobe-N+norm+fit: the blur stacks of the group's objects, u_stack_layer their first layers",
            "// (viewer/lobe_batches.py StackArrays; read by shaders/blur_stack.glsl).",
            f"layout(binding = {TEXTURE_UNITS['u_blur_stack']}) uniform sampler2DArray u_blur_stack;",
            "#endif",
            "#endif",
        ]
    )  # fmt: skip
