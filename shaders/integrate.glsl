// Integration of incident light over the lobes of a material (thesis 4.4), for one shading
// point: the methods of DESIGN.md chosen by #define.
//   METHOD_LOBE  lobe-N: deterministic pattern, MIP level per sample, Eq. 4.25
//   METHOD_FIS   fis-N: the same N quasi-random importance samples at every pixel, each
//                filtered with Colbert & Krivanek's lod = 0.5 log2(omega_s / omega_p) + bias
//   METHOD_MC    mc-N / reference: importance samples from a Sobol sequence with a per-pixel
//                Cranley-Patterson rotation, no filtering (unbiased; accumulated over passes)
#include "bsdf.glsl"

uniform samplerCube u_radiance;     // incident radiance, full MIP chain
uniform float u_face_size;          // size of MIP level 0 of u_radiance
uniform samplerCube u_irradiance;   // irradiance E(n) for the diffuse term (lobe-N, fis-N)
uniform sampler2D u_sobol;          // 2D Sobol points, row-major, u_sobol_count of them
uniform int u_sobol_count;
uniform int u_sample_offset;        // first Sobol index of this pass (progressive refinement)
uniform int u_samples;              // N
uniform float u_lod_bias;
uniform vec2 u_pattern[MAX_LOBES * MAX_PATTERN];  // per-lobe pattern coordinates (xi1, xi2)
uniform vec3 u_kd;                  // Lambert kd, or (1 - metallic) baseColor for glTF
uniform float u_gltf_diffuse;       // 1: glTF diffuse (1 - F_dielectric(V.H)) factor
uniform uint u_seed;

uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Deterministic per-pixel, per-lobe rotation in [0, 1)^2 (documented scrambling).
vec2 pixel_rotation(uvec2 pixel, int lobe) {
    uint h1 = pcg_hash(pixel.x + pcg_hash(pixel.y + pcg_hash(uint(lobe) + 17u * u_seed)));
    uint h2 = pcg_hash(h1 ^ 0x9e3779b9u);
    return vec2(float(h1 >> 8u), float(h2 >> 8u)) / 16777216.0;
}

vec2 sobol_point(int index) {
    int i = index % u_sobol_count;
    ivec2 size = textureSize(u_sobol, 0);
    return texelFetch(u_sobol, ivec2(i % size.x, i / size.x), 0).xy;
}

vec3 lookup(vec3 dir_world, float lod) { return textureLod(u_radiance, dir_world, max(lod, 0.0)).rgb; }

vec3 diffuse_eval(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 f = u_kd / PI;
    if (u_gltf_diffuse > 0.5) {
        vec3 h = normalize(wi + wo);
        f *= 1.0 - schlick(abs(dot(wo, h)), vec3(0.04));
    }
    return f;
}

vec3 cosine_hemisphere(vec2 u) {
    // Malley's method on Shirley's concentric disk (same map as materials/vec.py).
    float a = 2.0 * u.x - 1.0;
    float b = 2.0 * u.y - 1.0;
    float r, phi;
    if (a == 0.0 && b == 0.0) {
        r = 0.0;
        phi = 0.0;
    } else if (abs(a) > abs(b)) {
        r = a;
        phi = 0.25 * PI * (b / a);
    } else {
        r = b;
        phi = 0.5 * PI - 0.25 * PI * (a / b);
    }
    vec2 d = r * vec2(cos(phi), sin(phi));
    return vec3(d, sqrt(max(1.0 - dot(d, d), 0.0)));
}

#if defined(METHOD_LOBE)
vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    int n = u_samples;
    float area = lobe_sample_area(l, wo, n);
    vec3 num = vec3(0.0);
    vec3 den = vec3(0.0);
    for (int i = 0; i < n; ++i) {
        vec3 h = pattern_half_vector(l, u_pattern[lobe_index * MAX_PATTERN + i]);
        vec3 wr = 2.0 * dot(wo, h) * h - wo;   // Eq. 4.8
        if (wr.z <= 0.0) continue;              // below the horizon: discarded
        vec3 wi = reflected_wi(l, wr);
        vec3 world = tbn * wi;
        vec3 f = lobe_eval(l, wi, wo);
        float p = lobe_half_pdf(l, wi, wo);
        if (p <= 0.0) continue;
        float c = abs(wi.z);
        vec3 li = lookup(world, cube_lod(world, area, u_face_size) + u_lod_bias);
        // Eq. 4.25: sum L c^2 f^2 / p / sum f c, written as (f c / p) (f c) to stay in range.
        vec3 fc = f * c;
        num += li * (fc / p) * fc;
        den += fc;
    }
    return vec3(den.r > 0.0 ? num.r / den.r : 0.0, den.g > 0.0 ? num.g / den.g : 0.0,
                den.b > 0.0 ? num.b / den.b : 0.0);
}
#else
vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    vec3 sum = vec3(0.0);
    int n = u_samples;
#if defined(METHOD_MC)
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index);
#endif
    for (int i = 0; i < n; ++i) {
#if defined(METHOD_MC)
        vec2 u = fract(sobol_point(u_sample_offset + i) + rotation);
#else
        vec2 u = sobol_point(i);
#endif
        vec3 wi = lobe_sample(l, u, wo);
        float p = lobe_sample_pdf(l, wi, wo);
        if (p <= 0.0) continue;
        vec3 world = tbn * wi;
#if defined(METHOD_FIS)
        // omega_s = 1 / (N p); texel solid angle omega_p = 4 max|w|^3 / face^2 (cube_lod).
        float lod = cube_lod(world, 1.0 / (float(n) * p), u_face_size) + u_lod_bias;
#else
        float lod = 0.0;
#endif
        sum += lookup(world, lod) * lobe_eval(l, wi, wo) * (abs(wi.z) / p);
    }
    return sum / float(n);
}
#endif

vec3 integrate_diffuse(vec3 wo, mat3 tbn) {
#if defined(METHOD_MC)
    vec3 sum = vec3(0.0);
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), MAX_LOBES);
    for (int i = 0; i < u_samples; ++i) {
        vec3 wi = cosine_hemisphere(fract(sobol_point(u_sample_offset + i) + rotation));
        if (wi.z <= 0.0) continue;
        // f cos / pdf with pdf = cos / pi
        sum += lookup(tbn * wi, 0.0) * diffuse_eval(wi, wo) * PI;
    }
    return sum / float(u_samples);
#else
    // kd E / pi (Eq. 4.1) with E from the irradiance map; glTF's (1 - F(V.H)) factor is
    // approximated at the view direction.
    vec3 e = textureLod(u_irradiance, tbn[2], 0.0).rgb;
    vec3 f = u_kd / PI;
    if (u_gltf_diffuse > 0.5) f *= 1.0 - schlick(wo.z, vec3(0.04));
    return f * e;
#endif
}

// Outgoing radiance towards wo (local) for the frame tbn (columns: tangent, bitangent, normal).
vec3 shade(vec3 wo, mat3 tbn) {
    vec3 result = vec3(0.0);
#if defined(HAS_DIFFUSE)
    result += integrate_diffuse(wo, tbn);
#endif
    for (int i = 0; i < u_lobe_count; ++i) result += integrate_lobe(get_lobe(i), i, wo, tbn);
    return result;
}
