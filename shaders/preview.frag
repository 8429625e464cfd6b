#version 450 core
// Object preview: one object lit only by a distant environment (no lightmap).
#include "frame.glsl"
#include "integrate.glsl"

in vec3 v_position;
in vec3 v_normal;
in vec4 v_tangent;

uniform vec3 u_camera_position;

layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_position;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out vec4 out_tangent;

void main() {
    vec3 geometric_normal = normalize(cross(dFdx(v_position), dFdy(v_position)));
    vec3 footprint_r = light_footprint_direction(v_position, u_camera_position, v_normal);  // cap_lights.glsl
    set_light_footprint(dFdx(footprint_r), dFdy(footprint_r));
    mat3 tbn = rotate_tangent(shading_frame(v_normal, v_tangent, geometric_normal), u_tangent_rotation);
    vec3 wo = view_in_frame(tbn, normalize(u_camera_position - v_position));
    vec3 radiance = shade(wo, tbn);
    // Never write NaN/Inf into the accumulation buffer: flag it in alpha (tests look for it).
    bool bad = any(isnan(radiance)) || any(isinf(radiance));
    out_radiance = bad ? vec4(0.0, 0.0, 0.0, -1.0) : vec4(radiance, 1.0);
    out_position = vec4(v_position, 1.0);
    out_normal = vec4(tbn[2], 1.0);
    out_tangent = vec4(tbn[0], 1.0);
}
