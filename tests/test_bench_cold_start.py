"""The cold-start bench's reading of the viewer's frame log (bench/cold_start.py): which frame is
the first, when the baked scene came in and when nothing was left to finish."""

from __future__ import annotations

from lobeview.bench.cold_start import events, markdown


def _frame(t, bake=None, cubes=None, state="still"):
    return {"t": t, "background_bake": bake, "cube_build": cubes, "state": state}


def test_bake_then_cube_maps_then_finished():
    log = [
        (6.5, _frame(4.0, bake="baking: bounce 1/2 (30 %)", cubes="3 of 211")),
        (30.0, _frame(27.5, bake="baking: bounce 2/2 (80 %)", cubes="40 of 211")),
        (41.0, _frame(38.5, cubes="1 of 211")),  # the baked scene in, its cube maps built again
        (70.0, _frame(67.5, cubes="200 of 211")),
        (75.0, _frame(72.5)),
        (77.0, _frame(74.5)),
    ]
    found = events(log)
    assert found["first_frame_s"] == 6.5 and found["first_frame_window_s"] == 4.0
    assert found["first_frame_bake"].startswith("baking") and found["first_frame_cube_build"] == "3 of 211"
    assert found["baked_s"] == 41.0
    assert found["swap_pause_s"] == 11.0  # from the last frame drawn while baking
    assert found["finished_s"] == 75.0  # not the bake's end: cube maps were still being built
    assert found["frames"] == 6


def test_a_horizon_map_worker_still_running_is_not_finished():
    running = {**_frame(3.0), "horizon_maps": "self-occlusion horizons: lightmap 1 of 1"}
    found = events([(2.0, running), (4.0, _frame(3.5))])
    assert found["finished_s"] == 4.0


def test_warm_start_is_finished_at_its_first_frame():
    found = events([(2.0, _frame(1.1)), (2.1, _frame(1.2))])
    assert found["baked_s"] is None and found["finished_s"] == 2.0 and found["swap_pause_s"] is None


def test_an_unfinished_start_says_so():
    log = [(5.0, _frame(3.0, bake="baking", cubes=[1, 9])), (9.0, _frame(7.0, bake="baking", cubes=[2, 9]))]
    found = events(log)
    assert found["baked_s"] is None and found["finished_s"] is None
    assert events([])["first_frame_s"] is None
    result = {**found, "scene": "builtin:apartment", "size": [1280, 800], "timeout_s": 900.0}
    text = markdown([result], "llvmpipe", "20261128", "python -m lobeview.bench.cold_start")
    assert "| builtin:apartment | 1280x800 | 5.0 | baking / cube map 1 of 9 | - | - | not within 900 | 2 |" in text
