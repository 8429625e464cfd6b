"""Renders one view in Blender Cycles (run as ``python bench/cycles_worker.py JOB.json`` by
:mod:`lobeview.bench.cycles`, in its own process: bpy must not share a process with lobeview's
OpenGL context). The job file says the glTF, the environment, the camera in glTF coordinates,
the size, the samples and where the linear EXR goes.

Conventions (each verified by :mod:`lobeview.bench.cycles` against lobeview's own ``reference``):
- Blender's glTF importer turns glTF (x, y, z) into Blender (x, -z, y); the camera is given in
  glTF coordinates and turned the same way here.
- lobeview's field of view is vertical: sensor fit VERTICAL with angle_y.
- the world is an Environment Texture (equirectangular) turned by -90 degrees about Blender's z
  (up): lobeview's u = 0.5 faces -z (glTF), Blender's u = 0.5 faces -x.
- box pixel filter of one pixel, no denoiser, view transform Standard, exposure 0, film
  transparent (the alpha marks the object's coverage), output linear 32-bit EXR.
- roughness floor (job "roughness_floor", default ROUGHNESS_FLOOR): Cycles 4.3 renders a GGX
  lobe of roughness about 0.003-0.015 black (its glossy light is NaN and the sample dropped: a
  metal sphere under a white sky at roughness 0.005 / 0.008 / 0.012 gives 0.9 / 6 / 21 % of its
  brightness at 0, 0.002 or 0.02; DamagedHelmet's visor has roughness 0.004-0.012 in its texture).
  Every Principled BSDF's Roughness and Coat Roughness are raised to at least the floor (a Math
  node after a texture): at 0.02 the lobe is far narrower than a pixel or an environment texel
  here, so the floor changes nothing else (the same sphere at 0 and at 0.02: equal means).
  ``python -m lobeview.bench.cycles --roughness-sweep`` measures it again.
- single-sided glTF materials: back faces hidden from camera rays (:func:`cull_back_faces`).
- job "passes" (``python -m lobeview.bench.cycles --passes``): the view layer's light passes
  (PASSES) go into a multilayer EXR beside the combined image: Combined = DiffCol (DiffDir +
  DiffInd) + GlossCol (GlossDir + GlossInd); under the white sky (radiance 1) GlossDir is the
  share of the glossy lobe that sees the sky past the object itself.
"""

from __future__ import annotations

import json
import math
import sys

ROUGHNESS_FLOOR = 0.02
ROUGHNESS_INPUTS = ("Roughness", "Coat Roughness")
PASSES = ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol")
PASS_PROPERTIES = {"DiffDir": "use_pass_diffuse_direct", "DiffInd": "use_pass_diffuse_indirect",
                   "DiffCol": "use_pass_diffuse_color", "GlossDir": "use_pass_glossy_direct",
                   "GlossInd": "use_pass_glossy_indirect", "GlossCol": "use_pass_glossy_color"}  # fmt: skip


def _blender_vector(v):
    """glTF (x, y, z) -> Blender (x, -z, y)."""
    from mathutils import Vector

    return Vector((v[0], -v[2], v[1]))


def raise_roughness(materials, floor: float) -> int:
    """Raise every Principled BSDF's roughness inputs to at least ``floor`` (see the module's
    docstring); returns how many inputs were changed or given a Math node."""
    changed = 0
    for material in materials:
        if not material.use_nodes or material.node_tree is None:
            continue
        tree = material.node_tree
        for node in list(tree.nodes):
            if node.type != "BSDF_PRINCIPLED":
                continue
            for name in ROUGHNESS_INPUTS:
                socket = node.inputs.get(name)
                if socket is None:
                    continue
                if socket.is_linked:
                    link = socket.links[0]
                    clamp = tree.nodes.new("ShaderNodeMath")
                    clamp.operation = "MAXIMUM"
                    clamp.inputs[1].default_value = floor
                    tree.links.new(link.from_socket, clamp.inputs[0])
                    tree.links.new(clamp.outputs[0], socket)
                    changed += 1
                elif socket.default_value < floor:
                    socket.default_value = floor
                    changed += 1
    return changed


def cull_back_faces(materials) -> int:
    """glTF's single-sided materials (doubleSided false: back faces culled, spec 3.9.6) as the
    rasteriser shows them: Blender's importer sets ``use_backface_culling``, which Cycles does
    not honour, so a camera ray that meets such a back face passes through it (Light Path "Is
    Camera Ray" x Geometry "Backfacing" mixes in a Transparent BSDF). Other rays are left alone:
    culling is a rule of what the camera sees, not of light transport (ClearCoatTest's partly
    transparent coat, seen through, showed the inside of its sample's box in Cycles and the sky
    behind it in lobeview). Returns how many materials were changed."""
    changed = 0
    for material in materials:
        if not material.use_backface_culling or not material.use_nodes or material.node_tree is None:
            continue
        tree = material.node_tree
        output = next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output), None)
        if output is None or not output.inputs["Surface"].is_linked:
            continue
        surface = output.inputs["Surface"].links[0].from_socket
        geometry = tree.nodes.new("ShaderNodeNewGeometry")
        light_path = tree.nodes.new("ShaderNodeLightPath")
        culled = tree.nodes.new("ShaderNodeMath")
        culled.operation = "MULTIPLY"
        tree.links.new(geometry.outputs["Backfacing"], culled.inputs[0])
        tree.links.new(light_path.outputs["Is Camera Ray"], culled.inputs[1])
        transparent = tree.nodes.new("ShaderNodeBsdfTransparent")
        mix = tree.nodes.new("ShaderNodeMixShader")
        tree.links.new(culled.outputs[0], mix.inputs["Fac"])
        tree.links.new(surface, mix.inputs[1])
        tree.links.new(transparent.outputs["BSDF"], mix.inputs[2])
        tree.links.new(mix.outputs["Shader"], output.inputs["Surface"])
        changed += 1
    return changed


def render(job: dict) -> None:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=job["gltf"])
    floor = float(job.get("roughness_floor", ROUGHNESS_FLOOR))
    if floor > 0:
        print(f"roughness floor {floor}: {raise_roughness(bpy.data.materials, floor)} inputs", flush=True)
    print(f"single-sided materials: {cull_back_faces(bpy.data.materials)}", flush=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = int(job["spp"])
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.seed = int(job.get("seed", 0))
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.cycles.max_bounces = int(job.get("bounces", 12))
    scene.render.resolution_x, scene.render.resolution_y = job["size"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.threads_mode = "FIXED"
    scene.render.threads = int(job.get("threads", 2))
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"

    world = bpy.data.worlds.new("lobeview environment")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = nodes["Background"]
    background.inputs["Strength"].default_value = 1.0
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = bpy.data.images.load(job["environment"])
    texture.image.colorspace_settings.name = "Linear Rec.709"
    texture.interpolation = "Closest" if job.get("closest", False) else "Linear"
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(float(job.get("env_rotation_deg", -90.0))))
    coordinates = nodes.new("ShaderNodeTexCoord")
    links.new(coordinates.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    links.new(texture.outputs["Color"], background.inputs["Color"])

    camera_data = bpy.data.cameras.new("lobeview camera")
    camera_data.sensor_fit = "VERTICAL"
    camera_data.angle_y = math.radians(float(job["fov_y"]))
    camera = bpy.data.objects.new("lobeview camera", camera_data)
    scene.collection.objects.link(camera)
    position = _blender_vector(job["camera"])
    target = _blender_vector(job["target"])
    up = _blender_vector(job.get("up", (0.0, 1.0, 0.0)))
    camera.location = position
    # clipping planes from the distance to the target: models come in any unit (the CornellBox
    # is 556 units wide, seen from 1300 away)
    distance = max((target - position).length, 1e-6)
    camera_data.clip_start = 1e-3 * distance
    camera_data.clip_end = 1e3 * distance
    forward = (target - position).normalized()
    right = forward.cross(up).normalized()
    true_up = right.cross(forward)
    from mathutils import Matrix

    # Blender cameras look down their local -z with +y up.
    rotation = Matrix((right, true_up, -forward)).transposed()
    camera.rotation_euler = rotation.to_euler()
    scene.camera = camera

    scene.render.image_settings.file_format = "OPEN_EXR"
    if job.get("passes", False):
        for name in PASSES:
            setattr(bpy.context.view_layer, PASS_PROPERTIES[name], True)
        scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = job["out"]
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    with open(sys.argv[-1], encoding="utf-8") as handle:
        render(json.load(handle))
