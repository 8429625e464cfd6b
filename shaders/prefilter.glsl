// Prefiltering with a radially symmetric kernel (numpy reference: materials/prefilter.py):
// M(d) = integral p(angle(d, l)) L(l) dl, by stratified importance quadrature. Ring k lies at
// the kernel's mass quantile (k + 1/2) / rings, its u_azimuths samples rotated by a golden-ratio
// offset per ring; each sample stands for 1 / (rings azimuths) of the mass and is a filtered
// lookup covering its solid angle omega_k = 1 / (rings azimuths p(psi_k)) (Colbert & Krivanek).
#include "cube.glsl"

uniform samplerCube u_source;      // radiance with a full MIP chain
uniform float u_source_face;       // size of its MIP level 0
uniform sampler2D u_nodes;         // (psi_k, omega_k) per ring (x) and kernel row (y)
uniform int u_rings;
uniform int u_azimuths;
uniform float u_lod_bias;

vec3 prefilter(vec3 d, int row) {
    vec3 helper = abs(d.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 t = normalize(cross(helper, d));
    vec3 b = cross(d, t);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < u_rings; ++k) {
        vec2 node = texelFetch(u_nodes, ivec2(k, row), 0).rg;
        float s = sin(node.x);
        float c = cos(node.x);
        float offset = fract(float(k) * 0.6180339887);
        for (int m = 0; m < u_azimuths; ++m) {
            float beta = 2.0 * PI * (float(m) + offset) / float(u_azimuths);
            vec3 l = c * d + s * (cos(beta) * t + sin(beta) * b);
            float lod = cube_lod(l, node.y, u_source_face) + u_lod_bias;
            sum += textureLod(u_source, l, max(lod, 0.0)).rgb;
        }
    }
    return sum / float(u_rings * u_azimuths);
}
