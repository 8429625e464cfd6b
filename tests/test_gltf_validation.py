"""glTF numbers the loader used unchecked (issue 43): an emissiveFactor of 2 or 5 numbers reached
the uniform packing as a struct.error, a MOZ_lightmap intensity of -1 rendered negative radiance
with no warning. Each is now a warned, documented fallback, and the scene renders."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_textures import _textured_gltf

from lobeview.scenes.gltf_loader import load_gltf

GREY = np.full((4, 4, 4), 200, np.uint8)


def _load(tmp_path, material: dict, images=()) -> tuple:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_gltf(_textured_gltf(tmp_path, material, list(images)))
    return scene, "\n".join(str(w.message) for w in caught)


@pytest.mark.parametrize(
    "factor, expected, message",
    [
        ([1.0, 0.5], [0.0, 0.0, 0.0], "is not 3 finite numbers"),
        ([1.0, 0.5, 0.2, 0.1, 0.0], [0.0, 0.0, 0.0], "is not 3 finite numbers"),
        ([2.0, -1.0, 0.5], [1.0, 0.0, 0.5], "clamped to [0, 1]"),
    ],
)
def test_emissive_factor_is_validated(tmp_path, factor, expected, message):
    scene, text = _load(tmp_path, {"emissiveFactor": factor})
    np.testing.assert_array_equal(scene.materials[0].emission, expected)
    assert message in text


@pytest.mark.parametrize(
    "material, message, check",
    [
        ({"pbrMetallicRoughness": {"baseColorFactor": [1, 1]}}, "baseColorFactor [1.0, 1.0] is unusable",
         lambda m: m.desc["base_color"] == [1.0, 1.0, 1.0] and m.base_alpha == 1.0),
        ({"pbrMetallicRoughness": {"baseColorFactor": [2, -1, 0.5, 1.5]}}, "baseColorFactor [2.0, -1.0, 0.5, 1.5] "
         "clamped to [0.0, 1.0]", lambda m: m.desc["base_color"] == [1.0, 0.0, 0.5] and m.base_alpha == 1.0),
        ({"pbrMetallicRoughness": {"baseColorFactor": [1e400, 1, 1, 1]}},
         "baseColorFactor [inf, 1.0, 1.0, 1.0] is unusable", lambda m: m.desc["base_color"] == [1.0, 1.0, 1.0]),
        ({"pbrMetallicRoughness": {"metallicFactor": 5}}, "metallicFactor 5.0 clamped to [0.0, 1.0]",
         lambda m: m.desc["metallic"] == 1.0),
        ({"pbrMetallicRoughness": {"metallicFactor": 1e400}}, "metallicFactor inf is unusable; 1.0 used",
         lambda m: m.desc["metallic"] == 1.0),
        ({"pbrMetallicRoughness": {"roughnessFactor": -1}}, "roughnessFactor -1.0 clamped to [0.0, 1.0]",
         lambda m: m.desc["roughness"] == 0.0),
        ({"normalTexture": {"index": 0, "scale": 1e400}}, "normalTexture.scale inf is unusable; 1.0 used",
         lambda m: m.normal_scale == 1.0),
        ({"normalTexture": {"index": 0, "scale": -2}}, None, lambda m: m.normal_scale == -2.0),  # the spec allows it
        ({"occlusionTexture": {"index": 0, "strength": 5}}, "occlusionTexture.strength 5.0 clamped to [0.0, 1.0]",
         lambda m: m.occlusion_strength == 1.0),
        ({"occlusionTexture": {"index": 0, "strength": 1e400}}, "occlusionTexture.strength inf is unusable",
         lambda m: m.occlusion_strength == 1.0),
    ],
)  # fmt: skip
def test_core_material_numbers_are_validated(tmp_path, material, message, check):
    """Out-of-range factors were clamped or replaced without a word, and a baseColorFactor of
    two numbers stopped the load; each is now a warned fallback (docs/guide.md "glTF numbers")."""
    scene, text = _load(tmp_path, material, [GREY])
    assert check(scene.materials[0]), (scene.materials[0].desc, text)
    if message is None:
        assert "unusable" not in text and "clamped" not in text
    else:
        assert message in text, text


def test_emissive_factor_of_the_wrong_type_is_a_clear_error(tmp_path):
    from lobeview.scenes.gltf_common import GltfError

    with pytest.raises(GltfError, match="cannot parse glTF"):  # pygltflib's own type check
        _load(tmp_path, {"emissiveFactor": "bright"})


def test_emissive_strength_is_validated(tmp_path):
    material = {
        "emissiveFactor": [1.0, 1.0, 1.0],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": -3}},
    }
    scene, text = _load(tmp_path, material)
    np.testing.assert_array_equal(scene.materials[0].emission, [1.0, 1.0, 1.0])
    assert "emissiveStrength -3 is not a finite number >= 0; 1 used" in text


def test_bad_lightmap_numbers_are_warned_and_render_no_negative_light(tmp_path):
    from lobeview.scenes.envmap import EnvironmentMap
    from lobeview.viewer.camera import Camera
    from lobeview.viewer.context import create_headless_context
    from lobeview.viewer.scene_renderer import SceneRenderer
    from lobeview.viewer.settings import RenderSettings

    material = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
                "extensions": {"MOZ_lightmap": {"index": 0, "texCoord": 0, "intensity": -1}}}  # fmt: skip
    scene, text = _load(tmp_path, material, [GREY])
    assert "MOZ_lightmap intensity -1 is not a finite number >= 0; 1 used" in text
    assert scene.materials[0].lightmap.intensity == 1.0
    ctx = create_headless_context()
    env = EnvironmentMap.from_function(lambda d: np.ones(d.shape[:-1] + (3,)), height=16, name="white")
    renderer = SceneRenderer(ctx, scene, env, size=(32, 32), progress=False, settings=RenderSettings(cube_face_size=16))
    try:
        result = renderer.render(Camera(position=(0.5, 0.5, 1.5), target=(0.5, 0.5, 0.0), fov_y=40.0), "lobe-7")
        assert result.mask.any() and result.radiance[result.mask].min() > 0.0
    finally:
        renderer.release()
        ctx.release()
    material["extensions"]["MOZ_lightmap"] = {"index": 0, "texCoord": 7}
    (tmp_path / "again").mkdir()
    scene, text = _load(tmp_path / "again", material, [GREY])
    assert "texCoord 7 is not 0 or 1; TEXCOORD_1 used" in text and scene.materials[0].lightmap.tex_coord == 1
    material["extensions"]["MOZ_lightmap"] = [0]
    (tmp_path / "list").mkdir()
    scene, text = _load(tmp_path / "list", material, [GREY])
    assert "is no object; ignored" in text and scene.materials[0].lightmap is None


def test_names_with_control_characters_are_escaped(tmp_path):
    """Issue 43: node names with ANSI escape sequences were written raw to the terminal. Names are
    escaped (and cut to NAME_LIMIT) once, when the file is parsed."""
    import json

    from lobeview.scenes.gltf_common import NAME_LIMIT, printable_name

    path = _textured_gltf(tmp_path, {"name": "red\r\u202emat"}, [])
    doc = json.loads(open(path).read())
    doc["nodes"][0]["name"] = "\u001b[31mred\u001b[0m node"
    doc["meshes"][0]["name"] = "m" * 5000
    open(path, "w").write(json.dumps(doc))
    scene = load_gltf(path)
    assert scene.objects[0].name == "\\x1b[31mred\\x1b[0m node"
    assert scene.materials[0].name == "red\\r\\u202emat"
    assert printable_name("m" * 5000) == "m" * (NAME_LIMIT - 3) + "..."
    assert printable_name("Wohnzimmer Süd") == "Wohnzimmer Süd"  # printable text stays as it is
    assert printable_name(None) is None and printable_name(12) == "12"


def _node_edit(tmp_path, **node):
    import json
    from pathlib import Path

    from test_textures import _textured_gltf

    path = Path(_textured_gltf(tmp_path, {}, []))
    gltf = json.loads(path.read_text())
    gltf["nodes"][0].update(node)
    path.write_text(json.dumps(gltf))
    return path


@pytest.mark.parametrize(
    "node, message",
    [
        ({"translation": [1, 2]}, "node 0: translation has 2 numbers, not 3"),
        ({"scale": [1, 1, 1, 1]}, "node 0: scale has 4 numbers, not 3"),
        ({"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0]}, "node 0: matrix has 15 numbers, not 16"),
    ],
)
def test_node_transforms_of_the_wrong_length_stop_the_load(tmp_path, node, message):
    """A matrix of 15 numbers was ignored without a word (the node drawn untransformed) and a
    translation of 2 numbers failed inside numpy ("could not broadcast")."""
    from lobeview.scenes.gltf_common import GltfError

    with pytest.raises(GltfError, match=message.replace("[", r"\[")):
        load_gltf(_node_edit(tmp_path, **node))


def test_a_rotation_that_is_not_a_unit_quaternion_is_normalised_with_a_warning(tmp_path):
    """The rotation formula assumes |q| = 1: twice the quarter turn about z, (0, 0, 2s, 2s) with
    s = sqrt(1/2), stretched the unit quad threefold; normalised it is the quarter turn."""
    half = float(np.sqrt(0.5))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        turned = load_gltf(_node_edit(tmp_path, rotation=[0, 0, 2 * half, 2 * half]))
    assert any("is not a unit quaternion; normalised" in str(w.message) for w in caught)
    positions = turned.objects[0].mesh.positions
    np.testing.assert_allclose(positions.min(axis=0), [-1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(positions.max(axis=0), [0, 1, 0], atol=1e-6)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        zero = load_gltf(_node_edit(tmp_path, rotation=[0, 0, 0, 0]))
    assert any("is zero; no rotation used" in str(w.message) for w in caught)
    np.testing.assert_allclose(zero.objects[0].mesh.positions.max(axis=0), [1, 1, 0], atol=1e-6)


def _many_nodes(tmp_path, count: int):
    """The textured quad's file with ``count`` nodes, each placing its mesh."""
    import json
    from pathlib import Path

    path = Path(_textured_gltf(tmp_path, {}, []))
    gltf = json.loads(path.read_text())
    gltf["nodes"] = [{"mesh": 0, "translation": [float(i), 0.0, 0.0]} for i in range(count)]
    gltf["scenes"] = [{"nodes": list(range(count))}]
    path.write_text(json.dumps(gltf))
    return path


def test_object_and_node_counts_are_bounded(tmp_path):
    """Issue 43: 100 000 nodes in a 5 MB file ran for minutes (per-node work, cube maps drawing
    every object). Objects beyond ``Limits.max_objects`` (CLI --max-objects) and nodes beyond
    ``max_nodes`` stop the load with the count, before the scene is built."""
    import time

    from lobeview.app.cli import main
    from lobeview.core.trust import Limits
    from lobeview.scenes.gltf_common import GltfError

    assert len(load_gltf(_many_nodes(tmp_path, 6), Limits(max_objects=6)).objects) == 6
    with pytest.raises(GltfError, match="more than 5 drawable objects"):
        load_gltf(_many_nodes(tmp_path, 6), Limits(max_objects=5))
    started = time.perf_counter()
    with pytest.raises(GltfError, match="200000 nodes, more than the limit of 100000"):
        load_gltf(_many_nodes(tmp_path, 200_000))
    assert time.perf_counter() - started < 30  # refused from the count, not after visiting them
    assert main(["shot", str(_many_nodes(tmp_path, 6)), "--max-objects", "0", "--out", str(tmp_path / "x.png")]) == 2


@pytest.mark.parametrize("semantic", ["NORMAL", "TEXCOORD_0"])
def test_an_attribute_shorter_than_position_stops_the_load(tmp_path, semantic):
    """The long fuzz run (seed 12) found a NORMAL accessor of count 1 beside 24 positions: the
    loader kept it, the baker indexed past its end (IndexError). Every attribute of a primitive
    has POSITION's count (glTF 2.0 3.7.2.1)."""
    import json
    from pathlib import Path

    from lobeview.scenes.gltf_common import GltfError

    path = Path(_textured_gltf(tmp_path, {}, []))
    gltf = json.loads(path.read_text())
    attributes = gltf["meshes"][0]["primitives"][0]["attributes"]
    if semantic not in attributes:  # a NORMAL made from POSITION's data (VEC3 floats)
        gltf["accessors"].append(dict(gltf["accessors"][attributes["POSITION"]]))
        attributes[semantic] = len(gltf["accessors"]) - 1
    gltf["accessors"][attributes[semantic]]["count"] = 1
    path.write_text(json.dumps(gltf))
    with pytest.raises(GltfError, match=f"{semantic} has 1 elements, POSITION"):
        load_gltf(path)
