"""lobe-N+norm+fit's table on the GPU (materials/fitted_pattern.py; read by shaders/fitted.glsl).

One RGBA32F 3D texture per sample count N, read with texelFetch (the shader blends the four
nodes around a lobe's (alpha, view) itself, in float, as fitted_pattern.table_reads does):
x = slot (0: the lobe's (mean_a, spread_a, spread_b) in radians, 1..: the reads' (a / spread_a,
b / spread_b, weight, sigma / min spread), unused slots weight 0), y = view node, z = distribution
(DIST_BECKMANN, DIST_GGX) x FITTED_ALPHAS + alpha node.
"""

from __future__ import annotations

import moderngl
import numpy as np

from lobeview.materials import fitted_pattern as fp

from .interface import DISTRIBUTIONS


def fitted_texture_data(n: int) -> np.ndarray:
    """(depth, views, slots, 4) float32 of lobe-N's fitted tables; a missing table raises with what
    to run."""
    tables = {}
    for kind in DISTRIBUTIONS:
        try:
            tables[kind] = fp.load_table(kind, fp.read_count(kind, n))
        except (KeyError, OSError) as error:
            raise ValueError(f"lobe-{n}+norm+fit: no fitted table ({error}); "
                             f"python -m lobeview.bench.fitted_patterns --n {n} makes it") from None  # fmt: skip
    slots = 1 + max(table.reads.shape[2] for table in tables.values())
    alphas, views = len(fp.TABLE_ALPHAS), len(fp.TABLE_VIEWS_DEG)
    data = np.zeros((len(DISTRIBUTIONS) * alphas, views, slots, 4), dtype=np.float32)
    for kind, code in DISTRIBUTIONS.items():
        table = tables[kind]
        block = data[code * alphas : (code + 1) * alphas]
        block[:, :, 0, :3] = table.lobe
        block[:, :, 1 : 1 + table.reads.shape[2]] = table.reads
    return data


def fitted_texture(ctx: moderngl.Context, n: int) -> moderngl.Texture3D:
    data = fitted_texture_data(n)
    depth, views, slots, _ = data.shape
    tex = ctx.texture3d((slots, views, depth), 4, np.ascontiguousarray(data).tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return tex
