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
