"""``lobeview view [SCENE]``: the interactive walkthrough window.

moderngl-window (pyglet backend) + an ImGui panel (imgui-bundle). While the camera moves, every
frame is rendered with the chosen real-time method (lobe-N by default); as soon as the camera,
the materials and the method stay still, each frame adds a batch of unbiased quasi-random MIS
samples to a float accumulation buffer and the display shows the running mean (thesis 4.4.2),
converging to what ``lobeview shot --method reference`` renders. The batch size adapts to keep
frames near a target time.

Controls: W/A/S/D move, Q/E down/up, drag with the right mouse button to look around (left
button in orbit mode), wheel changes speed (Shift: x4), O toggles orbit mode, left click in the
view selects an object, F12 saves an EXR + PNG screenshot and prints the ``lobeview shot`` command
that renders it again, Esc quits.

This module holds the options and the start-up (everything a file can get wrong is checked
before the scene loads); the window is app/window.py, the panel app/panel.py, material editing
app/editor.py, the camera app/walk.py and scripted sessions app/script.py.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from lobeview.app.frame_pacing import DEFAULT_TARGET_FPS, target_frame_seconds
from lobeview.app.options import (
    add_method_arguments,
    add_scene_arguments,
    apply_material_edits,
    apply_reflection_proxy,
    check_scene_options,
    read_material_edits,
    renderer_cache_folder,
    resolve_method_args,
)
from lobeview.core.errors import MAX_RENDER_EDGE, OptionError, parse_size
from lobeview.scenes.setup import default_environment, is_builtin, load_scene_and_environment, unbaked_builtin_scene

MAX_VIEW_SUPERSAMPLE = 4


def add_arguments(p) -> None:
    p.add_argument(
        "scene", nargs="?", help="glTF scene with lightmaps, builtin:demo (default) or builtin:apartment[-ROOMS]"
    )
    p.add_argument("--env", help="environment outside the scene (default builtin:overcast)")
    p.add_argument("--size", default="1280x800", help="window size WxH (default 1280x800)")
    add_method_arguments(p, what="real-time method while moving: ")
    p.add_argument("--view", help="start at this scene camera (name or index)")
    p.add_argument(
        "--supersample",
        type=int,
        default=1,
        choices=range(1, MAX_VIEW_SUPERSAMPLE + 1),
        metavar="K",
        help="render K x K shading points a window pixel and average them: anti-aliased edges, creases and "
        f"glints at K^2 the shading (1-{MAX_VIEW_SUPERSAMPLE}, default 1; for a GPU: on the CPU renderer the "
        "frame rate falls by K^2)",
    )
    p.add_argument("--no-vsync", action="store_true", help="disable vsync")
    p.add_argument(
        "--target-fps",
        type=float,
        default=DEFAULT_TARGET_FPS,
        help="while the view changes, render at the resolution that holds this frame rate, upsampled to the window "
        "(full resolution, then refinement, once it rests); 0: always full resolution "
        f"(default {DEFAULT_TARGET_FPS:g})",
    )
    p.add_argument(
        "--stats",
        metavar="FILE",
        help="frame log: one JSON line per frame (interval, state, render scale and size, pass time, method, "
        "samples, camera position) written to FILE",
    )
    add_scene_arguments(p)
    p.add_argument("--screenshot-dir", default=None,
                   help="where F12 writes screenshots (default: ~/Pictures/lobeview, or the cache folder's "
                        "screenshots/ without a Pictures folder)")  # fmt: skip
    p.add_argument(
        "--path",
        metavar="FILE|builtin",
        help="fly a recorded camera path (JSON, scenes/camera_path.py; 'builtin': the built-in scene's own "
        "path); P pauses and resumes, moving or looking takes over",
    )
    p.add_argument("--script", help="JSON list of scripted actions (testing/demos): see app/script.py")
    p.add_argument("--exit-after", type=int, default=0, help="quit after this many frames (0: never)")
    p.add_argument(
        "--no-background-bake",
        action="store_true",
        help="the first-use bake (a built-in scene, or a glTF without lightmaps) runs before the window shows "
        "the scene (default: the window opens on the scene without lightmaps and swaps them in when the bake, "
        "in a worker process, ends)",
    )
    p.add_argument(
        "--no-first-use-bake",
        action="store_true",
        help="show a glTF file without lightmaps as it is (environment irradiance, no occlusion) instead of "
        "baking it once under --env into the cache (`lobeview bake`'s defaults; cached by content)",
    )


def builtin_camera_path(scene_arg: str | None, scene_path: Path):
    """``--path builtin``: the recorded path of the demo or the apartment (written beside it)."""
    from lobeview.scenes.camera_path import CameraPath

    if scene_arg is None or scene_arg == "builtin:demo":
        from lobeview.scenes.demo import demo_path

        return demo_path()
    if scene_arg.startswith("builtin:"):
        from lobeview.scenes.apartment import apartment_path_file

        return CameraPath.load(apartment_path_file(scene_path))
    raise OptionError(
        "--path builtin: only the built-in scenes (builtin:demo, builtin:apartment[-ROOMS]) have a recorded "
        "path; give a path file (JSON) for this scene"
    )


def first_use_bake_applies(args, script) -> bool:
    """A glTF file (not a built-in scene) in an interactive window: a --script or a --path renders
    the file as it is (their frames are compared or measured), --no-first-use-bake too."""
    return not (is_builtin(args.scene) or args.no_first_use_bake or script or args.path is not None)


def first_use_bake(args, scene_path: Path, scene, cache: Path):
    """(scene path, scene, background bake or None) for a glTF file: the file as loaded when it
    has lightmaps; else its bake under the view's environment from the cache (scenes/gltf_bake.py,
    keyed by content), or baked now with --no-background-bake, or (the default) the file as it
    is while a worker process bakes it (swapped in when done: app/finishing.py)."""
    from lobeview.core import progress
    from lobeview.scenes.gltf_bake import bake_first_use, first_use_bake_file, has_lightmaps
    from lobeview.scenes.gltf_loader import load_gltf

    if has_lightmaps(scene) or not scene.objects:
        return scene_path, scene, None
    env_spec = args.env or default_environment(args.scene)
    try:
        baked = first_use_bake_file(scene_path, env_spec, cache, args.limits)
    except (OSError, ValueError) as exc:  # an unreadable reference: the load already warned, show the file
        print(f"lobeview: no first-use bake of {scene_path.name} ({exc})", file=sys.stderr)
        return scene_path, scene, None
    if not baked.exists():
        if not args.no_background_bake:
            from lobeview.app.background_bake import BackgroundBake

            print(f"lobeview: {scene_path.name} has no lightmaps: baking them in the background into {baked}",
                  file=sys.stderr)  # fmt: skip
            horizon_cache = renderer_cache_folder(cache)
            return scene_path, scene, BackgroundBake.for_gltf(scene_path, env_spec, baked, args.limits, horizon_cache)
        progress.report(f"baking the lightmaps of {scene_path.name} (first use)", None)
        try:
            bake_first_use(scene_path, env_spec, baked, args.limits)
        except Exception as exc:  # noqa: BLE001 - the viewer shows the file as it is, and says why
            print(f"lobeview: the first-use bake of {scene_path.name} failed ({type(exc).__name__}: {exc}); "
                  "showing it without lightmaps", file=sys.stderr)  # fmt: skip
            return scene_path, scene, None
    try:
        baked_scene = load_gltf(baked, args.limits)
    except Exception as exc:  # noqa: BLE001 - a damaged cache file: the file as it is, and why
        print(f"lobeview: the first-use bake {baked} could not be loaded ({type(exc).__name__}: {exc}); showing "
              f"{scene_path.name} without lightmaps (delete that file to bake again)", file=sys.stderr)  # fmt: skip
        return scene_path, scene, None
    print(f"lobeview: {scene_path.name}: lightmaps from the first-use bake {baked}", file=sys.stderr)
    return baked, baked_scene, None


def _no_display_hint() -> str:
    """How to run the viewer under a virtual X server, with the lobeview this process runs as."""
    executable = Path(sys.argv[0]) if sys.argv and sys.argv[0] else None
    if executable is not None and executable.name == "lobeview" and executable.exists():
        command = str(executable)
    else:
        command = f"{sys.executable} -m lobeview"
    return f"xvfb-run -s '-screen 0 1920x1080x24' {command} view"


def run(args) -> int:
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print(
            "lobeview view needs a display (no DISPLAY or WAYLAND_DISPLAY is set). Render "
            "headless with `lobeview shot` instead, or run under a virtual X server: " + _no_display_hint(),
            file=sys.stderr,
        )
        return 2
    width, height = parse_size(args.size)
    if max(width, height) * args.supersample > MAX_RENDER_EDGE:
        raise OptionError(f"--size {args.size} at --supersample {args.supersample} renders over {MAX_RENDER_EDGE} "
                          "pixels a side; use a smaller window or K")  # fmt: skip
    try:
        target_frame_seconds(args.target_fps)
    except ValueError as exc:
        raise OptionError(str(exc)) from None
    if args.stats:
        from lobeview.core.errors import check_output_folder

        check_output_folder(args.stats, "--stats")
    method = resolve_method_args(args)
    check_scene_options(args)
    if method.kind == "reference":
        raise OptionError(
            "--method must be a real-time method (lobe-N, fis-N, mc-N, prefiltered[-MODE]); refinement is automatic"
        )
    # Everything that can be wrong with the files is checked before the scene is loaded.
    edits = read_material_edits(args.materials, args.limits) if args.materials is not None else None
    script = []
    if args.script:
        from lobeview.app.script import load_script

        script = load_script(args.script)

    camera_path = None
    if args.path is not None and args.path != "builtin":
        from lobeview.scenes.camera_path import CameraPath

        camera_path = CameraPath.load(args.path)  # a bad file stops here, before the scene loads
    import moderngl_window as mglw

    from lobeview.app.window import LobeviewWindow, Session

    def load_session() -> Session:
        """Build (first use) and load the scene: inside the window, whose loading overlay shows
        each step (app/window.py show_progress). A built-in scene not baked yet opens without its
        lightmaps while a worker process bakes it (app/background_bake.py), unless
        --no-background-bake, a --script or a --path asks for the finished scene."""
        background = None
        if not args.no_background_bake and is_builtin(args.scene) and not script and args.path is None:
            from lobeview.app.background_bake import BackgroundBake
            from lobeview.core.paths import cache_dir
            from lobeview.scenes.builtin_env import load_environment

            cache = cache_dir(args.cache)
            unbaked = unbaked_builtin_scene(args.scene, cache)
            if unbaked is not None:
                background = BackgroundBake.for_builtin(args.scene, cache, renderer_cache_folder(cache))
                scene, scene_path = unbaked, Path(f"{args.scene or 'builtin:demo'} (lightmaps baking)")
                environment = load_environment(args.env or default_environment(args.scene))
        if background is None:
            scene_path, scene, environment, cache = load_scene_and_environment(
                args.scene, args.env, args.cache, args.limits
            )
            if first_use_bake_applies(args, script):
                scene_path, scene, background = first_use_bake(args, scene_path, scene, cache)
        apply_reflection_proxy(scene, args.reflection_proxy)
        original, loaded = None, None
        if edits is not None:
            original = {m.name: m.desc for m in scene.materials}
            loaded = apply_material_edits(scene, edits)
        path = builtin_camera_path(args.scene, scene_path) if args.path == "builtin" else camera_path
        return Session(scene, scene_path, environment, args, method, cache, script, original, loaded, path, background)

    LobeviewWindow.load_session = staticmethod(load_session)
    LobeviewWindow.loading_title = args.scene or "builtin:demo"
    LobeviewWindow.window_size = (width, height)
    LobeviewWindow.vsync = not args.no_vsync
    mglw.run_window_config(LobeviewWindow, args=["--window", "pyglet"])
    return 0
