"""The viewer's ImGui panel: timings, the rendering options, the object list with the scene
analysis' decisions, and the selected object's material editor. Everything it changes goes
through the window's and the renderer's methods (set_method, select, configure,
set_object_method, the MaterialEditor), never their attributes."""

from __future__ import annotations

import json
from pathlib import Path

from imgui_bundle import imgui, implot

from lobeview.app.editor import lobe_plot_values, material_widgets
from lobeview.app.fit_job import FIT_MODELS, lockable_parameters
from lobeview.app.frame_pacing import scaled_size
from lobeview.app.walk import WalkCamera
from lobeview.core.methods import MAX_PATTERN, method_choice, method_from_choice, realtime_choices, with_default_fit
from lobeview.materials.fitted_pattern import fitted_sample_counts
from lobeview.viewer.camera import Camera
from lobeview.viewer.tonemap import TONEMAPS

SAMPLE_SLIDER_MAX = {"lobe": MAX_PATTERN}  # fis-N / mc-N: PANEL_MAX_SAMPLES
PANEL_MAX_SAMPLES = 256


PANEL_WIDTH = 430  # wide enough for every label beside its widget (LABEL_WIDTH)
STATUS_LINES = 11  # the status region's height: its longest usual content (refining and stopped, a message)
LABEL_WIDTH = 170  # pixels right of each slider, combo and input for its label


def draw_panel(window) -> None:
    """The panel: status lines on top, then tabs (Rendering, Objects, Material), so that each
    section shows without scrolling whatever the scene's size; a click that selects an object in
    the scene brings the Material tab forward."""
    imgui.new_frame()
    window.widget_rects = {}
    imgui.set_next_window_pos((10, 10), imgui.Cond_.first_use_ever.value)
    height = max(min(window.wnd.size[1] - 20, 900), 200)
    imgui.set_next_window_size((PANEL_WIDTH, height), imgui.Cond_.first_use_ever.value)
    imgui.begin("lobeview")
    imgui.push_item_width(-LABEL_WIDTH)
    # The status lines come and go and wrap (refinement, cube maps, messages): in a region of a
    # fixed height, so that the widgets below never move under a pointer about to click them.
    imgui.begin_child("status", imgui.ImVec2(0, STATUS_LINES * imgui.get_text_line_height_with_spacing()))
    _status(window)
    if window.message:
        imgui.text_wrapped(window.message)
    imgui.end_child()
    if imgui.begin_tab_bar("sections"):
        if imgui.begin_tab_item("Rendering")[0]:
            _rendering(window)
            imgui.end_tab_item()
        if imgui.begin_tab_item("Objects")[0]:
            for i, needs in enumerate(window.renderer.analysis.objects):
                if imgui.selectable(f"{needs.name}  [{needs.kind}]##{i}", window.selected == i)[0]:
                    window.select(i)
            imgui.end_tab_item()
        if window.selected is not None:
            flags = imgui.TabItemFlags_.set_selected.value if window.show_material_tab else 0
            window.show_material_tab = False
            if imgui.begin_tab_item("Material", None, flags)[0]:
                _material(window)
                imgui.end_tab_item()
        imgui.end_tab_bar()
    imgui.pop_item_width()
    window.panel_area.record()
    imgui.end()
    imgui.render()
    window.ctx.screen.use()
    window.imgui.render(imgui.get_draw_data())


def _status(window) -> None:
    imgui.text(f"{window.ctx.info['GL_RENDERER']}")
    # fps from the measured interval between frames (ImGui's own estimate assumes 60 Hz at first)
    fps = 1000.0 / window.frame_ms if window.frame_ms > 0 else 0.0
    imgui.text(f"{fps:.1f} fps, frame {window.frame_ms:.1f} ms")
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            "frame: the smoothed interval between the starts of two frames (everything: events, scene, panel)\n"
            "pass: the last scene pass (real-time frame or refinement batch) with glFinish\n"
            "cube map: the last cube-map refresh after a material edit"
        )
    imgui.text(f"pass {window.pass_ms:.1f} ms, last cube map {window.cube_ms:.1f} ms")
    scale, (width, height) = window.render_scale.scale, window.wnd.buffer_size
    target = window.render_scale.target_s
    supersample = getattr(window, "supersample", 1)
    if supersample > 1:
        imgui.text(f"supersampled {supersample}x{supersample}: frames rendered at "
                   f"{width * supersample}x{height * supersample}")  # fmt: skip
    if target is None:
        imgui.text("moving: full resolution (--target-fps 0)")
    else:
        w, h = scaled_size((width, height), scale * supersample)
        imgui.text(f"moving: {w}x{h} ({scale:.2f}x) for {1.0 / target:.0f} fps")
    imgui.text_wrapped(window.renderer.probes.residency.report(window.renderer.objects))
    refinement = window.refinement
    if refinement.samples:
        imgui.text_wrapped(refinement.status())
    else:
        imgui.text(f"moving: {window.method}")


def _sample_slider(label: str, kind: str, samples: int) -> tuple[bool, int]:
    return imgui.slider_int(label, samples, 1, SAMPLE_SLIDER_MAX.get(kind, PANEL_MAX_SAMPLES))


def _report_lines(summary: str, lines: list[str], fold_above: int = 6) -> None:
    """A report, folded under a one-line summary when it is long (the apartment's 19 reflectors)."""
    if len(lines) <= fold_above:
        for line in lines:
            imgui.text_wrapped(line)
        return
    if imgui.tree_node(summary):
        for line in lines:
            imgui.text_wrapped(line)
        imgui.tree_pop()


def _method_combo(window, kinds: list[str]) -> tuple[bool, int]:
    """imgui.combo for the method, with its box and (while open) its items' rectangles recorded
    in ``window.widget_rects`` (the frame log's: tests click them)."""
    current = kinds.index(method_choice(window.method))
    x, y = imgui.get_cursor_screen_pos()
    width, height = imgui.calc_item_width(), imgui.get_frame_height()
    window.widget_rects["method"] = (float(x), float(y), float(width), float(height))
    chosen = current
    if imgui.begin_combo("method", kinds[current]):
        # A popup's first frame lays it out hidden, at a provisional place: not where it shows.
        shown = not imgui.is_window_appearing()
        for k, kind in enumerate(kinds):
            if imgui.selectable(kind, k == current)[0]:
                chosen = k
            (x0, y0), (x1, y1) = imgui.get_item_rect_min(), imgui.get_item_rect_max()
            if shown:
                window.widget_rects[f"method: {kind}"] = (float(x0), float(y0), float(x1 - x0), float(y1 - y0))
        imgui.end_combo()
    return chosen != current, chosen


def _rendering(window) -> None:
    renderer = window.renderer
    kinds = list(realtime_choices())
    c, k = _method_combo(window, kinds)
    c2, n = _sample_slider("samples N", window.method.kind, window.method.samples)
    c3, window.lobe_normalize = imgui.checkbox("lobe-N energy normalisation", window.lobe_normalize)
    # lobe-N+ring: the thesis' ring at every N instead of the double ring from N = 11 (for comparison)
    c_ring, ring = imgui.checkbox("lobe-N: thesis ring at every N", window.method.pattern == "ring")
    # lobe-N+norm+fit: reads fitted to the lobe (materials/fitted_pattern.py), for the N with a
    # table; kept apart from the method (like the normalisation) so an N without a table and back
    # keeps the choice. On by default (--lobe-fit).
    fitted_counts = fitted_sample_counts()
    c_fit, window.lobe_fit = imgui.checkbox("lobe-N: fitted reads", window.lobe_fit and not ring)
    if imgui.is_item_hovered():
        counts = ", ".join(str(x) for x in fitted_counts) or "none"
        imgui.set_tooltip(f"lobe-N+norm+fit (default): reads fitted to each isotropic GGX/Beckmann lobe,\n"
                          f"for N = {counts} with the energy normalisation; other N and lobes keep\n"
                          "the thesis pattern")  # fmt: skip
    if c_ring and ring:
        window.lobe_fit = False
    if c_fit and window.lobe_fit:
        ring = False
    if c or c2 or c3 or c_ring or c_fit:
        chosen = method_from_choice(kinds[k], n, window.lobe_normalize, "ring" if ring else "auto")
        window.set_method(with_default_fit(chosen, window.lobe_fit, fitted_counts))
    _, window.progressive = imgui.checkbox("refine when still", window.progressive)
    c4, mirrors = imgui.checkbox("planar mirror passes", renderer.settings.mirrors)
    c5, scale = imgui.slider_float("mirror resolution", renderer.settings.mirror_scale, 0.1, 1.0)
    # lobe-N reflectors whose lookups read coarse levels get 1/2 or 1/4 of that (--mirror-sizes)
    c5b, lobe_sizes = imgui.checkbox("mirror buffers sized by their lobes", renderer.settings.mirror_lobe_sizes)
    # reflectors in one plane (room floors) share its pass (scenes/planar_mirror.py coplanar_groups)
    c5d, sharing = imgui.checkbox("one mirror pass per plane", renderer.settings.mirror_plane_sharing)
    # an object's own surface hiding its specular lookups (--self-occlusion)
    c5c, self_occlusion = imgui.checkbox("specular self-occlusion", renderer.settings.self_occlusion)
    if c4 or c5 or c5b or c5c or c5d:
        renderer.configure(
            mirrors=mirrors, mirror_scale=scale, mirror_lobe_sizes=lobe_sizes, self_occlusion=self_occlusion,
            mirror_plane_sharing=sharing,
        )  # fmt: skip
        window.dirty = True
    passes = renderer.mirror_passes
    _report_lines(
        f"mirror passes: {passes.drawn_passes} for {len(passes.drawn)} reflectors, {len(passes.skipped)} skipped",
        passes.report,
    )
    c6, culling = imgui.checkbox("frustum culling", renderer.settings.frustum_culling)
    if c6:
        renderer.configure(frustum_culling=culling)
        window.dirty = True  # the image is the same; the counts below are the next frame's
    c7, indirect = imgui.checkbox("GPU-driven drawing (multi-draw)", renderer.settings.indirect_draws)
    if c7:  # the same image (tests/test_indirect_draws.py); the draw calls below change
        renderer.configure(indirect_draws=indirect)
        window.dirty = True
    if window.finishing.bake_status is not None:  # app/background_bake.py
        imgui.text_wrapped(f"{window.finishing.bake_status} (in the background; until then diffuse light is the "
                           "environment's, unoccluded)")  # fmt: skip
    if window.finishing.horizon_status is not None:  # app/finishing.py poll_horizon_maps
        imgui.text_wrapped(f"{window.finishing.horizon_status} (in the background; until then glossy "
                           "self-occlusion from the vertices')")  # fmt: skip
    if renderer.cube_build_status is not None:
        imgui.text_wrapped(renderer.cube_build_status)
    for line in renderer.draw_report:
        imgui.text_wrapped(line)
    if window.camera_path is not None:
        state = f"t = {window.path_time:.1f}" if window.path_time is not None else "paused"
        imgui.text_wrapped(f"camera path: {state} of {window.camera_path.duration:.1f} s (P: pause / resume)")
    scene = window.scene
    if scene.cameras:
        names = [c.name or f"camera {i}" for i, c in enumerate(scene.cameras)]
        preview = "(walking: choose one)" if window.camera_index is None else names[window.camera_index]
        pick = None
        if imgui.begin_combo("scene camera", preview):
            for i, name in enumerate(names):
                if imgui.selectable(f"{name}##{i}", i == window.camera_index)[0]:
                    pick = i
            imgui.end_combo()
        if pick is not None:
            window.camera_index = pick
            cam = scene.cameras[pick]
            camera = Camera.from_scene_camera(cam)
            window.walk = WalkCamera.from_camera(camera)
            window.dirty = True
    c, vsync = imgui.checkbox("vsync", window.vsync)
    if c:
        window.vsync = vsync
        window.wnd.vsync = vsync
    _, window.exposure = imgui.slider_float("exposure", window.exposure, -6.0, 6.0)
    c, t = imgui.combo("tonemap", TONEMAPS.index(window.tonemap), list(TONEMAPS))
    window.tonemap = TONEMAPS[t]


def _material(window) -> None:
    renderer, editor, index = window.renderer, window.editor, window.selected
    desc = editor.desc(index)
    imgui.text(f"{window.scene.objects[index].name}: {desc['model']} model")
    override = renderer.object_method(index)
    choices = ["global", *realtime_choices()]
    current = 0 if override is None else choices.index(method_choice(override))
    c, k = imgui.combo("object method", current, choices)
    shown = override or window.method
    c2, n = _sample_slider("object N", shown.kind, shown.samples)
    if c or c2:
        # The override keeps the panel's normalisation and fitted-reads choices, as the global method does.
        chosen = None
        if choices[k] != "global":
            chosen = method_from_choice(choices[k], n, window.lobe_normalize)
            chosen = with_default_fit(chosen, window.lobe_fit, fitted_sample_counts())
        renderer.set_object_method(index, chosen)
        window.dirty = True
    needs = renderer.analysis.objects[index]
    if needs.needs_cube_map:  # its face size and why (scenes/analysis.py)
        imgui.text_wrapped(f"cube map {needs.cube_face}^2: {needs.cube_face_reason}")
        if needs.shared_probe:  # scenes/probe_groups.py
            imgui.text_wrapped(f"shared probe {needs.shared_probe} (scenes/probe_groups.py)")
    memory = renderer.probes.prefiltered_memory(index)
    if memory:
        imgui.text(f"prefiltered maps: {sum(memory.values()) / 2**20:.1f} MB")
        for name, size in memory.items():
            imgui.bullet_text(f"{name}: {size / 2**20:.2f} MB")
    changed, new = material_widgets(imgui, desc)
    if changed:
        window.message = editor.apply(index, new) or ""
        window.dirty = True
    key = json.dumps(editor.desc(index), sort_keys=True)
    if window.plot_cache[0] != key:  # a BSDF build + 181 evaluations: not every frame
        window.plot_cache = (key, lobe_plot_values(json.loads(key)))
    x, y = window.plot_cache[1]
    if implot.begin_plot("lobe, 45 deg view", (-1, 160)):
        implot.plot_line("(f cos)^1/3", x, y)
        implot.end_plot()
    _fit(window)
    if imgui.button("undo (Ctrl+Z)") and editor.undo_last():
        window.dirty = True
    imgui.same_line()
    sidecar = Path(str(window.session.scene_path) + ".materials.json")
    if imgui.button("save"):
        try:
            editor.save(sidecar)
            window.message = f"saved {sidecar}"
        except OSError as exc:  # read-only folder, full disk: say so, keep running
            window.message = f"cannot save {sidecar}: {exc.strerror or exc}"
    imgui.same_line()
    if imgui.button("load"):
        if sidecar.exists():
            from lobeview.core.errors import OptionError
            from lobeview.materials.spec import MaterialError

            try:
                editor.load(sidecar)
                window.dirty = True
            except (OptionError, MaterialError, OSError) as exc:
                window.message = f"not loaded: {exc}"
        else:
            window.message = f"no {sidecar} to load"


def _fit(window) -> None:
    """Fit a measurement to the selected material in the background (app/fit_job.py): the data
    as ``lobeview fit`` takes it, the model, and which current values to lock."""
    if not imgui.tree_node("fit to a measurement"):
        return
    _, window.fit_data = imgui.input_text("data", window.fit_data)
    imgui.text_disabled(".csv, MERL .binary, virtual:MATERIAL, virtual-merl:MATERIAL")
    _, m = imgui.combo("model", FIT_MODELS.index(window.fit_model), list(FIT_MODELS))
    window.fit_model = FIT_MODELS[m]
    lockable = lockable_parameters(window.editor.desc(window.selected), window.fit_model)
    if lockable:
        imgui.text("lock at the current value:")
    for name, value in lockable.items():
        changed, on = imgui.checkbox(f"{name} = {value:.4g}", name in window.fit_locks)
        if changed:
            (window.fit_locks.add if on else window.fit_locks.discard)(name)
    job = window.fit_job
    if job is not None and job.running:
        imgui.text_wrapped(job.status)
        if imgui.button("cancel fit"):
            job.cancel()
    else:
        if imgui.button("fit"):
            try:
                window.start_fit(window.fit_data.strip(), window.fit_model, sorted(window.fit_locks & set(lockable)))
            except ValueError as exc:
                window.message = str(exc)
        if job is not None:
            imgui.text_wrapped(job.status)
    imgui.tree_pop()
