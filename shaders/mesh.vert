#version 450 core
in vec3 in_position;
in vec3 in_normal;
in vec4 in_tangent;

uniform mat4 u_model;
uniform mat3 u_normal_matrix;
uniform mat4 u_view_projection;

out vec3 v_position;
out vec3 v_normal;
out vec4 v_tangent;

void main() {
    vec4 world = u_model * vec4(in_position, 1.0);
    v_position = world.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_tangent = vec4(mat3(u_model) * in_tangent.xyz, in_tangent.w);
    gl_Position = u_view_projection * world;
}
