#version 450 core
// Adds weight * radiance of one pass into the float accumulation buffer (additive blending).
in vec2 v_uv;
uniform sampler2D u_source;
uniform float u_weight;
out vec4 out_color;
void main() { out_color = vec4(texture(u_source, v_uv).rgb * u_weight, u_weight); }
