#version 450 core
// Probe of shaders/measured.glsl for tests (tests/test_measured.py): per invocation, read
// (wi, wo) and (u, _) from the input buffer, write the table's value, the sampled direction for
// u with its density, and the density of wi: the GLSL twin held to materials/measured.py exactly.
layout(local_size_x = 64) in;
#define HAS_MEASURED 1
#include "bsdf.glsl"

layout(std430, binding = 2) readonly buffer ProbeIn { vec4 probe_in[]; };    // 3 per item: wi, wo, (u, 0, 0)
// 3 per item: f, (sampled wi, its pdf), (pdf of wi, 0, 0, 0)
layout(std430, binding = 4) writeonly buffer ProbeOut { vec4 probe_out[]; };
uniform int u_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec3 wi = probe_in[3 * i].xyz;
    vec3 wo = probe_in[3 * i + 1].xyz;
    vec2 u = probe_in[3 * i + 2].xy;
    probe_out[3 * i] = vec4(measured_brdf(wi, wo), 0.0);
    float sampled_pdf;
    probe_out[3 * i + 1] = vec4(measured_sample(u, wo, sampled_pdf), sampled_pdf);
    probe_out[3 * i + 2] = vec4(measured_sample_pdf(wi, wo), 0.0, 0.0, 0.0);
}
