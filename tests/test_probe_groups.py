"""Shared probes (scenes/probe_groups.py): which nearby small objects share one cube map."""

from __future__ import annotations

import numpy as np
import pytest

from lobeview.scenes.probe_groups import ProbeGroup, group_probes


def _ball(centre, radius):
    c = np.asarray(centre, np.float64)
    half = radius / np.sqrt(3.0)  # a cube whose half-diagonal is ``radius``
    return (c - half, c + half)


def test_close_objects_of_similar_size_share_and_the_probe_sits_in_their_box():
    boxes = {3: _ball([0, 1, 0], 0.2), 7: _ball([0.6, 1, 0], 0.2), 9: _ball([5, 1, 0], 0.2)}
    groups = group_probes(boxes, link=2.5)
    assert [g.members for g in groups] == [(3, 7)]
    group = groups[0]
    assert group.owner == 3
    np.testing.assert_allclose(group.centre, [0.3, 1, 0])
    assert np.all(group.box_min <= boxes[3][0]) and np.all(group.box_max >= boxes[7][1])


def test_link_distance_is_relative_to_the_objects_sizes():
    # centres 1 m apart: radii 0.25 link at 2.5 (1 <= 2.5 x 0.5) but not at 1.5
    boxes = {0: _ball([0, 0, 0], 0.25), 1: _ball([1, 0, 0], 0.25)}
    assert len(group_probes(boxes, link=2.5)) == 1
    assert group_probes(boxes, link=1.5) == []
    # ten times larger and farther: the same verdicts
    scaled = {i: (10 * lo, 10 * hi) for i, (lo, hi) in boxes.items()}
    assert len(group_probes(scaled, link=2.5)) == 1 and group_probes(scaled, link=1.5) == []


def test_a_support_is_not_grouped_with_what_stands_on_it():
    desk = _ball([0, 0.4, 0], 0.9)
    sphere = _ball([0.2, 1.0, 0], 0.17)  # above the desk box, not in it
    assert group_probes({0: desk, 1: sphere}, link=10.0) == []  # radii 5x apart
    assert len(group_probes({0: desk, 1: sphere}, link=10.0, size_ratio=6.0)) == 1


def test_what_encloses_another_member_is_not_grouped_with_it():
    walls = (np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0]))
    inside = _ball([0.5, 0.5, 0.5], 0.6)  # similar size, centre inside the walls' box
    assert group_probes({0: walls, 1: inside}, link=10.0, size_ratio=10.0) == []
    beside = _ball([2.0, 0.5, 0.5], 0.8)
    assert len(group_probes({0: walls, 1: beside}, link=10.0, size_ratio=10.0)) == 1


def test_complete_linkage_keeps_a_row_from_chaining_and_groups_are_capped():
    row = {i: _ball([0.45 * i, 0, 0], 0.1) for i in range(12)}  # neighbours 0.45 m apart link at 2.5
    groups = group_probes(row, link=2.5, max_members=8)
    for group in groups:  # every pair of members links, not just neighbours
        xs = [0.45 * i for i in group.members]
        assert max(xs) - min(xs) <= 2.5 * 0.2 + 1e-9
    assert [g.members for g in groups] == [(0, 1), (2, 3), (4, 5), (6, 7), (8, 9), (10, 11)]
    crowd = {i: _ball([0.13 * i, 0, 0], 0.1) for i in range(12)}
    assert [len(g.members) for g in group_probes(crowd, link=100.0, max_members=8)] == [8, 4]


def test_grouping_does_not_depend_on_the_order_the_candidates_come_in():
    rng = np.random.default_rng(3)
    boxes = {int(i): _ball(rng.uniform(0, 2, 3), rng.uniform(0.1, 0.2)) for i in rng.permutation(30)}
    shuffled = dict(sorted(boxes.items(), key=lambda kv: -kv[0]))
    assert [g.members for g in group_probes(boxes)] == [g.members for g in group_probes(shuffled)]
    members = [i for g in group_probes(boxes) for i in g.members]
    assert len(members) == len(set(members))  # an object is in one group at most


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="probe groups"):
        group_probes({}, link=0.0)
    with pytest.raises(ValueError, match="probe groups"):
        group_probes({}, size_ratio=0.5)
    assert isinstance(ProbeGroup((1, 2), np.zeros(3), np.ones(3)).centre, np.ndarray)


# -- the renderer (viewer/scene_renderer.py) ------------------------------------------------------


def _props_scene(material=None):
    """A floor and four small spheres (plastic, or ``material``): three 0.25 m apart, one 2.7 m away."""
    from lobeview.materials.spec import load_material
    from lobeview.scenes.demo import diffuse_material
    from lobeview.scenes.meshes import quad, translated, uv_sphere
    from lobeview.scenes.scene import Scene, SceneMaterial, SceneObject

    materials = [SceneMaterial("floor", diffuse_material([0.5, 0.45, 0.4]))]
    objects = [SceneObject("floor", quad([-3, 0, 3], [6, 0, 0], [0, 0, -6]), 0, planar_reflector=False)]
    for k, x in enumerate((-0.25, 0.0, 0.25, 2.7)):  # a material each: edits change one ball
        materials.append(SceneMaterial(f"ball {k}", material or load_material("plastic")))
        mesh = translated(uv_sphere(0.08, 16, 32), [x, 0.08, 0], f"ball {k}")
        objects.append(SceneObject(f"ball {k}", mesh, len(materials) - 1))
    return Scene(objects, materials)


def _env():
    from lobeview.scenes.envmap import EnvironmentMap

    return EnvironmentMap.from_function(
        lambda d: 0.3 + np.clip(d[..., 1:2], 0, 1) * [1.0, 0.9, 0.8] + 3 * (d[..., 0:1] > 0.9), 32
    )


def _renderers(ctx, budget=None):
    import warnings

    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    env = _env()
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no lightmaps here
        for shared in (False, True):
            out[shared] = SceneRenderer(
                ctx,
                _props_scene(),
                env,
                size=(120, 80),
                progress=False,
                settings=RenderSettings(cube_face_size=64, shared_probes=shared, cube_budget_mb=budget),
            )
    return out


def _member_pixels(renderer, camera):
    from lobeview.core.methods import Method

    result = renderer.render(camera, Method.parse("lobe-5"))
    return result.radiance, result.object_id


def test_nearby_small_objects_share_one_cube_map_within_a_small_error(ctx):
    from lobeview.viewer.camera import Camera

    renderers = _renderers(ctx)
    own, shared = renderers[False], renderers[True]
    assert [g.members for g in shared.probes.groups] == [(1, 2, 3)]
    assert own.probes.groups == []
    assert [o.cube is not None for o in shared.objects] == [False, True, False, False, True]
    assert [o.cube is not None for o in own.objects] == [False, True, True, True, True]
    assert shared.objects[1].probe_centre == pytest.approx([0.0, 0.08, 0.0], abs=1e-6)
    assert all(shared.objects[i].probe_owner == 1 for i in (1, 2, 3))
    report = shared.analysis.report()
    assert f"shared probe {shared.objects[1].cube.face_size}^2 with 'ball 1', 'ball 2'" in report
    camera = Camera((0.0, 0.5, 0.9), (0.0, 0.08, 0.0), (0.0, 1.0, 0.0), 40.0)
    want, ids = _member_pixels(own, camera)
    got, _ = _member_pixels(shared, camera)
    assert np.all(np.isfinite(got))
    for index in (1, 2, 3):
        mask = ids == index
        assert mask.sum() > 100
        error = np.sqrt(np.mean((want[mask] - got[mask]) ** 2)) / np.sqrt(np.mean(want[mask] ** 2))
        assert 1e-4 < error < 0.08, (index, error)  # changed, and close
    for renderer in renderers.values():
        renderer.release()


def test_an_edit_regroups_as_a_fresh_start_and_refinement_dissolves(ctx):
    from lobeview.materials.spec import load_material
    from lobeview.viewer.camera import Camera

    renderers = _renderers(ctx)
    shared = renderers[True]
    renderers[False].release()
    # Ball 2 becomes chrome: its lobes are too narrow to share; balls 1 and 3 still link.
    shared.update_material(2, load_material("chrome"))
    assert [g.members for g in shared.probes.groups] == [(1, 3)]
    assert shared.objects[2].probe_owner == 2 and shared.objects[2].cube is not None
    assert shared.objects[3].probe_owner == 1 and shared.objects[3].cube is None
    assert shared.objects[1].probe_exclude == frozenset((1, 3))
    assert "shared probe" not in shared.analysis.report().splitlines()[3]  # ball 2's row
    # A fresh renderer on the edited scene groups the same way.
    import warnings

    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fresh = SceneRenderer(
            ctx,
            shared.scene,
            _env(),
            size=(120, 80),
            progress=False,
            settings=RenderSettings(cube_face_size=64, shared_probes=True),
        )
    assert [g.members for g in fresh.probes.groups] == [(1, 3)]
    camera = Camera((0.0, 0.5, 0.9), (0.0, 0.08, 0.0), (0.0, 1.0, 0.0), 40.0)
    fresh.request_full_faces(camera)  # the group is in view: dissolved (then queued for full faces)
    assert fresh.probes.groups == [] and all(fresh.objects[i].probe_owner == i for i in (1, 2, 3))
    assert all(fresh.objects[i].cube is not None for i in (1, 2, 3))
    for renderer in (shared, fresh):
        renderer.release()


def test_a_member_edited_to_narrower_lobes_resizes_the_shared_probe(ctx):
    import warnings

    from lobeview.materials.spec import load_material, validate
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    rough = validate({"model": "gltf", "base_color": [0.5, 0.5, 0.5], "metallic": 0.0, "roughness": 0.9})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        renderer = SceneRenderer(
            ctx,
            _props_scene(rough),
            _env(),
            size=(64, 40),
            progress=False,
            settings=RenderSettings(cube_face_size=64, shared_probes=True),
        )
    assert [g.members for g in renderer.probes.groups] == [(1, 2, 3)]
    # 32^2: the face follows the lobe's width, not lobe-N's wider filter for wide lobes (16^2 with
    # it: materials/lobe_spread.py finest_sample_solid_angle)
    assert renderer.objects[1].cube.face_size == 32
    renderer.update_material(2, load_material("plastic"))  # a member, not the owner: still wide enough
    assert [g.members for g in renderer.probes.groups] == [(1, 2, 3)]
    assert renderer.objects[1].cube.face_size == 64 and renderer.objects[2].cube is None
    assert "shared probe 64^2" in renderer.analysis.report()
    renderer.release()


def test_a_member_in_view_restores_its_groups_evicted_probe(ctx):
    from lobeview.core.methods import Method
    from lobeview.viewer.camera import Camera

    renderers = _renderers(ctx, budget=0.01)  # every cube map is evicted after the frame that drew it
    shared = renderers[True]
    far = Camera((2.7, 0.6, 1.0), (2.7, 0.08, 0.0), (0.0, 1.0, 0.0), 40.0)
    shared.draw_frame(far, Method.parse("lobe-5"))
    assert shared.objects[1].cube is None  # the group's probe, not drawn in that frame, was evicted
    # Only ball 3 (index 3, not the owner) in view: the owner's probe comes back for it.
    camera = Camera((0.25, 0.35, 0.45), (0.25, 0.08, 0.0), (0.0, 1.0, 0.0), 20.0)
    got, ids = _member_pixels(shared, camera)
    assert (ids == 3).sum() > 100 and not (ids == 1).any()
    assert shared.probes.residency.restores  # restored for the member
    want, _ = _member_pixels(renderers[True], camera)
    np.testing.assert_array_equal(got, want)
    for renderer in renderers.values():
        renderer.release()


def test_the_option_shares_only_where_faces_follow_the_lobes(ctx, tmp_path):
    """--shared-probes reaches the renderer for real-time methods; a reference keeps a cube map
    per object (--cube-sizes auto), like the default without the option."""
    import argparse
    import warnings

    from lobeview.app.options import scene_renderer_from_args
    from lobeview.core.methods import Method

    for flag, method, expected in ((True, "lobe-7", [(1, 2, 3)]), (True, "reference", []), (False, "lobe-7", [])):
        args = argparse.Namespace(face_size=64, mirror_scale=1.0, mirrors=True, cube_sizes="auto", shared_probes=flag)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            renderer = scene_renderer_from_args(
                ctx, _props_scene(), _env(), (64, 40), tmp_path, args, Method.parse(method)
            )
        assert [g.members for g in renderer.probes.groups] == expected, (flag, method)
        renderer.release()


def test_probe_sharing_bench_measures_each_member_and_reports(ctx):
    """bench/probe_sharing.py on the props scene: views that show the group, an error per member
    against a cube map per object, the figure row and the report's table."""
    from lobeview.bench.probe_sharing import _views, markdown, member_errors
    from lobeview.core.methods import Method

    renderers = _renderers(ctx)
    own, shared = renderers[False], renderers[True]
    method = Method.parse("lobe-5")
    views = _views(own, shared.probes.groups, method)
    assert len(views) == 2 and all(members == (1, 2, 3) for members, _ in views)
    figure = []
    rows = member_errors(own, shared, views, method, figure)
    assert {r["object"] for r in rows} == {"ball 0", "ball 1", "ball 2"}
    assert all(0.0 < r["rel_rmse"] < 0.1 and r["pixels"] >= 30 for r in rows)
    assert len(figure) == 1 and figure[0].shape == (80, 360, 3)
    result = {"device": "test", "size": [120, 80], "method": "lobe-5", "scenes": [
        {"scene": "props", "objects": 5, "cube_maps": 4, "cube_mb": 1.0, "startup_s": 0.5,
         "links": [{"link": 2.0, "groups": [["ball 0", "ball 1", "ball 2"]], "cube_maps": 2, "cube_mb": 0.5,
                    "startup_s": 0.4, "members": rows}]}]}  # fmt: skip
    text = markdown(result, "stamp")
    worst = max(r["rel_rmse"] for r in rows)
    assert f"| props | 2.0 | 1 | 2 (4) | 0.5 (1.0) | 0.4 (0.5) | {len(rows)} | {worst:.3f} |" in text
    for renderer in renderers.values():
        renderer.release()
