#version 450 core
// One tile of a reflection-space IBR map (viewer/rsibr.py; Cabral, Olano and Nemec 1999, seed 004,
// section 2 "radiance environment maps"): texel r of view v_j and tangent angle u_angle holds the
// radiance the material's baked lobes (u_rsibr_lobes) send towards v_j from the normal
// n_j = normalize(v_j + r), integrated by fis-N (METHOD_FIS, u_lod_bias 0) from the radiance cube.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
// frame.glsl declares what set_material writes (u_tangent_rotation: unused, the slice frame is final)
#include "frame.glsl"
#include "integrate.glsl"
#include "rsibr_common.glsl"

layout(rgba32f, binding = 0) uniform writeonly image2DArray u_target;
uniform int u_rows;
uniform int u_rsibr_lobes;
uniform int u_tile;
uniform vec3 u_view;
uniform float u_angle;

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    int rows = u_rows;
    if (id.x >= 2 * rows || id.y >= rows) return;
    vec3 r = latlong_to_direction((vec2(id) + 0.5) / vec2(2 * rows, rows));
    mat3 tbn = rsibr_slice_frame(rsibr_warped_normal(r, u_view), u_angle, u_view);
    vec3 wo = transpose(tbn) * u_view;
    wo.z = max(wo.z, 1e-4);  // as view_in_frame: no lobe formula sees wo.z <= 0
    wo = normalize(wo);
    vec3 sum = vec3(0.0);
    for (int i = 0; i < u_lobe_count; ++i) {
        if ((u_rsibr_lobes & (1 << i)) != 0) sum += integrate_lobe(get_lobe(i), i, wo, tbn);
    }
    bool bad = any(isnan(sum)) || any(isinf(sum));
    imageStore(u_target, ivec3(id, u_tile), vec4(bad ? vec3(0.0) : sum, bad ? -1.0 : 1.0));
}
