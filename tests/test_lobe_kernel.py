"""bench/lobe_kernel.py: lobe-N as one kernel (its lookups' weights found by linearity) and the
Gaussian model of a read of the tent MIP chain, checked on the GPU."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.bench import lobe_kernel as lk
from lobeview.materials import fitted_pattern as fp
from lobeview.materials import patterns
from lobeview.viewer.gl_probes import headless_gl


def smooth_radiance(world: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """A radiance that depends on direction and level, so that the weights must pair each read
    with its own value."""
    grey = 1.0 + 0.5 * world[:, 0] - 0.3 * world[:, 1] + 0.2 * world[:, 2] * world[:, 0] + 0.05 * np.asarray(lod)
    return np.repeat(grey[:, None], 3, axis=1)


@pytest.mark.parametrize("case", ["ggx:0.3", "beckmann:0.15"])
@pytest.mark.parametrize("view_deg", [30.0, 75.0])
def test_lookup_weights_reproduce_lobe_n(case, view_deg):
    lobe = lk.lobe_of(case)
    table = patterns.AlbedoTable.build(lobe)
    t = np.radians(view_deg)
    wo = np.array([np.sin(t), 0.0, np.cos(t)])
    weights, directions, lods = lk.lookup_weights(lobe, wo, 7, table)
    expected = patterns.integrate_lobe(lobe, wo, smooth_radiance, 7, lk.FACE_SIZE, albedo_table=table)[0]
    # reads below the horizon are left out (a tail quarter, ring samples at grazing)
    assert 1 < len(weights) <= 7 + (patterns.GGX_TAIL_SAMPLES if case.startswith("ggx") else 0)
    assert np.sum(weights * smooth_radiance(directions, lods)[:, 0]) == pytest.approx(expected, rel=1e-9)
    # +norm is exact under uniform light: the weights sum to the lobe's albedo.
    assert np.sum(weights) == pytest.approx(table.lookup(wo)[0], rel=1e-9)


def test_gaussian_kernel_has_its_sigma():
    grid, solid = lk.direction_grid(512)
    axis = np.array([0.0, 0.0, 1.0])
    for sigma in (0.05, 0.12):
        kernel = lk.gaussian_kernel(grid, solid, axis, sigma)
        assert np.sum(kernel * solid) == pytest.approx(1.0, rel=1e-9)
        spread = np.sqrt(np.sum(kernel * solid * grid[:, 0] ** 2))
        assert spread == pytest.approx(sigma, rel=0.03)


def test_kernel_distance_grows_at_grazing():
    """lobe-7's round reads on a ring fit an oblique lobe worse than one seen from above (issue 45)."""
    lobe = lk.lobe_of("beckmann:0.15")
    table = patterns.AlbedoTable.build(lobe)
    grid, solid = lk.direction_grid(128)
    l2, l1 = lk.kernel_distances(lobe, 30.0, 7, table, grid, solid)
    assert 0.0 < l2 < 1.0 and 0.0 < l1 < 2.0
    wider_l2, _ = lk.kernel_distances(lobe, 80.0, 7, table, grid, solid)
    assert wider_l2 > 2.0 * l2


def test_mip_chain_reads_have_the_modelled_sigma():
    """The model of a read of the tent chain against the driver's own filtering, at levels and
    between them (trilinear: the two levels' variances blend)."""
    with headless_gl() as ctx:
        measured = lk.measure_mip_kernel_sigma(ctx, levels=(1, 2, 2.5, 3, 3.25, 4), face_size=128)
    for level, sigma in measured.items():
        assert sigma == pytest.approx(float(fp.read_sigma_texels(level)) / 2**level, rel=0.01), level
