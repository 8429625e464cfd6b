"""The cube maps' GPU memory budget (issue 18; viewer/cube_bake.py CubeResidency): after a frame
the least recently drawn cube maps go until the budget holds, never one that frame drew; an
evicted object a later pass draws gets its cube map back first (from the disk cache: the frame is
bit-identical to one without a budget; without a cache: rendered again)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_indirect_draws import assert_within_rounding

from lobeview.core.methods import Method
from lobeview.viewer.cube_bake import cube_gpu_bytes

BUDGET_MB = 12  # the demo's cube maps take ~42 MB (five 256^2 faces of 8.4 MB each)
SIZE = (160, 100)


@pytest.fixture(scope="module")
def demo():
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.scenes.setup import scene_view
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context

    scene = load_gltf(build_demo_scene())
    ctx = create_headless_context()
    cameras = {view: Camera(*scene_view(scene, view)) for view in ("table", "overview")}
    yield ctx, scene, load_environment(DEMO_ENVIRONMENT), cameras
    ctx.release()


def _renderer(demo, cache_dir, budget):
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    ctx, scene, env, _ = demo
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SceneRenderer(
            ctx,
            scene,
            env,
            size=SIZE,
            cache_dir=cache_dir,
            progress=False,
            settings=RenderSettings(cube_budget_mb=budget),
        )


def _resident_bytes(renderer) -> int:
    return sum(cube_gpu_bytes(obj.cube) for obj in renderer.objects if obj.cube is not None)


def test_budget_evicts_what_the_frame_did_not_draw_and_restores_it_exactly(demo, tmp_path):
    _, scene, _, cameras = demo
    method = Method.parse("lobe-7+norm")
    plain = _renderer(demo, tmp_path, None)
    expected = {view: plain.render(camera, method).radiance for view, camera in cameras.items()}
    assert plain.probes.residency.evictions == 0
    plain.release()
    budgeted = _renderer(demo, tmp_path, BUDGET_MB)  # the same cache folder: start-up from disk
    try:
        table = budgeted.render(cameras["table"], method)
        drawn = set(np.unique(table.object_id)) - {-1}
        residency = budgeted.probes.residency
        assert residency.evictions > 0
        for obj in budgeted.objects:
            if obj.index in residency.evicted:
                assert obj.cube is None and obj.index not in drawn
        # Either under budget, or every resident cube map was drawn by the frame.
        resident = [obj.index for obj in budgeted.objects if obj.cube is not None]
        assert _resident_bytes(budgeted) <= BUDGET_MB * 2**20 or all(
            residency.last_used.get(i) == residency.frame - 1 for i in resident
        )
        # Under a budget the lobe-shaded objects are drawn one by one (viewer/lobe_batches.py),
        # without it by multi-draws: the same frame within rounding (tests/test_lobe_batches.py).
        assert_within_rounding(table.radiance, expected["table"], "table")
        overview = budgeted.render(cameras["overview"], method)  # evicted objects come back into view
        assert sum(residency.restores.values()) > 0 and set(residency.restores) == {"disk cache"}
        assert_within_rounding(overview.radiance, expected["overview"], "overview")
        assert "evicted" in residency.report(budgeted.objects)
    finally:
        budgeted.release()


def test_without_a_cache_evicted_cube_maps_are_rendered_again(demo):
    _, _, _, cameras = demo
    method = Method.parse("lobe-3+norm")
    budgeted = _renderer(demo, None, BUDGET_MB)
    try:
        before = budgeted.render(cameras["overview"], method).radiance
        budgeted.render(cameras["table"], method)
        after = budgeted.render(cameras["overview"], method).radiance
        assert budgeted.probes.residency.restores.get("rendered", 0) > 0
        # Rendered again as one bounce over the final cube maps (as a refreshed cube): close to
        # the start-up cube map, not bit-identical.
        assert np.abs(after - before).max() <= 0.05 * before.max()
    finally:
        budgeted.release()


def test_bad_budget_is_refused(demo):
    with pytest.raises(ValueError, match="cube_budget_mb must be positive"):
        _renderer(demo, None, 0)
