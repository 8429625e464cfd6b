"""Scripted viewer sessions (``lobeview view --script FILE``) for tests and demos.

A script is a JSON list of steps ``{"frame": N, "action": A, ...}``, each run at the start of
frame N (in order; steps of earlier frames first):

    press / release   key: "W", "S", ... (a real key event through the window's handler)
    move              direction: [x, y, z] (right, up, forward), seconds (default 0.2)
    look              dx, dy: mouse pixels
    select            object: name
    set               path: into the selected material's description, value
    method            value: a method name (core/methods.py grammar)
    screenshot        name: file stem in --screenshot-dir
    save_materials    path
    load_materials    path (as the panel's load button)
    undo              the last material edit (as Ctrl+Z)
    click             x, y: window pixels, a left click through the window's mouse handler
    fit               data, model (thesis|microfacet|rational), lock: [names], extra: [fit options],
                      wait (default true): the panel's fit for the selected object
    stats             print "stats frame=N gl_objects=K rss_mib=M cached=C" (soak tests)
    refine            value: true/false, as the panel's "refine when still" checkbox
    path              value: seconds; the recorded camera path (--path) jumps there and plays on;
                      prints "path frame=N t=T position=x,y,z target=x,y,z"
    refinement        print "refinement frame=N scene_passes=P spp=S refined_share=F noise=X
                      realtime=Y shown=Z finished=..." (F: the refined image's mean weight in
                      what is shown; X, Y, Z: estimated display RMS errors of the refined mean,
                      the real-time frame and the shown blend, x 255, -1 before the first
                      estimate; viewer/refinement.py)
    quit
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lobeview.core.methods import Method, with_default_fit
from lobeview.core.viewer_script import ACTIONS, ScriptError, load_script  # noqa: F401 (the script format)
from lobeview.materials.fitted_pattern import fitted_sample_counts

# Actions after which the image is unchanged (no reset of the refinement).
_KEEP_IMAGE = ("screenshot", "save_materials", "stats", "refine", "refinement")


def live_gl_objects() -> int:
    """moderngl objects alive (not released) in this process: a leak shows as growth."""
    import gc

    import moderngl

    kinds = (
        moderngl.Texture,
        moderngl.TextureCube,
        moderngl.Buffer,
        moderngl.Framebuffer,
        moderngl.Program,
        moderngl.VertexArray,
        moderngl.Renderbuffer,
        moderngl.Sampler,
        moderngl.TextureArray,
    )
    gc.collect()
    return sum(1 for obj in gc.get_objects() if isinstance(obj, kinds) and type(obj.mglo).__name__ != "InvalidObject")


def resident_mib() -> float:
    """Resident set size of this process (Linux /proc; 0 where unavailable)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def run_due_steps(window, steps: list[dict]) -> None:
    """Run (and remove) the steps due at ``window.frame``. ``window`` is app/window.py's
    LobeviewWindow: the actions go through the same methods as keys, mouse and panel."""
    while steps and steps[0].get("frame", 0) <= window.frame:
        step = steps.pop(0)
        action = step["action"]
        if action in ("press", "release"):
            keys = window.wnd.keys
            state = keys.ACTION_PRESS if action == "press" else keys.ACTION_RELEASE
            window.on_key_event(getattr(keys, step["key"]), state, window.wnd.modifiers)
        elif action == "move":
            window.walk.move(np.asarray(step["direction"], float), float(step.get("seconds", 0.2)))
        elif action == "look":
            window.walk.look(float(step["dx"]), float(step["dy"]))
        elif action == "select":
            names = [o.name for o in window.scene.objects]
            if step["object"] not in names:
                raise ScriptError(f"select: no object {step['object']!r}; the scene has {names}")
            window.select(names.index(step["object"]))
        elif action == "set":
            if window.selected is None:
                raise ScriptError(f"set {step['path']}: no object is selected (a select step first)")
            desc = window.editor.desc(window.selected)
            target = desc
            try:
                for part in step["path"][:-1]:
                    target = target[part]
                target[step["path"][-1]] = step["value"]
            except (KeyError, IndexError, TypeError):
                name = window.scene.objects[window.selected].name
                raise ScriptError(f"set: the material of {name!r} has no {step['path']}") from None
            window.message = window.editor.apply(window.selected, desc) or ""
        elif action == "method":
            method = Method.parse(step["value"])
            # A bare lobe-N follows the panel's two checkboxes; a suffix is taken as written.
            if method.kind == "lobe" and not method.normalize and method.weighting == "eq4.25":
                method = method.with_normalize(window.lobe_normalize)
                if method.pattern == "auto":
                    method = with_default_fit(method, window.lobe_fit, fitted_sample_counts())
            window.set_method(method)
        elif action == "screenshot":
            window.save_screenshot(step["name"])
        elif action == "save_materials":
            window.editor.save(Path(step["path"]))
        elif action == "load_materials":
            window.editor.load(Path(step["path"]))
        elif action == "undo":
            window.editor.undo_last()
        elif action == "click":
            window.on_mouse_press_event(float(step["x"]), float(step["y"]), 1)
            window.on_mouse_release_event(float(step["x"]), float(step["y"]), 1)
        elif action == "fit":
            try:
                job = window.start_fit(
                    str(step.get("data", "")),
                    str(step.get("model", "thesis")),
                    list(step.get("lock", [])),
                    [str(a) for a in step.get("extra", [])],
                )
            except ValueError as exc:
                raise ScriptError(f"fit: {exc}") from None
            if step.get("wait", True):
                job.wait()
                window.poll_fit()
        elif action == "stats":
            # GL objects held by the bounded caches on purpose (material tables, scene
            # textures): a leak is growth of the rest.
            cached = len(window.renderer.shading.material_textures) + len(window.renderer.shading.textures)
            live, rss = live_gl_objects(), resident_mib()
            print(f"stats frame={window.frame} gl_objects={live} rss_mib={rss:.0f} cached={cached}", flush=True)
        elif action == "refine":
            window.progressive = bool(step.get("value", True))
        elif action == "refinement":
            refinement, estimate = window.refinement, window.refinement.estimate
            noise, realtime = (estimate.noise * 255, estimate.realtime * 255) if estimate else (-1.0, -1.0)
            print(
                f"refinement frame={window.frame} scene_passes={window.scene_passes} spp={refinement.samples}"
                f" refined_share={estimate.refined_share if estimate else 0.0:.3f} noise={noise:.3f}"
                f" realtime={realtime:.3f} shown={estimate.shown * 255 if estimate else -1.0:.3f}"
                f" finished={refinement.finished or '-'}",
                flush=True,
            )
        elif action == "path":
            try:
                window.set_path_time(float(step.get("value", 0.0)))
            except ValueError as exc:
                raise ScriptError(f"path: {exc}") from None
            camera = window.camera_path.camera_at(window.path_time)
            where = ",".join(f"{x:.4f}" for x in camera.position)
            target = ",".join(f"{x:.4f}" for x in camera.target)
            print(f"path frame={window.frame} t={window.path_time:.4f} position={where} target={target}", flush=True)
        elif action == "quit":
            window.quit_requested = True
        if action not in _KEEP_IMAGE:
            window.dirty = True
