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
// Median angle below which a fitted lobe is read from the radiance cube's MIP chain instead of its
// map, which cannot resolve it (viewer/prefiltered.py lobe_direct_angle; 0: never).
uniform float u_lobe_direct_angle[MAX_LOBES];
// viewer/prefilter_modes.py lobe_table: row lobe_index * LOBE_TABLE_ROWS + j; texels 0..S-1 the axis of
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

// materials/prefilter.py split_sum_line_quantiles and split_sum_line_weights
// (tests/test_methods_on_mitsuba_sky.py checks these against it): the line's slopes per unit scale,
// by distribution (DIST_BECKMANN, DIST_GGX), and the probability each node stands for.
const float SPLIT_SUM_LINE_SLOPES[2][11] = float[2][11](
    float[11](-1.555925243, -1.046476592, -0.684070350, -0.416808192, -0.199556951, 0.0, 0.199556951,
              0.416808192, 0.684070350, 1.046476592, 1.555925243),
    float[11](-4.153735804, -1.693710931, -0.894427191, -0.496138938, -0.227921153, 0.0, 0.227921153,
              0.496138938, 0.894427191, 1.693710931, 4.153735804));
const float SPLIT_SUM_LINE_WEIGHTS[11] = float[11](0.027777778, 0.083333333, 0.111111111, 0.111111111,
    0.111111111, 0.111111111, 0.111111111, 0.111111111, 0.111111111, 0.083333333, 0.027777778);
#define SPLIT_SUM_LINE_NODES 11
#define SPLIT_SUM_LINE_RATIO 1.05
// materials/split_sum_oblique.py: an isotropic lobe seen off the normal narrows across the plane
// of incidence; it reads the map at alpha rho(alpha, cos theta_o) (OBLIQUE_RATIO: rows
// OBLIQUE_ALPHAS, columns cos theta_o 0.1 .. 1.0, GGX's rows first, then Beckmann's).
#define MIN_OBLIQUE_XY 1e-4
const float OBLIQUE_ALPHAS[8] = float[8](0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0);
const float OBLIQUE_RATIO[160] = float[160](
    0.205, 0.249, 0.323, 0.408, 0.499, 0.596, 0.694, 0.794, 0.897, 1.000,
    0.288, 0.307, 0.359, 0.429, 0.508, 0.598, 0.691, 0.789, 0.892, 1.000,
    0.362, 0.367, 0.403, 0.458, 0.526, 0.604, 0.691, 0.786, 0.889, 1.000,
    0.476, 0.470, 0.488, 0.522, 0.571, 0.631, 0.703, 0.787, 0.886, 1.000,
    0.556, 0.547, 0.557, 0.582, 0.618, 0.667, 0.726, 0.799, 0.889, 1.000,
    0.625, 0.611, 0.617, 0.636, 0.665, 0.705, 0.755, 0.818, 0.898, 1.000,
    0.802, 0.763, 0.753, 0.760, 0.775, 0.800, 0.835, 0.876, 0.932, 1.000,
    1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000, 1.000,
    0.140, 0.217, 0.307, 0.402, 0.500, 0.598, 0.698, 0.799, 0.901, 1.000,
    0.170, 0.243, 0.322, 0.408, 0.500, 0.597, 0.696, 0.796, 0.898, 1.000,
    0.202, 0.270, 0.344, 0.423, 0.509, 0.598, 0.695, 0.794, 0.896, 1.000,
    0.259, 0.323, 0.390, 0.460, 0.535, 0.614, 0.699, 0.792, 0.892, 1.000,
    0.306, 0.368, 0.431, 0.496, 0.564, 0.635, 0.712, 0.795, 0.889, 1.000,
    0.344, 0.404, 0.464, 0.526, 0.589, 0.655, 0.725, 0.803, 0.892, 1.000,
    0.397, 0.455, 0.513, 0.571, 0.633, 0.699, 0.771, 0.850, 0.930, 1.000,
    0.447, 0.516, 0.597, 0.693, 0.813, 0.973, 1.000, 1.000, 1.000, 1.000);
float oblique_ratio(int dist, float alpha, float cos_o) {
    float a = clamp(alpha, 0.1, 1.0);
    int i = 0;
    for (int k = 0; k < 6; ++k) if (a >= OBLIQUE_ALPHAS[k + 1]) i = k + 1;
    float ta = clamp((a - OBLIQUE_ALPHAS[i]) / (OBLIQUE_ALPHAS[i + 1] - OBLIQUE_ALPHAS[i]), 0.0, 1.0);
    float cc = clamp(cos_o, 0.1, 1.0) * 10.0 - 1.0;
    int j = min(int(floor(cc)), 8);
    float tc = cc - float(j);
    int base = dist == DIST_GGX ? 0 : 80;
    float r00 = OBLIQUE_RATIO[base + i * 10 + j], r01 = OBLIQUE_RATIO[base + i * 10 + j + 1];
    float r10 = OBLIQUE_RATIO[base + (i + 1) * 10 + j], r11 = OBLIQUE_RATIO[base + (i + 1) * 10 + j + 1];
    return mix(mix(r00, r01, tc), mix(r10, r11, tc), ta);
}

// materials/split_sum_levels.py split_sum_lod. GGX: SPLIT_SUM_LOD_GGX, the blend whose radial mass matches
// the lobe kernel's, at sqrt(alpha) = k / 40 (the split-sum cube's SPLIT_SUM_LEVELS = 6 levels);
// Beckmann: from level PEAK_MATCHED_FROM on, the blend whose peak is alpha's.
#define SPLIT_SUM_LOD_NODES 41
const float SPLIT_SUM_LOD_GGX[SPLIT_SUM_LOD_NODES] = float[SPLIT_SUM_LOD_NODES](
    0.0000, 0.0000, 0.0075, 0.0425, 0.1275, 0.2850, 0.5050, 0.7575, 1.0000, 1.0775, 1.1750,
    1.2925, 1.4250, 1.5700, 1.7150, 1.8625, 2.0000, 2.1300, 2.2650, 2.4000, 2.5325, 2.6600,
    2.7825, 2.8950, 3.0000, 3.1650, 3.3175, 3.4600, 3.5900, 3.7100, 3.8175, 3.9150, 4.0000,
    4.1850, 4.3500, 4.4975, 4.6275, 4.7425, 4.8400, 4.9275, 5.0000);
#define PEAK_MATCHED_FROM 2.0
float split_sum_lod(int dist, float alpha, float max_level) {
    if (dist == DIST_GGX) {
        float x = sqrt(clamp(alpha, 0.0, 1.0)) * float(SPLIT_SUM_LOD_NODES - 1);
        int k = min(int(floor(x)), SPLIT_SUM_LOD_NODES - 2);
        return min(mix(SPLIT_SUM_LOD_GGX[k], SPLIT_SUM_LOD_GGX[k + 1], x - float(k)), max_level);
    }
    float lod = sqrt(alpha) * max_level;
    if (lod <= PEAK_MATCHED_FROM || lod >= max_level) return clamp(lod, 0.0, max_level);
    float lower = clamp(floor(lod), PEAK_MATCHED_FROM, max_level - 1.0);
    float inv_lower = pow(max_level / lower, 4.0);
    float inv_upper = pow(max_level / (lower + 1.0), 4.0);
    float inv = 1.0 / (alpha * alpha);
    return lower + (inv_lower - inv) / (inv_lower - inv_upper);
}

vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    if (wo.z <= 0.0) return vec3(0.0);
    if (u_lobe_map_mode[lobe_index] == LOBE_MAP_SPLITSUM) {
        // The mirror direction, or for a thin transmission lobe its mirror image (straight
        // through), turned towards the normal (materials/prefilter.py split_sum_lean: a rough lobe
        // at a grazing view leans off the mirror direction, Lagarde & de Rousiers 2014); an
        // anisotropic lobe reads the map at its narrower alpha at quantiles of its slopes along its
        // wider axis, each weighted by its probability, the nodes below the surface left out
        // (split_sum_line), all leant at the alpha of the level they read; an isotropic lobe
        // seen off the normal reads the same line along the plane of incidence at the narrower
        // alpha of its spread across that plane, leant at its own alpha (split_sum_oblique.py).
        bool through = lobe_is_transmission(l);
        float alpha = sqrt(l.ax * l.ay);
        float roughness = sqrt(alpha);
        vec3 normal_side = through ? -tbn[2] : tbn[2];
        float a_min = min(l.ax, l.ay);
        float a_max = max(l.ax, l.ay);
        bool aniso_line = a_max > SPLIT_SUM_LINE_RATIO * a_min;
        float len_xy = length(wo.xy);
        bool oblique = !aniso_line && len_xy > MIN_OBLIQUE_XY;
        bool line = aniso_line || oblique;
        float level_alpha = aniso_line ? a_min : (oblique ? alpha * oblique_ratio(l.dist, alpha, wo.z) : alpha);
        float lean_alpha = aniso_line ? a_min : alpha;  // the whole lobe's off-specular shift
        float smooth_part = 1.0 - clamp(lean_alpha, 0.0, 1.0);
        float lean = smooth_part * (sqrt(smooth_part) + (1.0 - smooth_part));
        float spread = aniso_line ? sqrt(a_max * a_max - a_min * a_min)
                                  : sqrt(max(alpha * alpha - level_alpha * level_alpha, 0.0));
        vec2 major = oblique ? wo.xy / len_xy : (l.ax >= l.ay ? vec2(1.0, 0.0) : vec2(0.0, 1.0));
        float lod = split_sum_lod(l.dist, level_alpha, u_split_sum_max_level);
        vec3 radiance = vec3(0.0);
        vec3 radiance_all = vec3(0.0);  // every node, for a view whose whole line lies below the surface
        float weight_sum = 0.0;
        int nodes = line ? SPLIT_SUM_LINE_NODES : 1;
        for (int k = 0; k < nodes; ++k) {
            float slope = line ? SPLIT_SUM_LINE_SLOPES[l.dist][k] * spread : 0.0;
            float weight = line ? SPLIT_SUM_LINE_WEIGHTS[k] : 1.0;
            vec3 h = normalize(vec3(-slope * major, 1.0));
            vec3 local_r = 2.0 * dot(h, wo) * h - wo;
            vec3 r = tbn * vec3(local_r.xy, through ? -local_r.z : local_r.z);
            r = normalize(mix(normal_side, r, lean));
            vec3 r_from_point = r;  // the self-occlusion cone's direction (incident.glsl)
#if defined(PARALLAX)
            float unused_offset;
            r = proxy_direction(r, unused_offset);
#endif
            vec3 value = self_occluded(r_from_point, textureLod(u_split_sum[l.dist], r, lod).rgb,
                                       split_sum_footprint(l.dist, level_alpha)) * weight;
            radiance_all += value;
            if (local_r.z > 0.0) {
                radiance += value;
                weight_sum += weight;
            }
        }
        radiance = weight_sum > 0.0 ? radiance / weight_sum : radiance_all;
        // The albedo: an anisotropic GGX lobe's from the anisotropic table (the isotropic one at
        // the geometric-mean alpha was up to 9 % too bright on GGX 0.05 x 0.3), Beckmann's from
        // the isotropic table at that alpha (no anisotropic Beckmann table).
        vec4 dfg = textureLod(u_dfg, dfg_coordinates(wo.z, roughness, textureSize(u_dfg, 0)), 0.0);
        vec2 ab = l.dist == DIST_GGX ? (aniso_line ? anisotropic_ggx_dfg(l, wo) : dfg.ba) : dfg.rg;
        return radiance * lobe_dfg_albedo(l, ab, wo.z);
    }
    if (u_lobe_map_mode[lobe_index] == LOBE_MAP_BANKS) return banks_lookup(lobe_index, wo, tbn);
    float s = sqrt(clamp(wo.z, 0.0, 1.0)) * float(LOBE_SLICES - 1);  // lobe_fit.slice_coordinate
    int s0 = min(int(floor(s)), LOBE_SLICES - 2);
    float f = s - float(s0);
    // Rotation of the local frame that takes azimuth 0 to wo's azimuth.
    float len_xy = length(wo.xy);
    vec2 u = len_xy > 1e-7 ? wo.xy / len_xy : vec2(-1.0, 0.0);
    bool transmission = lobe_is_transmission(l);
    vec3 m = vec3(-len_xy, 0.0, transmission ? -wo.z : wo.z);  // mirror direction at azimuth 0
    int count = u_lobe_map_count[lobe_index];
    int depth = u_lobe_map_depth[lobe_index];
    vec3 sum = vec3(0.0);
    for (int j = 0; j < count; ++j) {
        int row = lobe_index * LOBE_TABLE_ROWS + j;
        // The axis relative to the mirror direction (lobe_fit.mirror_relative_axes), rebuilt in
        // this pixel's own mirror frame (m, e = dm/dtheta_o) at azimuth 0, then rotated to wo's.
        vec3 a = lobe_table_mix(row, s0, f);
        vec3 energy = lobe_table_mix(row, LOBE_SLICES + s0, f);
        vec3 e = transmission ? vec3(-wo.z, 0.0, len_xy) : vec3(-wo.z, 0.0, -len_xy);
        vec3 local0 = a.x * e + vec3(0.0, a.y, 0.0) + a.z * m;
        vec3 axis = tbn * normalize(vec3(local0.x * u + local0.y * vec2(-u.y, u.x), local0.z));
        float median = mix(texelFetch(u_lobe_table, ivec2(s0, row), 0).w,
                           texelFetch(u_lobe_table, ivec2(s0 + 1, row), 0).w, f);
        if (median < u_lobe_direct_angle[lobe_index]) {
            // Narrower than the map resolves: the cube's MIP chain over the lobe's footprint
            // (lookup() follows the reflection proxy and its footprint change itself).
            float area = LOBE_DIRECT_AREA_PER_MEDIAN2 * median * median;
            sum += lookup(axis, cube_lod(axis, area, u_face_size), area) * energy;
            continue;
        }
        vec3 axis_from_point = axis;  // the self-occlusion cone's direction (incident.glsl)
#if defined(PARALLAX)
        float unused_offset;
        axis = proxy_direction(axis, unused_offset);
#endif
        // Fitted lobe j owns slices j depth .. (j + 1) depth - 1: linear filtering in z never
        // mixes two lobes because z stays between the first and last slice centre of the block.
        float z = (float(j * depth) + (depth > 1 ? s : 0.0) + 0.5) / float(count * depth);
        vec3 mapped = texture(u_lobe_maps[lobe_index], vec3(direction_to_latlong(axis), z)).rgb;
        sum += self_occluded(axis_from_point, mapped, LOBE_DIRECT_AREA_PER_MEDIAN2 * median * median) * energy;
    }
    return sum;
}

#include "rsibr.glsl"
