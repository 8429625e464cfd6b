"""Material descriptions: validation messages, presets, JSON round trip, and the CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lobeview.app.cli import main
from lobeview.materials.presets import PRESETS
from lobeview.materials.spec import MaterialError, build_bsdf, load_material, validate


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_validates_and_round_trips_through_json(name):
    desc = validate(PRESETS[name])
    again = validate(json.loads(json.dumps(desc)))
    assert again == desc
    bsdf = build_bsdf(again)
    r, t = bsdf.albedo(np.array([0.0, 0.0, 1.0]), order=64)
    assert np.all(np.isfinite(r)) and np.all(r > 0)


@pytest.mark.parametrize(
    "desc,message",
    [
        (
            {
                "model": "thesis",
                "kd": 0.1,
                "lobes": [{"ks": 1, "mx": 2.0, "my": 0.1, "r0": 0.5, "alpha": 0}],
            },
            r"lobes\[0\]\.mx = 2\.0 is outside its range \[0\.0001, 1\.0\]",
        ),
        ({"model": "thesis", "kd": float("nan")}, r"kd = nan is not finite"),
        ({"model": "thesis", "kd": [0.1, 0.2]}, r"kd: expected a number or an RGB triple"),
        (
            {"model": "thesis", "lobes": [{"ks": 1, "mx": 0.1, "my": 0.1, "r0": 0.5}]},
            r"missing parameter\(s\) \['alpha'\]",
        ),
        (
            {
                "model": "thesis",
                "transmission_lobes": [{"kt": -0.1, "mx": 0.1, "my": 0.1, "r0": 0.5, "alpha": 0}],
            },
            r"transmission_lobes\[0\]\.kt = -0\.1 is outside its range \[0\.0, 1\.0\]",
        ),
        (
            {
                "model": "thesis",
                "lobes": [{"ks": 1, "mx": 0.1, "my": 0.1, "r0": 0.5, "alpha": 1.5}],
            },
            r"lobes\[0\]\.alpha = 1\.5 is outside its range \[0\.0, 1\.0\]",
        ),
        ({"model": "thesis", "shininess": 3}, r"unknown parameter\(s\) \['shininess'\]"),
        ({"model": "microfacet", "distribution": "ggx"}, r"missing alpha"),
        (
            {"model": "microfacet", "distribution": "ggx", "alpha": float("inf")},
            r"alpha = inf is not finite",
        ),
        (
            {"model": "microfacet", "distribution": "phong", "alpha": 0.2},
            r"distribution: expected 'ggx' or 'beckmann'",
        ),
        (
            {
                "model": "microfacet",
                "distribution": "ggx",
                "alpha": 0.2,
                "fresnel": {"type": "conductor", "eta": 1},
            },
            r"missing parameter\(s\) \['k'\]",
        ),
        ({"model": "gltf", "roughness": 1.2}, r"roughness = 1\.2 is outside its range"),
        ({"model": "gltf", "metallic": True}, r"metallic: expected a number"),
        ({"model": "phong"}, r"model: expected one of"),
        ([1, 2], r"a material must be a JSON object"),
    ],
)
def test_bad_materials_are_rejected_with_a_message_naming_the_parameter(desc, message):
    with pytest.raises(MaterialError, match=message):
        validate(desc)


def test_load_material_from_preset_file_and_inline_json(tmp_path):
    assert load_material("chrome")["model"] == "thesis"
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"model": "gltf", "base_color": [1, 0, 0], "metallic": 0, "roughness": 0.3}))
    assert load_material(str(path))["roughness"] == 0.3
    assert (
        load_material('{"model": "microfacet", "distribution": "beckmann", "alpha_u": 0.1, "alpha_v": 0.2}')["alpha_v"]
        == 0.2
    )
    with pytest.raises(MaterialError, match="neither a preset name"):
        load_material("no-such-material")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(MaterialError, match="not valid JSON"):
        load_material(str(tmp_path / "bad.json"))


def test_cli_material_list_and_show(capsys):
    assert main(["material", "list"]) == 0
    out = capsys.readouterr().out
    for name in PRESETS:
        assert name in out
    assert main(["material", "show", "alanod-2000gs-1lobe"]) == 0
    out = capsys.readouterr().out
    assert "ks=0.9" in out and "mx=0.11" in out
    lines = [line for line in out.splitlines() if line.strip().startswith(("0°", "30°", "60°", "80°"))]
    assert len(lines) == 4
    assert main(["material", "show", "white-foil", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    angles = [row["theta_deg"] for row in data["albedo"]]
    assert angles == [0.0, 30.0, 60.0, 80.0]
    normal = data["albedo"][0]
    assert 0.7 < np.mean(normal["reflectance"]) < 0.85  # kd 0.76 + lobe
    assert 0.15 < np.mean(normal["transmittance"]) < 0.18


def test_cli_reports_bad_material_without_traceback(capsys):
    assert main(["material", "show", '{"model": "thesis", "kd": 3}']) == 2
    err = capsys.readouterr().err
    assert "kd = 3" in err and "Traceback" not in err


def test_cli_material_plot_writes_png(tmp_path):
    out = tmp_path / "lobe.png"
    result = subprocess.run(
        [sys.executable, "-m", "lobeview", "material", "plot", "miro5-2lobe", "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    from PIL import Image

    image = Image.open(out)
    assert image.size[0] > 1000 and image.size[1] > 700
    pixels = np.asarray(image.convert("L"), dtype=float)
    assert pixels.std() > 10  # not a blank canvas


def test_panel_offers_the_gltf_extension_factors_and_writes_only_moved_ones():
    """The material panel's glTF widgets (app/editor.py) with a stand-in imgui: every
    KHR_materials_* factor gets a slider; only the one moved enters the description, which
    still validates."""
    import types

    from lobeview.app.editor import GLTF_EXTENSION_SLIDERS, material_widgets

    labels = []

    def slider_float(label, value, low, high, fmt, flags):
        labels.append(label)
        return (label == "clearcoat", 0.7 if label == "clearcoat" else value)

    imgui = types.SimpleNamespace(
        SliderFlags_=types.SimpleNamespace(logarithmic=types.SimpleNamespace(value=32)),
        slider_float=slider_float,
        color_edit3=lambda label, value: (False, value),
        slider_float3=lambda label, value, low, high: (False, value),
    )
    desc = {"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 0.0, "roughness": 0.5}
    changed, edited = material_widgets(imgui, desc)
    assert changed and edited["clearcoat"] == 0.7
    assert set(edited) - set(desc) == {"clearcoat"}
    assert [name.replace("_", " ") for name, _ in GLTF_EXTENSION_SLIDERS] == labels[2:]
    assert validate(edited)["clearcoat"] == 0.7


def test_cli_output_into_a_closed_pipe_is_not_an_error():
    """`lobeview material list | head`: the reader leaves before lobeview writes (here `true`,
    gone before the interpreter has started); no error message, status 0 (it said "lobeview:
    error: [Errno 32] Broken pipe", status 2)."""
    import subprocess
    import sys

    command = f"{sys.executable} -m lobeview material list | true; exit ${{PIPESTATUS[0]}}"
    done = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, (done.returncode, done.stderr)
    assert "Broken pipe" not in done.stderr and "error" not in done.stderr, done.stderr
