"""The fuzzer's quick subset (issue 17): 200 deterministic mutations of every kind of input,
each run in a sandboxed worker; every outcome must be a clean error, a warned fallback or a
clean load, never a traceback, crash, hang, runaway allocation, file opened outside the scene's
folder or NaN output. The long run (2000+ cases, bake included) is
``python -m lobeview.bench.fuzz --cases 2000`` with its report in bench/results."""

from __future__ import annotations

import json

import pytest

from lobeview.bench import fuzz


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    work = tmp_path_factory.mktemp("fuzz")
    outcomes = fuzz.run_fuzz(200, seed=20261124, work=work, long_mode=False, progress=None)
    return work, outcomes


def test_quick_fuzz_subset_keeps_the_promise(quick_run):
    _, outcomes = quick_run
    summary = fuzz.summarise(outcomes)
    assert summary["cases"] == 200
    assert summary["failures"] == 0, json.dumps(summary["failed_cases"], indent=1)


def test_the_mutations_reach_every_target_and_outcome(quick_run):
    """A fuzzer whose mutations all fail at the first byte, or that never reaches the renderer,
    would pass the test above without testing anything."""
    _, outcomes = quick_run
    summary = fuzz.summarise(outcomes)
    assert set(summary["by_target"]) >= {"load", "env", "material", "edits", "shot", "fit", "path", "script"}
    assert {"json", "uri", "flip", "truncate", "header", "csv"} <= set(summary["by_operator"])
    classes = summary["classes"]
    assert classes["error"] >= 20 and classes["ok"] + classes["warned"] >= 20
    hostile = [o for o in outcomes if o.operator == "uri"]
    assert hostile and all("outside the scene's folder" in o.message or o.outcome == "ok" for o in hostile)
    assert any(o.target == "shot" and o.outcome in ("ok", "warned") for o in outcomes)


def test_cases_are_reproducible_by_seed(tmp_path):
    sources_a, sources_b = tmp_path / "a" / "sources", tmp_path / "b" / "sources"
    names = fuzz.write_sources(sources_a)
    fuzz.write_sources(sources_b)
    for i in range(12):
        case_a = fuzz.make_case(i, 5, names, sources_a, tmp_path / "a", False)
        case_b = fuzz.make_case(i, 5, names, sources_b, tmp_path / "b", False)
        assert (case_a.source, case_a.operator, case_a.target, case_a.detail.replace("/a/", "/b/")) == (
            case_b.source,
            case_b.operator,
            case_b.target,
            case_b.detail,
        )
        assert (tmp_path / "a" / case_a.entry).read_bytes().replace(b"/a/", b"/b/") == (
            tmp_path / "b" / case_b.entry
        ).read_bytes()
