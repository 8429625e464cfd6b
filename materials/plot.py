"""Lobe plots for judging a material: polar plots of the BSDF in the plane of incidence and
across it, a 2D slice over the projected hemisphere, and the directional albedo curve."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .bsdf import BSDF
from .vec import direction_from_angles_deg

INCIDENCE_DEG = (0.0, 30.0, 60.0, 80.0)


def _plane_curve(bsdf: BSDF, wo: np.ndarray, plane_phi: float, n: int = 721):
    """f(wi, wo) |cos theta_i| along the great circle through n in the plane at azimuth
    ``plane_phi``; returns signed angle from +n (-180..180 deg) and RGB-mean values."""
    angle = np.linspace(-np.pi, np.pi, n)
    wi = np.stack([np.sin(angle) * np.cos(plane_phi), np.sin(angle) * np.sin(plane_phi), np.cos(angle)], -1)
    value = bsdf.eval(wi, np.broadcast_to(wo, wi.shape)).mean(axis=-1) * np.abs(wi[:, 2])
    return angle, value


def plot_material(bsdf: BSDF, title: str, out_path: str | Path, resolution: int = 401) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(14, 9.5))
    fig.suptitle(title, fontsize=13)
    colors = plt.cm.viridis(np.linspace(0.0, 0.85, len(INCIDENCE_DEG)))

    for panel, (plane_deg, label) in enumerate(
        (
            (0.0, "plane of incidence (phi = 0, along tangent)"),
            (90.0, "plane of incidence at phi = 90 (along bitangent)"),
        )
    ):
        ax = fig.add_subplot(2, 3, panel + 1, projection="polar")
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        for theta_o, color in zip(INCIDENCE_DEG, colors, strict=True):
            wo = direction_from_angles_deg(theta_o, plane_deg)
            angle, value = _plane_curve(bsdf, wo, np.radians(plane_deg))
            # Cube root as in the thesis' plots, so the diffuse floor and sharp peaks both show.
            ax.plot(angle, np.cbrt(value), color=color, lw=1.4, label=f"view {theta_o:.0f} deg")
            # Marker on the viewer direction.
            ax.plot([np.radians(theta_o)], [np.cbrt(value).max() * 1.05], marker="v", color=color, ms=5)
        ax.set_title(f"(f cos)^(1/3), {label}", fontsize=9)
        ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.25, -0.18))

    # 2D slice over the projected hemispheres for a 30 deg view.
    wo = direction_from_angles_deg(30.0, 0.0)
    grid = np.linspace(-1, 1, resolution)
    X, Y = np.meshgrid(grid, grid)
    inside = X**2 + Y**2 < 1
    Z = np.sqrt(np.clip(1 - X**2 - Y**2, 0, None))
    has_transmission = any(c.hemisphere == "transmission" for c in bsdf.components)
    for idx, (sign, name) in enumerate(((1.0, "reflection (upper hemisphere)"), (-1.0, "transmission (lower)"))):
        if sign < 0 and not has_transmission:
            ax = fig.add_subplot(2, 3, 4 + idx)
            ax.axis("off")
            ax.text(0.5, 0.5, "no transmission lobes", ha="center", va="center", fontsize=10)
            continue
        wi = np.stack([X, Y, sign * Z], -1)
        value = bsdf.eval(wi, np.broadcast_to(wo, wi.shape)).mean(-1) * Z
        value = np.where(inside, value, np.nan)
        ax = fig.add_subplot(2, 3, 4 + idx)
        im = ax.imshow(np.cbrt(value), extent=(-1, 1, -1, 1), origin="lower", cmap="inferno")
        ax.set_title(f"(f cos)^(1/3), {name}\nview at 30 deg from +x side", fontsize=9)
        ax.set_xlabel("wi.x (tangent)")
        ax.set_ylabel("wi.y (bitangent)")
        fig.colorbar(im, ax=ax, fraction=0.046)

    # Directional albedo curves.
    ax = fig.add_subplot(2, 3, 3)
    thetas = np.linspace(0, 89, 46)
    refl = np.array([bsdf.albedo(direction_from_angles_deg(t, 0.0), order=96)[0] for t in thetas])
    trans = np.array([bsdf.albedo(direction_from_angles_deg(t, 0.0), order=96)[1] for t in thetas])
    for c, cname in enumerate("rgb"):
        ax.plot(thetas, refl[:, c], color=cname, lw=1.2, label=f"reflectance {cname.upper()}")
        if trans.max() > 0:
            ax.plot(
                thetas,
                trans[:, c],
                color=cname,
                lw=1.2,
                ls="--",
                label=f"transmittance {cname.upper()}",
            )
    ax.set_xlabel("viewing angle theta_o (deg)")
    ax.set_ylabel("directional albedo")
    ax.set_ylim(0, max(1.05, float(np.max(refl + trans)) * 1.05))
    ax.axhline(1.0, color="gray", lw=0.6, ls=":")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax.set_title("directional albedo (Eq. 2.7, 2.8)", fontsize=9)

    ax = fig.add_subplot(2, 3, 6)
    ax.axis("off")
    ax.text(0.0, 1.0, _describe(bsdf), va="top", family="monospace", fontsize=8)

    fig.tight_layout()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_path, dpi=110)
    plt.close(fig)
    return out_path


def _describe(bsdf: BSDF) -> str:
    lines = [f"components of {bsdf.name}:"]
    for comp, prob in zip(bsdf.components, bsdf.selection_probabilities, strict=True):
        extra = ""
        dist = getattr(comp, "distribution", None)
        if dist is not None:
            extra = f" {dist.kind} ax={dist.alpha_x:g} ay={dist.alpha_y:g}"
        lines.append(f"  {comp.name}{extra}  (sampled {prob:.0%})")
    return "\n".join(lines)
