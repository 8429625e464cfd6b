#version 450 core
// Probe of shaders/rational.glsl for tests (tests/test_rational.py): per invocation, read
// (wi, wo) and (u, _) from the input buffer, write the Rational BRDF, the sampled direction for
// u and the density of wi. Holds the GLSL twin to materials/rational_brdf.py exactly, not through
// an image.
layout(local_size_x = 64) in;
#define HAS_RATIONAL 1
#include "bsdf.glsl"

layout(std430, binding = 2) readonly buffer ProbeIn { vec4 probe_in[]; };    // 3 per item: wi, wo, (u, 0, 0)
// 4 per item: f, (sampled wi, its pdf), (pdf of wi, 0, 0, 0), (wi sampled with the tangent-anchored lattice, its pdf)
layout(std430, binding = 3) writeonly buffer ProbeOut { vec4 probe_out[]; };
uniform int u_count;
uniform float u_theta_max;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec3 wi = probe_in[3 * i].xyz;
    vec3 wo = probe_in[3 * i + 1].xyz;
    vec2 u = probe_in[3 * i + 2].xy;
    probe_out[4 * i] = vec4(rational_brdf(wi, wo, u_theta_max), 0.0);
    float sampled_pdf;
    probe_out[4 * i + 1] = vec4(rational_sample(u, wo, false, sampled_pdf), sampled_pdf);
    probe_out[4 * i + 2] = vec4(rational_sample_pdf(wi, wo), 0.0, 0.0, 0.0);
    float anchored_pdf;
    probe_out[4 * i + 3] = vec4(rational_sample(u, wo, true, anchored_pdf), anchored_pdf);
}
