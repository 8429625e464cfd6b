#version 450 core
// Depth only (viewer/occlusion.py): the occluders and the queried reflectors of the mirror
// passes' occlusion test. Invariant, so that a surface drawn twice gets the same depth.
in vec3 in_position;
uniform mat4 u_view_projection;
invariant gl_Position;

void main() {
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
