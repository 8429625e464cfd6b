"""`lobeview bake` keeps the scene (issue 16, item 4): the output is the input glTF with only the
lightmap added, checked field by field, image by image and triangle corner by corner."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from lobeview.app.cli import main
from lobeview.core.trust import DEFAULT_LIMITS
from lobeview.scenes.baked_gltf import source_json, write_baked_gltf
from lobeview.scenes.baker import bake_lightmap, lightmap_uv_overlap
from lobeview.scenes.demo import unwrap_lightmap_uvs
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.gltf_common import GltfError
from lobeview.scenes.gltf_loader import _parse, _Reader, load_gltf

ASSETS = Path(__file__).resolve().parents[2] / "shared" / "assets" / "gltf"
BAKE_FAST = ["--resolution", "64", "--rays", "4", "--bounces", "1", "--light-samples", "4"]
# What a bake may change at the top level of the JSON (everything else must be equal).
CHANGED_TOP_LEVEL = {"accessors", "bufferViews", "buffers", "images", "meshes", "nodes", "materials", "textures",
                     "samplers", "extensionsUsed", "asset"}  # fmt: skip


def _sky():
    return EnvironmentMap(np.full((8, 16, 3), 0.5, np.float32))


def _quad(offset, uv1=None):
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32) + np.asarray(offset, np.float32)
    normals = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 99, 199]], np.uint8)
    return positions, normals, uvs, colours, uv1


def _rich_gltf(folder: Path, shared_atlas: bool = False) -> Path:
    """A .gltf with an external .bin and PNG, an instanced and a mirrored node, a primitive with
    no material, a VEC3 unsigned-byte colour (4-byte stride), a lobeview material file, a KHR
    extension, extras and a camera: everything a bake must carry over."""
    blob = bytearray()
    views, accessors = [], []

    def add(array: np.ndarray, kind: str, component: int, target: int, stride: int | None = None, **extra):
        data = np.ascontiguousarray(array)
        if stride is not None:  # pad rows to the stride, as an exporter of VEC3 bytes must
            rows = np.zeros((len(data), stride), np.uint8)
            rows[:, : data.itemsize * data.shape[1]] = data.view(np.uint8).reshape(len(data), -1)
            data = rows
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes, "target": target,
                      **({"byteStride": stride} if stride else {})})  # fmt: skip
        blob.extend(data.tobytes())
        accessors.append({"bufferView": len(views) - 1, "componentType": component, "count": len(array),
                          "type": kind, **extra})  # fmt: skip
        return len(accessors) - 1

    meshes = []
    for index, uv1 in enumerate(
        [np.array([[0, 0.45], [0.45, 0.45], [0.45, 0], [0, 0]], np.float32) if shared_atlas else None,
         np.array([[0.55, 1], [1, 1], [1, 0.55], [0.55, 0.55]], np.float32) if shared_atlas else None]
    ):  # fmt: skip
        positions, normals, uvs, colours, _ = _quad([0, 0, 0])
        attributes = {
            "POSITION": add(positions, "VEC3", 5126, 34962, min=[0, 0, 0], max=[1, 1, 0]),
            "NORMAL": add(normals, "VEC3", 5126, 34962),
            "TEXCOORD_0": add(uvs, "VEC2", 5126, 34962),
            "COLOR_0": add(colours, "VEC3", 5121, 34962, stride=4, normalized=True),
        }
        if uv1 is not None:
            attributes["TEXCOORD_1"] = add(uv1, "VEC2", 5126, 34962)
        indices = add(np.array([[0], [1], [2], [0], [2], [3]], np.uint16), "SCALAR", 5123, 34963)
        primitive = {"attributes": attributes, "indices": indices, "extras": {"kept": index}}
        if index == 0:
            primitive["material"] = 0
        meshes.append({"name": f"quad{index}", "primitives": [primitive]})
    (folder / "geometry.bin").write_bytes(bytes(blob))
    pixels = np.zeros((4, 4, 4), np.uint8)
    pixels[..., 0], pixels[..., 1], pixels[..., 2], pixels[..., 3] = 200, 120, 40, 255
    Image.fromarray(pixels).save(folder / "albedo.png")
    (folder / "paint.json").write_text(json.dumps({"model": "gltf", "base_color": [0.2, 0.3, 0.9], "metallic": 0.0,
                                                   "roughness": 0.4}))  # fmt: skip
    doc = {
        "asset": {"version": "2.0", "generator": "lobeview test"},
        "extensionsUsed": ["KHR_materials_clearcoat"],
        "buffers": [{"byteLength": len(blob), "uri": "geometry.bin"}],
        "bufferViews": views,
        "accessors": accessors,
        "images": [{"uri": "albedo.png", "name": "albedo"}],
        "samplers": [{"wrapS": 33648, "wrapT": 33071, "magFilter": 9728}],
        "textures": [{"source": 0, "sampler": 0}],
        "materials": [
            {
                "name": "coated",
                "doubleSided": True,
                "alphaMode": "MASK",
                "alphaCutoff": 0.3,
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0},
                    "baseColorFactor": [1, 0.5, 0.5, 0.9],
                    "metallicFactor": 0.25,
                    "roughnessFactor": 0.6,
                },
                "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 0.8}},
                "extras": {"author": "test"},
            },
            {"name": "painted", "extras": {"lobeview": "paint.json"}},
        ],  # fmt: skip
        "meshes": meshes,
        "nodes": [
            {"name": "original", "mesh": 0, "translation": [0, 0, 0]},
            {"name": "instance", "mesh": 0, "translation": [3, 0, 0]},
            {"name": "mirrored", "mesh": 1, "scale": [-1, 1, 1], "translation": [0, 3, 0]},
            {"name": "view", "camera": 0, "translation": [0, 1, 6], "extras": {"bookmark": True}},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
        "scenes": [{"nodes": [0, 1, 2, 3], "name": "main"}],
        "scene": 0,
    }
    if not shared_atlas:
        doc["meshes"][1]["primitives"][0]["material"] = 1
        del doc["meshes"][0]["primitives"][0]["material"]  # a primitive without a material
    path = folder / "scene.gltf"
    path.write_text(json.dumps(doc))
    return path


def _corners(path: Path, node_index: int) -> dict:
    """Per attribute, the values at the three corners of every triangle of the node's first
    primitive, each triangle rotated (not reflected) to start at its smallest corner and the
    triangles sorted: equal for two files that draw the same triangles with the same winding."""
    reader = _Reader(_parse(path, DEFAULT_LIMITS), path)
    doc = source_json(path)
    prim = doc["meshes"][doc["nodes"][node_index]["mesh"]]["primitives"][0]
    triangles = reader.accessor(prim["indices"], raw=True).reshape(-1, 3).astype(np.int64)
    names = sorted(n for n in prim["attributes"] if n != "TEXCOORD_1")
    values = {n: reader.accessor(prim["attributes"][n], raw=True).astype(np.float64) for n in names}
    key = np.concatenate([values[n] for n in names], axis=1)[triangles]  # (T, 3, channels)
    first = np.array([min(range(3), key=lambda c, t=t: tuple(t[c])) for t in key])
    order = (first[:, None] + np.arange(3)[None, :]) % 3
    rotated = np.take_along_axis(key, order[:, :, None], axis=1)
    return np.array(sorted(map(lambda t: tuple(t.ravel()), rotated)))


def _image_bytes(path: Path, image_index: int) -> bytes:
    doc = source_json(path)
    image = doc["images"][image_index]
    if "uri" in image:
        return (path.parent / image["uri"]).read_bytes()
    reader = _Reader(_parse(path, DEFAULT_LIMITS), path)
    return bytes(reader.view_bytes(image["bufferView"])[0])


def test_bake_writes_the_input_back_with_only_the_lightmap_added(tmp_path):
    source_folder = tmp_path / "in"
    source_folder.mkdir()
    source = _rich_gltf(source_folder)
    scene = load_gltf(source)
    assert all(obj.origin is not None for obj in scene.objects)
    scene = unwrap_lightmap_uvs(scene, 64)
    lightmap = bake_lightmap(scene, _sky(), 64, rays=4, bounces=1, progress=False, light_samples=4)
    out = tmp_path / "elsewhere" / "baked.glb"
    assert write_baked_gltf(source, scene, lightmap, out) == [out]
    before, after = source_json(source), source_json(out)

    for key in set(before) | set(after):
        if key not in CHANGED_TOP_LEVEL:
            assert after.get(key) == before.get(key), key
    # Materials: unchanged but for MOZ_lightmap; the material file inlined; the default explicit.
    lightmap_texture = len(before["textures"])
    for index, material in enumerate(before["materials"]):
        baked = json.loads(json.dumps(after["materials"][index]))
        assert baked["extensions"].pop("MOZ_lightmap") == {"index": lightmap_texture, "texCoord": 1, "intensity": 1.0}
        if not baked["extensions"]:
            del baked["extensions"]
        if material.get("extras", {}).get("lobeview") == "paint.json":
            assert baked["extras"]["lobeview"] == json.loads((source_folder / "paint.json").read_text())
            baked["extras"]["lobeview"] = "paint.json"
        assert baked == material
    default = after["materials"][len(before["materials"])]
    assert default["extensions"]["MOZ_lightmap"]["index"] == lightmap_texture
    assert after["meshes"][0]["primitives"][0]["material"] == len(before["materials"])
    # Textures, samplers and images: the input's first, byte for byte, then the lightmap.
    assert after["textures"][: len(before["textures"])] == before["textures"]
    assert after["samplers"][: len(before["samplers"])] == before["samplers"]
    assert _image_bytes(out, 0) == (source_folder / "albedo.png").read_bytes()
    assert after["images"][0]["mimeType"] == "image/png" and "uri" not in after["images"][0]
    assert set(after["extensionsUsed"]) == {"KHR_materials_clearcoat", "MOZ_lightmap"}
    assert after["buffers"] == [{"byteLength": after["buffers"][0]["byteLength"]}]  # one embedded buffer
    # Nodes: the instance got its own copy of the mesh (its own place in the atlas).
    assert [n.get("mesh") for n in after["nodes"]] == [0, len(before["meshes"]), 1, None]
    for a, b in zip(after["nodes"], before["nodes"], strict=True):
        assert {k: v for k, v in a.items() if k != "mesh"} == {k: v for k, v in b.items() if k != "mesh"}
    # Geometry: every triangle with every attribute at its corners, winding included (the
    # mirrored node's too), the padded VEC3 colour as stored, primitive extras kept.
    for node in range(3):
        np.testing.assert_array_equal(_corners(out, node), _corners(source, node))
        prim = after["meshes"][after["nodes"][node]["mesh"]]["primitives"][0]
        assert prim["extras"] == {"kept": 0 if node < 2 else 1}
        colour = after["accessors"][prim["attributes"]["COLOR_0"]]
        assert colour["componentType"] == 5121 and colour["normalized"] is True
        assert after["bufferViews"][colour["bufferView"]]["byteStride"] == 4
    # The lightmap: embedded, read back exactly, on TEXCOORD_1 of every object.
    baked_scene = load_gltf(out)
    assert len(baked_scene.objects) == 3 and not [w for w in baked_scene.warnings if "lightmap" in w]
    for obj in baked_scene.objects:
        material = baked_scene.materials[obj.material]
        assert obj.uv1 is not None and obj.uv1.min() >= 0 and obj.uv1.max() <= 1
        np.testing.assert_array_equal(material.lightmap.image, lightmap)
    assert lightmap_uv_overlap(baked_scene, 64) < 0.05
    coated = baked_scene.materials[0]
    assert (coated.alpha_mode, coated.alpha_cutoff, coated.double_sided) == ("MASK", 0.3, True)
    assert coated.textures["base_color"].wrap_s == 33648
    assert sorted(os.listdir(source_folder)) == ["albedo.png", "geometry.bin", "paint.json", "scene.gltf"]


def test_a_shared_atlas_in_the_file_is_baked_into_without_touching_the_geometry(tmp_path):
    source = _rich_gltf(tmp_path, shared_atlas=True)
    scene = load_gltf(source)
    # Two nodes draw mesh 0: an instanced mesh with its own TEXCOORD_1 overlaps itself.
    assert lightmap_uv_overlap(scene, 64) > 0.2
    scene.objects = [o for o in scene.objects if o.origin[0] != 1]
    assert lightmap_uv_overlap(scene, 64) < 0.05
    lightmap = bake_lightmap(scene, _sky(), 64, rays=4, bounces=1, progress=False, light_samples=4)
    out = write_baked_gltf(source, scene, lightmap, tmp_path / "baked.glb", external_lightmap=True)
    assert out == [tmp_path / "baked.glb", tmp_path / "baked_lightmap.exr"]
    before, after = source_json(source), source_json(out[0])
    # Geometry untouched; only the primitive without a material got the explicit default.
    assert after["meshes"][1]["primitives"][0].pop("material") == len(before["materials"])
    assert after["meshes"] == before["meshes"]
    assert after["accessors"] == before["accessors"]
    assert after["images"][-1] == {"name": "lightmap", "uri": "baked_lightmap.exr"}
    for node in (0, 2):
        np.testing.assert_array_equal(_corners(out[0], node), _corners(source, node))


def test_bake_command_writes_into_the_current_folder_and_checks_the_output_first(tmp_path, monkeypatch, capsys):
    source = _rich_gltf(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["bake", str(source), *BAKE_FAST]) == 0
    assert (work / "scene_baked.glb").is_file() and not (tmp_path / "scene_baked.glb").exists()
    assert "unwrapping all 3 objects" in capsys.readouterr().out
    # An output that cannot be written is refused before the bake starts.
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where a folder should be")
    assert main(["bake", str(source), *BAKE_FAST, "--out", str(blocked / "x.glb")]) != 0
    err = capsys.readouterr().err
    assert "cannot write" in err and "--out" in err and "[bake]" not in err
    assert main(["bake", str(source), *BAKE_FAST, "--out", str(work / "x.gltf")]) != 0
    assert ".glb" in capsys.readouterr().err


def test_bake_refuses_to_replace_texcoord1_that_a_texture_reads(tmp_path, capsys):
    source = _rich_gltf(tmp_path)
    doc = json.loads(source.read_text())
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] = 1
    doc["meshes"][0]["primitives"][0]["material"] = 0
    source.write_text(json.dumps(doc))
    assert main(["bake", str(source), *BAKE_FAST, "--out", str(tmp_path / "o.glb")]) != 0
    err = capsys.readouterr().err
    assert "TEXCOORD_1" in err and "'coated'" in err and not (tmp_path / "o.glb").exists()


@pytest.mark.skipif(not (ASSETS / "CornellBox" / "CornellBox.glb").is_file(), reason="shared assets missing")
def test_cornell_box_at_authored_scale_is_rebaked_into_one_atlas(tmp_path, capsys):
    """The sample's TEXCOORD_1 is one [0, 1] map per object: baking into it would overlay six
    objects in one image. The bake sees that, unwraps, and the result lights every object."""
    source = ASSETS / "CornellBox" / "CornellBox.glb"
    assert lightmap_uv_overlap(load_gltf(source), 64) > 0.5
    out = tmp_path / "cornell.glb"
    assert main(["bake", str(source), "--resolution", "128", "--rays", "8", "--bounces", "1", "--out", str(out)]) == 0
    assert "claims" in capsys.readouterr().out
    before, baked = load_gltf(source), load_gltf(out)
    assert [m.name for m in baked.materials] == [m.name for m in before.materials]
    for obj in baked.objects:
        image = baked.materials[obj.material].lightmap.image
        uv = np.clip((obj.uv1 * 128).astype(int), 0, 127)
        assert np.all(np.isfinite(image)) and image[uv[:, 1], uv[:, 0]].max() > 0, obj.name
    assert lightmap_uv_overlap(baked, 128) < 0.05


def test_embedded_hdr_images_are_read_with_their_header_checked(tmp_path):
    """An EXR inside a .glb is read like an EXR file: decoded exactly, its declared size checked
    against the limits first (refused: the documented lightmap fallback, with the reason)."""
    from lobeview.core.trust import Limits

    source = _rich_gltf(tmp_path)
    scene = unwrap_lightmap_uvs(load_gltf(source), 64)
    lightmap = np.random.default_rng(3).random((64, 64, 3)).astype(np.float32)
    out = write_baked_gltf(source, scene, lightmap, tmp_path / "b.glb")[0]
    np.testing.assert_array_equal(load_gltf(out).materials[0].lightmap.image, lightmap)
    refused = load_gltf(out, Limits(max_image_pixels=32 * 32))
    assert refused.materials[0].lightmap is None
    assert any("lightmap" in w and "1024 pixels" in w for w in refused.warnings), refused.warnings


@pytest.fixture
def xatlas_meshes(monkeypatch):
    """The positions of every mesh the unwrap hands to xatlas, in order."""
    import xatlas

    handed = []

    class RecordingAtlas(xatlas.Atlas):
        def add_mesh(self, positions, *args, **kwargs):
            handed.append(np.array(positions))
            return super().add_mesh(positions, *args, **kwargs)

    monkeypatch.setattr(xatlas, "Atlas", RecordingAtlas)
    return handed


def test_unwrap_hands_xatlas_one_mesh_and_keeps_each_objects_charts_its_own(xatlas_meshes):
    """xatlas' add-mesh queue can be reallocated under a worker thread between two add_mesh calls
    (a CI run crashed there): the unwrap adds one mesh. Objects that touch (boxes sharing a face),
    coincide (two back-to-back quads) or continue each other in one plane still get charts of
    their own, and every triangle keeps its corners."""
    from lobeview.scenes.meshes import box_mesh, quad
    from lobeview.scenes.scene import Scene, SceneObject

    meshes = [
        box_mesh((0.0, 0.5, 0.0), (1.0, 1.0, 1.0)),
        box_mesh((1.0, 0.5, 0.0), (1.0, 1.0, 1.0)),  # shares the x = 0.5 face with the first
        quad((2, 0, 0), (1, 0, 0), (0, 1, 0)),
        quad((3, 0, 0), (-1, 0, 0), (0, 1, 0)),  # the same square, facing the other way
        quad((4, 0, 0), (1, 0, 0), (0, 1, 0)),
        quad((5, 0, 0), (1, 0, 0), (0, 1, 0)),  # coplanar with the one before, sharing an edge
    ]
    scene = Scene([SceneObject(f"object {i}", mesh, 0) for i, mesh in enumerate(meshes)], [])
    corners_before = [mesh.positions[mesh.indices] for mesh in meshes]
    unwrap_lightmap_uvs(scene, 128)

    assert [len(positions) for positions in xatlas_meshes] == [sum(len(mesh.positions) for mesh in meshes)]
    for obj, mesh, corners in zip(scene.objects, meshes, corners_before, strict=True):
        np.testing.assert_array_equal(obj.mesh.positions[obj.mesh.indices], corners)
        np.testing.assert_array_equal(obj.mesh.positions, mesh.positions[obj.vertex_map])
        assert obj.uv1.shape == (len(obj.mesh.positions), 2) and 0.0 <= obj.uv1.min() and obj.uv1.max() <= 1.0
    assert lightmap_uv_overlap(scene, 128) < 0.01
    # One chart over two objects would give their shared edge the same lightmap coordinates.
    for a in range(len(meshes)):
        for b in range(a):
            gaps = np.abs(scene.objects[a].uv1[:, None] - scene.objects[b].uv1[None]).max(axis=2)
            assert gaps.min() > 1.0 / 128, (a, b)


def test_unwrap_keeps_a_small_object_exact_beside_a_large_one(xatlas_meshes):
    """Moving the objects apart for the one xatlas mesh must not cost a small object its float32
    precision: a 2 cm bead beside a 10 km ground reaches xatlas with its shape intact."""
    import trimesh

    from lobeview.scenes.meshes import Mesh, quad
    from lobeview.scenes.scene import Scene, SceneObject

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.01)
    bead_positions = (sphere.vertices + [4999.0, 0.01, -4999.0]).astype(np.float32)
    bead = Mesh(
        bead_positions,
        sphere.vertex_normals.astype(np.float32),
        np.tile(np.array([[1, 0, 0, 1]], np.float32), (len(sphere.vertices), 1)),
        np.zeros((len(sphere.vertices), 2), np.float32),
        sphere.faces.astype(np.uint32),
        "bead",
    )
    ground = quad((-5000, 0, 5000), (10000, 0, 0), (0, 0, -10000))
    scene = Scene([SceneObject("ground", ground, 0), SceneObject("bead", bead, 0)], [])
    unwrap_lightmap_uvs(scene, 512)
    (positions,) = xatlas_meshes
    handed_bead = positions[len(ground.positions) :]
    shape_error = (handed_bead - handed_bead[0]) - (bead_positions - bead_positions[0])
    assert np.abs(shape_error).max() < 1e-6 * 0.02
    bead_uv = scene.objects[1].uv1[scene.objects[1].mesh.indices]
    assert np.ptp(bead_uv.reshape(-1, 2), axis=0).min() > 0


def test_a_measured_material_travels_with_the_baked_scene(tmp_path):
    """A measured material (a MERL table named by the material file, in the scene's folder) is
    resolved inside that folder; the bake copies the table beside its output and names it there,
    so the baked scene loads the same material from its own folder."""
    from lobeview.materials.measurement import merl_table_from_bsdf, read_merl, write_merl
    from lobeview.materials.spec import build_bsdf, load_material

    source_folder = tmp_path / "in"
    source_folder.mkdir()
    source = _rich_gltf(source_folder)
    write_merl(merl_table_from_bsdf(build_bsdf(load_material("plastic"))), source_folder / "plastic.binary")
    (source_folder / "paint.json").write_text(json.dumps({"model": "measured", "file": "plastic.binary"}))
    scene = unwrap_lightmap_uvs(load_gltf(source), 64)
    painted = next(m for m in scene.materials if m.name == "painted")
    assert painted.desc["file"] == str((source_folder / "plastic.binary").resolve())
    lightmap = np.random.default_rng(5).random((64, 64, 3)).astype(np.float32)
    out = tmp_path / "elsewhere" / "baked.glb"
    out.parent.mkdir()
    written = write_baked_gltf(source, scene, lightmap, out)
    assert written == [out, out.parent / "baked_plastic.binary"]
    baked = next(m for m in load_gltf(out).materials if m.name == "painted")
    assert baked.desc["model"] == "measured" and Path(baked.desc["file"]).parent == out.parent.resolve()
    np.testing.assert_array_equal(read_merl(baked.desc["file"]), read_merl(source_folder / "plastic.binary"))
    # A table outside the scene's folder is refused with the folder rule's message.
    outside = {"model": "measured", "file": "../elsewhere/baked_plastic.binary"}
    (source_folder / "paint.json").write_text(json.dumps(outside))
    with pytest.raises(GltfError, match="outside the scene's folder"):
        load_gltf(source)
