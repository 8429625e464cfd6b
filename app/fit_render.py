"""``lobeview fit ... --render PNG``: the measurement rendered as it is beside its fit (issue 44).

The preview sphere under an environment (``--render-env``, default builtin:studio), both with
``reference``: the measurement (a MERL table as ``measured:FILE``, materials/measured.py; a
``virtual:`` or ``virtual-merl:`` material as the material itself) | the fitted material | their
|difference| x4 (relative to the measurement's 99th percentile), with the relRMSE of linear
radiance on the sphere's pixels printed and written into the figure. A goniophotometer CSV holds
scattered tuples, not a BRDF that can be rendered: ``--render`` refuses it with that reason.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from lobeview.materials import measurement as meas
from lobeview.materials.spec import MEASURED_PREFIX, build_bsdf, load_material

RENDER_SIZE = 160
RENDER_SPP = 256


class RenderError(ValueError):
    """Data that cannot be rendered as they are."""


def check_renderable(data: str) -> None:
    """Raise :class:`RenderError` before a fit whose data ``--render`` could not render."""
    if not (data.startswith(("virtual:", "virtual-merl:")) or Path(data).suffix.lower() == ".binary"):
        raise RenderError(
            f"--render: {data} holds scattered goniophotometer tuples, not a BRDF that can be rendered as it is; "
            "it needs a MERL .binary table or virtual:MATERIAL"
        )


def measurement_bsdf(data: str):
    """(BSDF, label) of the measured data rendered as it is."""
    for prefix in ("virtual:", "virtual-merl:"):
        if data.startswith(prefix):
            material = data[len(prefix) :]
            if prefix == "virtual:":
                return build_bsdf(load_material(material)), f"virtual:{Path(material).stem}"
            # The table itself, through the measured material (its nearest-cell steps included).
            # The lobe holds the table once built: the 35 MB file goes with the folder.
            with tempfile.TemporaryDirectory(prefix="lobeview-render-") as folder:
                path = Path(folder) / f"{Path(material).stem}.binary"
                meas.write_merl(meas.merl_table_from_bsdf(build_bsdf(load_material(material))), path)
                return build_bsdf(load_material(f"{MEASURED_PREFIX}{path}")), f"table of {Path(material).stem}"
    check_renderable(data)
    return build_bsdf(load_material(f"{MEASURED_PREFIX}{data}")), Path(data).name


def render_comparison(data: str, desc: dict, out: str, env_spec: str = "builtin:studio", say=print) -> float:
    """Write the figure (measurement | fit | |error| x4) to ``out``; returns the relRMSE."""
    from PIL import Image, ImageDraw

    from lobeview.bench.metrics import exposure_for
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.meshes import uv_sphere
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.preview import PREVIEW_CAMERA, PreviewRenderer
    from lobeview.viewer.tonemap import tonemap

    truth_bsdf, truth_label = measurement_bsdf(data)
    ctx = create_headless_context()
    try:
        renderer = PreviewRenderer(ctx, load_environment(env_spec), uv_sphere(), size=(RENDER_SIZE, RENDER_SIZE))
        position, target, up, fov = PREVIEW_CAMERA
        camera = Camera(position=position, target=target, up=up, fov_y=fov)
        say(f"rendering the measurement and the fit ({RENDER_SIZE} px, reference {RENDER_SPP} spp) ...")
        truth = renderer.render(camera, truth_bsdf, "reference", spp=RENDER_SPP, background=False)
        fitted = renderer.render(camera, build_bsdf(desc), "reference", spp=RENDER_SPP, background=False)
        renderer.release()
    finally:
        ctx.release()
    mask = truth.mask
    a, b = fitted.radiance, truth.radiance
    rel = float(np.sqrt(((a[mask] - b[mask]) ** 2).mean() / max((b[mask] ** 2).mean(), 1e-30)))
    exposure = exposure_for(b, mask)
    scale = max(float(np.percentile(b[mask], 99)), 1e-6)
    error = np.clip(4.0 * np.abs(a - b).mean(axis=-1, keepdims=True) / scale, 0.0, 1.0) * mask[..., None]
    tiles = [np.clip(tonemap(b, "aces", exposure), 0, 1), np.clip(tonemap(a, "aces", exposure), 0, 1),
             np.repeat(error, 3, axis=-1)]  # fmt: skip
    # ~26 characters of PIL's default font fit a 160-pixel tile
    labels = [truth_label[:26], f"{desc['model']} fit", f"|err| x4: {100 * rel:.1f} % relRMSE"]
    image = Image.fromarray((np.concatenate(tiles, axis=1) * 255 + 0.5).astype(np.uint8))
    canvas = Image.new("RGB", (image.width, image.height + 14))
    canvas.paste(image, (0, 14))
    draw = ImageDraw.Draw(canvas)
    for i, text in enumerate(labels):
        draw.text((i * RENDER_SIZE + 2, 1), text, fill=(255, 255, 255))
    canvas.save(out)
    say(f"rendered against the measurement: relRMSE {100 * rel:.2f} % (sphere pixels, linear); wrote {out}")
    return rel
