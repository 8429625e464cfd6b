"""The long steps a user waits for tell the window's loading overlay what they do and how far
(core/progress.py report; issue 41 item 3): the scene renderer's set-up stages and every cube
map of every bounce, with a fraction that only grows."""

from __future__ import annotations

from lobeview.core import progress


def test_listeners_hear_reports_only_while_listening():
    heard = []
    progress.report("before")  # nobody listens: nothing happens
    with progress.listening(lambda what, fraction: heard.append((what, fraction))):
        progress.report("a step", 0.5)
        with progress.timed_step("tag", "a long step", announce=True):
            pass
        with progress.timed_step("tag", "a short step"):  # not announced: not a loading step
            pass
    progress.report("after")
    assert heard == [("a step", 0.5), ("a long step", None)]


def test_scene_renderer_reports_its_stages_and_each_cube_map(tmp_path):
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    scene = load_gltf(build_demo_scene())
    ctx = create_headless_context()
    heard = []
    with progress.listening(lambda what, fraction: heard.append((what, fraction))):
        renderer = SceneRenderer(
            ctx, scene, load_environment(DEMO_ENVIRONMENT), size=(32, 20), progress=False,
            settings=RenderSettings(cube_face_size=16), cache_dir=tmp_path,  # empty: every cube map rendered
        )  # fmt: skip
    cubes = sum(obj.cube is not None for obj in renderer.objects)
    bounces = renderer.cube_bounces
    renderer.release()
    ctx.release()
    texts = [what for what, _ in heard]
    assert texts[0].startswith("environment") and any(t.startswith("materials and geometry") for t in texts)
    cube_reports = [(what, fraction) for what, fraction in heard if what.startswith("cube maps, bounce")]
    assert len(cube_reports) == cubes * bounces, texts
    fractions = [fraction for _, fraction in cube_reports]
    assert fractions == sorted(fractions) and 0.0 <= fractions[0] and fractions[-1] < 1.0
    assert cube_reports[-1][0].endswith(f"({cubes} of {cubes})"), cube_reports[-1]


def test_the_lightmap_bake_reports_each_ray_of_each_bounce():
    from lobeview.scenes.baker import bake_lightmap
    from lobeview.scenes.builtin_env import load_environment
    from lobeview.scenes.demo import DEMO_ENVIRONMENT, build_demo_scene
    from lobeview.scenes.gltf_loader import load_gltf

    scene = load_gltf(build_demo_scene())  # has its lightmap UVs
    heard = []
    with progress.listening(lambda what, fraction: heard.append((what, fraction))):
        bake_lightmap(scene, load_environment(DEMO_ENVIRONMENT), 32, rays=4, bounces=2, progress=False,
                      light_samples=1, env_samples=1)  # fmt: skip
    rays = [(what, fraction) for what, fraction in heard if what.startswith("lightmap bake: bounce")]
    assert [what for what, _ in rays][-1] == "lightmap bake: bounce 2 of 2, ray 4 of 4" and len(rays) == 8
    fractions = [fraction for _, fraction in rays]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] < 1.0
    assert any(what.startswith("lightmap bake: environment light") for what, _ in heard)
