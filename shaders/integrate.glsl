// Integration of incident light over the lobes of a material (thesis 4.4), for one shading
// point: the methods of DESIGN.md chosen by #define.
//   METHOD_LOBE  lobe-N: deterministic pattern, MIP level per sample, Eq. 4.25
//   METHOD_FIS   fis-N: the same N quasi-random importance samples at every pixel, each
//                filtered with Colbert & Krivanek's lod = 0.5 log2(omega_s / omega_p) + bias
//   METHOD_MC    mc-N / reference: importance samples from a Sobol sequence with a per-pixel
//                Cranley-Patterson rotation, no filtering (unbiased; accumulated over passes).
//                With ENV_SAMPLING (the reference method) every BSDF sample is paired with a
//                sample of the environment's importance map, combined by multiple importance
//                sampling with the power heuristic (Veach 1997), so suns converge.
#include "bsdf.glsl"

uniform samplerCube u_radiance;     // incident radiance, full MIP chain
uniform float u_face_size;          // size of MIP level 0 of u_radiance
uniform samplerCube u_irradiance;   // irradiance E(n) for the diffuse term (lobe-N, fis-N)
uniform sampler2D u_sobol;          // 4D Sobol points (RGBA), row-major, u_sobol_count of them
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

vec4 sobol_point4(int index) {
    int i = index % u_sobol_count;
    ivec2 size = textureSize(u_sobol, 0);
    return texelFetch(u_sobol, ivec2(i % size.x, i / size.x), 0);
}

vec2 sobol_point(int index) { return sobol_point4(index).xy; }

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

#if defined(PARALLAX) || defined(MIRROR)
vec3 g_shading_position;                        // world position, set by the fragment shader
#endif

#if defined(PARALLAX)
// Reflected-geometry correction (thesis 4.4.1; scenes/reflection_proxy.py): the secondary ray
// from the shading point is intersected with the object's proxy (bounding planes or a box seen
// from inside) and the cube map is read toward the hit point as seen from its centre.
uniform vec3 u_cube_centre;
uniform int u_proxy_kind;                       // PROXY_PLANES or PROXY_BOX
uniform int u_proxy_plane_count;
uniform vec4 u_proxy_planes[MAX_PROXY_PLANES];  // unit normal n, d: n.x + d = 0
uniform vec3 u_proxy_box_min;
uniform vec3 u_proxy_box_max;

float proxy_hit_distance(vec3 o, vec3 d) {
    float t = 1e38;
    if (u_proxy_kind == PROXY_PLANES) {
        for (int k = 0; k < u_proxy_plane_count; ++k) {
            float denom = dot(u_proxy_planes[k].xyz, d);
            if (abs(denom) <= 1e-12) continue;
            float tk = -(dot(u_proxy_planes[k].xyz, o) + u_proxy_planes[k].w) / denom;
            if (tk > 1e-6) t = min(t, tk);
        }
    } else {
        for (int a = 0; a < 3; ++a) {
            if (d[a] > 0.0) t = min(t, (u_proxy_box_max[a] - o[a]) / d[a]);
            else if (d[a] < 0.0) t = min(t, (u_proxy_box_min[a] - o[a]) / d[a]);
        }
        if (t <= 1e-6) t = 1e38;
    }
    return t;
}

// Lookup direction toward the proxy hit; lod_offset = log2(|H - P| / |H - C|), the change of a
// footprint's solid angle seen from the cube's centre instead of the shading point.
vec3 proxy_direction(vec3 dir_world, out float lod_offset) {
    lod_offset = 0.0;
    vec3 d = normalize(dir_world);
    float t = proxy_hit_distance(g_shading_position, d);
    if (t >= 1e37) return d;
    vec3 to_hit = g_shading_position + t * d - u_cube_centre;
    float len = length(to_hit);
    if (len <= 1e-9) return d;
    lod_offset = log2(max(t, 1e-9) / len);
    return to_hit / len;
}

vec3 lookup(vec3 dir_world, float lod) {
    float lod_offset;
    vec3 d = proxy_direction(dir_world, lod_offset);
#if !defined(METHOD_MC)
    lod += lod_offset;  // filtered methods only; mc-N and the reference read level 0
#endif
    return textureLod(u_radiance, d, max(lod, 0.0)).rgb;
}
#else
vec3 lookup(vec3 dir_world, float lod) { return textureLod(u_radiance, dir_world, max(lod, 0.0)).rgb; }
#endif

#if defined(MIRROR)
// Planar reflector (thesis 4.5; numpy reference scenes/planar_mirror.py): incident light from
// buffers rendered this frame, the mirror buffer (from the mirrored camera: reflection lobes) and
// the see-through buffer (from the camera itself, the scene behind the plane: transmission lobes
// of a thin pane). Each direction is mapped into its buffer by the two-step tangent-plane
// projection of 4.5.2 and filtered by its share of the lobe (4.5.3).
uniform vec3 u_mirror_front;           // the plane's normal on the camera's side
uniform int u_mirror_sides;            // bit 0: mirror buffer bound, bit 1: see-through buffer bound
uniform sampler2D u_mirror_radiance;   // MIP chain rebuilt every frame
uniform sampler2D u_mirror_position;   // xyz world, w: 1 geometry, 0 environment
uniform sampler2D u_mirror_normal;
uniform mat4 u_mirror_view;            // world -> mirror eye (camera view x reflection)
uniform mat4 u_mirror_view_projection; // with the plain (not oblique) projection: x, y, w rows
uniform vec3 u_mirror_eye;             // mirrored camera position C'
uniform float u_mirror_focal_px;       // (H / 2) / tan(fov_y / 2) of the buffer
uniform sampler2D u_through_radiance;  // the see-through buffer, same layout
uniform sampler2D u_through_position;
uniform sampler2D u_through_normal;
uniform mat4 u_through_view;
uniform mat4 u_through_view_projection;
uniform vec3 u_through_eye;
uniform float u_through_focal_px;

vec2 buffer_uv(mat4 view_projection, vec4 point) {
    vec4 clip = view_projection * point;
    return clamp(clip.xy / max(clip.w, 1e-6) * 0.5 + 0.5, 0.0, 1.0);
}

ivec2 buffer_texel(sampler2D position_tex, vec2 uv) {
    ivec2 size = textureSize(position_tex, 0);
    return clamp(ivec2(uv * vec2(size)), ivec2(0), size - 1);
}

// Hit of p + t wi with the plane through `point` with `normal` (homogeneous; w = 0: missed).
vec4 plane_hit(vec3 p, vec3 wi, vec3 point, vec3 normal) {
    float denom = dot(wi, normal);
    if (abs(denom) < 1e-6) return vec4(wi, 0.0);
    float t = dot(point - p, normal) / denom;
    return t > 0.0 ? vec4(p + t * wi, 1.0) : vec4(wi, 0.0);
}

// Hit of p + t wi with the tangent plane stored at `texel` (homogeneous; w = 0: the environment).
vec4 buffer_tangent_hit(sampler2D position_tex, sampler2D normal_tex, vec3 p, vec3 wi, ivec2 texel, out vec3 normal) {
    vec4 surface = texelFetch(position_tex, texel, 0);
    normal = texelFetch(normal_tex, texel, 0).xyz;
    return surface.w < 0.5 ? vec4(wi, 0.0) : plane_hit(p, wi, surface.xyz, normal);
}

// Running sums of the planes found at this pixel, per buffer (0 mirror, 1 see-through).
vec4 g_plane_point_sum[2] = vec4[2](vec4(0.0), vec4(0.0));
vec3 g_plane_normal_sum[2] = vec3[2](vec3(0.0), vec3(0.0));

#if defined(PLANE_AVERAGE)
// Progressive refinement (Fig. 4.46b; planar_mirror.TangentPlaneAverage): the hit points and
// plane normals found by all earlier samples of this pixel are summed, across passes through four
// float targets, and the next sample's first step intersects their average plane instead of P_R's.
uniform sampler2D u_plane_point_state[2];   // the previous pass: sum of hit points (xyz), count (w)
uniform sampler2D u_plane_normal_state[2];  // the previous pass: sum of plane normals (xyz)

void plane_average_load() {
    if (u_sample_offset > 0) {  // the first pass starts afresh
        ivec2 pixel = ivec2(gl_FragCoord.xy);
        for (int side = 0; side < 2; ++side) {
            g_plane_point_sum[side] = texelFetch(u_plane_point_state[side], pixel, 0);
            g_plane_normal_sum[side] = texelFetch(u_plane_normal_state[side], pixel, 0).xyz;
        }
    }
}
#endif

vec3 buffer_incident(sampler2D radiance_tex, sampler2D position_tex, sampler2D normal_tex, mat4 view,
                     mat4 view_projection, vec3 eye, float focal_px, int side, vec3 wi, float solid_angle) {
    vec3 p = g_shading_position;
    vec3 normal;
    vec4 hit = vec4(0.0);
#if defined(PLANE_AVERAGE)
    float normal_length = length(g_plane_normal_sum[side]);
    if (g_plane_point_sum[side].w > 0.5 && normal_length >= 1e-6)
        hit = plane_hit(p, wi, g_plane_point_sum[side].xyz / g_plane_point_sum[side].w,
                        g_plane_normal_sum[side] / normal_length);
#endif
    if (hit.w < 0.5)  // P_R's plane: what the buffer shows at P's own position
        hit = buffer_tangent_hit(position_tex, normal_tex, p, wi,
                                 buffer_texel(position_tex, buffer_uv(view_projection, vec4(p, 1.0))), normal);
    vec2 uv = buffer_uv(view_projection, hit);
    // Second step: the plane seen there.
    hit = buffer_tangent_hit(position_tex, normal_tex, p, wi, buffer_texel(position_tex, uv), normal);
    uv = buffer_uv(view_projection, hit);
#if defined(PLANE_AVERAGE)
    // A third step: the averaged plane lands further from the true hit than P_R's near depth edges;
    // measured against a ray tracer (bench --mirrors) averaging helps only with this step.
    hit = buffer_tangent_hit(position_tex, normal_tex, p, wi, buffer_texel(position_tex, uv), normal);
    uv = buffer_uv(view_projection, hit);
    if (hit.w > 0.5) {
        g_plane_point_sum[side] += vec4(hit.xyz, 1.0);
        g_plane_normal_sum[side] += normal;
    }
#endif
    float lod = 0.0;
    if (solid_angle > 0.0) {
        // The sample's solid angle in buffer pixels through the tangent plane (planar_mirror.py).
        vec4 eye_point = view * hit;
        float distance = length(eye_point.xyz);
        float cos_alpha = max(-eye_point.z / max(distance, 1e-30), 1e-3);
        float pixels = solid_angle * focal_px * focal_px / (cos_alpha * cos_alpha * cos_alpha);
        if (hit.w > 0.5) {
            float t = length(hit.xyz - p);
            vec3 to_hit = (hit.xyz - eye) / max(distance, 1e-30);
            pixels *= t * t / max(abs(dot(normal, wi)), 1e-3) * abs(dot(normal, to_hit)) / max(distance * distance, 1e-30);
        }
        lod = 0.5 * log2(max(pixels, 1e-30)) + u_lod_bias;
    }
    return textureLod(radiance_tex, uv, max(lod, 0.0)).rgb;
}

vec3 mirror_incident(vec3 wi, float solid_angle) {
    if (dot(wi, u_mirror_front) >= 0.0) {
        if ((u_mirror_sides & 1) == 0) return vec3(0.0);
        return buffer_incident(u_mirror_radiance, u_mirror_position, u_mirror_normal, u_mirror_view,
                               u_mirror_view_projection, u_mirror_eye, u_mirror_focal_px, 0, wi, solid_angle);
    }
    if ((u_mirror_sides & 2) == 0) return vec3(0.0);
    return buffer_incident(u_through_radiance, u_through_position, u_through_normal, u_through_view,
                           u_through_view_projection, u_through_eye, u_through_focal_px, 1, wi, solid_angle);
}
#endif

// Incident radiance from world direction `dir` for a sample covering `solid_angle` sr
// (0: no filtering, the unbiased methods).
vec3 incident(vec3 dir, float solid_angle) {
#if defined(MIRROR)
    return mirror_incident(normalize(dir), solid_angle);
#else
    return lookup(dir, solid_angle > 0.0 ? cube_lod(dir, solid_angle, u_face_size) + u_lod_bias : 0.0);
#endif
}

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
#if defined(LOBE_NORMALIZE)
// Per-lobe directional albedo over (cos theta_o, phi_o), blocks of ALBEDO_ROWS rows per lobe
// (materials/patterns.py AlbedoTable); linear filtering between texel centres.
const int ALBEDO_ROWS = ALBEDO_PHI + 1;
uniform sampler2D u_albedo;

vec3 lobe_albedo(int lobe_index, vec3 wo) {
    float phi = atan(wo.y, wo.x) / (2.0 * PI);
    phi = phi - floor(phi);
    float row = float(lobe_index * ALBEDO_ROWS) + phi * float(ALBEDO_PHI) + 0.5;
    // Columns are uniform in sqrt(cos theta_o) (AlbedoTable: dense near grazing).
    return texture(u_albedo, vec2(sqrt(max(wo.z, 0.0)), row / float(MAX_LOBES * ALBEDO_ROWS))).rgb;
}
#endif

vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    int n = u_samples;
    float area = lobe_sample_area(l, wo, n);
    vec3 num = vec3(0.0);
    vec3 den = vec3(0.0);
    vec3 num_unit = vec3(0.0);  // Eq. 4.25's numerator for L = 1 (normalisation)
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
        vec3 li = incident(world, area);
        // Eq. 4.25: sum L c^2 f^2 / p / sum f c, written as (f c / p) (f c) to stay in range.
        vec3 fc = f * c;
        num += li * (fc / p) * fc;
        num_unit += (fc / p) * fc;
        den += fc;
    }
#if defined(LOBE_NORMALIZE)
    // lobeview's energy normalisation: Eq. 4.25 rescaled to be exact under uniform light.
    vec3 target = lobe_albedo(lobe_index, wo);
    return vec3(num_unit.r > 0.0 ? num.r * target.r / num_unit.r : 0.0,
                num_unit.g > 0.0 ? num.g * target.g / num_unit.g : 0.0,
                num_unit.b > 0.0 ? num.b * target.b / num_unit.b : 0.0);
#else
    return vec3(den.r > 0.0 ? num.r / den.r : 0.0, den.g > 0.0 ? num.g / den.g : 0.0,
                den.b > 0.0 ? num.b / den.b : 0.0);
#endif
}
#elif defined(METHOD_PREFILTERED)
// One lookup per lobe (viewer/prefiltered.py). Split-sum (Karis 2013) for microfacet and glTF
// lobes: the cube map prefiltered at the lobe's roughness (isotropic alpha = sqrt(ax ay)) times
// F0 A + B from the DFG table. Kautz-McCool lobe maps (seed 000, section 5) for the rest, or
// for every lobe when selected: per fitted lobe (several in the multi mode, 5.3) the 3D map at
// the fitted lobe axis and cos(theta_o), times its share of the true directional albedo of that
// elevation (the energy rescaling of section 3.1). Banks maps (seed 001, 5.3) for anisotropic
// lobes when selected: the map at the fibre direction t and asin(|v.t|), times the albedo
// tabulated over the view elevation and azimuth (materials/banks.py).
uniform samplerCube u_split_sum[2];            // by distribution (DIST_BECKMANN, DIST_GGX)
uniform float u_split_sum_max_level;
uniform sampler2D u_dfg;                       // rg: Beckmann (A, B), ba: GGX; x = cos, y = roughness
uniform sampler3D u_lobe_maps[MAX_LOBES];
uniform int u_lobe_map_mode[MAX_LOBES];        // LOBE_MAP_SPLITSUM, LOBE_MAP_LOBES or LOBE_MAP_BANKS
uniform int u_lobe_map_depth[MAX_LOBES];       // slices per fitted lobe (LOBE_SLICES or 1), Banks slices
uniform int u_lobe_map_count[MAX_LOBES];       // fitted lobes in the lobe map
uniform int u_banks_fibre[MAX_LOBES];          // Banks fibre axis: 0 tangent, 1 bitangent
// render_base.lobe_table: row lobe_index * LOBE_TABLE_ROWS + j; texels 0..S-1 the axis of
// fitted lobe j (local, wo at azimuth 0), S..2S-1 its energy (Banks: albedo at azimuth j).
uniform sampler2D u_lobe_table;

vec3 lobe_table_mix(int row, int column, float f) {
    return mix(texelFetch(u_lobe_table, ivec2(column, row), 0).rgb,
               texelFetch(u_lobe_table, ivec2(column + 1, row), 0).rgb, f);
}

vec3 banks_lookup(int lobe_index, vec3 wo, mat3 tbn) {
    int fibre = u_banks_fibre[lobe_index];
    float along = fibre == 0 ? wo.x : wo.y;    // v.t
    float across = fibre == 0 ? wo.y : wo.x;
    // L_banks(t, v.t) = L_banks(-t, -v.t): the map holds v.t >= 0 only.
    vec3 t = tbn * (fibre == 0 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)) * (along < 0.0 ? -1.0 : 1.0);
    int depth = u_lobe_map_depth[lobe_index];
    float slice = asin(min(abs(along), 1.0)) / (0.5 * PI) * float(depth - 1);  // banks.slice_angles
    vec3 radiance = texture(u_lobe_maps[lobe_index], vec3(direction_to_latlong(t), (slice + 0.5) / float(depth))).rgb;
    // Albedo, bilinear over (sqrt cos theta_o, azimuth from the fibre folded into [0, pi/2]).
    float x = sqrt(clamp(wo.z, 0.0, 1.0)) * float(LOBE_SLICES - 1);
    int x0 = min(int(floor(x)), LOBE_SLICES - 2);
    float y = atan(abs(across), abs(along)) / (0.5 * PI) * float(LOBE_TABLE_ROWS - 1);
    int y0 = min(int(floor(y)), LOBE_TABLE_ROWS - 2);
    int row = lobe_index * LOBE_TABLE_ROWS + y0;
    vec3 energy = mix(lobe_table_mix(row, LOBE_SLICES + x0, x - float(x0)),
                      lobe_table_mix(row + 1, LOBE_SLICES + x0, x - float(x0)), y - float(y0));
    return radiance * energy;
}

vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    if (wo.z <= 0.0) return vec3(0.0);
    if (u_lobe_map_mode[lobe_index] == LOBE_MAP_SPLITSUM) {
        vec3 r = tbn * vec3(-wo.xy, wo.z);
#if defined(PARALLAX)
        float unused_offset;
        r = proxy_direction(r, unused_offset);
#endif
        float roughness = sqrt(sqrt(l.ax * l.ay));
        vec3 radiance = textureLod(u_split_sum[l.dist], r, roughness * u_split_sum_max_level).rgb;
        vec4 dfg = texture(u_dfg, vec2(wo.z, roughness));
        vec2 ab = l.dist == DIST_GGX ? dfg.ba : dfg.rg;
        vec3 f0 = lobe_fresnel(l, 1.0);
        vec3 scale = l.type == LOBE_GLTF_SPECULAR ? vec3(1.0) : l.k;
        return radiance * (f0 * ab.x + ab.y) * scale;
    }
    if (u_lobe_map_mode[lobe_index] == LOBE_MAP_BANKS) return banks_lookup(lobe_index, wo, tbn);
    float s = sqrt(clamp(wo.z, 0.0, 1.0)) * float(LOBE_SLICES - 1);  // lobe_fit.slice_coordinate
    int s0 = min(int(floor(s)), LOBE_SLICES - 2);
    float f = s - float(s0);
    // Rotation of the local frame that takes azimuth 0 to wo's azimuth.
    float len_xy = length(wo.xy);
    vec2 u = len_xy > 1e-7 ? wo.xy / len_xy : vec2(-1.0, 0.0);
    int count = u_lobe_map_count[lobe_index];
    int depth = u_lobe_map_depth[lobe_index];
    vec3 sum = vec3(0.0);
    for (int j = 0; j < count; ++j) {
        int row = lobe_index * LOBE_TABLE_ROWS + j;
        vec3 a = lobe_table_mix(row, s0, f);
        vec3 energy = lobe_table_mix(row, LOBE_SLICES + s0, f);
        vec3 axis = tbn * normalize(vec3(a.x * u + a.y * vec2(-u.y, u.x), a.z));
#if defined(PARALLAX)
        float unused_offset;
        axis = proxy_direction(axis, unused_offset);
#endif
        // Fitted lobe j owns slices j depth .. (j + 1) depth - 1: linear filtering in z never
        // mixes two lobes because z stays between the first and last slice centre of the block.
        float z = (float(j * depth) + (depth > 1 ? s : 0.0) + 0.5) / float(count * depth);
        sum += texture(u_lobe_maps[lobe_index], vec3(direction_to_latlong(axis), z)).rgb * energy;
    }
    return sum;
}
#elif defined(ENV_SAMPLING)
vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    vec3 sum = vec3(0.0);
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index);
    vec2 rotation_env = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index + 2 * MAX_LOBES);
    for (int i = 0; i < u_samples; ++i) {
        vec4 q = sobol_point4(u_sample_offset + i);
        // BSDF sample, MIS-weighted against the environment sampler.
        vec3 wi = lobe_sample(l, fract(q.xy + rotation), wo);
        float p_bsdf = lobe_sample_pdf(l, wi, wo);
        if (p_bsdf > 0.0) {
            vec3 world = tbn * wi;
            float w = power_heuristic(p_bsdf, env_pdf(world));
            sum += lookup(world, 0.0) * lobe_eval(l, wi, wo) * (abs(wi.z) * w / p_bsdf);
        }
        // Environment sample, MIS-weighted against the BSDF sampler.
        vec3 world_e = env_sample(fract(q.zw + rotation_env));
        vec3 wi_e = transpose(tbn) * world_e;
        vec3 f = lobe_eval(l, wi_e, wo);
        if (any(greaterThan(f, vec3(0.0)))) {
            float p_env = env_pdf(world_e);
            float w = power_heuristic(p_env, lobe_sample_pdf(l, wi_e, wo));
            sum += lookup(world_e, 0.0) * f * (abs(wi_e.z) * w / p_env);
        }
    }
    return sum / float(u_samples);
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
        float solid_angle = 1.0 / (float(n) * p);
#else
        float solid_angle = 0.0;
#endif
        sum += incident(world, solid_angle) * lobe_eval(l, wi, wo) * (abs(wi.z) / p);
    }
    return sum / float(n);
}
#endif

vec3 integrate_diffuse(vec3 wo, mat3 tbn) {
#if defined(METHOD_MC)
    vec3 sum = vec3(0.0);
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), MAX_LOBES);
#if defined(ENV_SAMPLING)
    vec2 rotation_env = pixel_rotation(uvec2(gl_FragCoord.xy), 3 * MAX_LOBES);
#endif
    for (int i = 0; i < u_samples; ++i) {
        vec4 q = sobol_point4(u_sample_offset + i);
        vec3 wi = cosine_hemisphere(fract(q.xy + rotation));
        if (wi.z > 0.0) {
            // f cos / pdf with pdf = cos / pi
            vec3 world = tbn * wi;
#if defined(ENV_SAMPLING)
            float w = power_heuristic(wi.z / PI, env_pdf(world));
#else
            float w = 1.0;
#endif
            sum += lookup(world, 0.0) * diffuse_eval(wi, wo) * (PI * w);
        }
#if defined(ENV_SAMPLING)
        vec3 world_e = env_sample(fract(q.zw + rotation_env));
        vec3 wi_e = transpose(tbn) * world_e;
        if (wi_e.z > 0.0) {
            float p_env = env_pdf(world_e);
            float w = power_heuristic(p_env, wi_e.z / PI);
            sum += lookup(world_e, 0.0) * diffuse_eval(wi_e, wo) * (wi_e.z * w / p_env);
        }
#endif
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
