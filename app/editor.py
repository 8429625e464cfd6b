"""Material editing in the viewer: validated edits with an undo stack, save/load of a
materials file (name -> description, exact round trip), the ImGui widgets for every parameter
of the three models, and the panel's live lobe plot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lobeview.materials.spec import RANGES, MaterialError, validate

UNDO_DEPTH = 50


class MaterialEditor:
    """Edits of material descriptions with validation and an undo stack (last UNDO_DEPTH edits)."""

    def __init__(self, renderer, original: dict | None = None, limits=None):
        self.renderer = renderer
        self.limits = limits  # core/trust.py Limits of the files a materials file may name
        self.undo: list[tuple[int, dict]] = []
        # What the scene file says (``original``: name -> description, when edits were applied
        # before the renderer was built), to tell which materials were edited (edits(), F12).
        current = {m.name: m.desc for m in renderer.scene.materials}
        self.original = json.loads(json.dumps(original if original is not None else current))

    def desc(self, index: int) -> dict:
        scene = self.renderer.scene
        if not 0 <= index < len(scene.objects):
            raise IndexError(f"object {index} does not exist: the scene has {len(scene.objects)} objects")
        return json.loads(json.dumps(scene.materials[scene.objects[index].material].desc))

    def edits(self) -> dict:
        """Material name -> description of every material that differs from the scene file."""
        return {m.name: m.desc for m in self.renderer.scene.materials if m.desc != self.original.get(m.name)}

    def apply(self, index: int, desc: dict) -> str | None:
        """Validate and apply; returns an error message instead of raising."""
        try:
            desc = validate(desc)
        except MaterialError as exc:
            return str(exc)
        self.undo.append((index, self.desc(index)))
        del self.undo[:-UNDO_DEPTH]
        self.renderer.update_material(index, desc)
        return None

    def undo_last(self) -> bool:
        if not self.undo:
            return False
        index, desc = self.undo.pop()
        self.renderer.update_material(index, desc)
        return True

    def save(self, path: Path) -> None:
        from lobeview.materials.spec import relative_material_files

        scene = self.renderer.scene
        data = {m.name: relative_material_files(m.desc, Path(path).parent) for m in scene.materials}
        path.write_text(json.dumps(data, indent=2, sort_keys=True))

    def load(self, path: Path) -> list[str]:
        """Apply a materials file; a corrupt or invalid file raises OptionError/MaterialError
        before anything changes (the panel shows the message)."""
        from lobeview.app.options import read_material_edits
        from lobeview.materials.spec import validate

        data = {name: validate(desc) for name, desc in read_material_edits(path, self.limits).items()}
        scene = self.renderer.scene
        changed = []
        for i, obj in enumerate(scene.objects):
            name = scene.materials[obj.material].name
            if name in data and data[name] != scene.materials[obj.material].desc:
                self.renderer.update_material(i, data[name])
                changed.append(name)
        return changed


def _slider(imgui, label: str, value: float, key: str) -> tuple[bool, float]:
    low, high = RANGES[key]
    flags = imgui.SliderFlags_.logarithmic.value if key in ("mx", "my", "alpha_u", "alpha_v") else 0
    return imgui.slider_float(label, float(value), float(low), float(high), "%.4g", flags)


def _scalar_or_rgb_slider(imgui, label: str, value, key: str):
    if isinstance(value, list):
        changed, new = (
            imgui.color_edit3(label, [float(v) for v in value])
            if key in ("kd", "base_color")
            else imgui.slider_float3(label, [float(v) for v in value], *RANGES[key])
        )
        return changed, [float(v) for v in new]
    return _slider(imgui, label, value, key)


# The KHR_materials_* factors the panel offers for glTF materials, with their defaults.
GLTF_EXTENSION_SLIDERS = (
    ("anisotropy", 0.0),
    ("anisotropy_rotation", 0.0),
    ("ior", 1.5),
    ("specular", 1.0),
    ("clearcoat", 0.0),
    ("clearcoat_roughness", 0.0),
    ("transmission", 0.0),
    ("sheen_roughness", 0.0),
)


def material_widgets(imgui, desc: dict) -> tuple[bool, dict]:
    """ImGui widgets for every parameter of the models (a Rational BRDF's coefficients are shown,
    not edited); returns (changed, new desc)."""
    changed_any = False
    d = json.loads(json.dumps(desc))
    if d["model"] == "thesis":
        c, d["kd"] = _scalar_or_rgb_slider(imgui, "kd", d["kd"], "kd")
        changed_any |= c
        for group, key in (("lobes", "ks"), ("transmission_lobes", "kt")):
            remove = None
            for i, lobe in enumerate(d[group]):
                imgui.push_id(f"{group}{i}")
                imgui.separator_text(f"{group[:-1].replace('_', ' ')} {i}")
                for name in (key, "mx", "my", "r0", "alpha"):
                    c, lobe[name] = _scalar_or_rgb_slider(imgui, name, lobe[name], name)
                    changed_any |= c
                if imgui.small_button("remove"):
                    remove = i
                imgui.pop_id()
            if remove is not None:
                d[group].pop(remove)
                changed_any = True
            if len(d[group]) < 8 and imgui.small_button(f"add {group[:-1].replace('_', ' ')}"):
                d[group].append({key: 0.5, "mx": 0.1, "my": 0.1, "r0": 0.5, "alpha": 0.0})
                changed_any = True
    elif d["model"] == "microfacet":
        for name in ("alpha_u", "alpha_v"):
            c, d[name] = _slider(imgui, name, d[name], name)
            changed_any |= c
        fr = d["fresnel"]
        if fr["type"] == "schlick":
            c, fr["r0"] = _scalar_or_rgb_slider(imgui, "r0", fr["r0"], "r0")
            changed_any |= c
        elif fr["type"] == "conductor":
            c, fr["eta"] = _scalar_or_rgb_slider(imgui, "eta", fr["eta"], "eta")
            changed_any |= c
            c, fr["k"] = _scalar_or_rgb_slider(imgui, "k", fr["k"], "k")
            changed_any |= c
    elif d["model"] == "rational":
        # Fitted coefficients, not parameters to slide: refit (the panel's fit) to change them.
        counts = [f"{len(fn['numerator'])}/{len(fn['denominator'])}" for fn in d["brdf"]]
        imgui.text(f"Rational BRDF, theta_max {d['theta_max']:g} deg, coefficients {' '.join(counts)}")
    elif d["model"] == "measured":
        # A measured table, rendered as it is: nothing to slide (fit it to get parameters).
        imgui.text(f"measured table {d['file']}")
    else:
        c, d["base_color"] = _scalar_or_rgb_slider(imgui, "base colour", d["base_color"], "base_color")
        changed_any |= c
        for name in ("metallic", "roughness"):
            c, d[name] = _slider(imgui, name, d[name], name)
            changed_any |= c
        # KHR_materials_* factors: written into the description only once moved off the default.
        for name, default in GLTF_EXTENSION_SLIDERS:
            c, value = _slider(imgui, name.replace("_", " "), d.get(name, default), name)
            if c:
                d[name] = value
            changed_any |= c
    return changed_any, d


def lobe_plot_values(desc: dict, theta_deg: float = 45.0, count: int = 181) -> tuple[np.ndarray, np.ndarray]:
    """(f cos)^(1/3) in the plane of incidence for a 45 deg view: the panel's live lobe plot."""
    from lobeview.materials.spec import build_bsdf
    from lobeview.materials.vec import direction_from_angles_deg

    bsdf = build_bsdf(desc)
    angle = np.linspace(-np.pi, np.pi, count)
    wi = np.stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)], -1)
    wo = np.broadcast_to(direction_from_angles_deg(theta_deg, 0.0), wi.shape)
    value = bsdf.eval(wi, wo).mean(-1) * np.abs(wi[:, 2])
    return np.degrees(angle).astype(np.float32), np.cbrt(value).astype(np.float32)
