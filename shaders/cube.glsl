// Direction helpers shared by the shading and prefiltering shaders.
const float PI = 3.14159265358979323846;

// Eq. 4.16-4.17 (and Colbert-Krivanek's lod with solid angle omega_s): MIP level of a lookup
// covering solid angle `area` in world direction `dir` on a cube map with faces of size `face`.
float cube_lod(vec3 dir, float area, float face) {
    vec3 a = abs(dir);
    float max_c = max(max(a.x, a.y), max(a.z, 1e-6));
    float texels = area / (max_c * max_c * max_c) * face * face * 0.25;
    return 0.5 * log2(max(texels, 1e-30));
}

// materials/fitted_pattern.py lod_for_sigma: the MIP level whose read blurs by `sigma` (rad) in
// `dir` on faces of size `face`: the integer level L below (4^L 5/12 - 1/4 base texels^2 <= s^2)
// and the trilinear blend of L + 1 that makes up the rest; never sharper than level 0 (1/6).
float lod_for_sigma(vec3 dir, float sigma, float face) {
    vec3 m = abs(normalize(dir));
    float texel2 = 4.0 / (face * face) * pow(max(max(m.x, m.y), m.z), 3.0);
    float s2 = max(sigma * sigma / texel2, 1.0 / 6.0);
    float low = floor(0.5 * log2((s2 + 0.25) * 2.4) + 1e-6);
    float v_low = exp2(2.0 * low) * (5.0 / 12.0) - 0.25;
    float v_high = exp2(2.0 * low + 2.0) * (5.0 / 12.0) - 0.25;
    return low + clamp((s2 - v_low) / (v_high - v_low), 0.0, 1.0);
}

// Direction through (sc, tc) in [-1, 1]^2 of a face (OpenGL table 8.19; scenes/cube_layout.py).
vec3 cube_face_direction(int face, float sc, float tc) {
    if (face == 0) return vec3(1.0, -tc, -sc);
    if (face == 1) return vec3(-1.0, -tc, sc);
    if (face == 2) return vec3(sc, 1.0, tc);
    if (face == 3) return vec3(sc, -1.0, -tc);
    if (face == 4) return vec3(sc, -tc, 1.0);
    return vec3(-sc, -tc, -1.0);
}

// Equirectangular (u, v) of a world direction, the convention of scenes/envmap.py: u = 0.5
// faces -Z, u = 0.75 faces +X, v = 0 is +Y. Used by the lobe maps (3D textures).
vec2 direction_to_latlong(vec3 d) {
    float u = 0.5 + atan(d.x, -d.z) / (2.0 * PI);
    float v = acos(clamp(d.y, -1.0, 1.0)) / PI;
    return vec2(u, v);
}

vec3 latlong_to_direction(vec2 uv) {
    float phi = 2.0 * PI * (uv.x - 0.5);
    float theta = PI * uv.y;
    return vec3(sin(theta) * sin(phi), cos(theta), -sin(theta) * cos(phi));
}
