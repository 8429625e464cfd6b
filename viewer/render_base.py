"""What the preview and scene renderers share: method parsing, the Sobol table, float render
targets with a G-buffer, material/cube uniforms and the environment background."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import moderngl
import numpy as np
from scipy.stats import qmc

from lobeview.materials.banks import BANKS_AZIMUTHS, fit_banks
from lobeview.materials.conductor import MicrofacetReflection
from lobeview.materials.lobe_fit import LOBE_SLICES, MAP_LOBES, fit_lobe_maps, is_isotropic
from lobeview.materials.patterns import LOBE_LOD_BIAS
from lobeview.materials.prefilter import SPLIT_SUM_LEVELS

from .cubemap import RadianceCube
from .material_gpu import MAX_LOBES, MAX_PATTERN, PackedMaterial, albedo_texture_data, pack_patterns
from .shaders import ProgramCache

SOBOL_SIDE = 256  # 65536 scrambled 4D Sobol points
SOBOL_SEED = 20100501
REFERENCE_BATCH = 64  # samples per lobe per pass of the reference method
# MIP level bias b in lod = 0.5 log2(Omega_s / Omega_p) + b, chosen by `lobeview bench`'s sweep
# (mean PSNR over 6 material classes x 2 HDR environments at 640x400, b in -1..2; details in
# bench/results): fis-N is best at -0.5 (fis-16) to 0 (fis-64), not Colbert & Krivanek's +1
# (fis-16: 31.3 dB vs 25.6 dB); lobe-N at -1 (lobe-7) to -0.5 (lobe-15), not the thesis' 0
# (lobe-7: 30.8 dB vs 27.3 dB). The best bias grows with N for the ring pattern: its samples sit
# on one ring, so the filter that closes the gaps shrinks more slowly than the lobe area / N of
# Eq. 4.14.
DEFAULT_FIS_LOD_BIAS = -0.5
DEFAULT_LOBE_LOD_BIAS = LOBE_LOD_BIAS  # -0.5 (materials/patterns.py, shared with the numpy reference)

_METHOD = re.compile(r"^(lobe|fis|mc)-(\d+)$|^(reference)$|^prefiltered(?:-(splitsum|lobe|lobe2d|phong|multi|banks))?$")
#: prefiltered sub-modes: auto = split-sum for microfacet/glTF lobes, lobe maps for the rest;
#: banks = Banks maps for anisotropic lobes, lobe maps for isotropic ones
PREFILTER_MODES = ("auto", "splitsum", "lobe", "lobe2d", "phong", "multi", "banks")
# Rows of the lobe table (shaders/integrate.glsl) per component: the fitted lobes of a lobe map,
# or the view azimuths of a Banks map's albedo table.
LOBE_TABLE_ROWS = max(MAP_LOBES, BANKS_AZIMUTHS)
LOBE_TABLE_UNIT = 19
MAX_MATERIAL_TEXTURES = 64  # per-material textures kept (live material edits make new ones)


@dataclass(frozen=True)
class Method:
    kind: str  # 'lobe', 'fis', 'mc', 'reference', 'prefiltered'
    samples: int  # N per lobe (reference: per pass)
    normalize: bool = False  # lobe-N: energy normalisation by the lobe's albedo table
    mode: str = ""  # prefiltered: one of PREFILTER_MODES

    @classmethod
    def parse(cls, text: str) -> Method:
        m = _METHOD.match(text.strip())
        if not m:
            raise ValueError(
                f"unknown method {text!r}; use lobe-N, fis-N, mc-N, reference or "
                "prefiltered[-splitsum|-lobe|-lobe2d|-phong|-multi|-banks]"
            )
        if m.group(3):
            return cls("reference", REFERENCE_BATCH)
        if m.group(1) is None:
            return cls("prefiltered", 1, mode=m.group(4) or "auto")
        n = int(m.group(2))
        limit = MAX_PATTERN if m.group(1) == "lobe" else 4096
        if not 1 <= n <= limit:
            raise ValueError(f"{text}: N must be in [1, {limit}]")
        return cls(m.group(1), n)

    def __str__(self) -> str:
        if self.kind == "reference":
            return "reference"
        if self.kind == "prefiltered":
            return "prefiltered" if self.mode == "auto" else f"prefiltered-{self.mode}"
        return f"{self.kind}-{self.samples}" + (" (normalised)" if self.normalize and self.kind == "lobe" else "")

    def defines(self) -> dict:
        return {
            "MAX_LOBES": MAX_LOBES,
            "MAX_PATTERN": MAX_PATTERN,
            "METHOD_LOBE": self.kind == "lobe",
            "METHOD_FIS": self.kind == "fis",
            "METHOD_MC": self.kind in ("mc", "reference"),
            "ENV_SAMPLING": self.kind == "reference",
            "LOBE_NORMALIZE": self.kind == "lobe" and self.normalize,
            "METHOD_PREFILTERED": self.kind == "prefiltered",
            "LOBE_SLICES": LOBE_SLICES,
            "LOBE_TABLE_ROWS": LOBE_TABLE_ROWS,
        }

    def default_lod_bias(self) -> float:
        return DEFAULT_FIS_LOD_BIAS if self.kind == "fis" else DEFAULT_LOBE_LOD_BIAS

    def passes(self, spp: int) -> int:
        return max(1, int(np.ceil(spp / self.samples))) if self.kind == "reference" else 1


def prefilter_plan(material: PackedMaterial, mode: str) -> list[str]:
    """Per lobe: 'splitsum', 'banks' or the lobe-map fit mode ('lobe', 'lobe2d', 'phong',
    'multi'). Split-sum needs a microfacet BRDF (its DFG table), so the thesis' Kurt lobes use
    lobe maps; a Banks map needs an anisotropic lobe (a fibre direction), so isotropic lobes
    use lobe maps under 'banks'."""
    plan = []
    for comp in material.lobe_components:
        microfacet = isinstance(comp, MicrofacetReflection)  # includes glTF specular
        if mode in ("auto", "splitsum"):
            plan.append("splitsum" if microfacet else "lobe")
        elif mode == "banks":
            anisotropic = getattr(comp, "distribution", None) is not None and not is_isotropic(comp)
            plan.append("banks" if anisotropic else "lobe")
        else:
            plan.append(mode)
    return plan


def lobe_table(plan: list[str], fitted: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lobe-map and Banks parameters the shader reads (shaders/integrate.glsl), as
    (table, counts, fibres). ``fitted``: per lobe, the BanksFit ('banks'), the list of
    LobeMapFit (lobe-map modes) or None ('splitsum'). table: (MAX_LOBES * LOBE_TABLE_ROWS,
    2 LOBE_SLICES, 4); component i owns rows i LOBE_TABLE_ROWS + j: for lobe maps, fitted lobe
    j's axis (local, for wo at azimuth 0) in texels 0..S-1 and its energy in S..2S-1; for a Banks
    map, the albedo at view azimuth j pi / (2 (BANKS_AZIMUTHS - 1)) from the fibre in texels
    S..2S-1. counts: fitted lobes per component; fibres: the Banks fibre axis (0 = tangent,
    1 = bitangent)."""
    table = np.zeros((MAX_LOBES * LOBE_TABLE_ROWS, 2 * LOBE_SLICES, 4), dtype=np.float32)
    counts = np.zeros(MAX_LOBES, dtype=np.int32)
    fibres = np.zeros(MAX_LOBES, dtype=np.int32)
    for i, (kind, fit) in enumerate(zip(plan, fitted, strict=True)):
        base = i * LOBE_TABLE_ROWS
        if kind == "banks":
            table[base : base + BANKS_AZIMUTHS, LOBE_SLICES:, :3] = fit.energy.transpose(1, 0, 2)
            counts[i], fibres[i] = 1, fit.axis
        elif kind != "splitsum":
            for j, lobe in enumerate(fit):
                table[base + j, :LOBE_SLICES, :3] = lobe.local_axes()
                table[base + j, LOBE_SLICES:, :3] = lobe.energy
            counts[i] = len(fit)
    return table, counts, fibres


def fit_plan(plan: list[str], components: list) -> list:
    """Per lobe what its prefiltered map is built from: a BanksFit, a list of LobeMapFit, or
    None for split-sum (lobe_table's ``fitted``)."""
    return [
        fit_banks(comp) if kind == "banks" else None if kind == "splitsum" else fit_lobe_maps(comp, kind)
        for kind, comp in zip(plan, components, strict=True)
    ]


def sobol_points(count: int = SOBOL_SIDE * SOBOL_SIDE, seed: int = SOBOL_SEED) -> np.ndarray:
    """Owen-scrambled 4D Sobol points (scipy's generator), fixed seed: a frame renders the same
    image every time. Dimensions 0-1 drive BSDF sampling, 2-3 environment sampling."""
    return qmc.Sobol(d=4, scramble=True, seed=seed).random(count).astype(np.float32)


@dataclass
class RenderResult:
    radiance: np.ndarray  # (H, W, 3) linear
    position: np.ndarray  # (H, W, 3) world
    normal: np.ndarray  # (H, W, 3) shading normal used
    tangent: np.ndarray  # (H, W, 3)
    mask: np.ndarray  # (H, W) object pixels
    invalid: np.ndarray  # (H, W) pixels whose shading produced NaN/Inf (written as 0)
    timings: dict = field(default_factory=dict)  # seconds; 'gpu shade' from a GL timer query
    samples_per_pixel: int = 0
    object_id: np.ndarray | None = None  # (H, W) scene object index, -1 = background (scenes only)


def set_uniform(program, name: str, value) -> None:
    if name in program:
        program[name].value = value


class RendererBase:
    """Float RGBA targets (radiance, position, normal, tangent) + depth, the Sobol table."""

    def __init__(self, ctx: moderngl.Context, size):
        self.ctx = ctx
        self.programs = ProgramCache(ctx)
        sobol = sobol_points()
        self.sobol = ctx.texture((SOBOL_SIDE, SOBOL_SIDE), 4, sobol.tobytes(), dtype="f4")
        self.sobol.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.sobol_count = len(sobol)
        self._vaos: dict = {}
        self._material_textures: dict = {}  # (kind, ..., lobes_key) -> (texture, derived data)
        self._dummy_textures: dict = {}
        self._timer = None
        self.targets: list = []
        self.resize(size)

    def resize(self, size):
        if self.targets:  # a resize, not the first call: the old framebuffer and depth go too
            self.fbo.release()
            self.depth.release()
        for t in self.targets:
            t.release()
        self.size = (int(size[0]), int(size[1]))
        self.targets = [self.ctx.texture(self.size, 4, dtype="f4") for _ in range(4)]
        self.depth = self.ctx.depth_renderbuffer(self.size)
        self.fbo = self.ctx.framebuffer(color_attachments=self.targets, depth_attachment=self.depth)

    def gpu_timer(self):
        """A GL_TIME_ELAPSED query (``with timer: draw``; ``timer.elapsed`` in ns), or None where
        the driver has none: callers then report wall-clock time only."""
        if self._timer is None:
            try:
                self._timer = self.ctx.query(time=True)
            except moderngl.Error:
                self._timer = False
        return self._timer or None

    def read(self, attachment: int, fbo=None, size=None) -> np.ndarray:
        """Row 0 at the top (OpenGL rows start at the bottom)."""
        fbo = fbo or self.fbo
        width, height = size or self.size
        data = fbo.read(components=4, attachment=attachment, dtype="f4")
        return np.frombuffer(data, dtype=np.float32).reshape(height, width, 4)[::-1].copy()

    def set_material(
        self, program, material: PackedMaterial, method: Method, lod_bias: float | None, seed: int, planar=False
    ) -> None:
        set_uniform(program, "u_lobe_count", material.lobe_count)
        if "u_lobes" in program:
            program["u_lobes"].write(material.lobes.tobytes())
        if method.kind == "lobe" and "u_pattern" in program:
            program["u_pattern"].write(pack_patterns(material, method.samples, planar).tobytes())
        set_uniform(program, "u_kd", tuple(float(x) for x in material.kd))
        set_uniform(program, "u_gltf_diffuse", 1.0 if material.gltf_diffuse else 0.0)
        set_uniform(program, "u_samples", method.samples)
        set_uniform(
            program,
            "u_lod_bias",
            float(method.default_lod_bias() if lod_bias is None else lod_bias),
        )
        set_uniform(program, "u_sobol_count", self.sobol_count)
        set_uniform(program, "u_seed", int(seed))
        if method.kind == "lobe" and method.normalize and "u_albedo" in program:

            def albedo_texture():
                data = albedo_texture_data(material)
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 3, data.tobytes(), dtype="f4")
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                tex.repeat_x = tex.repeat_y = False
                return tex, None

            self._material_texture(("albedo", material.lobes_key), albedo_texture)[0].use(7)
            set_uniform(program, "u_albedo", 7)

    def _material_texture(self, key: tuple, make) -> tuple:
        """(texture, derived data) of a material, made by ``make()`` on first use and cached by
        content; the oldest is released beyond MAX_MATERIAL_TEXTURES."""
        if key not in self._material_textures:
            if len(self._material_textures) >= MAX_MATERIAL_TEXTURES:
                self._material_textures.pop(next(iter(self._material_textures)))[0].release()
            self._material_textures[key] = make()
        return self._material_textures[key]

    def bind_cube(self, program, cube: RadianceCube, method: Method, material: PackedMaterial | None = None) -> None:
        """Texture units: 0 radiance, 2 Sobol, 3-4 importance (reference only), 8-18
        prefiltered maps and 19 the lobe table (prefiltered only, built on first use for this cube
        and material)."""
        if method.kind == "prefiltered":
            self.bind_prefiltered(program, cube, material, method)
        cube.radiance.use(0)
        self.sobol.use(2)
        set_uniform(program, "u_radiance", 0)
        set_uniform(program, "u_sobol", 2)
        set_uniform(program, "u_face_size", float(cube.face_size))
        if method.kind == "reference":
            cube.env_cdf.use(3)
            cube.env_pdf.use(4)
            set_uniform(program, "u_env_cdf", 3)
            set_uniform(program, "u_env_pdf", 4)
            set_uniform(program, "u_env_texels", int(cube.importance.probabilities.size))
            set_uniform(program, "u_env_size", int(cube.importance.size))

    def bind_prefiltered(self, program, cube: RadianceCube, material: PackedMaterial, method: Method) -> None:
        maps = cube.prefiltered_maps(self.programs)
        plan = prefilter_plan(material, method.mode)
        for unit, kind in ((8, "beckmann"), (9, "ggx")):
            if any(p == "splitsum" and material.lobe_distributions[i].kind == kind for i, p in enumerate(plan)):
                maps.split_sum(kind).use(unit)
            else:
                self._dummy_texture("cube").use(unit)
        set_uniform(program, "u_split_sum", [8, 9])
        set_uniform(program, "u_split_sum_max_level", float(SPLIT_SUM_LEVELS - 1))
        maps.dfg().use(10)
        set_uniform(program, "u_dfg", 10)

        def lobe_table_texture():
            fitted = fit_plan(plan, material.lobe_components)
            table, counts, fibres = lobe_table(plan, fitted)
            tex = self.ctx.texture((table.shape[1], table.shape[0]), 4, table.tobytes(), dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return tex, (fitted, counts, fibres)

        table, (fitted, counts, fibres) = self._material_texture(
            ("lobe table", method.mode, material.lobes_key), lobe_table_texture
        )
        table.use(LOBE_TABLE_UNIT)
        set_uniform(program, "u_lobe_table", LOBE_TABLE_UNIT)
        modes = np.zeros(MAX_LOBES, dtype=np.int32)
        depth = np.ones(MAX_LOBES, dtype=np.int32)
        units = list(range(11, 11 + MAX_LOBES))
        for i in range(MAX_LOBES):
            texture = self._dummy_texture("3d")
            if i < len(plan) and plan[i] == "banks":
                texture = maps.banks_map(fitted[i], f"lobe {i}")
                modes[i], depth[i] = 2, len(fitted[i].profiles)
            elif i < len(plan) and plan[i] != "splitsum":
                texture = maps.lobe_map(fitted[i], f"lobe {i}")
                modes[i], depth[i] = 1, len(fitted[i][0].profiles)
            texture.use(units[i])
        set_uniform(program, "u_lobe_maps", units)
        for name, values in (
            ("u_lobe_map_mode", modes),
            ("u_lobe_map_depth", depth),
            ("u_lobe_map_count", counts),
            ("u_banks_fibre", fibres),
        ):
            if name in program:
                program[name].write(np.ascontiguousarray(values).tobytes())

    def method_memory(self, cube: RadianceCube, material: PackedMaterial, method: Method) -> dict[str, int]:
        """Bytes of the GPU resources that shading ``material`` with ``method`` reads from one
        cube (the bench's memory column): the radiance cube with its MIP chain, plus the
        importance tables (reference), the albedo table (normalised lobe-N) or the prefiltered
        maps (prefiltered)."""
        from .prefiltered import DFG_SIZE, banks_map_shape, cube_bytes, lobe_map_shape

        face = cube.face_size
        memory = {"radiance cube": cube_bytes(face, int(np.log2(face)) + 1)}
        if method.kind == "reference":
            memory["importance tables"] = cube.env_cdf.width * cube.env_cdf.height * 4 + cube_bytes(
                cube.importance.size, 1, 4
            )
        if method.kind == "lobe" and method.normalize:
            memory["albedo table"] = int(albedo_texture_data(material).size * 4)
        if method.kind == "prefiltered":
            plan = prefilter_plan(material, method.mode)
            for i, kind in enumerate(plan):
                if kind == "splitsum":
                    distribution = material.lobe_distributions[i].kind
                    memory[f"split-sum {distribution}"] = cube_bytes(face, SPLIT_SUM_LEVELS)
                    memory["DFG table"] = DFG_SIZE * DFG_SIZE * 16
                elif kind == "banks":
                    width, height, depth = banks_map_shape(fit_banks(material.lobe_components[i]))
                    memory[f"Banks map {i}"] = width * height * depth * 16
                else:
                    width, height, depth = lobe_map_shape(fit_lobe_maps(material.lobe_components[i], kind))
                    memory[f"lobe map {i}"] = width * height * depth * 16
        return memory

    def _dummy_texture(self, kind: str):
        """A 1-texel black texture for sampler slots a material does not use."""
        if kind not in self._dummy_textures:
            if kind == "cube":
                tex = self.ctx.texture_cube((1, 1), 4, b"\0" * 16 * 6, dtype="f4")
            else:
                tex = self.ctx.texture3d((1, 1, 1), 4, b"\0" * 16, dtype="f4")
            self._dummy_textures[kind] = tex
        return self._dummy_textures[kind]

    def draw_background(self, cube: RadianceCube, view_proj: np.ndarray) -> None:
        """Environment behind everything (depth test off, so it writes no depth)."""
        program = self.programs.program("background.vert", "background.frag", {})
        key = ("background", id(program))
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(program, [])
        program["u_inverse_view_projection"].value = tuple(np.linalg.inv(view_proj).T.astype("f4").ravel())
        cube.radiance.use(0)
        program["u_radiance"].value = 0
        self.ctx.disable(moderngl.DEPTH_TEST)
        self._vaos[key].render(moderngl.TRIANGLES, vertices=3)

    def release(self):
        for tex, _ in self._material_textures.values():
            tex.release()
        for tex in self._dummy_textures.values():
            tex.release()
        for vao in self._vaos.values():
            vao.release()
        self._timer = None  # moderngl 5 queries have no release(); freed with the context
        for t in self.targets:
            t.release()
        self.depth.release()
        self.fbo.release()
        self.sobol.release()
