#version 450 core
// World-space scene geometry (transforms applied at load time).
in vec3 in_position;
in vec3 in_normal;
in vec4 in_tangent;
in vec2 in_uv0;
in vec2 in_uv1;
in vec4 in_visibility;  // scenes/self_visibility.py: bent normal, cos of the cone's half angle
in vec4 in_horizon0;  // ... and the horizon's sine in azimuth sectors 0-3
in vec4 in_horizon1;  // ... and 4-7

uniform mat4 u_view_projection;
#if defined(OBJECT_RECORDS)
// The object's index: a per-instance attribute, so a multi-draw command's baseInstance picks
// it (viewer/object_batches.py ObjectBatches); GL 4.2 core, no draw-parameters extension.
in uint in_object;
flat out uint v_object;
#endif

out vec3 v_position;
out vec3 v_normal;
out vec4 v_tangent;
out vec2 v_uv0;
out vec2 v_uv1;
out vec4 v_visibility;
out vec4 v_horizon0;
out vec4 v_horizon1;
// The same expression as depth.vert: the depth pre-pass (viewer/occlusion.py) must match exactly.
invariant gl_Position;

void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_tangent = in_tangent;
    v_uv0 = in_uv0;
    v_uv1 = in_uv1;
    v_visibility = in_visibility;
    v_horizon0 = in_horizon0;
    v_horizon1 = in_horizon1;
#if defined(OBJECT_RECORDS)
    v_object = in_object;
#endif
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
