"""What ``lobeview shot`` and ``lobeview view`` share: their common options (declared once), the
parsing of sizes, vectors and cameras, loading the scene, environment and material edits, the
SceneRenderer they both build, and :func:`shot_command`, the ``lobeview shot`` line that
reproduces a view (F12 prints it; tests/test_app_commands.py pastes it back)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

import numpy as np

from lobeview.core.errors import OptionError
from lobeview.core.methods import GRAMMAR_HELP, Method, method_cli_flags, resolve_cli_method
from lobeview.core.paths import lobeview_program
from lobeview.scenes.setup import (
    BUILTIN_SCENES,
    builtin_apartment_rooms,
)
from lobeview.viewer.camera import Camera
from lobeview.viewer.mip_chain import DEFAULT_MIP_FILTER, MIP_FILTERS

DEFAULT_FACE_SIZE = 256


# -- option declarations -------------------------------------------------------------------------
def _percent(text: str) -> float:
    """--method-target: a percentage in (0, 100] as a fraction."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (a percentage, e.g. 8)") from None
    if not 0.0 < value <= 100.0:
        raise argparse.ArgumentTypeError(f"{text}: the target must be in (0, 100] percent")
    return value / 100.0


def add_method_arguments(p, default: str = "lobe-11", what: str = "") -> None:
    p.add_argument("--method", default=default, help=f"{what}{GRAMMAR_HELP} (default {default})")
    p.add_argument(
        "--lobe-normalize",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="lobe-N: rescale Eq. 4.25 by each lobe's directional albedo, exact under uniform light"
        " (default on, lobe-N+norm; --no-lobe-normalize: Eq. 4.25 as printed; lobe-N+eq4.24 is never normalised)",
    )
    p.add_argument(
        "--lobe-fit",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="normalised lobe-N: reads fitted to each isotropic GGX/Beckmann lobe, from the cube's blur stack"
        " (default on where N has a fitted table, N = 3, 5, 7, 11, 15, 19: lobe-N+norm+fit; --no-lobe-fit:"
        " the thesis pattern, lobe-N+norm)",
    )


def resolve_method_args(args) -> Method:
    """The method that ``--method``, ``--lobe-normalize`` and ``--lobe-fit`` select together
    (core/methods.py resolve_cli_method, with the fitted tables lobeview ships)."""
    from lobeview.materials.fitted_pattern import fitted_sample_counts

    return resolve_cli_method(args.method, args.lobe_normalize, args.lobe_fit, fitted_sample_counts())


def add_scene_arguments(p) -> None:
    """Options of the scene renderer: cube maps, reflection proxies, mirror passes, cache, edits."""
    a = p.add_argument
    a(
        "--face-size",
        type=int,
        default=DEFAULT_FACE_SIZE,
        help=f"cube-map face resolution of the narrowest lobes (default {DEFAULT_FACE_SIZE}); objects with wider "
        "lobes get smaller faces (see --cube-sizes)",
    )
    a(
        "--cube-sizes",
        choices=CUBE_SIZE_CHOICES,
        default="auto",
        help="per-object cube-map face size: 'lobe' = the smallest power of two on which the object's finest "
        "lobe-N lookups still read MIP level 0 or coarser (the scene analysis prints each size and why); 'full' = "
        "every cube map at --face-size; 'auto' (default) = 'lobe', but 'full' for shot's reference, mc-N and "
        "prefiltered methods, which read finer than lobe-N",
    )
    a(
        "--method-target",
        type=_percent,
        default=None,
        metavar="PERCENT",
        help="per object, the cheapest real-time method whose measured error under bright light is at most "
        "PERCENT relative RMSE (e.g. 8; materials/method_choice.py, its table bench/method_table.py): it replaces "
        "--method on every object with microfacet lobes (the scene analysis prints each pick, its error and "
        "lookups); the panel can still override one. Default: off, every object takes --method",
    )
    a(
        "--shared-probes",
        action="store_true",
        help="nearby small objects with wide lobes share one cube map (scenes/probe_groups.py; fewer cube maps, "
        "measured median 1.5 %%, up to 23 %% relative RMSE on a small gold prop's pixels, bench/probe_sharing.py); "
        "only where faces follow "
        "the lobes (--cube-sizes lobe, or auto for real-time methods); refinement in the viewer gives the "
        "members in view their own cube maps again",
    )
    a(
        "--cube-budget",
        type=float,
        default=None,
        metavar="MB",
        help="GPU memory for cube maps (with MIP chains and prefiltered maps): after each frame the least "
        "recently drawn ones are released until it holds, and restored (from the cache, else rendered) when "
        "an object comes back into view; default: no budget",
    )
    a(
        "--mip-filter",
        choices=MIP_FILTERS,
        default=DEFAULT_MIP_FILTER,
        help="how the MIP chains of cube maps and mirror buffers are made: 'tent' (default) = a [1 3 3 1]/8 "
        "tent per level, read by lobe-N at LOD bias -1; 'box' = glGenerateMipmap's 2x2 box (the thesis' chain), "
        "read by lobe-N at its best bias there, -0.5 (both measured; shot's --lod-bias overrides either)",
    )
    a(
        "--bright-sources",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="take the bright sources out of every radiance cube (suns, windows, softboxes, lamps: regions at least "
        "50x the cube's median and 100x their surroundings, at most 10 degrees wide, a hard cap's radiance 300x the "
        "median) and integrate them as cap "
        "lights per pixel in every method but the reference (default: on; --no-bright-sources reads them from "
        "the cube as before)",
    )
    a(
        "--reflection-proxy",
        choices=("scene", "none", "floor", "room"),
        default="scene",
        help="cube-map lookup correction for every glossy object (thesis 4.4.1): floor = bounding plane at "
        "the scene's lowest point, room = box-projected to the scene bounds, none = distant lookup; "
        "default 'scene': what each node's extras say (none if unset)",
    )
    a(
        "--mirrors",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="planar mirror passes for the reflectors the scene analysis lists (thesis 4.5; default on;"
        " --no-mirrors: cube maps for every object)",
    )
    a(
        "--mirror-scale",
        type=float,
        default=1.0,
        help="mirror-buffer resolution relative to the frame, 0.05..2 (default 1)",
    )
    a(
        "--mirror-sizes",
        choices=("lobe", "full"),
        default="lobe",
        help="'lobe' (default): a reflector shaded by lobe-N gets its mirror buffers at 1/2 or 1/4 of "
        "--mirror-scale where its finest lookups read that much coarser (rough floors; the scene's report "
        "shows each pass's size); 'full': every buffer at --mirror-scale",
    )
    a(
        "--self-occlusion",
        choices=("on", "off"),
        default="on",
        help="'on' (default): specular lookups that an object's own surface hides (its visibility cones, "
        "traced against its triangles at load) see the object instead of its cube map; 'off': the cube map "
        "everywhere",
    )
    a(
        "--cache",
        help="cache folder for the demo scene, cube maps, prefiltered maps and tables"
        " (default ~/.cache/lobeview or $LOBEVIEW_CACHE)",
    )
    a("--materials", help="apply edited materials from this JSON file (the viewer's save/F12 writes them)")
    add_trust_arguments(p)


def add_trust_arguments(p) -> None:
    """The trust boundary's two user controls (docs/guide.md "Untrusted files and limits")."""
    p.add_argument(
        "--allow-outside-references",
        action="store_true",
        help="let the scene file read images, buffers and lightmaps outside its own folder (absolute paths,"
        " '..'); off by default because a downloaded scene could otherwise read any file you can",
    )
    p.add_argument(
        "--max-objects",
        type=int,
        default=5000,
        help="most drawable objects (mesh primitives) a glTF scene may place (default 5000; its nodes: 20x"
        " that); a file with more is refused",
    )
    p.add_argument(
        "--memory-budget",
        default="6G",
        help="most memory one scene load may allocate for geometry and images, e.g. 6G or 512M (default 6G);"
        " a file declaring more is refused before anything is allocated",
    )


def trust_limits(args):
    """:class:`~lobeview.core.trust.Limits` from ``--allow-outside-references`` / ``--memory-budget``."""
    from lobeview.core.trust import Limits, parse_budget

    try:
        budget = parse_budget(args.memory_budget)
    except ValueError as exc:
        raise OptionError(f"--memory-budget: {exc}") from None
    max_objects = getattr(args, "max_objects", 5000)
    if max_objects < 1:
        raise OptionError(f"--max-objects: at least 1, got {max_objects}")
    return Limits(
        allow_outside=args.allow_outside_references,
        memory_budget_bytes=budget,
        max_objects=max_objects,
        max_nodes=max(20 * max_objects, 100_000),
    )


def check_environment_option(env: str | None) -> None:
    """A missing environment file is reported before the scene is loaded and cube maps baked."""
    if env is not None and not env.startswith("builtin:") and not Path(env).is_file():
        raise OptionError(f"--env: no such file {env!r} (use an .exr/.hdr file or builtin:studio|sky|overcast)")


# -- values ---------------------------------------------------------------------------------------
def parse_vec3(text: str, name: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise OptionError(f"{name}: expected X,Y,Z numbers, got {text!r}") from None
    if len(values) != 3 or not all(np.isfinite(values)):
        raise OptionError(f"{name}: expected three finite numbers X,Y,Z, got {text!r}")
    return values


def check_scene_options(args) -> None:
    if not 8 <= args.face_size <= 2048 or args.face_size & (args.face_size - 1):
        raise OptionError(f"--face-size must be a power of two in [8, 2048], got {args.face_size}")
    if not 0.05 <= args.mirror_scale <= 2.0:
        raise OptionError(f"--mirror-scale must be in [0.05, 2], got {args.mirror_scale}")
    budget = getattr(args, "cube_budget", None)
    if budget is not None and not (np.isfinite(budget) and budget > 0):
        raise OptionError(f"--cube-budget must be a positive number of MB, got {budget}")
    if args.materials is not None and not Path(args.materials).is_file():
        raise OptionError(f"--materials: no such file {args.materials!r}")
    scene = getattr(args, "scene", None)
    if scene is not None and scene.startswith("builtin:"):
        if scene != "builtin:demo":
            builtin_apartment_rooms(scene)
    elif scene is not None and not Path(scene).is_file():
        raise OptionError(f"scene: no such file {scene!r} (a .gltf/.glb file, or {BUILTIN_SCENES})")
    check_environment_option(getattr(args, "env", None))
    args.limits = trust_limits(args)


def camera_from_args(args, default) -> Camera:
    position, target, up, fov = default
    if args.camera is not None:
        position = parse_vec3(args.camera, "--camera")
        target = parse_vec3(args.target, "--target")
        up = parse_vec3(args.up, "--up")
    if args.fov is not None:
        fov = args.fov
    if not 1.0 <= fov <= 170.0:
        raise OptionError(f"--fov must be in [1, 170] degrees, got {fov}")
    camera = Camera(position=tuple(position), target=tuple(target), up=tuple(up), fov_y=fov)
    camera.view()  # validates position != target and up not parallel
    return camera


# -- scene set-up ---------------------------------------------------------------------------------
def read_material_edits(path: str | Path, limits=None) -> dict:
    """A materials file (material name -> description), as the viewer's save and F12 write it."""
    from lobeview.core.jsonio import JSONInputError, read_json_file

    try:
        data = read_json_file(path, "--materials")
    except JSONInputError as exc:
        raise OptionError(str(exc)) from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise OptionError(f"--materials {path}: expected an object of material name -> description")
    from lobeview.materials.spec import MaterialError, resolve_material_files

    try:  # a measured table is named relative to the file's folder (and may not leave it)
        return {name: resolve_material_files(desc, Path(path).parent, limits) for name, desc in data.items()}
    except MaterialError as exc:
        raise OptionError(f"--materials {path}: {exc}") from None


def apply_material_edits(scene, edits: dict) -> list[str]:
    """Replace the descriptions of the scene's materials named in ``edits`` (validated); returns
    the names changed. Names the scene lacks are an error, not silently skipped."""
    from lobeview.materials.spec import validate

    names = {m.name for m in scene.materials}
    unknown = sorted(set(edits) - names)
    if unknown:
        raise OptionError(f"--materials: the scene has no material(s) {unknown}; it has {sorted(names)}")
    changed = []
    for material in scene.materials:
        if material.name in edits:
            desc = validate(edits[material.name])
            if desc != material.desc:
                material.desc = desc
                changed.append(material.name)
    return changed


def apply_reflection_proxy(scene, choice: str) -> None:
    """``--reflection-proxy``: override every object's proxy unless the choice is 'scene'."""
    from lobeview.scenes.reflection_proxy import ReflectionProxy

    if choice == "scene":
        return
    proxy = ReflectionProxy.from_description({"type": choice}, scene.bounds)
    for obj in scene.objects:
        obj.reflection_proxy = proxy


CUBE_SIZE_CHOICES = ("auto", "lobe", "full")
FULL_CUBE_METHODS = ("reference", "mc", "prefiltered")  # --cube-sizes auto: full faces for these


def lobe_width_cubes(args, method: Method | None = None) -> bool:
    """``--cube-sizes``: whether cube maps shrink to their lobes' width (``method``: shot's)."""
    choice = getattr(args, "cube_sizes", "auto")
    if choice == "auto":
        return method is None or method.kind not in FULL_CUBE_METHODS
    return choice == "lobe"


def renderer_cache_folder(cache: Path) -> Path:
    """The scene renderer's cache folder (cube maps, cones, horizon maps) under the cache ``cache``:
    where a worker process leaves what the renderer reads (app/background_bake.py)."""
    return Path(cache) / "cubes"


def scene_renderer_from_args(
    ctx, scene, env, size, cache, args, method: Method | None = None, progressive_cubes: bool = False
):
    """The SceneRenderer of ``shot`` and ``view``: cube-map size, cache and mirror-pass options
    (``method``: what shot renders, for --cube-sizes auto; ``progressive_cubes``: the viewer's
    start on preview cube maps, SceneRenderer says more)."""
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    renderer = SceneRenderer(
        ctx,
        scene,
        env,
        size=size,
        cache_dir=renderer_cache_folder(cache),
        settings=RenderSettings(
            cube_face_size=args.face_size,
            mirror_scale=args.mirror_scale,
            lobe_width_cubes=lobe_width_cubes(args, method),
            shared_probes=bool(getattr(args, "shared_probes", False)) and lobe_width_cubes(args, method),
            cube_budget_mb=getattr(args, "cube_budget", None),
            mip_filter=getattr(args, "mip_filter", DEFAULT_MIP_FILTER),
            bright_sources=bool(getattr(args, "bright_sources", True)),
            method_target=getattr(args, "method_target", None),
            mirrors=bool(args.mirrors),
            mirror_lobe_sizes=getattr(args, "mirror_sizes", "lobe") == "lobe",
            self_occlusion=getattr(args, "self_occlusion", "on") == "on",
        ),
        progressive_cubes=progressive_cubes,
    )
    return renderer


# -- the reproducing command line ------------------------------------------------------------------
def default_screenshot_dir() -> Path:
    """Where F12 writes when --screenshot-dir is not given: a lobeview folder in the user's
    Pictures folder when there is one, else in the cache folder (not the working folder, which
    may be a git clone)."""
    from lobeview.core.paths import cache_dir

    pictures = Path.home() / "Pictures"
    return pictures / "lobeview" if pictures.is_dir() else cache_dir() / "screenshots"


def shot_command(
    camera: Camera,
    size: tuple[int, int],
    method: Method,
    out: str | Path,
    scene: str | None = None,
    spp: int | None = None,
    args=None,
    materials: str | Path | None = None,
    tonemap: str = "aces",
    exposure: float = 0.0,
) -> str:
    """The ``lobeview shot`` command that renders this view again: every value as
    ``--flag=value`` (a vector starting with '-' is otherwise taken for an option), paths
    quoted for the shell, and the scene options of ``args`` (view's) where they differ from the
    defaults."""
    parts = [*(shlex.quote(part) for part in lobeview_program()), "shot"]
    if scene is not None:
        parts.append(shlex.quote(str(scene)))
    parts.append(camera.describe())
    parts.append(f"--size={size[0]}x{size[1]}")
    parts.append(method_cli_flags(method))
    if method.kind == "reference" and spp is not None:
        parts.append(f"--spp={int(spp)}")
    if args is not None:
        if getattr(args, "env", None):
            parts.append(f"--env={shlex.quote(str(args.env))}")
        if args.face_size != DEFAULT_FACE_SIZE:
            parts.append(f"--face-size={args.face_size}")
        if getattr(args, "cube_budget", None) is not None:
            parts.append(f"--cube-budget={args.cube_budget:g}")
        if getattr(args, "cube_sizes", "auto") != "auto":
            parts.append(f"--cube-sizes={args.cube_sizes}")
        if getattr(args, "shared_probes", False):
            parts.append("--shared-probes")
        if getattr(args, "method_target", None) is not None:
            parts.append(f"--method-target={100 * args.method_target:g}")
        if getattr(args, "mip_filter", DEFAULT_MIP_FILTER) != DEFAULT_MIP_FILTER:
            parts.append(f"--mip-filter={args.mip_filter}")
        if not getattr(args, "bright_sources", True):
            parts.append("--no-bright-sources")
        if args.reflection_proxy != "scene":
            parts.append(f"--reflection-proxy={args.reflection_proxy}")
        if not args.mirrors:
            parts.append("--no-mirrors")
        if args.mirror_scale != 1.0:
            parts.append(f"--mirror-scale={args.mirror_scale:g}")
        if getattr(args, "mirror_sizes", "lobe") != "lobe":
            parts.append(f"--mirror-sizes={args.mirror_sizes}")
        if getattr(args, "self_occlusion", "on") != "on":
            parts.append(f"--self-occlusion={args.self_occlusion}")
        if getattr(args, "supersample", 1) != 1:
            parts.append(f"--supersample={args.supersample}")
        if getattr(args, "cache", None):
            parts.append(f"--cache={shlex.quote(str(args.cache))}")
    if materials is not None:
        parts.append(f"--materials={shlex.quote(str(materials))}")
    if tonemap != "aces":
        parts.append(f"--tonemap={tonemap}")
    if exposure != 0.0:
        parts.append(f"--exposure={exposure:g}")
    parts.append(f"--out={shlex.quote(str(out))}")
    return " ".join(parts)
