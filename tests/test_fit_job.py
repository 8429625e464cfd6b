"""The viewer's fit (app/fit_job.py, the panel's "fit to a measurement", the script's fit step):
a background job that runs ``lobeview fit``'s own code, locks parameters, cancels, and reports
failures without raising; the panel's widgets with a stand-in imgui."""

from __future__ import annotations

import json
import math
import os
import time
import types

import numpy as np
import pytest
from conftest import run_scripted_view

from lobeview.app.editor import material_widgets
from lobeview.app.fit_job import FitJob, lockable_parameters
from lobeview.materials.spec import load_material, validate

# A coarse virtual goniophotometer: each fit takes seconds.
COARSE = ["--theta-i", "0,20,65", "--phi-i", "0,90", "--theta-step", "10", "--phi-step", "30"]
QUICK = ["--grid", "5", "--iterations", "3", *COARSE]


def test_job_fits_in_the_background_and_reports_progress():
    job = FitJob("virtual:gltf-red-plastic", "microfacet", extra=["--isotropic", *QUICK]).start()
    assert job.wait(300) == "done", job.error
    truth = load_material("gltf-red-plastic")
    fitted = validate(job.result)
    assert fitted["model"] == "gltf" and fitted["roughness"] == pytest.approx(truth["roughness"], abs=0.01)
    assert any("iteration" in line for line in job.lines)
    assert job.status.startswith("fitted in") and "error" in job.status


def test_locked_parameters_are_held_at_the_current_values():
    current = load_material("alanod-2000gs-1lobe")
    lockable = lockable_parameters(current, "thesis")
    assert {"kd", "lobe1.mx", "lobe1.my", "lobe1.r0", "lobe1.alpha", "lobe1.ks"} <= set(lockable)
    locked = {"lobe1.mx": 0.2, "lobe1.r0": lockable["lobe1.r0"]}  # 0.2: far from the data's 0.11
    job = FitJob("virtual:alanod-2000gs-1lobe", "thesis", locked, extra=QUICK).start()
    assert job.wait(300) == "done", job.error
    lobe = job.result["lobes"][0]
    assert lobe["mx"] == pytest.approx(0.2) and lobe["r0"] == pytest.approx(current["lobes"][0]["r0"])
    assert lobe["my"] == pytest.approx(current["lobes"][0]["my"], rel=0.2)  # still fitted


def test_cancel_stops_the_fit_within_an_iteration():
    job = FitJob("virtual:gltf-red-plastic", "microfacet", extra=["--grid", "8", "--iterations", "20"]).start()
    deadline = time.time() + 120
    while not job.lines and time.time() < deadline:  # the fit has started
        time.sleep(0.05)
    job.cancel()
    assert job.wait(120) == "cancelled" and job.result is None
    assert job.status == "fit cancelled"


@pytest.mark.parametrize(
    ("data", "model", "extra", "message"),
    [
        ("no/such/file.csv", "thesis", [], "no/such/file.csv"),
        ("virtual:no-such-preset", "microfacet", [], "no-such-preset"),
        ("virtual:gltf-red-plastic", "microfacet", ["--fix", "mx=0.1"], "unknown to --model microfacet"),
    ],
)
def test_a_failing_fit_reports_instead_of_raising(data, model, extra, message):
    job = FitJob(data, model, extra=[*extra, *COARSE]).start()
    assert job.wait(120) == "failed"
    assert message in job.error and job.status.startswith("fit failed")


def test_bad_options_are_refused_before_the_thread_starts():
    with pytest.raises(ValueError, match="model"):
        FitJob("virtual:plastic", "spline")
    with pytest.raises(ValueError, match="fit options"):
        FitJob("virtual:plastic", "thesis", extra=["--grid", "many"])


def test_lockable_parameters_follow_the_model():
    gltf = validate(
        {"model": "gltf", "base_color": [0.5] * 3, "metallic": 1.0, "roughness": 0.3, "anisotropy": 0.6,
         "anisotropy_rotation": math.pi / 2}
    )  # fmt: skip
    assert lockable_parameters(gltf, "microfacet") == {
        "roughness": 0.3,
        "metallic": 1.0,
        "anisotropy": -0.6,
        "transmission": 0.0,
    }
    skewed = dict(gltf, anisotropy_rotation=0.3)  # neither the tangent nor the bitangent: not lockable
    assert "anisotropy" not in lockable_parameters(skewed, "microfacet")
    assert lockable_parameters(gltf, "thesis") == {} and lockable_parameters(gltf, "rational") == {}
    coloured = validate({"model": "thesis", "kd": [0.1, 0.2, 0.3], "lobes": [{"ks": [0.5, 0.5, 0.4], "mx": 0.1,
                         "my": 0.2, "r0": 0.5, "alpha": 0.1}]})  # fmt: skip
    assert set(lockable_parameters(coloured, "thesis")) == {"lobe1.mx", "lobe1.my", "lobe1.r0", "lobe1.alpha"}


class _StandInImgui:
    """The imgui calls the fit widgets make, recording labels; ``press`` names the button pressed
    and the checkbox toggled this frame."""

    def __init__(self, press=(), typed=None):
        self.press, self.typed, self.labels = set(press), typed, []

    def tree_node(self, label):
        return True

    def tree_pop(self):
        pass

    def input_text(self, label, value):
        self.labels.append(label)
        return (self.typed is not None, value if self.typed is None else self.typed)

    def combo(self, label, current, items):
        self.labels.append(label)
        return False, current

    def checkbox(self, label, value):
        self.labels.append(label)
        toggled = label.split(" = ")[0] in self.press
        return toggled, (not value) if toggled else value

    def button(self, label):
        self.labels.append(label)
        return label in self.press

    def text(self, label):
        self.labels.append(label)

    text_disabled = text_wrapped = text


def test_panel_fit_widgets_start_a_fit_with_the_locked_values(monkeypatch):
    from lobeview.app import panel

    started = []

    def start_fit(data, model, lock):
        started.append((data, model, lock))
        if data == "bad":
            raise ValueError("give the measurement")

    window = types.SimpleNamespace(
        editor=types.SimpleNamespace(desc=lambda index: load_material("gltf-red-plastic")),
        selected=0,
        fit_data="",
        fit_model="microfacet",
        fit_locks=set(),
        fit_job=None,
        message="",
        start_fit=start_fit,
    )
    monkeypatch.setattr(panel, "imgui", _StandInImgui(press={"metallic"}, typed=" virtual:plastic "))
    panel._fit(window)
    assert window.fit_locks == {"metallic"} and window.fit_data == " virtual:plastic " and not started
    monkeypatch.setattr(panel, "imgui", _StandInImgui(press={"fit"}))
    panel._fit(window)
    assert started == [("virtual:plastic", "microfacet", ["metallic"])]
    window.fit_data = "bad"
    panel._fit(window)
    assert window.message == "give the measurement"
    running = types.SimpleNamespace(running=True, status="iteration 2", cancelled=False)
    running.cancel = lambda: setattr(running, "cancelled", True)
    window.fit_job = running
    stand_in = _StandInImgui(press={"cancel fit"})
    monkeypatch.setattr(panel, "imgui", stand_in)
    panel._fit(window)
    assert running.cancelled and "iteration 2" in stand_in.labels and "fit" not in stand_in.labels


def test_material_widgets_show_a_rational_material_without_editing_it():
    desc = load_material(os.path.join(os.path.dirname(__file__), "data", "gold-ggx-rational.json"))
    shown = []
    imgui = types.SimpleNamespace(text=shown.append)
    changed, same = material_widgets(imgui, desc)
    assert not changed and same == desc and "Rational BRDF" in shown[0]


def test_fit_step_in_the_viewer_replaces_the_material_under_xvfb(xvfb, tmp_path):
    """The whole loop in the real window: select the chrome sphere, fit a measured (virtual) red
    plastic to the glTF model, and the sphere turns red; undo brings the chrome back."""
    script = [
        {"frame": 1, "action": "select", "object": "chrome sphere"},
        {"frame": 3, "action": "screenshot", "name": "before"},
        {
            "frame": 4,
            "action": "fit",
            "data": "virtual:gltf-red-plastic",
            "model": "microfacet",
            "extra": ["--isotropic", *QUICK],
        },  # fmt: skip
        {"frame": 10, "action": "screenshot", "name": "fitted"},
        {"frame": 10, "action": "save_materials", "path": str(tmp_path / "materials.json")},
        {"frame": 11, "action": "undo"},
        {"frame": 16, "action": "screenshot", "name": "undone"},
        {"frame": 17, "action": "quit"},
    ]
    run_scripted_view(xvfb, tmp_path, script, ["--view=table", "--size=320x200", "--face-size=64"], 60)
    saved = json.loads((tmp_path / "materials.json").read_text())
    assert saved["chrome"]["model"] == "gltf" and saved["chrome"]["roughness"] == pytest.approx(0.4, abs=0.01)
    from lobeview.scenes.hdrio import read_hdr_image

    before, fitted, undone = (read_hdr_image(tmp_path / f"{n}.exr") for n in ("before", "fitted", "undone"))
    for image in (before, fitted, undone):
        assert np.all(np.isfinite(image)) and image.min() >= 0
    changed = np.abs(fitted - before).sum(axis=2) > 0.05
    assert changed.mean() > 0.002  # the sphere's pixels changed
    red = fitted[changed]
    assert red[:, 0].mean() > 2 * red[:, 1].mean()  # ... to a red material
    assert np.abs(undone - before).mean() < 0.25 * np.abs(fitted - before).mean()
