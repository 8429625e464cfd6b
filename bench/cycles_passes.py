"""Where lobeview's error against Cycles lies: Cycles' light passes split the object's pixels by
how much of the glossy lobe sees the sky past the object itself (``python -m lobeview.bench.cycles
--passes``; issue 40).

Cycles' combined image is DiffCol (DiffDir + DiffInd) + GlossCol (GlossDir + GlossInd). Under the
white sky (radiance 1) GlossDir is the share of the glossy lobe, weighed by the lobe, that reaches
the sky: 1 on an open surface, below 1 where the object hides part of its own reflection (a
crevice, a ledge below a wall, the inside of an ear), and GlossInd is the light those hidden
directions bring back from the object. lobeview's glossy visibility at the same pixel is read
back from its image as (lobeview - Cycles' diffuse) / GlossCol: exact where lobeview's diffuse
and glossy reflectance equal Cycles' (the open pixels check it: there it reads about 1).
Under any other environment GlossDir is an irradiance, not a visibility; the split is made under
the white sky only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PASS_SPP = 128  # the passes' own Cycles render: visibilities are smooth, a few % noise is enough
GLOSSY_SHADOW = 0.9  # a pixel's glossy lobe counts as self-occluded below this visible share
MIN_GLOSSY_COLOUR = 0.05  # ... where it has a glossy reflectance worth the name (grey GlossCol)
VISIBILITY_BANDS = ((0.0, 0.3), (0.3, 0.6), (0.6, 0.9), (0.9, 1.5))


def read_layers_exr(path: Path) -> dict:
    """A multilayer EXR of Cycles' view layer: {pass name: (H, W, 3 or 4) float32}, the layer's
    prefix dropped ('ViewLayer.GlossDir' -> 'GlossDir')."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=False) as exr:
        channels = exr.channels()
        return {name.rsplit(".", 1)[-1]: np.asarray(channel.pixels, dtype=np.float32)
                for name, channel in channels.items() if np.asarray(channel.pixels).ndim == 3}  # fmt: skip


def passes_job(job: dict) -> dict:
    """The job of ``job``'s light passes: the same view at PASS_SPP, into its own file."""
    return dict(job, passes=True, spp=PASS_SPP, out=str(Path(job["out"]).with_suffix(".passes.exr")))


def render_passes(job: dict, path: Path | None, run) -> dict:
    """Cycles' light passes of a :func:`passes_job`, rendered by ``run(job)`` (bench/cycles.py
    run_worker: the seconds it took) or read from the cache file ``path`` (None: no cache) where
    an earlier run wrote them: {pass: (H, W, 3)}."""
    from lobeview.bench.cycles_worker import PASSES
    from lobeview.core.cache import read_cache_file, write_cache_file

    width, height = job["size"]

    def read(file: Path) -> dict:
        with np.load(file) as data:
            layers = {name: data[name] for name in PASSES}
        if any(v.shape != (height, width, 3) or not np.all(np.isfinite(v)) for v in layers.values()):
            raise ValueError("passes of the wrong shape or not finite")
        return layers

    found = read_cache_file(path, read, "Cycles passes")
    if found is not None:
        return found
    seconds = run(job)
    layers = read_layers_exr(Path(job["out"]))
    missing = [name for name in PASSES if name not in layers]
    if missing:
        raise RuntimeError(f"Cycles wrote no {missing} passes into {job['out']}")
    layers = {name: layers[name][..., :3] for name in PASSES}
    print(f"[cycles] passes in {seconds:.1f} s", flush=True)
    if path is not None:
        write_cache_file(path, lambda handle: np.savez(handle, **layers))
    return layers


def glossy_visibility(layers: dict) -> tuple[np.ndarray, np.ndarray]:
    """(Cycles' glossy visibility GlossDir, its glossy reflectance GlossCol), grey, (H, W) each."""
    return layers["GlossDir"].mean(axis=-1), layers["GlossCol"].mean(axis=-1)


def self_occlusion_split(image: np.ndarray, truth: np.ndarray, layers: dict, mask: np.ndarray) -> dict:
    """How much of ``image``'s squared error against ``truth`` (both (H, W, 3), over ``mask``) lies
    on the pixels whose glossy lobe the object hides from itself in Cycles (visibility below
    GLOSSY_SHADOW), and per band of Cycles' visibility (VISIBILITY_BANDS) the medians of Cycles'
    glossy light over its colour, GlossDir + GlossInd (what the sky and the object's own surface
    bring), and of lobeview's, read back as (image - Cycles' diffuse) / GlossCol."""
    visibility, colour = glossy_visibility(layers)
    cycles_glossy = visibility + layers["GlossInd"].mean(axis=-1)
    diffuse = (layers["DiffCol"] * (layers["DiffDir"] + layers["DiffInd"])).mean(axis=-1)
    glossy = mask & (colour > MIN_GLOSSY_COLOUR)
    hidden = glossy & (visibility < GLOSSY_SHADOW)
    squared = np.sum((image[..., :3] - truth[..., :3]) ** 2, axis=-1)
    total = float(squared[mask].sum())
    lobeview_visibility = (image[..., :3].mean(axis=-1) - diffuse) / np.maximum(colour, 1e-6)
    bands = []
    for low, high in VISIBILITY_BANDS:
        band = glossy & (visibility >= low) & (visibility < high)
        bands.append({"band": [low, high], "pixels": int(band.sum()),
                      "cycles": float(np.median(cycles_glossy[band])) if band.any() else None,
                      "lobeview": float(np.median(lobeview_visibility[band])) if band.any() else None})  # fmt: skip
    rest = mask & ~hidden
    elsewhere = (
        np.sqrt(squared[rest].mean() / 3.0) / max(float(truth[..., :3][rest].mean()), 1e-12) if rest.any() else 0.0
    )
    return {
        "hidden_pixel_share": float(hidden.sum() / max(mask.sum(), 1)),
        "hidden_error_share": float(squared[hidden].sum() / total) if total > 0 else 0.0,
        "rel_rmse_elsewhere": float(elsewhere),
        "bands": bands,
    }


def markdown_lines(rows: list, methods: list, figure: str | None = None) -> list:
    """The split's table: per case under the white sky and method, the share of pixels whose
    glossy lobe Cycles finds hidden, the share of the squared error on them, the relative RMSE on
    the other pixels, and Cycles' / lobeview's median glossy visibility per band; ``figure``: the
    path of the visibility figure (:func:`visibility_figure_row` per case)."""
    rows = [row for row in rows if "self_occlusion" in row]
    if not rows:
        return []
    header = " | ".join(f"{low:g}-{high:g}" if high <= 1 else f">= {low:g}" for low, high in VISIBILITY_BANDS)
    lines = ["", f"Where the error lies (`--passes`; white sky only): Cycles' glossy direct pass at {PASS_SPP} spp "
             f"splits the object's pixels by the share of the glossy lobe that sees the sky past the object; "
             f"'hidden' is below {GLOSSY_SHADOW}. Per band of that share: the median glossy light over its colour, "
             "Cycles' (direct + indirect: the sky and the object's own surface) / lobeview's (read back as (image - "
             "Cycles' diffuse) / Cycles' glossy colour); pixels in the band.", "",
             f"| case | method | hidden pixels | their share of the squared error | rel. RMSE % elsewhere | {header} |",
             "|---|---|---|---|---|" + "---|" * len(VISIBILITY_BANDS)]  # fmt: skip
    for row in rows:
        for method in methods:
            split = row["self_occlusion"][method]
            cells = [f"{b['cycles']:.2f} / {b['lobeview']:.2f} ({b['pixels']})" if b["pixels"] else "-"
                     for b in split["bands"]]  # fmt: skip
            lines.append(f"| {row['case']} | {method} | {100 * split['hidden_pixel_share']:.1f} % | "
                         f"{100 * split['hidden_error_share']:.0f} % | {100 * split['rel_rmse_elsewhere']:.1f} | "
                         + " | ".join(cells) + " |")  # fmt: skip
    if figure:
        lines += [
            "",
            f"Figure: `{figure}` (one row per case above, the reference: Cycles' glossy light over its "
            "colour | lobeview's | lobeview's excess red, deficit blue, x2; grey: no glossy reflectance).",
        ]
    return lines


def visibility_figure_row(image: np.ndarray, layers: dict, mask: np.ndarray) -> np.ndarray:
    """One figure row, (H, 3 W, 3) in [0, 1]: Cycles' glossy light over its colour (direct +
    indirect: 1 white, 0 black) | lobeview's, read back from ``image`` as in
    :func:`self_occlusion_split` | lobeview's excess in red and its deficit in blue (x2), over
    the pixels with a glossy reflectance; grey elsewhere."""
    visibility, colour = glossy_visibility(layers)
    cycles = visibility + layers["GlossInd"].mean(axis=-1)
    diffuse = (layers["DiffCol"] * (layers["DiffDir"] + layers["DiffInd"])).mean(axis=-1)
    lobeview = (image[..., :3].mean(axis=-1) - diffuse) / np.maximum(colour, 1e-6)
    glossy = mask & (colour > MIN_GLOSSY_COLOUR)

    def grey(values: np.ndarray) -> np.ndarray:
        panel = np.full(values.shape + (3,), 0.25)
        panel[glossy] = np.clip(values[glossy], 0.0, 1.0)[:, None]
        return panel

    difference = np.zeros(cycles.shape + (3,))
    excess = np.clip(2.0 * (lobeview - cycles), 0.0, 1.0)
    deficit = np.clip(2.0 * (cycles - lobeview), 0.0, 1.0)
    difference[..., 0] = np.where(glossy, excess, 0.25)
    difference[..., 1] = np.where(glossy, 0.0, 0.25)
    difference[..., 2] = np.where(glossy, deficit, 0.25)
    return np.concatenate([grey(cycles), grey(lobeview), difference], axis=1)
