"""Scene set-up shared by the command line and the benchmarks (below both): a scene argument
(a glTF path, ``builtin:demo``, ``builtin:apartment[-N]``) to its loaded scene and default sky,
and a ``--view`` to a camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lobeview.core.errors import OptionError

SCENE_ENV = "builtin:overcast"
NO_CAMERA_FOV = 50.0  # scenes without a camera: the default view's vertical field of view


def scene_view(scene, view: str | None):
    """(position, target, up, fov) of ``--view`` (name or index; default the first camera), or a
    view of the whole scene for scenes without cameras."""
    if not scene.cameras:
        lo, hi = scene.bounds
        centre = (lo + hi) / 2
        eye = centre + np.array([0.0, 0.25, 1.2]) * float(np.max(hi - lo))
        return (tuple(eye), tuple(centre), (0.0, 1.0, 0.0), NO_CAMERA_FOV)
    if view is None:
        cam = scene.cameras[0]
    elif view.isdigit() and int(view) < len(scene.cameras):
        cam = scene.cameras[int(view)]
    else:
        matches = [c for c in scene.cameras if c.name == view]
        if not matches:
            raise OptionError(f"--view: no camera {view!r}; the scene has {[c.name for c in scene.cameras]}")
        cam = matches[0]
    return (tuple(cam.position), tuple(cam.target), tuple(cam.up), cam.fov_y)


BUILTIN_SCENES = "builtin:demo, builtin:apartment (12 rooms) or builtin:apartment-N (N = 1..40 rooms)"


def builtin_apartment_rooms(scene_arg: str) -> int:
    """The room count of ``builtin:apartment`` / ``builtin:apartment-N``; anything else after
    ``builtin:`` is an error naming the built-in scenes."""
    from lobeview.scenes.apartment import DEFAULT_ROOMS, MAX_ROOMS

    name = scene_arg.removeprefix("builtin:")
    if name == "apartment":
        return DEFAULT_ROOMS
    count = name.removeprefix("apartment-")
    if name.startswith("apartment-") and count.isdigit() and 1 <= int(count) <= MAX_ROOMS:
        return int(count)
    raise OptionError(f"unknown built-in scene {scene_arg!r}: the built-in scenes are {BUILTIN_SCENES}")


def load_scene_and_environment(scene_arg: str | None, env_arg: str | None, cache_arg: str | None, limits=None):
    """(scene path, Scene, EnvironmentMap, cache folder) for ``shot`` and ``view``: the demo
    (built and cached on first use) when no scene is given, with the matching default sky.
    ``limits``: the trust boundary of the scene file (:func:`trust_limits`)."""
    from lobeview.core.paths import cache_dir
    from lobeview.core.trust import DEFAULT_LIMITS
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.gltf_loader import load_gltf

    cache = cache_dir(cache_arg)
    if is_builtin(scene_arg):
        path = build_builtin_scene(scene_arg, cache)
    else:
        path = Path(scene_arg)
    env_name = env_arg or default_environment(scene_arg)
    return path, load_gltf(path, limits or DEFAULT_LIMITS), load_environment(env_name), cache


def is_builtin(scene_arg: str | None) -> bool:
    """Whether ``scene_arg`` names a built-in scene (None: the demo)."""
    return scene_arg is None or scene_arg.startswith("builtin:")


def default_environment(scene_arg: str | None) -> str:
    """The environment a scene is shown under when --env is not given."""
    from lobeview.scenes.apartment import APARTMENT_ENVIRONMENT
    from lobeview.scenes.demo import DEMO_ENVIRONMENT

    if scene_arg is None or scene_arg == "builtin:demo":
        return DEMO_ENVIRONMENT
    return APARTMENT_ENVIRONMENT if scene_arg.startswith("builtin:") else SCENE_ENV


def build_builtin_scene(scene_arg: str | None, cache: Path) -> Path:
    """The built-in scene's cached .glb, built and baked first when needed (minutes)."""
    from lobeview.scenes.apartment import build_apartment_scene
    from lobeview.scenes.demo import build_demo_scene

    if scene_arg is None or scene_arg == "builtin:demo":
        return build_demo_scene(directory=cache / "demo")
    return build_apartment_scene(builtin_apartment_rooms(scene_arg), directory=cache / "apartment")


def unbaked_builtin_scene(scene_arg: str | None, cache: Path):
    """The built-in scene without its lightmaps when its bake is not cached yet (the window shows
    it while the bake runs in the background: app/background_bake.py), else None."""
    from lobeview.scenes.apartment import apartment_geometry, apartment_is_built, apartment_scene_file
    from lobeview.scenes.demo import demo_geometry, demo_scene_file

    if scene_arg is None or scene_arg == "builtin:demo":
        return None if demo_scene_file(cache / "demo").exists() else demo_geometry()
    rooms = builtin_apartment_rooms(scene_arg)
    return None if apartment_is_built(apartment_scene_file(rooms, cache / "apartment")) else apartment_geometry(rooms)
