// glTF material textures sampled per pixel (core specification 3.9 and Appendix B); the numpy
// twin is scenes/texturing.py. Slots (MAP_*): base colour (sRGB RGBA, decoded by the SRGB8_ALPHA8
// texture before filtering), metallic-roughness (B metal, G roughness), tangent-space normal,
// occlusion (R) and emissive (sRGB). Each slot has its UV set, its KHR_texture_transform matrix
// and its sampler; the sampler object does repeat / clamp-to-edge and the filters, mirrored
// repeat is folded here (the texture repeats, so the GPU only sees coordinates in [0, 1]).

uniform sampler2D u_material_maps[MATERIAL_MAPS];
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform int u_map_texcoord[MATERIAL_MAPS];      // 0 or 1: the UV set; -1: the slot has no texture
uniform mat3 u_map_transform[MATERIAL_MAPS];    // uv' = T (u, v, 1): KHR_texture_transform
uniform ivec2 u_map_mirrored[MATERIAL_MAPS];    // MIRRORED_REPEAT in s, t
#endif

float mirrored_repeat(float x) {
    float t = x - 2.0 * floor(0.5 * x);  // [0, 2)
    return t > 1.0 ? 2.0 - t : t;
}

#if defined(OBJECT_RECORDS)
// With OBJECT_RECORDS the slot's texcoord and transform are read from a storage buffer, and the
// helper invocations of a pixel quad do not read one on every driver (llvmpipe gives them 0):
// derivatives of a value computed from them would be garbage there. The derivatives then come
// from the interpolated UV sets alone (taken in uniform control flow), carried through the
// affine texture transform; equal to dFdx of the transformed coordinates up to rounding.
vec2 map_uv_derivative(int slot, vec2 d_uv0, vec2 d_uv1) {
    return (u_map_transform[slot] * vec3(u_map_texcoord[slot] == 1 ? d_uv1 : d_uv0, 0.0)).xy;
}
#endif

// The slot's coordinates (folded where the sampler mirrors) and their screen derivatives, or
// false without a texture. Called in uniform control flow (before any discard).
bool map_coordinates(int slot, vec2 uv0, vec2 uv1, out vec2 uv, out vec2 gx, out vec2 gy) {
#if defined(OBJECT_RECORDS)
    vec2 d0x = dFdx(uv0), d0y = dFdy(uv0), d1x = dFdx(uv1), d1y = dFdy(uv1);
    if (u_map_texcoord[slot] < 0) return false;
    uv = (u_map_transform[slot] * vec3(u_map_texcoord[slot] == 1 ? uv1 : uv0, 1.0)).xy;
    gx = map_uv_derivative(slot, d0x, d1x);
    gy = map_uv_derivative(slot, d0y, d1y);
#else
    if (u_map_texcoord[slot] < 0) return false;
    uv = (u_map_transform[slot] * vec3(u_map_texcoord[slot] == 1 ? uv1 : uv0, 1.0)).xy;
    gx = dFdx(uv);
    gy = dFdy(uv);
#endif
    if (u_map_mirrored[slot].x == 1) uv.x = mirrored_repeat(uv.x);
    if (u_map_mirrored[slot].y == 1) uv.y = mirrored_repeat(uv.y);
    return true;
}

// The filter footprint of the material textures as a share of the pixel's: 1 for a pass that
// shades whole pixels; a box-filtered reference integrates the pixel itself over its passes'
// sub-pixel positions, and a texel filtered over the whole pixel as well was blurred twice (the
// DamagedHelmet 20.8 % rel-RMSE off Cycles against 17.5 % rendered 4x4 larger), so it reads the
// texture over one pass's share of the pixel, 1 / sqrt(passes) (viewer/scene_renderer.py render).
uniform float u_texture_footprint = 1.0;

// The slot's texel at this fragment, or `absent` without a texture: the derivatives of the
// unfolded coordinates pick the MIP level.
vec4 sample_map(int slot, vec2 uv0, vec2 uv1, vec4 absent) {
    vec2 uv, gx, gy;
    if (!map_coordinates(slot, uv0, uv1, uv, gx, gy)) return absent;
    return textureGrad(u_material_maps[slot], uv, gx * u_texture_footprint, gy * u_texture_footprint);
}

// The slot's texture averaged over a square ``widen`` (>= 1) times the pixel's footprint across
// (the occlusion texture over one lightmap texel, scene.frag): an explicit, isotropic MIP level
// from the longer footprint axis. textureGrad with the widened gradients would do the same, but
// llvmpipe ignores explicit gradients once a sampler filters anisotropically.
vec4 sample_map_widened(int slot, vec2 uv0, vec2 uv1, vec4 absent, float widen) {
    vec2 uv, gx, gy;
    if (!map_coordinates(slot, uv0, uv1, uv, gx, gy)) return absent;
    vec2 texels = vec2(textureSize(u_material_maps[slot], 0));
    float footprint = max(length(gx * texels), length(gy * texels)) * widen;
    return textureLod(u_material_maps[slot], uv, log2(max(footprint, 1e-8)));
}

// Tangent-space normal map (spec 3.9.3): n = normalize((2 t - 1) (scale, scale, 1)), expressed
// in the interpolated frame (columns tangent, bitangent with handedness, normal).
vec3 mapped_normal(mat3 vertex_frame, vec3 texel, float scale) {
    vec3 n = (2.0 * texel - 1.0) * vec3(scale, scale, 1.0);
    if (!(dot(n, n) > 1e-12)) return vertex_frame[2];
    return normalize(vertex_frame * normalize(n));
}
