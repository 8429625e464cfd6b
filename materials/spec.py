"""Material descriptions as plain JSON-able data, validated, and turned into BSDFs.

Three models share one format (a JSON object with a ``model`` key); see docs/guide.md "Material JSON".

thesis      {"model": "thesis", "kd": 0.1 | [r, g, b],
             "lobes": [{"ks", "mx", "my", "r0", "alpha"}, ...],
             "transmission_lobes": [{"kt", "mx", "my", "r0", "alpha"}, ...]}
microfacet  {"model": "microfacet", "distribution": "ggx" | "beckmann",
             "alpha": a  |  "alpha_u": au, "alpha_v": av,
             "fresnel": "none" | {"type": "schlick", "r0": ...}
                               | {"type": "conductor", "eta": [...], "k": [...]},
             "scale": 1.0 | [r, g, b]}
gltf        {"model": "gltf", "base_color": [r, g, b] | grey, "metallic": m, "roughness": r,
             "anisotropy": s, "anisotropy_rotation": radians,      (optional, KHR_materials_*:
             "ior": 1.5, "specular": 1, "specular_color": [r, g, b],  anisotropy, ior, specular,
             "clearcoat": c, "clearcoat_roughness": r,               clearcoat, transmission)
             "transmission": t, "sheen_color": [r, g, b], "sheen_roughness": r,
             "thickness": d, "attenuation_color": [r, g, b],       (KHR_materials_volume: a thick
             "attenuation_distance": x}                            transmitting volume, materials/volume.py)
rational    {"model": "rational", "theta_max": 80,               (Rational BRDF, seed 002;
             "brdf": [fn_r, fn_g, fn_b] | [fn],                    materials/rational_brdf.py,
             "sampling": {"theta": fn, "phi": fn},                 written by lobeview fit
             "proxy_alpha": a}  (optional)                         --model rational)
             with each fn {"form", "lower", "upper", "numerator", "denominator"}
measured    {"model": "measured", "file": "gold.binary",      (a MERL table rendered as it is,
             "proxy_alpha": a}  (optional)                         materials/measured.py; also
                                                                   --material measured:FILE)
             "file" is relative to the material JSON's folder and may not leave it.

Every parameter has a documented range (:data:`RANGES`). Out-of-range or non-finite values are
rejected with a :class:`MaterialError` that names the parameter, the value and the range; no
value is silently clamped.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from lobeview.core.methods import MAX_LOBES

from .bsdf import BSDF
from .conductor import microfacet_bsdf
from .fresnel import Fresnel
from .gltf import gltf_bsdf
from .microfacet import ALPHA_MAX, ALPHA_MIN
from .thesis import thesis_bsdf
from .volume import VOLUME_KEYS, volume_of

MODELS = ("thesis", "microfacet", "gltf", "rational", "measured")

#: (low, high) inclusive range of every parameter, by name.
RANGES: dict[str, tuple[float, float]] = {
    "kd": (0.0, 1.0),
    "ks": (0.0, 1.0),
    "kt": (0.0, 1.0),
    "mx": (ALPHA_MIN, ALPHA_MAX),
    "my": (ALPHA_MIN, ALPHA_MAX),
    "r0": (0.0, 1.0),
    "alpha": (0.0, 1.0),  # thesis shadowing exponent; the microfacet alpha uses "alpha_u/v"
    "alpha_u": (ALPHA_MIN, ALPHA_MAX),
    "alpha_v": (ALPHA_MIN, ALPHA_MAX),
    "eta": (0.01, 10.0),
    "k": (0.0, 20.0),
    "scale": (0.0, 1.0),
    "base_color": (0.0, 1.0),
    "metallic": (0.0, 1.0),
    "roughness": (0.0, 1.0),
    "anisotropy": (0.0, 1.0),
    "anisotropy_rotation": (-2 * math.pi, 2 * math.pi),
    "ior": (1.0, 10.0),  # or exactly 0: the KHR extensions' infinite index (f0 = 1)
    "specular": (0.0, 1.0),
    "specular_color": (0.0, 10.0),  # f0 = min(f0(ior) x colour, 1): the extension allows > 1
    "clearcoat": (0.0, 1.0),
    "clearcoat_roughness": (0.0, 1.0),
    "transmission": (0.0, 1.0),
    "sheen_color": (0.0, 1.0),
    "sheen_roughness": (0.0, 1.0),
    "thickness": (0.0, 1e6),  # KHR_materials_volume thicknessFactor, mesh units (0: thin-walled)
    "attenuation_color": (0.0, 1.0),
    "attenuation_distance": (1e-9, 1e30),  # world units; absent: no attenuation (the spec's infinity)
    "theta_max": (10.0, 90.0),  # rational: the fitted (theta_h, theta_d) domain, degrees
    "proxy_alpha": (ALPHA_MIN, ALPHA_MAX),
}
#: Optional glTF-model parameters (KHR_materials_* factors), kept in a description only when given.
GLTF_EXTENSION_KEYS = ("anisotropy", "anisotropy_rotation", "ior", "specular", "specular_color", "clearcoat",
                       "clearcoat_roughness", "transmission", "sheen_color", "sheen_roughness", "thickness",
                       "attenuation_color", "attenuation_distance")  # fmt: skip
#: The optional keys that are gltf_bsdf's keyword arguments: not KHR_materials_volume's
#: (VOLUME_KEYS, materials/volume.py), which are the renderers' (the path behind the surface).
GLTF_BSDF_KEYS = tuple(k for k in GLTF_EXTENSION_KEYS if k not in VOLUME_KEYS)


class MaterialError(ValueError):
    """A material description that cannot be used, with a message naming the parameter."""


def _number(value: Any, where: str, key: str) -> float:
    low, high = RANGES[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MaterialError(f"{where}: expected a number in [{low}, {high}], got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise MaterialError(f"{where} = {value!r} is not finite; expected a number in [{low}, {high}]")
    if not (low <= v <= high):
        raise MaterialError(f"{where} = {value!r} is outside its range [{low}, {high}]")
    return v


def _scalar_or_rgb(value: Any, where: str, key: str) -> float | list[float]:
    if isinstance(value, list | tuple):
        if len(value) != 3:
            raise MaterialError(f"{where}: expected a number or an RGB triple, got {value!r}")
        return [_number(v, f"{where}[{i}]", key) for i, v in enumerate(value)]
    return _number(value, where, key)


def _rgb(value: Any, key: str) -> list[float]:
    """A glTF colour: an RGB triple, a single number meaning grey. Always returned as a triple,
    since the renderer, the baker and the glTF writer read three channels (a grey 1 given as a
    number crashed the viewer's material binding: the fuzzer's edits mutation 105)."""
    value = _scalar_or_rgb(value, key, key)
    return list(value) if isinstance(value, list) else [value] * 3


def _check_keys(obj: dict, allowed: set[str], required: set[str], where: str) -> None:
    if not isinstance(obj, dict):
        raise MaterialError(f"{where}: expected a JSON object, got {type(obj).__name__}")
    unknown = set(obj) - allowed
    if unknown:
        raise MaterialError(f"{where}: unknown parameter(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    missing = required - set(obj)
    if missing:
        raise MaterialError(f"{where}: missing parameter(s) {sorted(missing)}")


def _validate_lobe(lobe: Any, where: str, key: str) -> dict:
    _check_keys(lobe, {key, "mx", "my", "r0", "alpha"}, {key, "mx", "my", "r0", "alpha"}, where)
    return {
        key: _scalar_or_rgb(lobe[key], f"{where}.{key}", key),
        "mx": _number(lobe["mx"], f"{where}.mx", "mx"),
        "my": _number(lobe["my"], f"{where}.my", "my"),
        "r0": _scalar_or_rgb(lobe["r0"], f"{where}.r0", "r0"),
        "alpha": _number(lobe["alpha"], f"{where}.alpha", "alpha"),
    }


def _validate_lobe_list(obj: dict, name: str, key: str) -> list[dict]:
    lobes = obj.get(name, [])
    if not isinstance(lobes, list):
        raise MaterialError(f"{name}: expected a list of lobes, got {lobes!r}")
    if len(lobes) > MAX_LOBES:
        raise MaterialError(f"{name}: at most {MAX_LOBES} lobes are supported, got {len(lobes)}")
    return [_validate_lobe(lobe, f"{name}[{i}]", key) for i, lobe in enumerate(lobes)]


def validate(desc: Any) -> dict:
    """Check a material description and return a normalised copy (floats, defaults filled)."""
    if not isinstance(desc, dict):
        raise MaterialError(f"a material must be a JSON object, got {type(desc).__name__}")
    model = desc.get("model")
    if model not in MODELS:
        raise MaterialError(f"model: expected one of {list(MODELS)}, got {model!r}")
    common = {"model", "name", "description", "fit"}
    out: dict[str, Any] = {"model": model}
    for key in ("name", "description"):
        if key in desc:
            if not isinstance(desc[key], str):
                raise MaterialError(f"{key}: expected a string, got {desc[key]!r}")
            out[key] = desc[key]
    if "fit" in desc:
        # Provenance written by `lobeview fit` (data, metric, error...): kept, never rendered.
        if not isinstance(desc["fit"], dict):
            raise MaterialError(f"fit: expected an object (the fit's provenance), got {desc['fit']!r}")
        out["fit"] = desc["fit"]

    if model == "thesis":
        _check_keys(desc, common | {"kd", "lobes", "transmission_lobes"}, set(), "thesis material")
        out["kd"] = _scalar_or_rgb(desc.get("kd", 0.0), "kd", "kd")
        out["lobes"] = _validate_lobe_list(desc, "lobes", "ks")
        out["transmission_lobes"] = _validate_lobe_list(desc, "transmission_lobes", "kt")
    elif model == "microfacet":
        allowed = common | {"distribution", "alpha", "alpha_u", "alpha_v", "fresnel", "scale"}
        _check_keys(desc, allowed, {"distribution"}, "microfacet material")
        if desc["distribution"] not in ("ggx", "beckmann"):
            raise MaterialError(f"distribution: expected 'ggx' or 'beckmann', got {desc['distribution']!r}")
        out["distribution"] = desc["distribution"]
        if "alpha" in desc:
            if "alpha_u" in desc or "alpha_v" in desc:
                raise MaterialError("give either alpha or alpha_u/alpha_v, not both")
            a = _number(desc["alpha"], "alpha", "alpha_u")
            out["alpha_u"] = out["alpha_v"] = a
        elif "alpha_u" in desc and "alpha_v" in desc:
            out["alpha_u"] = _number(desc["alpha_u"], "alpha_u", "alpha_u")
            out["alpha_v"] = _number(desc["alpha_v"], "alpha_v", "alpha_v")
        else:
            raise MaterialError("microfacet material: missing alpha (or both alpha_u and alpha_v)")
        out["fresnel"] = _validate_fresnel(desc.get("fresnel", "none"))
        out["scale"] = _scalar_or_rgb(desc.get("scale", 1.0), "scale", "scale")
    elif model == "rational":
        out.update(_validate_rational(desc, common))
    elif model == "measured":
        _check_keys(desc, common | {"file", "proxy_alpha"}, {"file"}, "measured material")
        if not isinstance(desc["file"], str) or not desc["file"]:
            raise MaterialError(f"file: expected the path of a MERL .binary file, got {desc['file']!r:.80}")
        out["file"] = desc["file"]
        if "proxy_alpha" in desc:
            out["proxy_alpha"] = _number(desc["proxy_alpha"], "proxy_alpha", "proxy_alpha")
    else:
        _check_keys(
            desc, common | {"base_color", "metallic", "roughness", *GLTF_EXTENSION_KEYS}, set(), "glTF material"
        )
        out["base_color"] = _rgb(desc.get("base_color", [1.0, 1.0, 1.0]), "base_color")
        out["metallic"] = _number(desc.get("metallic", 1.0), "metallic", "metallic")
        out["roughness"] = _number(desc.get("roughness", 1.0), "roughness", "roughness")
        for key in GLTF_EXTENSION_KEYS:
            if key not in desc:
                continue
            if key in ("specular_color", "sheen_color", "attenuation_color"):
                out[key] = _rgb(desc[key], key)
            elif key == "ior" and not isinstance(desc[key], bool) and desc[key] == 0:
                out[key] = 0.0
            else:
                out[key] = _number(desc[key], key, key)
    return out


#: (form, number of variables) of each function of a rational material
_RATIONAL_SHAPES = {"brdf": ("plain", 2), "theta": ("cdf_theta", 2), "phi": ("cdf_phi", 3)}


def _rational_function(value: Any, where: str, kind: str) -> dict:
    from .rational import RationalFitError, RationalFunction  # local: rational imports scipy

    form, dimension = _RATIONAL_SHAPES[kind]
    try:
        fn = RationalFunction.from_dict(value, where)
    except RationalFitError as exc:
        raise MaterialError(str(exc)) from None
    if fn.form != form or fn.dimension != dimension:
        raise MaterialError(
            f"{where}: expected form {form!r} of {dimension} variables, got {fn.form!r} of {fn.dimension}"
        )
    _check_denominator(fn, where)
    return fn.to_dict()


def _check_denominator(fn, where: str) -> None:
    """A denominator that is zero or changes sign inside the domain is a pole: the BRDF or its
    sampler becomes infinite there (issue 43: a zero denominator gave a NaN albedo and a black
    object, a pole an albedo of 455, both accepted). Checked on the points the fit verifies
    itself on (materials/rational.py denominator_check_points: a grid, and an inverse CDF's
    uniform variable near both ends), where the form's factor on p / q is not zero."""
    import numpy as np

    from .rational import denominator_check_points, function_defects

    points = denominator_check_points(fn.form, fn.lower, fn.upper)
    poles, falling = function_defects(fn, points)
    if poles.all():
        raise MaterialError(f"{where}: the denominator is zero (or not finite) over the domain")
    if poles.any():
        raise MaterialError(
            f"{where}: the denominator reaches zero inside the domain (a pole: the function is infinite there, "
            f"e.g. at {np.round(points[np.argmax(poles)], 4).tolist()}); refit the material"
        )
    if falling.any():  # an inverse CDF increases in its uniform variable, or the sampler folds
        raise MaterialError(
            f"{where}: the inverse CDF decreases in its uniform variable (at "
            f"{np.round(points[np.argmax(falling)], 4).tolist()}): samples fold over and their density is "
            "wrong; refit the material"
        )


def _validate_rational(desc: dict, common: set) -> dict:
    _check_keys(
        desc, common | {"theta_max", "brdf", "sampling", "proxy_alpha"}, {"brdf", "sampling"}, "rational material"
    )
    out: dict[str, Any] = {"theta_max": _number(desc.get("theta_max", 80.0), "theta_max", "theta_max")}
    brdf = desc["brdf"]
    if not isinstance(brdf, list) or len(brdf) not in (1, 3):
        raise MaterialError(f"brdf: expected a list of 1 or 3 rational functions (grey or R, G, B), got {brdf!r:.80}")
    out["brdf"] = [_rational_function(fn, f"brdf[{i}]", "brdf") for i, fn in enumerate(brdf)]
    sampling = desc["sampling"]
    _check_keys(sampling, {"theta", "phi"}, {"theta", "phi"}, "sampling")
    out["sampling"] = {key: _rational_function(sampling[key], f"sampling.{key}", key) for key in ("theta", "phi")}
    if "proxy_alpha" in desc:
        out["proxy_alpha"] = _number(desc["proxy_alpha"], "proxy_alpha", "proxy_alpha")
    return out


def _validate_fresnel(fresnel: Any) -> dict:
    if fresnel == "none" or fresnel == {"type": "none"}:
        return {"type": "none"}
    if not isinstance(fresnel, dict) or fresnel.get("type") not in ("schlick", "conductor"):
        raise MaterialError(
            "fresnel: expected 'none', {'type': 'schlick', 'r0': ...} or "
            f"{{'type': 'conductor', 'eta': [...], 'k': [...]}}, got {fresnel!r}"
        )
    if fresnel["type"] == "schlick":
        _check_keys(fresnel, {"type", "r0"}, {"type", "r0"}, "fresnel")
        return {"type": "schlick", "r0": _scalar_or_rgb(fresnel["r0"], "fresnel.r0", "r0")}
    _check_keys(fresnel, {"type", "eta", "k"}, {"type", "eta", "k"}, "fresnel")
    return {
        "type": "conductor",
        "eta": _scalar_or_rgb(fresnel["eta"], "fresnel.eta", "eta"),
        "k": _scalar_or_rgb(fresnel["k"], "fresnel.k", "k"),
    }


def build_bsdf(desc: dict) -> BSDF:
    """Validate ``desc`` and build its numpy reference BSDF."""
    d = validate(desc)
    name = d.get("name", d["model"])
    if d["model"] == "thesis":
        return thesis_bsdf(d["kd"], d["lobes"], d["transmission_lobes"], name=name)
    if d["model"] == "microfacet":
        fr = d["fresnel"]
        fresnel = Fresnel(
            fr["type"],
            r0=fr.get("r0", 1.0),
            eta=fr.get("eta", 1.0),
            k=fr.get("k", 0.0),
        )
        return microfacet_bsdf(d["distribution"], d["alpha_u"], d["alpha_v"], fresnel, d["scale"])
    if d["model"] == "rational":
        from .rational_brdf import rational_bsdf

        return rational_bsdf(d, name=name)
    if d["model"] == "measured":
        from .measured import measured_bsdf  # local: reads a 35 MB table

        return measured_bsdf(d, name=name)
    bsdf = gltf_bsdf(d["base_color"], d["metallic"], d["roughness"], **{k: d[k] for k in GLTF_BSDF_KEYS if k in d})
    bsdf.name = name
    # KHR_materials_volume: not the surface's scattering but the object's (materials/volume.py);
    # carried for the object preview, which renders a BSDF (viewer/preview.py).
    bsdf.volume = volume_of(d)
    return bsdf


#: ``--material measured:FILE``: a MERL table rendered as it is (materials/measured.py)
MEASURED_PREFIX = "measured:"


def load_material(source: str) -> dict:
    """A preset name, a path to a JSON file, an inline JSON object, or ``measured:FILE`` ->
    validated description."""
    from .presets import PRESETS  # local import: presets import this module

    if source in PRESETS:
        return validate(PRESETS[source])
    if source.startswith(MEASURED_PREFIX):
        target = Path(source[len(MEASURED_PREFIX) :])
        if not target.is_file():
            raise MaterialError(f"{source!r}: no such file {str(target)!r} (expected a MERL .binary file)")
        return validate({"model": "measured", "name": target.stem, "file": str(target.resolve())})
    from lobeview.core.jsonio import JSONInputError, parse_json_text, read_json_file

    text = source.strip()
    if text.startswith("{"):
        try:
            return validate(parse_json_text(text, "inline material JSON"))
        except JSONInputError as exc:
            raise MaterialError(str(exc)) from None
    path = Path(source)
    if not path.exists():
        names = ", ".join(sorted(PRESETS))
        raise MaterialError(f"{source!r} is neither a preset name ({names}) nor an existing file")
    try:
        desc = read_json_file(path, "material file")
    except JSONInputError as exc:
        raise MaterialError(str(exc)) from None
    try:
        return resolve_material_files(validate(desc), path.parent)
    except MaterialError as exc:
        raise MaterialError(f"{path}: {exc}") from None


def relative_material_files(desc: dict, folder: Path) -> dict:
    """The description as a JSON file in ``folder`` names its files: a measured table inside
    that folder by its relative path (what :func:`resolve_material_files` reads back); one
    outside keeps its absolute path, which loading refuses (copy the table beside the file)."""
    if desc.get("model") != "measured":
        return desc
    table = Path(desc["file"]).resolve()
    base = Path(folder).resolve()
    return {**desc, "file": table.relative_to(base).as_posix()} if table.is_relative_to(base) else desc


def resolve_material_files(desc: dict, folder: Path, limits=None) -> dict:
    """A validated description read from a JSON file in ``folder`` with the files it names
    (a measured material's table) resolved there: a file may lie only in that folder or below
    it (the scene-file trust boundary, core/trust.py), symbolic links included, unless
    ``limits`` (core/trust.py Limits; default DEFAULT_LIMITS) allow outside references (the
    --allow-outside-references the refusal names)."""
    if desc.get("model") != "measured":
        return desc
    from lobeview.core.trust import DEFAULT_LIMITS, UntrustedReferenceError, resolve_reference

    try:
        resolved = resolve_reference(folder, desc["file"], "measured table", limits or DEFAULT_LIMITS)
    except (UntrustedReferenceError, FileNotFoundError) as exc:
        raise MaterialError(str(exc)) from None
    return {**desc, "file": str(resolved)}
