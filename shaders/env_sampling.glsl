// GLSL twin of scenes/env_sampling.py: importance sampling of the radiance cube by its texel
// luminance (CubeImportance), its density, and the power heuristic that combines it with BSDF
// sampling (Veach 1997). Only the reference method (ENV_SAMPLING) uses it.

#if defined(ENV_SAMPLING)
// Environment importance sampling (numpy reference: scenes/env_sampling.py).
uniform sampler2D u_env_cdf;      // cumulative texel probabilities, rows of CDF_ROW
uniform int u_env_texels;         // 6 * size^2
uniform int u_env_size;           // importance face size
uniform samplerCube u_env_pdf;    // P_t (size/2)^2 per texel, nearest filtering

float env_cdf(int i) { return texelFetch(u_env_cdf, ivec2(i % CDF_ROW, i / CDF_ROW), 0).r; }

float env_pdf(vec3 d) {
    vec3 a = abs(d);
    float m = max(max(a.x, a.y), a.z);
    return textureLod(u_env_pdf, d, 0.0).r / (m * m * m);
}

vec3 env_sample(vec2 u) {
    int lo = 0;
    int hi = u_env_texels - 1;
    while (lo < hi) {  // smallest texel with cdf > u.x
        int mid = (lo + hi) / 2;
        if (env_cdf(mid) > u.x) hi = mid; else lo = mid + 1;
    }
    float lower = lo > 0 ? env_cdf(lo - 1) : 0.0;
    float s_in = clamp((u.x - lower) / max(env_cdf(lo) - lower, 1e-30), 0.0, 0.99999);
    int face = lo / (u_env_size * u_env_size);
    int row = (lo / u_env_size) % u_env_size;
    int col = lo % u_env_size;
    float sc = 2.0 * (float(col) + s_in) / float(u_env_size) - 1.0;
    float tc = 2.0 * (float(row) + u.y) / float(u_env_size) - 1.0;
    return normalize(cube_face_direction(face, sc, tc));
}

float power_heuristic(float a, float b) {
    // a^2 / (a^2 + b^2), scaled to avoid overflow for near-mirror densities.
    float m = max(a, b);
    if (m <= 0.0) return 0.0;
    a /= m;
    b /= m;
    return a * a / (a * a + b * b);
}
#endif

#if defined(ENV_SAMPLING)
// The reference's third strategy (numpy reference: scenes/env_sampling.py CapLightSampler): the
// bright sources separated from the cube (u_cap_light_* of cap_lights.glsl; none: the strategy is
// off and the two others' weights are as without it) as proposals, light k chosen with
// probability g_cap_choice[k], then a point uniform over its cap; the radiance read there is the
// whole cube's. Membership by 0.5 |w - axis|^2 <= 1 - cos r: exact for unit vectors, no
// cancellation on sub-degree caps.
#define CAP_CHOICE_UNIFORM 0.1
float g_cap_choice[MAX_CAP_LIGHTS];

// scenes/env_sampling.py cap_choice_for_lobe: per lobe and shading point, each light's share
// of an estimate of what it adds (its power times f cos at its axis), mixed with
// CAP_CHOICE_UNIFORM of the uniform choice so that a light the estimate misses (a wide cap whose
// axis lies outside a narrow lobe) is still proposed. Any positive choice keeps the sum unbiased:
// it only moves samples between lights. A uniform choice of 1 in 8 lights gave a GGX 0.05
// sphere under night.exr more noise than no light strategy at all.
void choose_cap_lights(Lobe l, vec3 wo, mat3 tbn) {
    float total = 0.0;
    for (int k = 0; k < u_cap_light_count; ++k) {
        vec3 axis_local = transpose(tbn) * u_cap_light_axis[k].xyz;
        vec3 f = lobe_eval(l, axis_local, wo);
        vec4 light = u_cap_light_radiance[k];
        float lit_solid_angle = 2.0 * PI * (1.0 - u_cap_light_axis[k].w) * 0.5 * (1.0 + light.w);
        float estimate = dot(f * light.rgb, vec3(0.2126, 0.7152, 0.0722)) * abs(axis_local.z) * lit_solid_angle;
        g_cap_choice[k] = max(estimate, 0.0);
        total += g_cap_choice[k];
    }
    float uniform_share = total > 0.0 ? CAP_CHOICE_UNIFORM : 1.0;
    for (int k = 0; k < u_cap_light_count; ++k) {
        float estimated = total > 0.0 ? g_cap_choice[k] / total : 0.0;
        g_cap_choice[k] = uniform_share / float(u_cap_light_count) + (1.0 - uniform_share) * estimated;
    }
}

float cap_light_pdf(vec3 world) {
    float density = 0.0;
    for (int k = 0; k < u_cap_light_count; ++k) {
        vec3 chord = world - u_cap_light_axis[k].xyz;
        float one_minus_cos = 1.0 - u_cap_light_axis[k].w;
        if (0.5 * dot(chord, chord) <= one_minus_cos) density += g_cap_choice[k] / (2.0 * PI * one_minus_cos);
    }
    return density;
}

// u.x picks the light by the cumulative choice and, rescaled within it, the point's area fraction
vec3 cap_light_sample(vec2 u) {
    int k = 0;
    float below = 0.0;
    while (k < u_cap_light_count - 1 && u.x >= below + g_cap_choice[k]) {
        below += g_cap_choice[k];
        ++k;
    }
    float along = clamp((u.x - below) / max(g_cap_choice[k], 1e-30), 0.0, 1.0);
    vec3 axis = u_cap_light_axis[k].xyz;
    float one_minus_cos_t = along * (1.0 - u_cap_light_axis[k].w);
    float sin_t = sqrt(max(one_minus_cos_t * (2.0 - one_minus_cos_t), 0.0));
    float phi = 2.0 * PI * u.y;
    vec3 helper = abs(axis.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 t = normalize(cross(helper, axis));
    vec3 b = cross(axis, t);
    return sin_t * (cos(phi) * t + sin(phi) * b) + (1.0 - one_minus_cos_t) * axis;
}

// a^2 / (a^2 + b^2 + c^2), the power heuristic of three strategies with one sample each (Veach
// 1997, Eq. 9.13); c = 0 gives power_heuristic(a, b) to the last bit.
float power_heuristic3(float a, float b, float c) {
    float m = max(max(a, b), c);
    if (m <= 0.0) return 0.0;
    a /= m;
    b /= m;
    c /= m;
    return a * a / (a * a + b * b + c * c);
}
#endif
