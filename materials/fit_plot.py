"""Measured against fitted transfer probabilities in the plane of incidence (the layout of thesis
Figures 3.12, 3.15 and 3.18): one panel per incidence (columns theta_i, rows phi_i and
hemisphere), measurements as green points, each model as a line, cube root of p as in the thesis.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .fit import model_transfer
from .lobe_fit import LUMINANCE
from .measurement import Measurement, angles_deg
from .vec import spherical_direction

PLOT_THETA_I_DEG = (0.0, 20.0, 65.0)
PLOT_PHI_I_DEG = (0.0, 90.0)
PLANE_TOLERANCE_DEG = 0.5  # measured tuples this close to the plane of incidence are drawn


def _nearest(values: np.ndarray, wanted) -> list[float]:
    out = []
    for w in wanted:
        v = float(values[np.argmin(np.abs(values - w))])
        if v not in out:
            out.append(v)
    return out


def _in_plane(m: Measurement, theta_i: float, phi_i: float, below: bool):
    """Signed detector angle (+ on the mirror side) and p of the tuples of one incidence lying
    within PLANE_TOLERANCE_DEG of its plane of incidence, on one hemisphere."""
    t_i, p_i = angles_deg(m.wi)
    sel = np.abs(t_i - theta_i) < 0.01
    if theta_i >= 0.01:  # at normal incidence the azimuth means nothing: every plane is scanned
        sel &= np.abs((p_i - phi_i + 180) % 360 - 180) < 0.01
    sel &= m.transmission if below else ~m.transmission
    wo = m.wo[sel]
    normal = np.array([-np.sin(np.radians(phi_i)), np.cos(np.radians(phi_i)), 0.0])  # plane's normal
    off_plane = np.degrees(np.arcsin(np.clip(np.abs(wo @ normal), 0, 1)))
    near = off_plane < PLANE_TOLERANCE_DEG
    wo = wo[near]
    along = wo @ np.array([np.cos(np.radians(phi_i)), np.sin(np.radians(phi_i)), 0.0])
    theta = np.degrees(np.arccos(np.clip(np.abs(wo[:, 2]), 0, 1)))
    signed = np.where(along <= 0, theta, -theta)  # mirror side (away from the light) positive
    p = m.p[sel][near]
    value = p[:, 0] if m.channels == 1 else p @ LUMINANCE
    order = np.argsort(signed)
    return signed[order], value[order]


def _model_curve(desc: dict, theta_i: float, phi_i: float, below: bool, n: int = 721):
    angle = np.radians(np.linspace(-89.5, 89.5, n))
    phi = np.radians(phi_i)
    # signed angle > 0: azimuth phi_i + 180 (the mirror side)
    wo = spherical_direction(np.abs(angle), np.where(angle > 0, phi + np.pi, phi))
    if below:
        wo[:, 2] = -wo[:, 2]
    wi = np.broadcast_to(spherical_direction(np.radians(theta_i), phi), wo.shape)
    probe = Measurement(wi, wo, np.zeros((n, 1)), np.ones(n))
    value = model_transfer(desc, probe) @ LUMINANCE
    return np.degrees(angle), value


def plot_fit(m: Measurement, models: dict[str, dict], out_path, title: str = "") -> Path:
    """Draw ``m`` against each material of ``models`` (label -> description); returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    incid = m.incidences()
    thetas = _nearest(incid[:, 0], PLOT_THETA_I_DEG)
    tilted = incid[incid[:, 0] >= 0.01]
    phis = _nearest(tilted[:, 1] if len(tilted) else incid[:, 1], PLOT_PHI_I_DEG)
    hemis = [False, True] if m.transmission.any() else [False]
    rows = [(phi, below) for below in hemis for phi in phis]
    fig, axes = plt.subplots(len(rows), len(thetas), figsize=(4.2 * len(thetas), 3.2 * len(rows)), squeeze=False)
    colours = ["tab:red", "tab:blue", "tab:orange", "tab:purple"]
    for r, (phi, below) in enumerate(rows):
        for c, theta in enumerate(thetas):
            ax = axes[r][c]
            x, y = _in_plane(m, theta, phi, below)
            ax.plot(x, np.cbrt(y), ".", color="tab:green", ms=3, label="measured")
            for (label, desc), colour in zip(models.items(), colours, strict=False):
                mx, my = _model_curve(desc, theta, phi, below)
                ax.plot(mx, np.cbrt(my), "-", color=colour, lw=1.2, label=label)
            hemi = "transmission" if below else "reflection"
            ax.set_title(f"theta_i {theta:g}, phi_i {phi:g} deg ({hemi})", fontsize=9)
            ax.set_xlim(-90, 90)
            ax.grid(alpha=0.3)
            if c == 0:
                ax.set_ylabel("cbrt(p)  [p = f |cos theta_o|]")
            if r == len(rows) - 1:
                ax.set_xlabel("detector angle in plane (deg, + = mirror side)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title or m.name, fontsize=11)
    fig.tight_layout()
    out = Path(out_path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
