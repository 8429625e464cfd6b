#version 450 core
// Probe of shaders/self_occlusion.glsl for tests (tests/test_self_visibility.py): per invocation,
// read (direction, footprint sr), (normal, 0), the eight horizon sines and (distribution, alpha)
// and write self_visibility(direction, footprint) for that normal and horizon, and
// split_sum_footprint(distribution, alpha).
layout(local_size_x = 64) in;
#include "cube.glsl"
#include "self_occlusion.glsl"

layout(std430, binding = 2) readonly buffer ProbeIn { vec4 probe_in[]; };    // 5 per item
layout(std430, binding = 3) writeonly buffer ProbeOut { vec4 probe_out[]; }; // 1 per item
uniform int u_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec4 direction = probe_in[5 * i];
    g_self_cone = vec4(0.0, 0.0, 1.0, 0.5);  // any cone: occlusion on
    set_self_normal(probe_in[5 * i + 1].xyz);
    for (int k = 0; k < 4; ++k) {
        g_self_horizon[k] = probe_in[5 * i + 2][k];
        g_self_horizon[k + 4] = probe_in[5 * i + 3][k];
    }
    vec4 lobe = probe_in[5 * i + 4];
    probe_out[i] = vec4(self_visibility(direction.xyz, direction.w),
                        split_sum_footprint(int(lobe.x), lobe.y), 0.0, 0.0);
}
