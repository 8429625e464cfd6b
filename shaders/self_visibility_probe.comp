#version 450 core
// Probe of shaders/self_occlusion.glsl for tests (tests/test_self_visibility.py): per invocation,
// read (direction, footprint sr), (normal, sectors), MAP_HORIZON_SECTORS horizon sines (the first
// `sectors` used: HORIZON_SECTORS as at vertices, or MAP_HORIZON_SECTORS as in a horizon map) and
// (distribution, alpha, whether the lobe reflects: g_self_below_hidden) and the lobe's normal (a
// normal map's tilt: set_self_lobe_normal), and write
// self_visibility(direction, footprint) for that normal and horizon, and
// split_sum_footprint(distribution, alpha).
layout(local_size_x = 64) in;
#include "cube.glsl"
#include "self_occlusion.glsl"

const int PROBE_VEC4S = 4 + MAP_HORIZON_SECTORS / 4;  // per item
layout(std430, binding = 2) readonly buffer ProbeIn { vec4 probe_in[]; };
layout(std430, binding = 3) writeonly buffer ProbeOut { vec4 probe_out[]; }; // 1 per item
uniform int u_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    int first = PROBE_VEC4S * i;
    vec4 direction = probe_in[first];
    g_self_cone = vec4(0.0, 0.0, 1.0, 0.5);  // any cone: occlusion on
    set_self_normal(probe_in[first + 1].xyz);
    g_self_sectors = int(probe_in[first + 1].w);
    for (int k = 0; k < MAP_HORIZON_SECTORS; ++k) g_self_horizon[k] = probe_in[first + 2 + k / 4][k % 4];
    vec4 lobe = probe_in[first + PROBE_VEC4S - 2];
    g_self_below_hidden = lobe.z > 0.5;
    set_self_lobe_normal(probe_in[first + PROBE_VEC4S - 1].xyz);
    probe_out[i] = vec4(self_visibility(direction.xyz, direction.w),
                        split_sum_footprint(int(lobe.x), lobe.y), 0.0, 0.0);
}
