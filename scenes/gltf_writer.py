"""Writing world-space scenes to .glb with TEXCOORD_1, MOZ_lightmap and lobeview material extras
(the format :mod:`lobeview.scenes.gltf_loader` reads), lightmap as an EXR beside the .glb."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .hdrio import write_hdr_image
from .scene import Scene


def _core_material(desc: dict):
    """glTF's core metallic-roughness values: the material's own for the ``gltf`` model (so other
    readers, Blender's importer among them, see what lobeview renders), a neutral grey for the
    thesis models, which only lobeview's ``extras.lobeview`` describes."""
    import pygltflib

    if desc.get("model") == "gltf":
        return pygltflib.PbrMetallicRoughness(
            baseColorFactor=[*(float(c) for c in desc.get("base_color", (1.0, 1.0, 1.0))), 1.0],
            metallicFactor=float(desc.get("metallic", 1.0)),
            roughnessFactor=float(desc.get("roughness", 1.0)),
        )
    return pygltflib.PbrMetallicRoughness(baseColorFactor=[0.8, 0.8, 0.8, 1.0], metallicFactor=0.0, roughnessFactor=0.5)


def write_glb(
    scene: Scene,
    path: str | Path,
    lightmap: np.ndarray | None = None,
    lightmap_name: str | None = None,
) -> Path:
    import pygltflib

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = bytearray()
    buffer_views, accessors = [], []

    def add(
        array: np.ndarray,
        target: int | None,
        kind: str,
        component: int = 5126,
        minmax: bool = False,
    ) -> int:
        data = np.ascontiguousarray(array)
        while len(blob) % 4:
            blob.append(0)
        offset = len(blob)
        blob.extend(data.tobytes())
        buffer_views.append(pygltflib.BufferView(buffer=0, byteOffset=offset, byteLength=data.nbytes, target=target))
        acc = pygltflib.Accessor(bufferView=len(buffer_views) - 1, componentType=component, count=len(data), type=kind)
        if minmax:
            acc.min = data.min(axis=0).tolist()
            acc.max = data.max(axis=0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    meshes, nodes = [], []
    for obj in scene.objects:
        m = obj.mesh
        attrs = pygltflib.Attributes(
            POSITION=add(m.positions.astype(np.float32), 34962, "VEC3", minmax=True),
            NORMAL=add(m.normals.astype(np.float32), 34962, "VEC3"),
            TANGENT=add(m.tangents.astype(np.float32), 34962, "VEC4"),
            TEXCOORD_0=add(m.uvs.astype(np.float32), 34962, "VEC2"),
        )
        if obj.uv1 is not None:
            attrs.TEXCOORD_1 = add(obj.uv1.astype(np.float32), 34962, "VEC2")
        indices = add(m.indices.astype(np.uint32).reshape(-1), 34963, "SCALAR", component=5125)
        meshes.append(
            pygltflib.Mesh(
                name=obj.name,
                primitives=[pygltflib.Primitive(attributes=attrs, indices=indices, material=obj.material)],
            )
        )
        custom = {}
        if obj.reflection_proxy is not None:
            custom["reflection_proxy"] = obj.reflection_proxy.to_description()
        if obj.planar_reflector != "auto":
            custom["planar_reflector"] = obj.planar_reflector
        extras = {"lobeview": custom} if custom else {}
        nodes.append(pygltflib.Node(name=obj.name, mesh=len(meshes) - 1, extras=extras))

    textures, images, samplers = [], [], []
    if lightmap is not None:
        name = lightmap_name or (path.stem + "_lightmap.exr")
        write_hdr_image(path.parent / name, lightmap)
        images.append(pygltflib.Image(uri=name, name="lightmap"))
        samplers.append(pygltflib.Sampler(magFilter=9729, minFilter=9729, wrapS=33071, wrapT=33071))
        textures.append(pygltflib.Texture(source=0, sampler=0))

    materials = []
    for mat in scene.materials:
        extensions = {}
        if lightmap is not None:
            extensions["MOZ_lightmap"] = {"index": 0, "texCoord": 1, "intensity": 1.0}
        emission = np.asarray(mat.emission, dtype=float)
        strength = float(max(emission.max(), 1.0))
        if emission.max() > 1.0:
            extensions["KHR_materials_emissive_strength"] = {"emissiveStrength": strength}
        materials.append(
            pygltflib.Material(
                name=mat.name,
                doubleSided=mat.double_sided,
                emissiveFactor=(emission / strength).tolist(),
                extras={"lobeview": mat.desc},
                extensions=extensions,
                pbrMetallicRoughness=_core_material(mat.desc),
            )
        )

    for i, cam in enumerate(scene.cameras):
        forward = np.asarray(cam.target, float) - np.asarray(cam.position, float)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, cam.up)
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -forward, cam.position
        nodes.append(pygltflib.Node(name=cam.name, camera=i, matrix=m.T.reshape(-1).tolist()))

    used = ["MOZ_lightmap"] if lightmap is not None else []
    if any(np.max(m.emission) > 1.0 for m in scene.materials):
        used.append("KHR_materials_emissive_strength")
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0", generator="lobeview"),
        scene=0,
        scenes=[pygltflib.Scene(nodes=list(range(len(nodes))))],
        nodes=nodes,
        meshes=meshes,
        materials=materials,
        accessors=accessors,
        bufferViews=buffer_views,
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
        textures=textures,
        images=images,
        samplers=samplers,
        cameras=[
            pygltflib.Camera(
                type="perspective",
                name=c.name,
                perspective=pygltflib.Perspective(yfov=float(np.radians(c.fov_y)), znear=0.05, aspectRatio=None),
            )
            for c in scene.cameras
        ],
        extensionsUsed=used,
    )
    gltf.set_binary_blob(bytes(blob))
    gltf.save_binary(str(path))
    return path
