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
"""

from __future__ import annotations

import json
import math
import sys


def _blender_vector(v):
    """glTF (x, y, z) -> Blender (x, -z, y)."""
    from mathutils import Vector

    return Vector((v[0], -v[2], v[1]))


def render(job: dict) -> None:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=job["gltf"])
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
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = job["out"]
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    with open(sys.argv[-1], encoding="utf-8") as handle:
        render(json.load(handle))
