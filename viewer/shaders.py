"""GLSL sources from ``shaders/``: ``#include "name.glsl"`` resolution with a cycle check, and
program variants chosen by ``#define``s, cached by the sorted tuple of defines.

Only defines listed in :data:`KNOWN_DEFINES` are accepted (an unknown name is a typo that would
silently select the wrong variant); a define with value ``False``/``None`` is left out, any other
value is emitted as ``#define NAME value`` (``True`` -> ``1``). Every program also gets the
shared constants of viewer/interface.py (SHADER_CONSTANTS), which a caller cannot override, and
records the uniforms its sources declare (``program.extra``) for interface.set_uniform's check.
"""

from __future__ import annotations

import re
from importlib import resources

import moderngl

from .interface import SHADER_CONSTANTS, declared_uniforms, lobe_layout_glsl
from .object_records import object_records_glsl

#: the variant switches a caller may set (the shared constants come from interface.py)
KNOWN_DEFINES = {
    "METHOD_LOBE",
    "METHOD_FIS",
    "METHOD_MC",
    "METHOD_PREFILTERED",
    "ENV_SAMPLING",
    "PLANE_AVERAGE",
    "LOBE_NORMALIZE",
    "LOBE_EQ424",
    "LOBE_FITTED",
    "BLUR_STACK",
    "HAS_DIFFUSE",
    "HAS_RATIONAL",
    "HAS_MEASURED",
    "SPECULAR",
    "PARALLAX",
    "MIRROR",
    "OBJECT_RECORDS",
    "OBJECT_INDEX",  # depth.vert: the object index for the counted occlusion test (viewer/occlusion.py)
}

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


class ShaderError(RuntimeError):
    pass


#: sources made from the Python side's single description of a contract (``#include`` them by name)
GENERATED_SOURCES = {"lobe_layout.glsl": lobe_layout_glsl, "object_records.glsl": object_records_glsl}


def read_source(name: str) -> str:
    if name in GENERATED_SOURCES:
        return GENERATED_SOURCES[name]()
    try:
        return resources.files("lobeview.shaders").joinpath(name).read_text()
    except FileNotFoundError:
        raise ShaderError(f"shader source {name!r} not found in lobeview/shaders") from None


def resolve_includes(name: str, _stack: tuple[str, ...] = ()) -> str:
    if name in _stack:
        raise ShaderError(f"#include cycle: {' -> '.join(_stack + (name,))}")
    source = read_source(name)

    def replace(match: re.Match) -> str:
        included = match.group(1)
        body = resolve_includes(included, _stack + (name,))
        return f"// begin {included}\n{body}\n// end {included}"

    return _INCLUDE.sub(replace, source)


def _literal(value) -> str:
    if value is True:
        return "1"
    if isinstance(value, float):
        return repr(value) if any(c in repr(value) for c in ".e") else f"{value!r}.0"
    return str(value)


def define_block(defines: dict) -> str:
    shared = set(defines) & set(SHADER_CONSTANTS)
    if shared:
        raise ShaderError(f"shader define(s) {sorted(shared)} are shared constants (viewer/interface.py)")
    unknown = set(defines) - KNOWN_DEFINES
    if unknown:
        raise ShaderError(f"unknown shader define(s) {sorted(unknown)}; known: {sorted(KNOWN_DEFINES)}")
    lines = [f"#define {key} {_literal(value)}" for key, value in sorted(SHADER_CONSTANTS.items())]
    for key in sorted(defines):
        value = defines[key]
        if value is False or value is None:
            continue
        lines.append(f"#define {key} {_literal(value)}")
    return "\n".join(lines)


def assemble(name: str, defines: dict) -> str:
    body = resolve_includes(name)
    if not body.lstrip().startswith("#version"):
        raise ShaderError(f"{name}: must start with a #version line")
    version, rest = body.lstrip().split("\n", 1)
    return f"{version}\n{define_block(defines)}\n#line 2\n{rest}"


class ProgramCache:
    """Programs keyed by (vertex, fragment/compute, sorted defines)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._programs: dict[tuple, moderngl.Program | moderngl.ComputeShader] = {}

    def program(self, vertex: str, fragment: str, defines: dict | None = None) -> moderngl.Program:
        defines = dict(defines or {})
        key = (vertex, fragment, tuple(sorted(defines.items())))
        if key not in self._programs:
            sources = (assemble(vertex, defines), assemble(fragment, defines))
            try:
                program = self.ctx.program(vertex_shader=sources[0], fragment_shader=sources[1])
            except moderngl.Error as exc:
                raise ShaderError(f"compiling {vertex} + {fragment} with {defines}: {exc}") from None
            program.extra = {"declared_uniforms": declared_uniforms(*sources), "sources": f"{vertex} + {fragment}"}
            self._programs[key] = program
        return self._programs[key]

    def compute(self, name: str, defines: dict | None = None) -> moderngl.ComputeShader:
        defines = dict(defines or {})
        key = (name, None, tuple(sorted(defines.items())))
        if key not in self._programs:
            source = assemble(name, defines)
            try:
                shader = self.ctx.compute_shader(source)
            except moderngl.Error as exc:
                raise ShaderError(f"compiling {name} with {defines}: {exc}") from None
            shader.extra = {"declared_uniforms": declared_uniforms(source), "sources": name}
            self._programs[key] = shader
        return self._programs[key]
