#version 450 core
// Light-mapped scene: diffuse kd E / pi from the lightmap (thesis Eq. 4.1) plus emission; with
// SPECULAR the view-dependent lobes integrated from the object's cube map (thesis 4.4).
#include "frame.glsl"
#include "integrate.glsl"

in vec3 v_position;
in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv0;
in vec2 v_uv1;

uniform vec3 u_camera_position;
uniform sampler2D u_lightmap;
uniform int u_lightmap_texcoord;      // 0 or 1; -1: no lightmap, use u_fallback_irradiance
uniform float u_lightmap_intensity;
uniform vec3 u_fallback_irradiance;
uniform sampler2D u_base_color;
uniform int u_has_base_color;
uniform vec3 u_emission;
uniform float u_object_id;            // for picking: written + 1 into the normal buffer's w

layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_position;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out vec4 out_tangent;
#if defined(PLANE_AVERAGE)
layout(location = 4) out vec4 out_plane_point[2];   // averaged tangent planes (integrate.glsl), 4-5
layout(location = 6) out vec4 out_plane_normal[2];  // 6-7
#endif

void main() {
#if defined(PARALLAX) || defined(MIRROR)
    g_shading_position = v_position;
#endif
#if defined(PLANE_AVERAGE)
    plane_average_load();
#endif
    vec3 geometric_normal = normalize(cross(dFdx(v_position), dFdy(v_position)));
    mat3 tbn = shading_frame(v_normal, v_tangent, geometric_normal);
    vec3 wo = view_in_frame(tbn, normalize(u_camera_position - v_position));

    vec3 irradiance = u_fallback_irradiance;
    if (u_lightmap_texcoord >= 0) {
        vec2 uv = u_lightmap_texcoord == 1 ? v_uv1 : v_uv0;
        irradiance = texture(u_lightmap, uv).rgb * u_lightmap_intensity;
    }
    vec3 albedo = u_kd;
    if (u_has_base_color == 1) albedo *= texture(u_base_color, v_uv0).rgb;
    vec3 diffuse = albedo / PI * irradiance;
    diffuse *= diffuse_weight(wo.z);
    vec3 radiance = u_emission + diffuse;
#if defined(SPECULAR)
    for (int i = 0; i < u_lobe_count; ++i) radiance += integrate_lobe(get_lobe(i), i, wo, tbn);
#endif
    bool bad = any(isnan(radiance)) || any(isinf(radiance));
    out_radiance = bad ? vec4(0.0, 0.0, 0.0, -1.0) : vec4(radiance, 1.0);
    out_position = vec4(v_position, 1.0);
    out_normal = vec4(tbn[2], u_object_id + 1.0);
    out_tangent = vec4(tbn[0], 1.0);
#if defined(PLANE_AVERAGE)
    for (int side = 0; side < 2; ++side) {
        out_plane_point[side] = g_plane_point_sum[side];
        out_plane_normal[side] = vec4(g_plane_normal_sum[side], 0.0);
    }
#endif
}
