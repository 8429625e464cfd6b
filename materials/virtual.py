"""Virtual measurements (issue 11): a lobeview material measured like a goniophotometer, the
input of every fit test and benchmark. Apart from materials/measurement.py because it builds the
material (materials/spec.py), which imports the Rational BRDF, which reads measurements."""

from __future__ import annotations

import math

import numpy as np

from .measurement import (
    THESIS_PHI_I_DEG,
    THESIS_THETA_I_DEG,
    Measurement,
    goniometer_directions,
    renderer_pair,
    sample_frame_eval,
)
from .spec import build_bsdf


def virtual_measurement(
    desc: dict,
    theta_i_deg=THESIS_THETA_I_DEG,
    phi_i_deg=THESIS_PHI_I_DEG,
    theta_step_deg: float = 5.0,
    phi_step_deg: float = 15.0,
    noise: float = 0.0,
    outliers: float = 0.0,
    seed: int = 0,
    name: str | None = None,
) -> Measurement:
    """Measure a lobeview material (a validated description) like a goniophotometer.

    ``noise``: relative Gaussian noise (sigma = noise x value, plus noise x 1e-3 / pi absolute, a
    sensor floor), clamped at 0. ``outliers``: fraction of tuples replaced by spikes (10-100 x the
    median non-zero value), the failure mode the thesis' L1 metric is chosen against.
    """
    bsdf = build_bsdf(desc)
    transmission = any(c.hemisphere == "transmission" for c in bsdf.components)
    wi, wo, weight = goniometer_directions(theta_i_deg, phi_i_deg, theta_step_deg, phi_step_deg, transmission)
    ri, ro = renderer_pair(wi, wo)
    f = sample_frame_eval(bsdf, ri, ro)
    p = f * np.abs(wo[:, 2:3])
    rng = np.random.default_rng(seed)
    if noise > 0:
        p = np.maximum(p + rng.normal(size=p.shape) * noise * (p + 1e-3 / math.pi), 0.0)
    if outliers > 0:
        count = int(round(outliers * len(p)))
        rows = rng.choice(len(p), size=count, replace=False)
        scale = float(np.median(p[p > 0])) if (p > 0).any() else 1.0
        p[rows] = scale * rng.uniform(10.0, 100.0, size=(count, 1))
    label = name or desc.get("name") or desc.get("description") or desc["model"]
    notes = [
        f"virtual measurement: theta_i {list(theta_i_deg)} deg, phi_i {list(phi_i_deg)} deg, "
        f"grid {theta_step_deg} x {phi_step_deg} deg + peak scan, noise {noise}, outliers {outliers}, seed {seed}"
    ]
    return Measurement(wi, wo, p, weight, name=str(label), source="virtual", notes=notes)
