"""The Python <-> GLSL contract (viewer/interface.py): shared constants reach every program and
are defined nowhere else, a misspelt uniform or a layout mismatch fails loudly, every sampler of
the shading programs has its own texture unit, the packed lobe follows LOBE_LAYOUT, and --cache
is honoured by every cached artefact."""

from __future__ import annotations

import re
import warnings
from importlib import resources

import moderngl
import numpy as np
import pytest

from lobeview.core.methods import MAX_LOBES, PREFILTER_MODES, Method
from lobeview.viewer.interface import (
    LOBE_LAYOUT,
    LOBE_ROWS,
    LOBE_TYPES,
    SHADER_CONSTANTS,
    TEXTURE_UNITS,
    UniformError,
    declared_uniforms,
    method_defines,
    set_uniform,
    write_uniform,
)
from lobeview.viewer.shaders import ProgramCache, ShaderError, assemble

SHADER_FILES = sorted(p.name for p in resources.files("lobeview.shaders").iterdir() if p.name.endswith(
    (".glsl", ".vert", ".frag", ".comp")))  # fmt: skip


@pytest.fixture(scope="module")
def programs():
    from lobeview.viewer.gl_probes import headless_gl

    with headless_gl() as ctx:
        yield ProgramCache(ctx)


def _variants():
    methods = [Method.parse(m) for m in ("lobe-7", "lobe-7+norm", "fis-8", "mc-8", "reference")]
    methods += [Method("prefiltered", 1, mode=mode) for mode in PREFILTER_MODES[:2]]
    for method in methods:
        yield "scene.vert", "scene.frag", {**method_defines(method), "SPECULAR": True}
        yield "mesh.vert", "preview.frag", {**method_defines(method), "HAS_DIFFUSE": True}
    yield "scene.vert", "scene.frag", {**method_defines(Method.parse("lobe-3")), "SPECULAR": True, "MIRROR": True}
    yield "scene.vert", "scene.frag", {**method_defines(Method.parse("mc-4")), "SPECULAR": True, "MIRROR": True,
                                       "PLANE_AVERAGE": True}  # fmt: skip
    yield (
        "scene.vert",
        "scene.frag",
        {**method_defines(Method.parse("prefiltered")), "SPECULAR": True, "MIRROR": True},
    )  # fmt: skip  (prefiltered maps and the mirror buffers: many samplers)
    yield "scene.vert", "scene.frag", {**method_defines(Method.parse("lobe-3")), "SPECULAR": True, "PARALLAX": True}
    yield "scene.vert", "scene.frag", {"METHOD_LOBE": True}


def test_shared_constants_are_defined_only_by_the_interface():
    """No shader source defines a shared constant itself (it would shadow or duplicate the
    Python value); every assembled program starts with all of them."""
    names = "|".join(SHADER_CONSTANTS)
    own_definition = re.compile(rf"^\s*(?:#define\s+({names})\b|const\s+\w+\s+({names})\s*=)", re.MULTILINE)
    for name in SHADER_FILES:
        source = resources.files("lobeview.shaders").joinpath(name).read_text()
        assert not own_definition.search(source), f"{name} defines {own_definition.search(source).group(0)!r}"
    source = assemble("scene.frag", {"METHOD_LOBE": True})
    for name in SHADER_CONSTANTS:
        assert re.search(rf"^#define {name} ", source, re.MULTILINE), name
    assert "#define XI_BORDER 0.01" in source and f"#define LOBE_ROWS {len(LOBE_LAYOUT)}" in source


def test_a_caller_cannot_override_a_shared_constant_or_use_an_unknown_define():
    with pytest.raises(ShaderError, match="shared constants"):
        assemble("scene.frag", {"MAX_LOBES": 4})
    with pytest.raises(ShaderError, match="unknown shader define"):
        assemble("scene.frag", {"METHOD_LOBES": True})


COMMON_SAMPLER_LIMIT = 32
# GL_SAMPLER_2D, _3D, _CUBE, _2D_ARRAY, _CUBE_MAP_ARRAY, _2D_ARRAY_SHADOW (moderngl Uniform.gl_type)
SAMPLER_TYPES = {0x8B5E, 0x8B5F, 0x8B60, 0x8DC1, 0x900C, 0x8DC4}


def test_declared_uniform_parser_sees_what_the_compiler_sees(programs):
    """Every active uniform of every shading variant is among the names the parser found in its
    sources (the check of set_uniform relies on that), and sampler uniforms have a unit."""
    samplers = set()
    most_samplers = 0
    for vertex, fragment, defines in _variants():
        program = programs.program(vertex, fragment, defines)
        declared = program.extra["declared_uniforms"]
        active = {name for name in program if hasattr(program[name], "value") and hasattr(program[name], "location")}
        assert active and active <= declared, (fragment, defines, active - declared)
        # Active samplers of the fragment stage, array elements counted: a GPU refuses to link
        # past GL_MAX_TEXTURE_IMAGE_UNITS (32 on current NVIDIA, AMD and Intel drivers and llvmpipe).
        in_use = sum(
            program[name].array_length
            for name in active
            if isinstance(program[name], moderngl.Uniform) and program[name].gl_type in SAMPLER_TYPES
        )
        most_samplers = max(most_samplers, in_use)
        source = assemble(fragment, defines)
        samplers |= set(re.findall(r"uniform\s+sampler\w+\s+(\w+)", source))
    assert samplers and samplers <= set(TEXTURE_UNITS), samplers - set(TEXTURE_UNITS)
    assert most_samplers <= COMMON_SAMPLER_LIMIT, most_samplers
    units = [u for v in TEXTURE_UNITS.values() for u in (v if isinstance(v, tuple) else (v,))]
    assert len(units) == len(set(units)), "two samplers share a texture unit"
    assert declared_uniforms("uniform vec4 u_a[3]; // uniform float u_comment;\nlayout(binding = 0) uniform "
                             "sampler2D u_b;") == {"u_a", "u_b"}  # fmt: skip


def test_a_misspelt_uniform_fails_loudly(programs):
    program = programs.program("scene.vert", "scene.frag", {**method_defines(Method.parse("lobe-7")), "SPECULAR": True})
    set_uniform(program, "u_lobe_count", 1)  # declared and active
    set_uniform(program, "u_proxy_kind", 1)  # declared (PARALLAX only) but not in this variant: skipped
    with pytest.raises(UniformError, match="u_lobe_cout"):
        set_uniform(program, "u_lobe_cout", 1)
    with pytest.raises(UniformError, match="u_lobez"):
        write_uniform(program, "u_lobez", np.zeros(4, np.float32))


def test_a_layout_mismatch_between_packer_and_shader_fails_loudly(programs):
    from lobeview.materials.spec import build_bsdf
    from lobeview.viewer.material_gpu import pack_material

    program = programs.program("scene.vert", "scene.frag", {**method_defines(Method.parse("lobe-7")), "SPECULAR": True})
    packed = pack_material(build_bsdf({"model": "gltf", "base_color": [0.5, 0.25, 0.125], "metallic": 0.75,
                                       "roughness": 0.3}))  # fmt: skip
    write_uniform(program, "u_lobes", packed.lobes)  # the real packing fits
    assert packed.lobes.shape == (MAX_LOBES * LOBE_ROWS, 4)
    one_row_more = np.zeros((MAX_LOBES * (LOBE_ROWS + 1), 4), np.float32)
    with pytest.raises(UniformError, match="layout disagree"):
        write_uniform(program, "u_lobes", one_row_more)
    # The packed glTF lobe follows LOBE_LAYOUT field by field.
    row = {field: value for fields, values in zip(LOBE_LAYOUT, packed.lobes[:LOBE_ROWS], strict=True)
           for field, value in zip(fields, values, strict=True)}  # fmt: skip
    assert row["type"] == LOBE_TYPES["gltf specular"] and row["metallic"] == pytest.approx(0.75)
    assert (row["r0.r"], row["r0.g"], row["r0.b"]) == pytest.approx((0.5, 0.25, 0.125))


def test_cache_option_is_honoured_by_every_cached_artefact(tmp_path, monkeypatch, capsys):
    """shot --cache DIR with the prefiltered method writes the cube maps, the prefiltered maps and
    the DFG table under DIR and nothing under the default cache folder."""
    from lobeview.app.cli import main
    from lobeview.materials.spec import validate
    from lobeview.scenes.gltf_writer import write_glb
    from lobeview.scenes.meshes import box_mesh, uv_sphere
    from lobeview.scenes.scene import Scene, SceneCamera, SceneMaterial, SceneObject

    default, chosen = tmp_path / "default", tmp_path / "chosen"
    monkeypatch.setenv("LOBEVIEW_CACHE", str(default))
    sphere = uv_sphere(0.3, 8, 16)
    sphere.positions = (sphere.positions + [0.0, 0.5, 0.0]).astype(np.float32)
    scene = Scene(
        objects=[SceneObject("floor", box_mesh([0, -0.05, 0], [4, 0.1, 4]), 0), SceneObject("ball", sphere, 1)],
        materials=[
            SceneMaterial("grey", validate({"model": "thesis", "kd": 0.5, "lobes": []})),
            SceneMaterial(
                "gold", validate({"model": "gltf", "base_color": [1, 0.8, 0.3], "metallic": 1, "roughness": 0.3})
            ),
        ],  # fmt: skip
        cameras=[SceneCamera("front", np.array([0.0, 1.0, 3.0]), np.array([0.0, 0.4, 0.0]), np.array([0, 1.0, 0]), 40)],
    )
    write_glb(scene, tmp_path / "scene.glb")
    argv = ["shot", str(tmp_path / "scene.glb"), "--size=32x24", "--face-size=16", "--method=prefiltered",
            f"--cache={chosen}", f"--out={tmp_path / 'out.npy'}"]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no lightmaps: the constant-irradiance fallback is warned
        assert main(argv) == 0, capsys.readouterr().err
    written = sorted(p.name for p in chosen.rglob("*") if p.is_file())
    assert any(n.startswith("cubes-") for n in written), written
    assert any(n.startswith("prefiltered-splitsum") for n in written), written
    assert any(n.startswith("dfg-") for n in written), written
    assert not default.exists() or not any(default.rglob("*")), sorted(default.rglob("*"))
    assert np.isfinite(np.load(tmp_path / "out.npy")).all()
