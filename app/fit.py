"""``lobeview fit`` and ``lobeview measure``: measured materials (thesis 3.4).

``lobeview measure MATERIAL -o data.csv`` writes a virtual goniophotometer measurement of any
lobeview material (the thesis' incidence angles, optional noise and outliers) in the CSV format
``lobeview fit`` reads; ``--merl FILE.binary`` writes the material's MERL table instead.

``lobeview fit DATA -o material.json`` fits the thesis model (kd + K reflection lobes + T
transmission lobes) by the hierarchical brute-force L1 search of thesis 3.4.1 and writes a
material JSON that ``lobeview shot --material`` and the viewer load; ``--plot PNG`` draws
measured against fitted slices (thesis Fig. 3.12 layout). ``--model rational`` fits the Rational
BRDF (seed 002) instead, ``--model microfacet`` the glTF metallic-roughness model (a ``gltf``
material a user's scene can take as it is).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from lobeview.materials import measurement as meas
from lobeview.materials.fit import FitError, FitOptions, fit_thesis, material_error, measured_albedo
from lobeview.materials.fit_selection import KD_EXACT_SHARE, KD_MIN_GAIN, fit_verdict
from lobeview.materials.lobe_fit import LUMINANCE, is_isotropic
from lobeview.materials.spec import build_bsdf, load_material
from lobeview.materials.virtual import virtual_measurement


def _float_list(text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _assignment(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    try:
        if not sep:
            raise ValueError
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected PARAM=VALUE (for example mx=0.1), got {text!r}") from None


def _interval(text: str) -> tuple[str, tuple[float, float]]:
    name, sep, value = text.partition("=")
    lo, colon, hi = value.partition(":")
    try:
        if not sep or not colon:
            raise ValueError
        return name.strip(), (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected PARAM=LO:HI (for example mx=0.01:0.3), got {text!r}") from None


def _stride(text: str) -> tuple[int, int, int]:
    parts = text.split(",")
    try:
        values = tuple(int(v) for v in parts)
        if len(values) != 3 or min(values) < 1:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three positive integers H,D,P, got {text!r}") from None
    return values  # type: ignore[return-value]


def _add_goniometer_arguments(p) -> None:
    g = p.add_argument_group("virtual goniophotometer")
    g.add_argument(
        "--theta-i",
        type=_float_list,
        default=list(meas.THESIS_THETA_I_DEG),
        help="incidence polar angles in degrees (default: the thesis' 0,5,20,35,50,65)",
    )
    g.add_argument(
        "--phi-i",
        type=_float_list,
        default=list(meas.THESIS_PHI_I_DEG),
        help="incidence azimuths in degrees from the tangent (default 0,15,...,90)",
    )
    g.add_argument("--theta-step", type=float, default=5.0, help="detector grid step in theta_o (deg, default 5)")
    g.add_argument("--phi-step", type=float, default=15.0, help="detector grid step in phi_o (deg, default 15)")
    g.add_argument("--noise", type=float, default=0.0, help="relative Gaussian noise (default 0)")
    g.add_argument("--outliers", type=float, default=0.0, help="fraction of tuples replaced by spikes (default 0)")
    g.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")


def _virtual(material: str, args) -> meas.Measurement:
    desc = load_material(material)
    if args.theta_step <= 0 or args.phi_step <= 0 or not (0 <= args.noise <= 10) or not (0 <= args.outliers < 1):
        raise FitError("--theta-step/--phi-step must be > 0, --noise in [0, 10], --outliers in [0, 1)")
    if not args.theta_i or not args.phi_i or not all(0 <= t < 90 for t in args.theta_i):
        raise FitError("--theta-i needs angles in [0, 90) and --phi-i at least one azimuth")
    return virtual_measurement(
        desc,
        args.theta_i,
        args.phi_i,
        args.theta_step,
        args.phi_step,
        args.noise,
        args.outliers,
        args.seed,
        name=material if len(material) < 60 else None,
    )


def merl_source(data: str) -> tuple[np.ndarray | None, str]:
    """The MERL table of a .binary file or of virtual-merl:MATERIAL (any isotropic lobeview
    material evaluated at every MERL cell), else (None, "")."""
    if data.startswith("virtual-merl:"):
        material = data[len("virtual-merl:") :]
        return meas.merl_table_from_bsdf(build_bsdf(load_material(material))), Path(material).stem
    if Path(data).suffix.lower() == ".binary":
        return meas.read_merl(Path(data)), Path(data).stem
    return None, ""


def load_data(data: str, args) -> tuple[meas.Measurement, meas.Measurement | None]:
    """The measurement to fit, and the one to plot (a MERL table is plotted at goniophotometer
    directions, as its cells have no common incidences)."""
    if data.startswith("virtual:"):
        m = _virtual(data[len("virtual:") :], args)
        return m, m
    table, name = merl_source(data)
    if table is not None:
        m = meas.merl_measurement(table, args.merl_stride, name=name)
        return m, meas.merl_goniometer_measurement(table, name=name)
    path = Path(data)
    if path.suffix.lower() in (".csv", ".txt"):
        m = meas.read_csv(path, negative=args.negative)
        return m, m
    raise FitError(f"{data}: expected a .csv goniophotometer file, a MERL .binary file or virtual:MATERIAL")


def fit_description(args, progress=print) -> tuple[dict, meas.Measurement, meas.Measurement]:
    """Fit ``args.model`` to ``args.data`` (the command's options): the material description
    (validated, with its ``fit`` provenance), the measurement fitted and the one to plot. Shared
    by ``lobeview fit`` and the viewer's fit panel (app/fit_job.py); ``progress`` gets every line."""
    say = progress or (lambda _msg: None)
    name = args.name or Path(args.output).stem
    if args.model == "rational":
        desc, measurement, plotted = _fit_rational(args, name, say)
    else:
        measurement, plotted = load_data(args.data, args)
        say(
            f"{measurement.name}: {len(measurement)} tuples ({int(measurement.transmission.sum())} transmission), "
            f"{measurement.channels} channel(s), {len(measurement.incidences())} incidences; {measurement.source}"
        )
        for note in measurement.notes:
            say(f"  {note}")
        isotropic = args.isotropic or measurement.source == "MERL table"
        detail = None if args.quiet else progress
        fit = _fit_microfacet if args.model == "microfacet" else _fit_thesis
        desc = fit(args, measurement, isotropic, detail, name)
    build_bsdf(desc)  # validates: the fitted values lie in the model's ranges
    return desc, measurement, plotted


def _fit_thesis(args, measurement, isotropic, progress, name: str) -> dict:
    options = FitOptions(
        lobes=args.lobes,
        transmission_lobes=args.transmission_lobes,
        grid=args.grid,
        iterations=args.iterations,
        alternations=args.alternations,
        metric=args.metric,
        fixed=dict(args.fix),
        ranges=dict(args.range),
        isotropic=isotropic,
        polish=not args.no_polish,
        diffuse=args.diffuse,
        progress=progress,
    )
    result = fit_thesis(measurement, options)
    return result.material(name=name, data=args.data)


def _fit_microfacet(args, measurement, isotropic, progress, name: str) -> dict:
    """The glTF metallic-roughness BRDF (GGX): roughness, metallic, anisotropy and transmission
    searched, the base colour solved exactly per candidate (materials/fit_gltf.py)."""
    from lobeview.materials.fit_gltf import GltfFitOptions, fit_gltf

    if args.lobes != 1 or args.transmission_lobes not in (None, 1):
        raise FitError("--lobes/--transmission-lobes apply to --model thesis; the glTF model has one specular lobe")
    options = GltfFitOptions(
        grid=args.grid,
        iterations=args.iterations,
        metric=args.metric,
        fixed=dict(args.fix),
        ranges=dict(args.range),
        isotropic=isotropic,
        polish=not args.no_polish,
        progress=progress,
    )
    result = fit_gltf(measurement, options)
    return result.material(name=name, data=args.data)


def _fit_rational(args, name: str, say) -> tuple[dict, meas.Measurement, meas.Measurement]:
    """The Rational BRDF (seed 002): one rational function of (theta_h, theta_d) per channel,
    fitted to the data projected onto that plane, and its rational inverse CDFs."""
    from lobeview.materials import rational_brdf as rb
    from lobeview.materials.rational import RationalFitError

    progress = None if args.quiet else say
    t0 = time.perf_counter()
    table, table_name = merl_source(args.data)
    if table is not None:
        projected = rb.project_merl(table, args.theta_max)
        measurement = meas.merl_measurement(table, args.merl_stride, name=table_name)
        plotted = meas.merl_goniometer_measurement(table, name=table_name)
    else:
        measurement = load_data(args.data, args)[0]
        projected = rb.project_measurement(measurement, theta_max_deg=args.theta_max)
        plotted = measurement
    say(f"{args.data}: {len(projected.points)} (theta_h, theta_d) points up to {args.theta_max} deg, "
        f"{projected.values.shape[1]} channel(s)")  # fmt: skip
    try:
        fit = rb.fit_rational_brdf(
            projected, args.eps, args.max_coefficients, theta_max_deg=args.theta_max, progress=progress
        )
        sampling = rb.fit_sampling(fit.functions, fit.theta_max_deg, progress=progress)
    except RationalFitError as exc:
        raise FitError(str(exc)) from None
    desc = rb.rational_description(fit, sampling, name=name)
    desc["fit"] = {
        "model": "rational (Pacanowski et al. 2012)",
        "data": args.data,
        "eps": args.eps,
        "theta_max": args.theta_max,
        "coefficients": [list(fn.counts) for fn in fit.functions],
        "sampling_coefficients": [list(sampling.theta.counts), list(sampling.phi.counts)],
        "max_relative_error": fit.max_relative_error,
        "error": material_error(desc, measurement, "l1"),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    for c, fn in enumerate(fit.functions):
        say(f"channel {c}: {fn.counts} (numerator, denominator) coefficients, max relative error "
            f"{fit.max_relative_error[c]:.3g} on the projected data")  # fmt: skip
    say(f"inverse CDFs: theta {sampling.theta.counts}, phi {sampling.phi.counts} coefficients")
    return desc, measurement, plotted


def parameter_lines(desc: dict) -> list[str]:
    """The fitted parameters, one line per lobe (thesis) or one line (glTF); the Rational BRDF's
    coefficients are in the JSON."""
    if desc["model"] == "thesis":
        lines = [f"kd = {desc['kd']}"]
        for key in ("lobes", "transmission_lobes"):
            for i, lobe in enumerate(desc[key]):
                lines.append(f"{key}[{i}]: " + "  ".join(f"{k}={v}" for k, v in lobe.items()))
        return lines
    if desc["model"] == "gltf":
        return ["  ".join(f"{k}={v}" for k, v in desc.items() if k not in ("model", "name", "description", "fit"))]
    return []


def cmd_fit(args) -> int:
    t0 = time.perf_counter()
    if args.render:  # refused before the fit, not after it
        from .fit_render import check_renderable

        check_renderable(args.data)
    desc, measurement, plotted = fit_description(args)
    metric_name = "l1" if args.model == "rational" else args.metric
    verdict = fit_verdict(measurement, desc["fit"]["error"], metric_name, desc["model"])
    desc["fit"]["verdict"] = verdict
    Path(args.output).write_text(json.dumps(desc, indent=2) + "\n", encoding="utf-8")
    print("\n" + "\n".join(parameter_lines(desc)))
    fit = desc["fit"]
    metric = "L1" if args.model == "rational" else args.metric.upper()
    extra = ""
    if "error_reflection" in fit:
        extra = f" (reflection {fit['error_reflection']:.6g}, transmission {fit['error_transmission']:.6g})"
    print(f"Eq. 3.7 {metric} error: {fit['error']:.6g}{extra}")
    diffuse = fit.get("diffuse")
    if diffuse:  # shown with --quiet too: the fit's answer depends on it
        kd = ", ".join(f"{v:.4g}" for v in diffuse["kd_histogram"])
        print(
            f"diffuse term {'kept' if diffuse['kept'] else 'dropped (kd = 0): not supported by the data'}: the "
            f"histogram's kd ({kd}) lowers the error by {100 * diffuse['gain_of_model_l1']:.1f} % of the fit's L1 "
            f"mass, {100 * diffuse['gain_of_error']:.0f} % of the kd = 0 fit's error (kept from "
            f"{100 * KD_MIN_GAIN:.0f} % or {100 * KD_EXACT_SHARE:.0f} %; --diffuse histogram keeps it always)"
        )
    for line in fit.get("warnings") or []:
        print(f"warning: {line}")
    # shown with --quiet too: whether the fit can be trusted at all
    print(f"verdict: {verdict['level']} ({100 * verdict['unexplained']:.1f} % of the data's Eq. 3.7 mass unexplained)")
    for line in verdict["messages"]:  # none for a good fit
        print(f"warning: {line}")
    _print_albedo(measurement, desc)
    print(f"wrote {args.output} ({time.perf_counter() - t0:.1f} s)")
    if args.plot:
        from lobeview.materials.fit_plot import plot_fit

        label = {"thesis": "fit", "gltf": "gltf fit", "rational": "rational"}[desc["model"]]
        what = {"thesis": f"{len(desc.get('lobes', []))} lobe(s)", "gltf": "glTF metallic-roughness"}
        title = f"{measurement.name}: {what.get(desc['model'], 'Rational BRDF')}, {metric} {fit['error']:.4g}"
        print(f"wrote {plot_fit(plotted, {label: desc}, args.plot, title=title)}")
    if args.render:
        from .fit_render import render_comparison

        render_comparison(args.data, desc, args.render, args.render_env)
    return 0


def _print_albedo(m: meas.Measurement, desc: dict) -> None:
    """Measured (Eq. 2.6 by the data's own quadrature) against the model's directional albedo."""
    rows = measured_albedo(m)
    if len(rows) > 400:  # scattered incidences (a MERL table): no per-incidence table
        return
    azimuths = sorted({row["phi_i"] for row in rows})
    shown = {azimuths[0], azimuths[-1]}  # the planes along the tangent and the bitangent
    rows = [row for row in rows if row["phi_i"] in shown or row["theta_i"] < 0.01]
    bsdf = build_bsdf(desc)
    print("directional albedo, measured (sum of p x solid angle) vs fitted model (quadrature):")
    print(f"  {'theta_i':>7} {'phi_i':>6}  {'R meas':>7} {'R model':>7}  {'T meas':>7} {'T model':>7}")
    for row in rows:
        wi = meas.spherical_direction(math.radians(row["theta_i"]), math.radians(row["phi_i"]))
        r, t = bsdf.albedo(wi, order=96)
        print(
            f"  {row['theta_i']:>7.1f} {row['phi_i']:>6.1f}  {row['reflectance']:>7.4f} {float(r @ LUMINANCE):>7.4f}  "
            f"{row['transmittance']:>7.4f} {float(t @ LUMINANCE):>7.4f}"
        )


def cmd_measure(args) -> int:
    desc = load_material(args.material)
    if args.merl:
        bsdf = build_bsdf(desc)
        if not all(is_isotropic(c) for c in bsdf.components) or bsdf.tangent_rotation:
            raise FitError(f"{args.material}: anisotropic; the MERL layout holds isotropic BRDFs only")
        if any(c.hemisphere == "transmission" for c in bsdf.components):
            print("note: MERL tables hold reflection only; the transmission lobes are not written")
        table = meas.merl_table_from_bsdf(bsdf)
        meas.write_merl(table, args.merl)
        print(f"wrote {args.merl} (MERL layout, {meas.MERL_FILE_BYTES} bytes)")
    if args.output:
        m = _virtual(args.material, args)
        meas.write_csv(m, args.output, comment=f"material: {args.material}\n" + "\n".join(m.notes))
        print(f"wrote {args.output}: {len(m)} tuples ({int(m.transmission.sum())} transmission)")
    if not args.merl and not args.output:
        raise FitError("give -o FILE.csv and/or --merl FILE.binary")
    return 0


def add_fit_arguments(p) -> None:
    p.add_argument("data", help="goniophotometer .csv, MERL .binary, or virtual:MATERIAL (preset, JSON file)")
    p.add_argument("-o", "--output", default="fitted.json", help="material JSON to write (default fitted.json)")
    p.add_argument("--name", default=None, help="material name (default: the output's file name)")
    p.add_argument(
        "--model",
        default="thesis",
        choices=["thesis", "rational", "microfacet"],
        help="thesis (Kurt lobes, thesis 3.4.1), rational (Rational BRDF, seed 002) or microfacet (the glTF "
        "metallic-roughness GGX model: roughness, metallic, anisotropy, transmission; writes a gltf material)",
    )
    r = p.add_argument_group("rational model")
    r.add_argument("--eps", type=float, default=0.05, help="relative interval half-width (default 0.05)")
    r.add_argument(
        "--max-coefficients", type=int, default=40, help="most numerator + denominator coefficients (default 40)"
    )
    r.add_argument(
        "--theta-max", type=float, default=80.0, help="fitted theta_h, theta_d domain in degrees (default 80)"
    )
    p.add_argument("--lobes", type=int, default=1, help="reflection lobes K (default 1)")
    p.add_argument(
        "--transmission-lobes",
        type=int,
        default=None,
        help="transmission lobes (default: 1 if the data has transmission tuples, else 0)",
    )
    p.add_argument(
        "--fix",
        type=_assignment,
        action="append",
        default=[],
        metavar="PARAM=VALUE",
        help="fix a parameter: kd, ks|kt|k, mx, my, r0, alpha (every lobe) or lobeN.PARAM / tlobeN.PARAM; "
        "microfacet: roughness, metallic, anisotropy (signed: < 0 along the bitangent), transmission",
    )
    p.add_argument(
        "--range",
        type=_interval,
        action="append",
        default=[],
        metavar="PARAM=LO:HI",
        help="search interval of a parameter (defaults: k, r0, alpha 0:1; mx, my 0.001:1, log-spaced; "
        "microfacet: roughness 0.01:1 log-spaced, metallic, transmission 0:1, anisotropy -1:1)",
    )
    p.add_argument("--grid", type=int, default=8, help="values per parameter and iteration, n (default 8)")
    p.add_argument("--iterations", type=int, default=6, help="refinement iterations (default 6)")
    p.add_argument("--alternations", type=int, default=3, help="rounds of refitting each lobe (default 3)")
    p.add_argument("--metric", default="l1", choices=["l1", "l2"], help="Eq. 3.7 (l1, default) or squared (l2)")
    p.add_argument(
        "--no-polish",
        action="store_true",
        help="skip the Nelder-Mead step after each brute-force search (the thesis' method exactly)",
    )
    p.add_argument(
        "--diffuse",
        default="auto",
        choices=["auto", "histogram"],
        help="thesis model: kd from the BRDF histogram only where it lowers the L1 error by at least "
        "10 %% of the fit's L1 mass or half the kd = 0 fit's error, else 0 (auto, default: a conductor's "
        "lobe tail is no diffuse term), or always (histogram, thesis 3.4.1 exactly)",
    )
    p.add_argument(
        "--isotropic",
        action="store_true",
        help="tie my = mx, or anisotropy = 0 for microfacet (always on for MERL tables)",
    )
    p.add_argument(
        "--negative",
        default="error",
        choices=["error", "clamp", "mask"],
        help="negative p in a CSV: refuse (default), clamp to 0 or drop the tuple",
    )
    p.add_argument(
        "--merl-stride",
        type=_stride,
        default=(2, 3, 6),
        metavar="H,D,P",
        help="fit every H-th theta_h, D-th theta_d, P-th phi_d MERL cell (default 2,3,6: ~31k tuples)",
    )
    p.add_argument("--plot", default=None, metavar="PNG", help="draw measured vs fitted slices to PNG")
    p.add_argument(
        "--render",
        default=None,
        metavar="PNG",
        help="render the measurement as it is (MERL table or virtual:) and the fit on the preview sphere "
        "(reference) with their difference to PNG",
    )
    p.add_argument("--render-env", default="builtin:studio", help="environment of --render (default builtin:studio)")
    p.add_argument("--quiet", action="store_true", help="no per-iteration progress")
    _add_goniometer_arguments(p)


def add_measure_arguments(p) -> None:
    p.add_argument("material", help="preset name, JSON file or inline JSON object")
    p.add_argument("-o", "--output", default=None, help="goniophotometer CSV to write")
    p.add_argument("--merl", default=None, metavar="FILE.binary", help="also write the MERL table (isotropic only)")
    _add_goniometer_arguments(p)
