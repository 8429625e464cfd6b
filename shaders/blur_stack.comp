#version 450 core
// One layer of a blur stack (materials/blur_stack.py; viewer/blur_stack_gpu.py) from a radiance
// cube's MIP chain: at each padded texel's direction the von Mises-Fisher blur of the layer's
// sigma less a bilinear read's tent (texel_blur), as taps on a (2 BLUR_STACK_TAPS + 1)^2 grid of
// the tangent plane (exponential map, area element sin(rho) / rho) out to 3.5 sigma (at most pi),
// each tap a read of the chain blurred by half the taps' spacing h (lod_for_sigma) and weighted by
// the vMF of the variance left: many small reads, so the chain's coarse lumps average out and the
// variances add as they do for narrow kernels (a tap blur of 1.5 h was 2-3x further from the exact
// blur, of h 1.5x). Against the exact blur of the cube's own texels (128^2, issue 45's sky): 0.3-1.0 %
// RMS per layer (tests/test_blur_stack.py).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
#include "cube.glsl"
layout(rgba32f, binding = 0) uniform writeonly image2DArray u_target;
uniform samplerCube u_source;
uniform float u_source_face;  // the source cube's level-0 face size
uniform int u_layer;          // k: writes layers 6 k + face
uniform float u_sigma;        // the layer's sigma (rad)

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    const int size = BLUR_STACK_FACE + 2 * BLUR_STACK_PAD;
    if (id.x >= size || id.y >= size) return;
    float sc = (float(id.x - BLUR_STACK_PAD) + 0.5) / float(BLUR_STACK_FACE) * 2.0 - 1.0;
    float tc = (float(id.y - BLUR_STACK_PAD) + 0.5) / float(BLUR_STACK_FACE) * 2.0 - 1.0;
    vec3 axis = normalize(cube_face_direction(id.z, sc, tc));
    vec3 m = abs(axis);
    float texel = 2.0 / float(BLUR_STACK_FACE) * pow(max(max(m.x, m.y), m.z), 1.5);
    float blur2 = max(u_sigma * u_sigma - texel * texel / 6.0, 0.09 * u_sigma * u_sigma);
    float radius = min(3.5 * sqrt(blur2), PI);
    float h = radius / float(BLUR_STACK_TAPS);
    float tap_blur = 0.5 * h;
    float weight_variance = max(blur2 - tap_blur * tap_blur, 0.25 * blur2);
    vec3 e1 = normalize(cross(axis, m.y < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0)));
    vec3 e2 = cross(axis, e1);
    vec3 sum = vec3(0.0);
    float weight_sum = 0.0;
    for (int i = -BLUR_STACK_TAPS; i <= BLUR_STACK_TAPS; ++i) {
        for (int j = -BLUR_STACK_TAPS; j <= BLUR_STACK_TAPS; ++j) {
            vec2 ab = vec2(float(i), float(j)) * h;
            float rho = length(ab);
            if (rho > radius) continue;
            float sinc = rho > 1e-6 ? sin(rho) / rho : 1.0;
            vec3 d = normalize(cos(rho) * axis + sinc * (ab.x * e1 + ab.y * e2));
            float w = exp((cos(rho) - 1.0) / weight_variance) * sinc;
            sum += w * textureLod(u_source, d, lod_for_sigma(d, tap_blur, u_source_face)).rgb;
            weight_sum += w;
        }
    }
    imageStore(u_target, ivec3(id.xy, 6 * u_layer + id.z), vec4(sum / weight_sum, 1.0));
}
