"""The cheapest real-time method that meets an error target, per material and view (issue 45).

No method wins everywhere: against Mitsuba (bench/results/mitsuba-*.md) prefiltered-rsibr is the
most accurate on rough GGX lobes, lobe-N on near-mirrors, and plain prefiltered reads one map
level (along a line of 11 lookups off the normal, Beckmann's at its lobe's own in-plane quantiles;
the table's rows were measured again after each change, bench/results/method-table-*.md). The
rule reads a measured table (``method_errors.json`` beside this file, written by
bench/method_table.py): the relative RMSE of each candidate method against lobeview's converged
reference on the preview sphere, per lobe shape (GGX or Beckmann, the narrower roughness
alpha_min, the anisotropy ratio alpha_max / alpha_min) and per n.v bin, under two demanding lights
(a sky with a sun 1e3 times brighter than its surroundings, a real interior capture), the larger of
the two counting. For a material it interpolates each lobe's error (linearly in log alpha_min and
log ratio, clamped to the table's range), takes the worst lobe, and picks among the methods whose
error meets the target the one with the fewest texture lookups per pixel; when none meets it, the
most accurate one, and says so.

Cost is counted in cube-map lookups per pixel and lobe, the device-independent part of a method's
cost (shaders/integrate.glsl, prefiltered.glsl, rsibr.glsl); prefiltered-rsibr also holds
reflection-space maps per material (sized by the lobe: up to 22 MB isotropic, 44 MB anisotropic,
materials/rsibr.py), which the choice's reason says; a thin transmission lobe under rsibr is read by
split-sum (its error and lookups are plain prefiltered's). Lobes without a microfacet
distribution (Rational BRDFs) have no table: the frame's method stays.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from .patterns import GGX_TAIL_SAMPLES, specular_lobes
from .prefilter import SPLIT_SUM_LINE_NODES, SPLIT_SUM_LINE_RATIO

TABLE_PATH = Path(__file__).with_name("method_errors.json")
#: the candidates, cheapest first within equal lookups; lobe-N as the command line's bare lobe-N
#: renders it (lobe-N+norm+fit, the accurate family: bench/results/mitsuba-*.md; anisotropic lobes
#: take the thesis pattern there), the thesis pattern's lobe-11+norm for comparison
CANDIDATES = ("prefiltered", "prefiltered-rsibr", "lobe-3+norm+fit", "lobe-5+norm+fit", "lobe-7+norm+fit",
              "lobe-11+norm+fit", "lobe-15+norm+fit", "lobe-19+norm+fit", "lobe-11+norm")  # fmt: skip
#: n.v bins of the table
NV_EDGES = (0.0, 0.35, 0.6, 0.8, 1.0)
#: the default target: relative RMSE against the converged reference under bright light
DEFAULT_TARGET = 0.08
RSIBR_VIEWS_READ = 3  # the three views of the pixel's icosahedron triangle (shaders/rsibr.glsl)
RSIBR_SLICES_READ = 2  # an anisotropic lobe blends the two tangent slices around its tangent


def lookups_per_lobe(method: str, anisotropic: bool, kind: str) -> int:
    """Cube-map (or map) lookups per pixel for one lobe of a ``kind`` ('ggx'/'beckmann')
    distribution: lobe-N reads N samples (+norm adds GGX_TAIL_SAMPLES tail lookups on GGX);
    prefiltered reads one split-sum level at SPLIT_SUM_LINE_NODES along a line (an anisotropic
    lobe's wider axis; an isotropic lobe's plane of incidence wherever the view is off the normal,
    materials/split_sum_oblique.py) and the DFG table; prefiltered-rsibr three views' maps (two
    tangent slices each when anisotropic); fis-N N samples."""
    from lobeview.core.methods import Method

    m = Method.parse(method)
    if m.kind == "lobe":
        return m.samples + (GGX_TAIL_SAMPLES if m.normalize and kind == "ggx" else 0)
    if m.kind in ("fis", "mc"):
        return m.samples
    if m.kind == "prefiltered" and m.mode in ("auto", "splitsum"):
        return SPLIT_SUM_LINE_NODES + 1
    if m.kind == "prefiltered" and m.mode == "rsibr":
        return RSIBR_VIEWS_READ * (RSIBR_SLICES_READ if anisotropic else 1)
    raise ValueError(f"no lookup count for {method!r}")


@dataclass(frozen=True)
class LobeShape:
    kind: str  # 'ggx' or 'beckmann'
    alpha_min: float
    ratio: float  # alpha_max / alpha_min >= 1
    # A thin transmission lobe: lobe-N mirrors its pattern (same shape); prefiltered-rsibr cannot
    # follow it between views and looks it up as plain prefiltered does (materials/rsibr.py).
    transmission: bool = False

    @classmethod
    def of(cls, lobe) -> LobeShape | None:
        distribution = getattr(lobe, "distribution", None)
        if distribution is None:
            return None
        low, high = sorted((distribution.alpha_x, distribution.alpha_y))
        return cls(distribution.kind, float(low), float(high / low), bool(getattr(lobe, "transmission", False)))

    def as_read_by(self, method: str) -> str:
        """The method whose table column and lookups apply to this lobe under ``method``."""
        return "prefiltered" if self.transmission and method == "prefiltered-rsibr" else method

    @property
    def anisotropic(self) -> bool:
        return self.ratio > SPLIT_SUM_LINE_RATIO


@dataclass
class MethodChoice:
    method: str | None  # None: no table for the material's lobes (keep the frame's method)
    error: float | None  # the table's error of that method for the worst lobe (relative RMSE)
    lookups: int  # per pixel, all lobes
    meets_target: bool
    reason: str
    errors: dict = field(default_factory=dict)  # every candidate's estimated error

    def describe(self) -> str:
        if self.method is None:
            return self.reason
        return f"{self.method} (~{100 * self.error:.0f} %, {self.lookups} lookups): {self.reason}"


class ErrorTable:
    """The measured table (bench/method_table.py's JSON), worst light per cell."""

    def __init__(self, data: dict):
        self.data = data
        self.methods = tuple(data["methods"])
        self.nv_edges = tuple(data["nv_edges"])
        cells: dict = {}
        for row in data["rows"]:
            key = (row["kind"], float(row["alpha_min"]), float(row["ratio"]))
            for method in self.methods:
                overall = row["overall"][method]
                # a bin without pixels (None) takes the whole sphere's error
                values = [overall, *(overall if v is None else v for v in row["bins"][method])]
                old = cells.setdefault(key, {}).get(method)
                # the worse light per value
                cells[key][method] = values if old is None else [max(a, b) for a, b in zip(old, values, strict=True)]
        self.cells = cells
        # The alpha grid of each (kind, ratio) (a ratio's grid stops where alpha_max would pass 1)
        # and the ratios of each kind.
        self.alphas: dict = {}
        for kind, alpha, ratio in cells:
            self.alphas.setdefault((kind, ratio), []).append(alpha)
        for grid in self.alphas.values():
            grid.sort()
        self.ratios = {kind: sorted(r for k, r in self.alphas if k == kind) for kind, _ in self.alphas}

    @classmethod
    @functools.cache
    def load(cls, path: str = str(TABLE_PATH)) -> ErrorTable:
        return cls(json.loads(Path(path).read_text()))

    def error(self, shape: LobeShape, method: str, nv: tuple[float, float] | None = None) -> float:
        """Estimated relative RMSE of ``method`` on a lobe of ``shape``: over the whole sphere, or
        the worst n.v bin overlapping ``nv`` = (low, high)."""
        if shape.kind not in self.ratios:
            raise KeyError(f"no table for {shape.kind} lobes")
        columns = [0]
        if nv is not None:
            low, high = nv
            columns = [
                1 + i
                for i, (a, b) in enumerate(zip(self.nv_edges[:-1], self.nv_edges[1:], strict=True))
                if b > low and a < high
            ]
            columns = columns or [0]
        return max(self._interpolate(shape, method, c) for c in columns)

    def _interpolate(self, shape: LobeShape, method: str, column: int) -> float:
        """Bilinear in (log alpha_min, log ratio) over the grid points present, clamped to the
        table's range; ratios whose alpha grid stops earlier (alpha_max <= 1) clamp to their own
        largest alpha."""
        ratios = self.ratios[shape.kind]
        r0, r1, tr = _bracket(ratios, shape.ratio)
        out = []
        for ratio in (r0, r1):
            a0, a1, ta = _bracket(self.alphas[(shape.kind, ratio)], shape.alpha_min)
            e0 = self.cells[(shape.kind, a0, ratio)][method][column]
            e1 = self.cells[(shape.kind, a1, ratio)][method][column]
            out.append(e0 + ta * (e1 - e0))
        return out[0] + tr * (out[1] - out[0])


def _bracket(grid: list[float], value: float) -> tuple[float, float, float]:
    """The grid points around ``value`` and the interpolation weight, in log space, clamped."""
    if value <= grid[0]:
        return grid[0], grid[0], 0.0
    if value >= grid[-1]:
        return grid[-1], grid[-1], 0.0
    for lo, hi in zip(grid[:-1], grid[1:], strict=True):
        if lo <= value <= hi:
            return lo, hi, (math.log(value) - math.log(lo)) / (math.log(hi) - math.log(lo))
    raise AssertionError("unreachable")


def lobe_shapes(bsdf) -> list[LobeShape | None]:
    return [LobeShape.of(lobe) for lobe in specular_lobes(bsdf)]


def choose_method(
    shapes: list[LobeShape | None],
    target: float = DEFAULT_TARGET,
    nv: tuple[float, float] | None = None,
    table: ErrorTable | None = None,
    candidates: tuple[str, ...] | None = None,
    extremes: list[LobeShape | None] | None = None,
) -> MethodChoice:
    """The cheapest candidate whose estimated error, for the worst of the material's lobes
    ``shapes`` (:func:`lobe_shapes`) and views ``nv``, is at most ``target``. ``extremes``: the
    same lobes, index for index, at the other end of what the material's textures can give (its
    narrowest roughness): their errors count, their lookups do not add (a pixel shades each lobe
    once, and pays for the costlier of its two shapes)."""
    # zip(strict=True): extremes that do not pair with the lobes raise ValueError
    variants = [[s] for s in shapes] if extremes is None else [list(p) for p in zip(shapes, extremes, strict=True)]
    if not shapes:
        return MethodChoice(None, None, 0, True, "no specular lobes: nothing view-dependent to shade")
    if any(shape is None for lobe in variants for shape in lobe):
        return MethodChoice(None, None, 0, False, "a lobe without a microfacet distribution: no error table")
    table = table or ErrorTable.load()
    candidates = tuple(m for m in (candidates or table.methods) if m in table.methods)
    errors = {m: max(table.error(s, s.as_read_by(m), nv) for lobe in variants for s in lobe) for m in candidates}
    lookups = {
        m: sum(max(lookups_per_lobe(s.as_read_by(m), s.anisotropic, s.kind) for s in lobe) for lobe in variants)
        for m in candidates
    }
    order = sorted(candidates, key=lambda m: (lookups[m], errors[m]))
    meeting = [m for m in order if errors[m] <= target]
    if meeting:
        best = meeting[0]
        reason = f"the cheapest within {100 * target:.0f} %"
        if best == "prefiltered-rsibr":
            reason += " (holds reflection-space maps per material, up to 22 MB, 44 MB anisotropic)"
        return MethodChoice(best, errors[best], lookups[best], True, reason, errors)
    best = min(candidates, key=lambda m: (round(errors[m], 3), lookups[m]))  # equal to 0.1 %: the cheaper
    return MethodChoice(best, errors[best], lookups[best], False, f"none within {100 * target:.0f} %: the most "
                        "accurate (the cheapest of equals)", errors)  # fmt: skip
