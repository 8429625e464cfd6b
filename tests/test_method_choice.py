"""The cheapest-method rule (materials/method_choice.py, issue 45): lookup counts as the shaders
make them, the table's interpolation, the choice (cheapest within the target, else the most
accurate), the committed table's shape, and the rule's use by the scene analysis, the renderer
and the command line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lobeview.materials.method_choice import (
    CANDIDATES,
    NV_EDGES,
    TABLE_PATH,
    ErrorTable,
    LobeShape,
    choose_method,
    lobe_shapes,
    lookups_per_lobe,
)
from lobeview.materials.patterns import GGX_TAIL_SAMPLES
from lobeview.materials.prefilter import SPLIT_SUM_LINE_NODES
from lobeview.materials.spec import build_bsdf, validate


def test_lookups_follow_the_shaders():
    assert lookups_per_lobe("lobe-7+norm", False, "beckmann") == 7
    assert lookups_per_lobe("lobe-7+norm", False, "ggx") == 7 + GGX_TAIL_SAMPLES  # the tail term
    assert lookups_per_lobe("lobe-7", False, "ggx") == 7  # no tail without +norm
    # the line of one level (off the normal, every lobe: split_sum_oblique.py) + the DFG table
    assert lookups_per_lobe("prefiltered", False, "ggx") == SPLIT_SUM_LINE_NODES + 1
    assert lookups_per_lobe("prefiltered", True, "ggx") == SPLIT_SUM_LINE_NODES + 1
    assert lookups_per_lobe("prefiltered-rsibr", False, "ggx") == 3
    assert lookups_per_lobe("prefiltered-rsibr", True, "beckmann") == 6
    assert lookups_per_lobe("fis-16", False, "ggx") == 16
    with pytest.raises(ValueError):
        lookups_per_lobe("prefiltered-banks", False, "ggx")


def _table(errors: dict) -> ErrorTable:
    """A synthetic table: ``errors[(kind, alpha, ratio)][method]`` = overall error, the bins 1.5x
    it at grazing and 1x elsewhere; two lights, the second 0.8x the first (the worst counts)."""
    rows = []
    for (kind, alpha, ratio), per_method in errors.items():
        for scale, env in ((1.0, "sky"), (0.8, "interior")):
            rows.append({
                "env": env, "kind": kind, "alpha_min": alpha, "ratio": ratio,
                "overall": {m: scale * e for m, e in per_method.items()},
                "bins": {m: [scale * e * 1.5, scale * e, scale * e, None] for m, e in per_method.items()},
            })  # fmt: skip
    methods = list(next(iter(errors.values())))
    return ErrorTable({"methods": methods, "nv_edges": list(NV_EDGES), "rows": rows})


def test_the_table_interpolates_in_log_alpha_and_clamps():
    table = _table({("ggx", 0.1, 1.0): {"lobe-7+norm": 0.04}, ("ggx", 0.4, 1.0): {"lobe-7+norm": 0.12},
                    ("ggx", 0.1, 4.0): {"lobe-7+norm": 0.2}, ("ggx", 0.4, 4.0): {"lobe-7+norm": 0.2}})  # fmt: skip
    at = lambda a, r=1.0, nv=None: table.error(LobeShape("ggx", a, r), "lobe-7+norm", nv)  # noqa: E731
    assert at(0.1) == pytest.approx(0.04) and at(0.4) == pytest.approx(0.12)
    assert at(0.2) == pytest.approx(0.08)  # 0.2 is halfway between 0.1 and 0.4 in log alpha
    assert at(0.01) == pytest.approx(0.04) and at(0.9) == pytest.approx(0.12)  # clamped
    assert at(0.1, 2.0) == pytest.approx(0.12)  # halfway in log ratio between 1 and 4
    assert at(0.1, nv=(0.0, 0.2)) == pytest.approx(0.06)  # the grazing bin
    assert at(0.1, nv=(0.9, 1.0)) == pytest.approx(0.04)  # an empty bin takes the sphere's error
    with pytest.raises(KeyError):
        table.error(LobeShape("beckmann", 0.1, 1.0), "lobe-7+norm")


def test_the_rule_picks_the_cheapest_method_within_the_target():
    errors = {"prefiltered": 0.10, "prefiltered-rsibr": 0.05, "lobe-3+norm": 0.07, "lobe-7+norm": 0.04}
    table = _table({("beckmann", a, 1.0): errors for a in (0.05, 0.5)})
    shapes = [LobeShape("beckmann", 0.2, 1.0)]
    # Lookups per Beckmann lobe: prefiltered 12 (its line of 11 and the DFG table), rsibr 3,
    # lobe-3+norm 3, lobe-7+norm 7; equal lookups: the smaller error first.
    pick = choose_method(shapes, 0.12, table=table)
    assert pick.method == "prefiltered-rsibr" and pick.meets_target and pick.lookups == 3
    assert "reflection-space maps" in pick.reason
    assert choose_method(shapes, 0.12, table=table, candidates=("prefiltered", "lobe-7+norm")).method == "lobe-7+norm"
    only = choose_method(shapes, 0.12, table=table, candidates=("prefiltered",))
    assert only.method == "prefiltered" and only.lookups == 12
    assert choose_method(shapes, 0.045, table=table).method == "lobe-7+norm"
    none = choose_method(shapes, 0.01, table=table)  # nothing meets it: the most accurate, said so
    assert none.method == "lobe-7+norm" and not none.meets_target and "none within 1 %" in none.reason
    # Two lobes: their lookups add up, the worse lobe's error counts.
    two = choose_method(shapes * 2, 0.12, table=table)
    assert two.lookups == 6 and two.error == pytest.approx(0.05)
    # One lobe at two ends of a texture's range: both errors count, its lookups once.
    ends = choose_method(shapes, 0.12, table=table, extremes=[LobeShape("beckmann", 0.05, 1.0)])
    assert ends.lookups == 3 and ends.method == "prefiltered-rsibr"
    with pytest.raises(ValueError):
        choose_method(shapes, 0.12, table=table, extremes=[])


def test_a_transmission_lobe_is_read_by_split_sum_under_rsibr():
    errors = {"prefiltered": 0.10, "prefiltered-rsibr": 0.03, "lobe-7+norm": 0.09}
    table = _table({("ggx", a, 1.0): errors for a in (0.05, 0.5)})
    glass = [LobeShape("ggx", 0.2, 1.0), LobeShape("ggx", 0.2, 1.0, transmission=True)]
    pick = choose_method(glass, 0.095, table=table)
    # rsibr would be 3 lookups at 3 %, but its transmission lobe is split-sum's 10 %: lobe-7 wins.
    assert pick.errors["prefiltered-rsibr"] == pytest.approx(0.10) and pick.method == "lobe-7+norm"
    # A loose target: rsibr's 3 + split-sum's 12 for the transmission lobe, prefiltered's 12 + 12
    # and lobe-7+norm's 2 x 11 lose to nothing cheaper among these three.
    loose = choose_method(glass, 0.2, table=table)
    assert loose.method == "prefiltered-rsibr" and loose.lookups == 15


def test_the_rule_keeps_the_frames_method_where_it_has_no_table():
    assert choose_method([]).method is None
    rational = choose_method([None, LobeShape("ggx", 0.1, 1.0)])
    assert rational.method is None and "no error table" in rational.reason


def test_lobe_shapes_of_a_material():
    bsdf = build_bsdf(validate({"model": "microfacet", "distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.05,
                                "fresnel": {"type": "none"}}))  # fmt: skip
    (shape,) = lobe_shapes(bsdf)
    assert shape.kind == "ggx" and shape.alpha_min == pytest.approx(0.05) and shape.ratio == pytest.approx(6.0)
    assert shape.anisotropic


def test_the_committed_table_is_complete_and_measured_under_both_lights():
    data = json.loads(TABLE_PATH.read_text())
    assert tuple(data["methods"]) == CANDIDATES and tuple(data["nv_edges"]) == NV_EDGES
    assert set(data["envs"]) == {"sky", "interior"}
    assert "absent" not in data["envs"]["interior"], "the table was made without the interior capture"
    cells = {(r["env"], r["kind"], r["alpha_min"], r["ratio"]) for r in data["rows"]}
    for env in ("sky", "interior"):
        for kind in ("ggx", "beckmann"):
            assert {(a, 1.0) for a in (0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.8)} <= {
                (a, r) for e, k, a, r in cells if (e, k) == (env, kind)
            }
    for row in data["rows"]:
        assert row["reference_noise"]["overall"] < 0.05, row  # the reference is converged enough
        for method in CANDIDATES:
            values = [row["overall"][method], *(b for b in row["bins"][method] if b is not None)]
            assert all(math.isfinite(v) and 0.0 <= v < 2.0 for v in values), (row["kind"], method)
    table = ErrorTable.load()
    # What the Mitsuba comparison found (bench/results/mitsuba-*.md), in the table too: on a rough
    # GGX lobe plain prefiltered beats lobe-7 no more than rsibr does, and lobe-19 is at least as
    # good as lobe-7 (more samples never cost accuracy).
    rough = LobeShape("ggx", 0.5, 1.0)
    assert table.error(rough, "prefiltered-rsibr") <= table.error(rough, "prefiltered") + 1e-9
    for alpha in (0.05, 0.2, 0.5):
        shape = LobeShape("ggx", alpha, 1.0)
        assert table.error(shape, "lobe-19+norm+fit") <= table.error(shape, "lobe-7+norm+fit") + 0.005


def test_the_bench_measures_a_table_row(tmp_path):
    """bench/method_table.py end to end at a tiny size: the row it writes is what the rule reads."""
    from lobeview.bench.method_table import main

    out = tmp_path / "table.json"
    assert main(["--size", "24", "--spp", "32", "--supersample", "1", "--cases", "beckmann:0.3",
                 "--envs", "sky", "--methods", "lobe-3+norm", "prefiltered", "--out", str(out)]) == 0  # fmt: skip
    data = json.loads(out.read_text())
    (row,) = data["rows"]
    assert (
        row["kind"] == "beckmann" and row["alpha_min"] == 0.3 and set(row["overall"]) == {"lobe-3+norm", "prefiltered"}
    )
    assert all(np.isfinite(row["overall"][m]) for m in row["overall"])
    pick = choose_method([LobeShape("beckmann", 0.3, 1.0)], 1.0, table=ErrorTable(data))
    assert pick.method == "lobe-3+norm"  # the cheaper one (3 lookups against 12), within a target of 100 %


def test_an_update_replaces_only_its_rows():
    """bench/method_table.py --update: the rows measured again replace theirs (same light and lobe
    shape), the others stay, the table keeps its order and lists the update; an update without
    every method of the table is refused."""
    from lobeview.bench.method_table import updated_table

    def row(env, kind, alpha, error):
        return {"env": env, "kind": kind, "alpha_min": alpha, "ratio": 1.0, "overall": {"lobe-7+norm": error}}

    rows = [row("sky", "ggx", 0.2, 0.1), row("sky", "ggx", 0.5, 0.2), row("interior", "ggx", 0.5, 0.3)]
    table = {"envs": {"sky": "", "interior": ""}, "methods": ["lobe-7+norm"], "rows": rows}
    update = {"methods": ["lobe-7+norm"], "date": "d", "command": "c", "minutes": 1.0,
              "rows": [row("interior", "ggx", 0.5, 0.03), row("sky", "ggx", 0.5, 0.02)]}  # fmt: skip
    merged = updated_table(table, update)
    assert [(r["env"], r["alpha_min"], r["overall"]["lobe-7+norm"]) for r in merged["rows"]] == [
        ("sky", 0.2, 0.1), ("sky", 0.5, 0.02), ("interior", 0.5, 0.03)
    ]  # fmt: skip
    assert merged["updates"] == [{"date": "d", "command": "c", "rows": 2, "minutes": 1.0}]
    assert len(table["rows"]) == 3 and table["rows"][1]["overall"]["lobe-7+norm"] == 0.2  # not changed in place
    with pytest.raises(SystemExit, match="every method"):
        updated_table(table, {**update, "methods": ["prefiltered"]})


def test_the_analysis_the_renderer_and_the_command_line_use_the_rule(ctx):
    """A textured glTF quad (roughness 0.24-0.9 from its texture, factor 1): the analysis picks for
    the lobes at both ends of the texture's range, the renderer shades the object with the pick,
    and turning the rule off gives the frame's method back."""
    import warnings

    from test_textures import _smooth_env, _textured_quad_scene

    from lobeview.app.options import _percent
    from lobeview.core.methods import Method
    from lobeview.scenes.analysis import analyse, narrowest_lobe_desc
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = _textured_quad_scene()
    analysis = analyse(scene, method_target=0.08)
    choice = analysis.objects[0].method_choice
    assert choice is not None and choice.method in CANDIDATES
    material = scene.materials[0]
    shapes = lobe_shapes(build_bsdf(material.desc)) + lobe_shapes(build_bsdf(narrowest_lobe_desc(material)))
    assert min(s.alpha_min for s in shapes) < 0.1 < max(s.alpha_min for s in shapes)  # both ends
    assert choice.error == pytest.approx(max(ErrorTable.load().error(s, choice.method) for s in shapes))
    # Both ends count toward the error, but the pixel shades each lobe once: the lookups are one set's.
    one_set = lobe_shapes(build_bsdf(material.desc))
    assert choice.lookups == sum(lookups_per_lobe(choice.method, s.anisotropic, s.kind) for s in one_set)
    assert "cheapest-method rule" in analysis.report() and choice.method in analysis.report()
    assert analyse(scene).objects[0].method_choice is None  # off by default

    env = EnvironmentMap.from_function(_smooth_env, height=32, name="smooth")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(ctx, scene, env, size=(16, 16), progress=False,
                                 settings=RenderSettings(cube_face_size=16, method_target=0.08))  # fmt: skip
    try:
        assert renderer.object_method(0) == Method.parse(choice.method)
        renderer.configure(method_target=None)
        assert renderer.object_method(0) is None
        renderer.configure(method_target=0.5)  # a loose target: the cheapest candidate (3 lookups a lobe)
        assert renderer.object_method(0) == Method.parse("prefiltered-rsibr")
    finally:
        renderer.release()
    with pytest.raises(ValueError):
        RenderSettings(method_target=0.0)
    assert _percent("8") == pytest.approx(0.08)
    with pytest.raises(Exception, match="percent"):
        _percent("150")


def test_a_planar_reflector_keeps_the_frames_method():
    """Its mirror pass is read by lobe-N; the table measured cube maps (a prefiltered pick would
    replace the mirror pass by a cube map: on the demo's floor 4.2 -> 6.5 % against the reference)."""
    from lobeview.scenes.analysis import analyse
    from lobeview.scenes.mirror_scene import mirror_floor_scene

    analysis = analyse(mirror_floor_scene(0.05), method_target=0.08)
    reflectors = [o for o in analysis.objects if o.reflector is not None]
    assert reflectors
    for needs in reflectors:
        assert needs.method_choice.method is None and "mirror pass" in needs.method_choice.reason
    # The scene's other objects are diffuse: nothing view-dependent, no pick.
    assert all(o.method_choice is None for o in analysis.objects if o.reflector is None and not o.needs_cube_map)
