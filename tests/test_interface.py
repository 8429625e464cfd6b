"""The Python <-> GLSL contract (viewer/interface.py): shared constants reach every program and
are defined nowhere else, a misspelt uniform or a layout mismatch fails loudly, every sampler of
the shading programs has its own texture unit, the packed lobe of every lobe type follows
LOBE_LAYOUT on both sides (one writer), and --cache is honoured by every cached artefact."""

from __future__ import annotations

import functools
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
    lobe_layout_glsl,
    method_defines,
    pack_lobe,
    set_uniform,
    unpack_lobe,
    write_uniform,
)
from lobeview.viewer.shaders import ProgramCache, ShaderError, assemble, define_block

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
    assert "#define XI_BORDER 0.01" in source and f"#define LOBE_ROWS {LOBE_ROWS}" in source


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
    assert declared_uniforms("uniform float u_c = 1.0; uniform vec3 u_d = vec3(0.5);") == {"u_c", "u_d"}


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
    row = unpack_lobe(packed.lobes[:LOBE_ROWS])
    assert row["type"] == LOBE_TYPES["gltf specular"] and row["metallic"] == pytest.approx(0.75)
    assert row["r0"] == pytest.approx((0.5, 0.25, 0.125))


# -- the packed lobe: one writer (interface.LOBE_LAYOUT) for both sides ---------------------------
def _layout_probe_source(lobes: int) -> str:
    """A compute shader that reads ``lobes`` lobes with the generated get_lobe and writes every
    field, in LOBE_LAYOUT order, to a float buffer."""
    writes = []
    for field in LOBE_LAYOUT:
        for name in field.names:
            for c in range(len(field.columns)):
                part = f"l.{name}" if len(field.columns) == 1 else f"l.{name}[{c}]"
                writes.append(f"    values[o++] = float({part});")
    return "\n".join([
        "#version 450", define_block({}), lobe_layout_glsl(),
        "layout(local_size_x = 1) in;", "layout(std430, binding = 0) buffer Out { float values[]; };",
        "void main() {", "    int i = int(gl_GlobalInvocationID.x);", "    Lobe l = get_lobe(i);",
        f"    int o = i * {_fields_per_lobe()};", *writes, "}",
    ])  # fmt: skip


def _fields_per_lobe() -> int:
    return sum(len(f.names) * len(f.columns) for f in LOBE_LAYOUT)


def _flat(values: dict) -> np.ndarray:
    return np.concatenate([np.ravel(np.asarray(values[n], np.float32)) for f in LOBE_LAYOUT for n in f.names])


def _rational_desc():
    import json
    from pathlib import Path

    return json.loads((Path(__file__).parent / "data" / "gold-ggx-rational.json").read_text())


@functools.lru_cache(maxsize=1)
def _measured_source() -> str:
    """``measured:FILE`` of a MERL table of gold-ggx written once per test session."""
    import atexit
    import shutil
    import tempfile
    from pathlib import Path

    from lobeview.materials.measurement import merl_table_from_bsdf, write_merl
    from lobeview.materials.spec import build_bsdf, load_material

    folder = tempfile.mkdtemp(prefix="lobeview-measured-")
    atexit.register(shutil.rmtree, folder, True)  # 35 MB: not left behind in /tmp
    path = Path(folder) / "gold.binary"
    write_merl(merl_table_from_bsdf(build_bsdf(load_material("gold-ggx"))), path)
    return f"measured:{path}"


LOBE_TYPE_MATERIALS = {
    "kurt reflection": lambda: "alanod-2000gs-1lobe",
    "kurt transmission": lambda: "white-foil",
    "microfacet": lambda: "gold-ggx",
    "gltf specular": lambda: {"model": "gltf", "base_color": [0.8, 0.4, 0.2], "metallic": 0.6, "roughness": 0.35,
                              "ior": 1.7, "specular": 0.8, "specular_color": [1.0, 0.7, 0.5], "clearcoat": 0.4},
    "gltf clearcoat": lambda: {"model": "gltf", "base_color": [0.3, 0.3, 0.9], "roughness": 0.5, "clearcoat": 0.7,
                               "clearcoat_roughness": 0.1},
    "gltf transmission": lambda: {"model": "gltf", "base_color": [0.9, 0.9, 0.9], "roughness": 0.2,
                                  "transmission": 0.8, "anisotropy": 0.5},
    "rational": _rational_desc,
    "measured": _measured_source,
}  # fmt: skip


def _expected_fields(comp) -> dict:
    """What the packed lobe must hold for ``comp``, written from the numpy component (not from
    the packer): the fields every lobe type defines."""
    from lobeview.materials.conductor import MicrofacetReflection
    from lobeview.materials.gltf import COAT_F0, GltfClearcoat, GltfSpecular, GltfTransmission
    from lobeview.materials.measured import MeasuredLobe
    from lobeview.materials.rational_brdf import RationalLobe
    from lobeview.materials.thesis import KurtLobe
    from lobeview.viewer.interface import DISTRIBUTIONS, FRESNEL_TYPES

    d = comp.distribution
    out = {"dist": DISTRIBUTIONS[d.kind], "ax": d.alpha_x, "ay": d.alpha_y}
    if isinstance(comp, KurtLobe):
        kind = "kurt transmission" if comp.transmission else "kurt reflection"
        out.update(k=comp.k, alpha=comp.alpha, r0=comp.r0, fresnel=FRESNEL_TYPES["schlick"])
    elif isinstance(comp, GltfTransmission | GltfSpecular):
        kind = "gltf transmission" if isinstance(comp, GltfTransmission) else "gltf specular"
        scale = comp.amount if isinstance(comp, GltfTransmission) else 1.0
        out.update(k=[scale] * 3, specular_weight=comp.specular, r0=comp.base_color, dielectric_f0=comp.f0,
                   metallic=comp.metallic, coat=comp.layers.coat)  # fmt: skip
    elif isinstance(comp, GltfClearcoat):
        kind = "gltf clearcoat"
        out.update(k=comp.scale, r0=[COAT_F0] * 3, fresnel=FRESNEL_TYPES["schlick"])
    elif isinstance(comp, RationalLobe):
        kind = "rational"
        out.update(k=[np.radians(comp.theta_max_deg), 0.0, 0.0])
    elif isinstance(comp, MeasuredLobe):
        kind = "measured"  # the proxy's shape only: the table is in its own buffers
        out.update(k=[0.0, 0.0, 0.0])
    else:
        assert isinstance(comp, MicrofacetReflection)
        kind = "microfacet"
        fr = comp.fresnel
        out.update(k=comp.scale, r0=fr.r0, fresnel=FRESNEL_TYPES[fr.kind], eta=fr.eta, kappa=fr.k)
    return {"type": LOBE_TYPES[kind], **out}


@pytest.mark.parametrize("lobe_type", list(LOBE_TYPES))
def test_every_lobe_type_packs_and_unpacks_field_by_field(programs, lobe_type):
    """Per lobe type: the packed material holds what the numpy component says, field by field
    (unpack_lobe), and the generated GLSL get_lobe reads exactly what unpack_lobe reads."""
    from lobeview.materials.spec import build_bsdf, load_material, validate
    from lobeview.viewer.material_gpu import pack_material

    desc = LOBE_TYPE_MATERIALS[lobe_type]()
    bsdf = build_bsdf(load_material(desc) if isinstance(desc, str) else validate(desc))
    packed = pack_material(bsdf)
    unpacked = [unpack_lobe(packed.lobes[i * LOBE_ROWS : (i + 1) * LOBE_ROWS]) for i in range(packed.lobe_count)]
    assert lobe_type in {next(k for k, v in LOBE_TYPES.items() if v == lobe["type"]) for lobe in unpacked}
    for comp, lobe in zip(packed.lobe_components, unpacked, strict=True):
        for name, value in _expected_fields(comp).items():
            assert np.asarray(lobe[name]) == pytest.approx(np.asarray(value, np.float32)), (lobe_type, name)
    # The GPU reads the same values through the generated get_lobe.
    ctx = programs.ctx
    shader = ctx.compute_shader(_layout_probe_source(packed.lobe_count))
    shader["u_lobes"].write(packed.lobes.tobytes())
    out = ctx.buffer(reserve=packed.lobe_count * _fields_per_lobe() * 4)
    out.bind_to_storage_buffer(0)
    shader.run(packed.lobe_count)
    ctx.finish()
    gpu = np.frombuffer(out.read(), np.float32).reshape(packed.lobe_count, -1)
    out.release()
    for i, lobe in enumerate(unpacked):
        np.testing.assert_array_equal(gpu[i], _flat(lobe), err_msg=f"{lobe_type}: lobe {i}")


def test_the_lobe_layout_has_one_writer():
    """Every shader reads the lobe through the generated get_lobe: no source declares the Lobe
    struct or u_lobes itself, bsdf.glsl includes the generated file, and the packer refuses a
    field the layout lacks, a wrong size, or two names of one slot."""
    for name in SHADER_FILES:
        source = resources.files("lobeview.shaders").joinpath(name).read_text()
        assert not re.search(r"struct\s+Lobe\b|uniform\s+vec4\s+u_lobes\b", source), name
    assert '#include "lobe_layout.glsl"' in resources.files("lobeview.shaders").joinpath("bsdf.glsl").read_text()
    assert "lobe_layout.glsl" not in SHADER_FILES  # generated, never a file that could go stale
    assert {n for f in LOBE_LAYOUT for n in f.names} == set(unpack_lobe(np.zeros((LOBE_ROWS, 4))))
    with pytest.raises(KeyError, match="no field 'kd'"):
        pack_lobe("microfacet", kd=(1, 1, 1))
    with pytest.raises(ValueError, match="takes 3 values"):
        pack_lobe("microfacet", k=(1, 1))
    with pytest.raises(ValueError, match="share one slot"):
        pack_lobe("gltf specular", alpha=2.0, specular_weight=0.5)


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
