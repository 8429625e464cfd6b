#version 450 core
in vec2 v_ndc;
uniform samplerCube u_background;
uniform mat4 u_inverse_view_projection;
layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_position;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out vec4 out_tangent;
void main() {
    vec4 far_point = u_inverse_view_projection * vec4(v_ndc, 1.0, 1.0);
    vec4 near_point = u_inverse_view_projection * vec4(v_ndc, -1.0, 1.0);
    vec3 dir = normalize(far_point.xyz / far_point.w - near_point.xyz / near_point.w);
    // The level of the pixel's footprint (implicit derivatives): a small cube face drawn from the
    // environment's 256^2 cube reads the MIP level of its texel's size, as a 2x2 box or tent
    // average, not level 0 at one point, which catches or misses a lamp smaller than the texel
    // (viewer/cubemap.py face_supersample: the same aliasing, measured). A camera pass magnifies
    // (its pixels are smaller than the cube's texels) and reads level 0 as before.
    out_radiance = vec4(texture(u_background, dir).rgb, 1.0);
    out_position = vec4(0.0);
    out_normal = vec4(0.0);
    out_tangent = vec4(0.0);
}
