#version 450 core
// Depth only (viewer/occlusion.py): the occluders and the queried reflectors of the mirror
// passes' occlusion test. Invariant, so that a surface drawn twice gets the same depth.
in vec3 in_position;
uniform mat4 u_view_projection;
invariant gl_Position;
#if defined(OBJECT_INDEX)
// The multi-drawn occlusion test counts each object's samples (visible_samples.frag): the object
// index is the command's baseInstance (viewer/object_batches.py SceneGeometry.object_slots).
in uint in_object;
flat out uint v_object;
#endif

void main() {
    gl_Position = u_view_projection * vec4(in_position, 1.0);
#if defined(OBJECT_INDEX)
    v_object = in_object;
#endif
}
