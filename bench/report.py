"""The benchmark's Markdown tables and plots, from a run's data (also rewritten from its JSON by
``lobeview bench report``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lobeview.core.methods import DEFAULT_FIS_LOD_BIAS, DEFAULT_LOBE_LOD_BIAS, Method

from .matrix_config import PSNR_TARGETS, THESIS_FPS
from .metrics import first_crossing, interpolate_log, pareto_front


def _time(cell) -> float:
    return cell["ms"]


def _family(method: str) -> str:
    return Method.parse(method).family


def _groups(cells):
    """(view, material, resolution) -> cells with errors."""
    groups: dict = {}
    for c in cells:
        if "psnr" in c:
            groups.setdefault((c["view"], c["material"], c["resolution"]), []).append(c)
    return groups


def write_plots(base: Path, cells, sweep, references) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    groups = _groups(cells)
    floors = {(r["view"], r["material"], r["resolution"]): r["psnr_floor"] for r in references}
    colours = {"lobe": "tab:blue", "lobe+norm": "tab:cyan", "fis": "tab:orange", "mc": "tab:grey"}
    colours.update({"lobe+ring": "tab:purple", "lobe+norm+ring": "tab:pink", "prefiltered": "tab:green"})
    for resolution in sorted({k[2] for k in groups}):
        keys = [k for k in groups if k[2] == resolution]
        columns = min(len(keys), 4)
        rows = -(-len(keys) // columns)
        fig, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 3.4 * rows), squeeze=False)
        for ax, key in zip(axes.ravel(), keys, strict=False):
            group = groups[key]
            times = [_time(c) for c in group]
            psnrs = [c["psnr"] for c in group]
            front = pareto_front(times, [-p for p in psnrs])
            for family in ("lobe", "lobe+norm", "lobe+ring", "lobe+norm+ring", "fis", "mc", "prefiltered"):
                members = sorted((c for c in group if _family(c["method"]) == family), key=_time)
                if not members:
                    continue
                style = "o-" if family in ("lobe", "lobe+ring", "fis") else "s"
                ax.plot(
                    [_time(c) for c in members],
                    [c["psnr"] for c in members],
                    style,
                    color=colours[family],
                    label=family,
                    ms=4,
                )
                for c in members:
                    if family in ("lobe", "lobe+ring", "fis", "mc"):
                        ax.annotate(
                            c["method"].split("-")[1].split("+")[0],
                            (_time(c), c["psnr"]),
                            fontsize=6,
                            xytext=(2, 2),
                            textcoords="offset points",
                        )
            ax.plot(
                [t for t, f in zip(times, front, strict=True) if f],
                [p for p, f in zip(psnrs, front, strict=True) if f],
                "o",
                mfc="none",
                mec="red",
                ms=9,
                label="Pareto front",
            )
            if key in floors:
                ax.axhline(floors[key], color="k", ls=":", lw=0.8, label="reference floor")
            ax.set_xscale("log")
            ax.set_title(f"{key[0]} - {key[1]}", fontsize=8)
            ax.set_xlabel("ms / frame", fontsize=7)
            ax.set_ylabel("PSNR (dB)", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.grid(alpha=0.3, which="both")
        for ax in axes.ravel()[len(keys) :]:
            ax.axis("off")
        axes.ravel()[0].legend(fontsize=6)
        fig.suptitle(f"PSNR against time per frame, {resolution} (numbers: samples per lobe)", fontsize=10)
        fig.tight_layout()
        path = Path(f"{base}-pareto-{resolution}.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    if sweep:
        fig, ax = plt.subplots(figsize=(5.5, 3.6))
        for method in sorted({r["method"] for r in sweep}):
            biases = sorted({r["bias"] for r in sweep if r["method"] == method})
            score = [
                _geomean([r["rel_rmse"] for r in sweep if r["method"] == method and r["bias"] == b]) for b in biases
            ]
            ax.plot(biases, score, "o-", label=method)
        ax.set_xlabel("MIP level bias b")
        ax.set_ylabel("geometric mean relRMSE")
        ax.set_title("LOD bias sweep (sphere views, all materials)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = Path(f"{base}-lod-bias.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def stamped_report_path(folder, prefix: str, module: str, argv) -> tuple[Path, str, str]:
    """(folder / prefix-STAMP.md, the stamp, the command line that made it) for a bench run as
    ``python -m lobeview.bench.<module>`` with ``argv`` (None: the process's); the folder is made."""
    import datetime
    import sys

    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    arguments = argv if argv is not None else sys.argv[1:]
    command = f"python -m lobeview.bench.{module} " + " ".join(arguments)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return folder / f"{prefix}-{stamp}.md", stamp, command.strip()


def write_markdown_report(folder: Path, name: str, lines: list[str]) -> Path:
    """Write a bench's Markdown ``lines`` to folder/name (the folder made if missing), print them
    and the path; returns the path."""
    path = Path(folder) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))
    print(f"wrote {path}")
    return path


def write_image_rows(out: Path, name: str, rows: list[np.ndarray]) -> Path:
    """A figure of image rows (each (H, W, 3) in [0, 1], stacked top to bottom) as out/name,
    8-bit PNG; the folder is made if missing."""
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    Image.fromarray((np.concatenate(rows, axis=0) * 255 + 0.5).astype(np.uint8)).save(path)
    return path


def _geomean(values) -> float:
    values = np.maximum(np.asarray(values, float), 1e-12)
    return float(np.exp(np.mean(np.log(values))))


def sweep_winners(sweep) -> dict:
    """method -> (best bias by mean PSNR, {bias: mean PSNR}, {bias: geometric-mean relRMSE}).
    PSNR of the tonemapped image decides (what a viewer sees, and what the targets of the
    report are stated in); relRMSE weighs the brightest texels and is listed beside it."""
    winners = {}
    for method in sorted({r["method"] for r in sweep}):
        biases = sorted({r["bias"] for r in sweep if r["method"] == method})
        rows = {b: [r for r in sweep if r["method"] == method and r["bias"] == b] for b in biases}
        psnr = {b: float(np.mean([r["psnr"] for r in rows[b]])) for b in biases}
        rel = {b: _geomean([r["rel_rmse"] for r in rows[b]]) for b in biases}
        winners[method] = (max(psnr, key=psnr.get), psnr, rel)
    return winners


def write_markdown(path: Path, data: dict, plots: list[Path]) -> None:
    meta, cells, sweep, references, fps = data["meta"], data["cells"], data["sweep"], data["references"], data["fps"]
    s = meta["settings"]
    timer = (
        "GPU timer query (GL_TIME_ELAPSED) around the shading pass"
        if s.get("timer") == "gpu"
        else "wall clock around the shading pass + glFinish (a software renderer: its timer queries do not "
        "cover rasterisation)"
    )
    lines = [
        f"# lobeview bench{' (--quick)' if meta['quick'] else ''}",
        "",
        f"- date: {meta['date']}",
        f"- device: {meta['device']}",
        *([f"- command: `{meta['command']}`"] if meta.get("command") else []),
        f"- time: median of {s['repeats']} frames after a warm-up; {timer}; both clocks are in the JSON",
        f"- reference: `reference` (MIS), {s['reference_spp']} samples per lobe as two independent halves; "
        "'floor' is the PSNR its own noise allows (PSNR of the halves + 6 dB)"
        if references
        else "- errors: none measured (a timing-only run, --error-resolutions none)",
        "- errors on the view-dependent pixels (sphere: the object; demo: objects with cube maps): relRMSE of "
        "linear radiance, PSNR of the 8-bit sRGB image after ACES with the reference's median luminance at "
        "0.18, mean LDR-FLIP (flip-evaluator, 67 ppd) of the same tonemapped image",
        "- memory: GPU textures the method reads per cube (radiance cube + MIP chain, importance tables, albedo "
        "table or prefiltered maps), summed over the scene's cube maps",
        "- first frame s: the warm-up frame (shader compilation; for prefiltered methods also the fits and "
        "maps not yet built: methods run in the order listed per view, so maps an earlier mode built, or "
        "that the --cache folder holds, cost ~0 here)",
        f"- LOD bias: fis-N {DEFAULT_FIS_LOD_BIAS:+g}, lobe-N {DEFAULT_LOBE_LOD_BIAS:+g} (defaults, see the sweep)",
        f"- cube faces {s['face_size']}^2; views: " + ", ".join(s["views"]),
        "",
    ]
    for p in plots:
        lines.append(f"![{p.stem}]({p.name})")
    lines.append("")
    groups = _groups(cells)
    floors = {(r["view"], r["material"], r["resolution"]): r for r in references}

    lines += ["## Fastest method reaching a PSNR target", ""]
    lines.append(
        "| view | material | resolution | floor (dB) | " + " | ".join(f"{t:g} dB" for t in PSNR_TARGETS) + " |"
    )
    lines.append("|---|---|---|---|" + "---|" * len(PSNR_TARGETS))
    for key, group in groups.items():
        floor = floors.get(key, {}).get("psnr_floor", float("nan"))
        entries = []
        for target_db in PSNR_TARGETS:
            reaching = [c for c in group if c["psnr"] >= target_db]
            if reaching:
                best = min(reaching, key=_time)
                entries.append(f"{best['method']} ({_time(best):.1f} ms)")
            else:
                best = max(group, key=lambda c: c["psnr"])
                if best["psnr"] < floor - 3.0:  # the reference resolves that no method gets there
                    entries.append(f"none (best {best['method']} {best['psnr']:.1f})")
                else:
                    entries.append(f"not measurable (best {best['method']} {best['psnr']:.1f}, floor {floor:.1f})")
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {floor:.1f} | " + " | ".join(entries) + " |")
    lines.append("")

    lines += [
        "## lobe-N against fis-N",
        "",
        "At equal time: fis-N's PSNR interpolated (log time) at lobe-N's time. At equal error: the time and "
        "the samples fis-N needs to reach lobe-N's PSNR (first crossing, log-linear); '-' where fis-N's "
        "measured range does not reach.",
        "",
        "| view | material | resolution | lobe-N | ms | PSNR | fis PSNR at equal time | fis ms at equal PSNR "
        "| fis N at equal PSNR |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key, group in groups.items():
        fis = [c for c in group if _family(c["method"]) == "fis"]
        if len(fis) < 2:
            continue
        fis_t = [_time(c) for c in fis]
        fis_p = [c["psnr"] for c in fis]
        fis_n = [int(c["method"].split("-")[1]) for c in fis]
        for c in sorted((c for c in group if _family(c["method"]) == "lobe"), key=_time):
            at_time = interpolate_log(_time(c), fis_t, fis_p)
            t_needed = first_crossing(c["psnr"], fis_t, fis_p)
            n_needed = first_crossing(c["psnr"], fis_n, fis_p)
            lines.append(
                f"| {key[0]} | {key[1]} | {key[2]} | {c['method']} | {_time(c):.1f} | {c['psnr']:.2f} | "
                f"{_fmt(at_time, '.2f')} | {_fmt(t_needed, '.1f')} | {_fmt(n_needed, '.0f')} |"
            )
    lines.append("")

    if sweep:
        winners = sweep_winners(sweep)
        lines += [
            "## MIP level bias (lod = 0.5 log2(Omega_s / Omega_p) + b)",
            "",
            "Mean PSNR (dB) / geometric-mean relRMSE over the sphere views and materials at the error resolution;"
            " the best bias by PSNR is marked.",
            "",
            "| method | " + " | ".join(f"b = {b:+g}" for b in sorted({r["bias"] for r in sweep})) + " | best b |",
            "|---|" + "---|" * (len({r["bias"] for r in sweep}) + 1),
        ]
        for method, (best, psnr, rel) in winners.items():
            values = " | ".join(
                (f"**{psnr[b]:.2f}** / {rel[b]:.4f}" if b == best else f"{psnr[b]:.2f} / {rel[b]:.4f}")
                for b in sorted(psnr)
            )
            lines.append(f"| {method} | {values} | {best:+g} |")
        lines.append("")

    lines += ["## All cells", ""]
    lines.append(
        "| view | material | resolution | method | ms / frame | GPU timer ms | first frame s | PSNR dB | relRMSE"
        " | FLIP | memory MiB |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cells:
        gpu = _fmt(c.get("gpu_ms"), ".1f")
        lines.append(
            f"| {c['view']} | {c['material']} | {c['resolution']} | {c['method']} | {c['ms']:.1f} | {gpu} | "
            f"{_fmt(c.get('first_frame_s'), '.2f')} | {_fmt(c.get('psnr'), '.2f')} | "
            f"{_fmt(c.get('rel_rmse'), '.4f')} | {_fmt(c.get('flip'), '.4f')} | "
            f"{c['memory_mb']:.1f} |"
        )
    lines.append("")
    lines += ["## References", "", "| view | material | resolution | environment | spp | seconds | floor (dB) |"]
    lines.append("|---|---|---|---|---|---|---|")
    for r in references:
        lines.append(
            f"| {r['view']} | {r['material']} | {r['resolution']} | {r['environment']} | {r['spp']} | "
            f"{r['seconds']:.1f} | {r['psnr_floor']:.1f} |"
        )
    lines.append("")
    if fps:
        size = s["fps_size"]
        lines += [
            f"## Frame rate by samples (thesis tables 4.1/4.2 layout), {size[0]}x{size[1]}, lobe-N",
            "",
            "Full: a glossy plane covers the frame; half: it covers the left half (background elsewhere). "
            "Thesis: table 4.1 (cube maps, GeForce GTS 450, 2012).",
            "",
            "| samples | full ms | full fps | half ms | half fps | fraction full / half | thesis fps full / half |",
            "|---|---|---|---|---|---|---|",
        ]
        for row in fps:
            full, half = row["full"], row["half"]
            thesis = THESIS_FPS.get(row["samples"])
            lines.append(
                f"| {row['samples']} | {full['ms']:.1f} | {1000 / full['ms']:.1f} | {half['ms']:.1f} | "
                f"{1000 / half['ms']:.1f} | {full['fraction']:.2f} / {half['fraction']:.2f} | "
                f"{'' if thesis is None else f'{thesis[0]} / {thesis[1]}'} |"
            )
        lines.append("")
    path.write_text("\n".join(lines) + "\n")


def _fmt(value, spec: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return format(value, spec)
