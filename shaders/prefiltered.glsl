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
const float SPLIT_SUM_LINE_EDGES[12] = float[12](0.0, 0.027777778, 0.111111111, 0.222222222, 0.333333333,
    0.444444444, 0.555555556, 0.666666667, 0.777777778, 0.888888889, 0.972222222, 1.0);

// erf^-1 (Giles 2010, "Approximating the erfinv function", single precision: relative error
// below 4e-7 over (-1, 1)): Beckmann's slope marginal's quantile.
float erfinv_giles(float x) {
    float w = -log(max((1.0 - x) * (1.0 + x), 1e-30));
    float p;
    if (w < 5.0) {
        w -= 2.5;
        p = 2.81022636e-08;
        p = 3.43273939e-07 + p * w;
        p = -3.5233877e-06 + p * w;
        p = -4.39150654e-06 + p * w;
        p = 0.00021858087 + p * w;
        p = -0.00125372503 + p * w;
        p = -0.00417768164 + p * w;
        p = 0.246640727 + p * w;
        p = 1.50140941 + p * w;
    } else {
        w = sqrt(w) - 3.0;
        p = -0.000200214257;
        p = 0.000100950558 + p * w;
        p = 0.00134934322 + p * w;
        p = -0.00367342844 + p * w;
        p = 0.00573950773 + p * w;
        p = -0.0076224613 + p * w;
        p = 0.00943887047 + p * w;
        p = 1.00167406 + p * w;
        p = 2.83297682 + p * w;
    }
    return p * x;
}

// split_sum_anisotropic.py slope_marginal_quantile: the slope marginal's quantile at alpha 1.
float slope_marginal_quantile(int dist, float u) {
    u = clamp(u, 1e-6, 1.0 - 1e-6);  // QUANTILE_MARGIN
    if (dist == DIST_GGX) return (2.0 * u - 1.0) / (2.0 * sqrt(u * (1.0 - u)));
    return erfinv_giles(2.0 * u - 1.0);
}

// split_sum_anisotropic.py anisotropic_line_slopes: an anisotropic lobe's line at the quantiles of
// its own f cos along its wider axis ``major``: the marginal's intervals reweighted by
// g = G2 (wo.h) / cos theta_h at the marginal's nodes (zero below the surface), the nodes at the
// reweighted quantiles, their offsets from the median shrunk by sqrt(1 - (a_min / a_max)^2).
void anisotropic_line_slopes(Lobe l, vec3 wo, vec2 major, float a_min, float a_max,
                             out float slopes[SPLIT_SUM_LINE_NODES]) {
    float mass[SPLIT_SUM_LINE_NODES];
    float total = 0.0;
    float lambda_o = lambda_smith(l, wo);
    for (int k = 0; k < SPLIT_SUM_LINE_NODES; ++k) {
        vec3 h = normalize(vec3(-SPLIT_SUM_LINE_SLOPES[l.dist][k] * a_max * major, 1.0));
        vec3 wi = 2.0 * dot(h, wo) * h - wo;
        float g = wi.z > 0.0 ? dot(h, wo) / (h.z * (1.0 + lambda_smith(l, wi) + lambda_o)) : 0.0;
        mass[k] = SPLIT_SUM_LINE_WEIGHTS[k] * g;
        total += mass[k];
    }
    float shrink = sqrt(max(1.0 - (a_min / a_max) * (a_min / a_max), 0.0));
    if (!(total > 0.0)) {  // every node below the surface: the marginal's own (all read, as before)
        for (int k = 0; k < SPLIT_SUM_LINE_NODES; ++k) slopes[k] = SPLIT_SUM_LINE_SLOPES[l.dist][k] * a_max * shrink;
        return;
    }
    // the targets (the middles of the intervals, in increasing order) walk the reweighted CDF once
    int bin = 0;
    float before = 0.0;  // the reweighted mass of the intervals before ``bin``
    for (int j = 0; j < SPLIT_SUM_LINE_NODES; ++j) {
        float target = 0.5 * (SPLIT_SUM_LINE_EDGES[j] + SPLIT_SUM_LINE_EDGES[j + 1]) * total;
        while (bin < SPLIT_SUM_LINE_NODES - 1 && before + mass[bin] <= target) {
            before += mass[bin];
            ++bin;
        }
        float within = mass[bin] > 0.0 ? clamp((target - before) / mass[bin], 0.0, 1.0) : 0.0;
        float u = mix(SPLIT_SUM_LINE_EDGES[bin], SPLIT_SUM_LINE_EDGES[bin + 1], within);
        slopes[j] = slope_marginal_quantile(l.dist, u) * a_max;
    }
    float median = slopes[SPLIT_SUM_LINE_NODES / 2];  // the middle interval's middle is 1/2
    for (int k = 0; k < SPLIT_SUM_LINE_NODES; ++k) slopes[k] = median + (slopes[k] - median) * shrink;
}
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
// The cell of the (OBLIQUE_ALPHAS, cos theta_o 0.1 .. 1.0) grid and the weights within it, alpha
// and cos theta_o clamped to the grid (split_sum_oblique.py oblique_alpha_ratio).
void oblique_cell(float alpha, float cos_o, out int i, out float ta, out int j, out float tc) {
    float a = clamp(alpha, 0.1, 1.0);
    i = 0;
    for (int k = 0; k < 6; ++k) if (a >= OBLIQUE_ALPHAS[k + 1]) i = k + 1;
    ta = clamp((a - OBLIQUE_ALPHAS[i]) / (OBLIQUE_ALPHAS[i + 1] - OBLIQUE_ALPHAS[i]), 0.0, 1.0);
    float cc = clamp(cos_o, 0.1, 1.0) * 10.0 - 1.0;
    j = min(int(floor(cc)), 8);
    tc = cc - float(j);
}
float oblique_ratio(int dist, float alpha, float cos_o) {
    int i, j;
    float ta, tc;
    oblique_cell(alpha, cos_o, i, ta, j, tc);
    int base = dist == DIST_GGX ? 0 : 80;
    float r00 = OBLIQUE_RATIO[base + i * 10 + j], r01 = OBLIQUE_RATIO[base + i * 10 + j + 1];
    float r10 = OBLIQUE_RATIO[base + (i + 1) * 10 + j], r11 = OBLIQUE_RATIO[base + (i + 1) * 10 + j + 1];
    return mix(mix(r00, r01, tc), mix(r10, r11, tc), ta);
}

// split_sum_oblique.py IN_PLANE_OFFSETS: Beckmann's oblique line at the lobe's own in-plane
// quantiles, t_k = (theta_k + theta_o) / alpha per (OBLIQUE_ALPHAS, cos theta_o) cell, 11 nodes
// each (materials/split_sum_in_plane.py computes them; tests/test_split_sum_oblique.py checks this copy).
const float IN_PLANE_OFFSETS[880] = float[880](
    -0.680, -0.359, 0.009, 0.342, 0.654, 0.955, 1.277, 1.631, 2.088, 2.720, 3.621,
    -1.519, -1.070, -0.588, -0.174, 0.185, 0.533, 0.883, 1.274, 1.758, 2.420, 3.350,
    -2.175, -1.505, -0.913, -0.445, -0.055, 0.305, 0.673, 1.069, 1.559, 2.223, 3.151,
    -2.496, -1.658, -1.026, -0.550, -0.161, 0.192, 0.552, 0.944, 1.420, 2.069, 2.970,
    -2.501, -1.657, -1.042, -0.588, -0.214, 0.128, 0.470, 0.844, 1.299, 1.914, 2.774,
    -2.368, -1.576, -1.004, -0.578, -0.236, 0.082, 0.408, 0.748, 1.176, 1.748, 2.547,
    -2.156, -1.444, -0.931, -0.549, -0.233, 0.053, 0.343, 0.652, 1.036, 1.546, 2.262,
    -1.861, -1.248, -0.810, -0.482, -0.216, 0.028, 0.271, 0.532, 0.862, 1.304, 1.911,
    -1.413, -0.952, -0.630, -0.374, -0.178, 0.010, 0.195, 0.394, 0.641, 0.972, 1.430,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    -0.333, -0.057, 0.271, 0.578, 0.859, 1.139, 1.436, 1.771, 2.198, 2.795, 3.636,
    -0.893, -0.580, -0.207, 0.140, 0.456, 0.764, 1.087, 1.445, 1.898, 2.517, 3.387,
    -1.405, -1.018, -0.571, -0.178, 0.168, 0.498, 0.835, 1.210, 1.673, 2.302, 3.178,
    -1.842, -1.327, -0.808, -0.383, -0.022, 0.319, 0.659, 1.036, 1.500, 2.123, 2.985,
    -2.134, -1.485, -0.923, -0.491, -0.131, 0.202, 0.539, 0.903, 1.355, 1.952, 2.781,
    -2.216, -1.498, -0.947, -0.528, -0.190, 0.130, 0.445, 0.791, 1.213, 1.776, 2.546,
    -2.101, -1.414, -0.905, -0.524, -0.212, 0.079, 0.368, 0.679, 1.067, 1.579, 2.279,
    -1.861, -1.258, -0.819, -0.482, -0.210, 0.040, 0.291, 0.566, 0.899, 1.344, 1.948,
    -1.488, -1.012, -0.667, -0.401, -0.185, 0.013, 0.212, 0.430, 0.698, 1.051, 1.524,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    -0.130, 0.116, 0.417, 0.702, 0.968, 1.232, 1.511, 1.830, 2.234, 2.792, 3.577,
    -0.528, -0.286, 0.034, 0.342, 0.629, 0.913, 1.211, 1.548, 1.972, 2.552, 3.356,
    -0.901, -0.643, -0.290, 0.047, 0.355, 0.656, 0.968, 1.318, 1.751, 2.343, 3.153,
    -1.244, -0.949, -0.549, -0.183, 0.141, 0.451, 0.774, 1.126, 1.565, 2.154, 2.958,
    -1.553, -1.181, -0.734, -0.348, -0.016, 0.299, 0.619, 0.970, 1.400, 1.976, 2.755,
    -1.794, -1.319, -0.841, -0.449, -0.122, 0.187, 0.499, 0.837, 1.250, 1.801, 2.539,
    -1.899, -1.343, -0.864, -0.490, -0.180, 0.110, 0.399, 0.715, 1.097, 1.605, 2.284,
    -1.822, -1.262, -0.821, -0.485, -0.202, 0.056, 0.315, 0.595, 0.936, 1.387, 1.985,
    -1.569, -1.086, -0.716, -0.433, -0.200, 0.019, 0.234, 0.472, 0.753, 1.127, 1.617,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    0.134, 0.318, 0.577, 0.829, 1.067, 1.305, 1.557, 1.843, 2.204, 2.691, 3.350,
    -0.076, 0.065, 0.316, 0.573, 0.820, 1.067, 1.331, 1.628, 2.001, 2.503, 3.173,
    -0.266, -0.170, 0.078, 0.341, 0.596, 0.854, 1.125, 1.432, 1.814, 2.324, 3.000,
    -0.450, -0.390, -0.141, 0.132, 0.396, 0.660, 0.940, 1.253, 1.642, 2.154, 2.825,
    -0.629, -0.597, -0.337, -0.053, 0.219, 0.490, 0.774, 1.088, 1.477, 1.986, 2.644,
    -0.825, -0.791, -0.511, -0.213, 0.066, 0.340, 0.625, 0.940, 1.322, 1.823, 2.457,
    -1.045, -0.962, -0.651, -0.343, -0.059, 0.214, 0.495, 0.802, 1.174, 1.656, 2.260,
    -1.273, -1.092, -0.748, -0.432, -0.154, 0.112, 0.383, 0.676, 1.030, 1.481, 2.041,
    -1.477, -1.154, -0.787, -0.476, -0.209, 0.039, 0.290, 0.563, 0.886, 1.299, 1.807,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    0.329, 0.444, 0.662, 0.885, 1.098, 1.313, 1.541, 1.797, 2.114, 2.532, 3.063,
    0.228, 0.277, 0.473, 0.691, 0.908, 1.128, 1.363, 1.627, 1.954, 2.380, 2.914,
    0.148, 0.117, 0.294, 0.510, 0.728, 0.954, 1.195, 1.466, 1.800, 2.234, 2.767,
    0.078, -0.038, 0.120, 0.337, 0.559, 0.790, 1.037, 1.314, 1.655, 2.091, 2.621,
    0.010, -0.195, -0.050, 0.168, 0.396, 0.633, 0.887, 1.169, 1.515, 1.952, 2.475,
    -0.095, -0.364, -0.219, 0.006, 0.241, 0.485, 0.744, 1.034, 1.381, 1.819, 2.335,
    -0.277, -0.548, -0.391, -0.153, 0.094, 0.347, 0.612, 0.904, 1.255, 1.690, 2.194,
    -0.571, -0.759, -0.563, -0.303, -0.043, 0.217, 0.488, 0.786, 1.137, 1.569, 2.064,
    -0.992, -1.000, -0.735, -0.443, -0.167, 0.103, 0.379, 0.678, 1.028, 1.454, 1.941,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    0.486, 0.532, 0.711, 0.907, 1.098, 1.294, 1.499, 1.728, 2.005, 2.353, 2.764,
    0.456, 0.417, 0.568, 0.757, 0.949, 1.147, 1.357, 1.593, 1.876, 2.229, 2.637,
    0.445, 0.302, 0.427, 0.610, 0.803, 1.005, 1.223, 1.465, 1.755, 2.112, 2.514,
    0.459, 0.186, 0.286, 0.465, 0.660, 0.868, 1.092, 1.341, 1.639, 2.000, 2.397,
    0.483, 0.055, 0.138, 0.317, 0.519, 0.734, 0.966, 1.224, 1.528, 1.895, 2.290,
    0.489, -0.094, -0.018, 0.167, 0.377, 0.602, 0.845, 1.112, 1.427, 1.800, 2.195,
    0.234, -0.277, -0.190, 0.009, 0.233, 0.472, 0.727, 1.006, 1.332, 1.713, 2.114,
    -0.146, -0.499, -0.381, -0.158, 0.086, 0.342, 0.612, 0.905, 1.244, 1.637, 2.045,
    -0.630, -0.789, -0.605, -0.341, -0.069, 0.209, 0.498, 0.808, 1.163, 1.568, 1.978,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    0.686, 0.621, 0.741, 0.900, 1.062, 1.228, 1.399, 1.580, 1.783, 2.006, 2.210,
    0.703, 0.550, 0.647, 0.801, 0.965, 1.134, 1.310, 1.497, 1.703, 1.925, 2.114,
    0.715, 0.468, 0.548, 0.699, 0.867, 1.043, 1.226, 1.419, 1.631, 1.853, 2.032,
    0.684, 0.369, 0.439, 0.593, 0.768, 0.953, 1.146, 1.349, 1.569, 1.794, 1.972,
    0.587, 0.251, 0.320, 0.482, 0.667, 0.864, 1.069, 1.283, 1.513, 1.744, 1.924,
    0.411, 0.112, 0.188, 0.362, 0.561, 0.774, 0.994, 1.222, 1.463, 1.704, 1.890,
    0.177, -0.056, 0.039, 0.230, 0.448, 0.679, 0.916, 1.161, 1.417, 1.668, 1.861,
    -0.097, -0.259, -0.138, 0.076, 0.316, 0.569, 0.827, 1.090, 1.362, 1.622, 1.815,
    -0.437, -0.524, -0.368, -0.125, 0.143, 0.420, 0.702, 0.985, 1.271, 1.532, 1.694,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000,
    0.681, 0.592, 0.688, 0.833, 0.980, 1.124, 1.259, 1.386, 1.499, 1.573, 1.534,
    0.629, 0.532, 0.628, 0.777, 0.931, 1.080, 1.220, 1.347, 1.456, 1.516, 1.450,
    0.549, 0.461, 0.563, 0.720, 0.882, 1.039, 1.184, 1.313, 1.419, 1.468, 1.382,
    0.441, 0.378, 0.492, 0.660, 0.833, 0.999, 1.151, 1.283, 1.387, 1.428, 1.339,
    0.316, 0.284, 0.412, 0.594, 0.780, 0.957, 1.117, 1.253, 1.356, 1.394, 1.314,
    0.180, 0.175, 0.321, 0.517, 0.716, 0.905, 1.074, 1.216, 1.321, 1.359, 1.292,
    0.009, 0.031, 0.194, 0.409, 0.627, 0.833, 1.017, 1.172, 1.290, 1.342, 1.284,
    -0.171, -0.136, 0.038, 0.267, 0.499, 0.722, 0.923, 1.093, 1.225, 1.288, 1.221,
    -0.374, -0.343, -0.171, 0.060, 0.303, 0.541, 0.759, 0.947, 1.097, 1.173, 1.102,
    0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000, 0.000);
float in_plane_angle(float alpha, float cos_o, int k) {
    int i, j;
    float ta, tc;
    oblique_cell(alpha, cos_o, i, ta, j, tc);
    float t00 = IN_PLANE_OFFSETS[(i * 10 + j) * 11 + k], t01 = IN_PLANE_OFFSETS[(i * 10 + j + 1) * 11 + k];
    float t10 = IN_PLANE_OFFSETS[((i + 1) * 10 + j) * 11 + k], t11 = IN_PLANE_OFFSETS[((i + 1) * 10 + j + 1) * 11 + k];
    return -acos(clamp(cos_o, -1.0, 1.0)) + min(alpha, 1.0) * mix(mix(t00, t01, tc), mix(t10, t11, tc), ta);
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
        // anisotropic lobe reads the map at its narrower alpha at the quantiles of its own f cos
        // along its wider axis (split_sum_anisotropic.py; its off-specular shift included, so not
        // leant), each weighted by its probability, the nodes below the surface left out
        // (split_sum_line); an isotropic lobe seen off the normal reads a line along the plane of
        // incidence at the narrower alpha of its spread across that plane, leant at its own alpha,
        // Beckmann's at its lobe's in-plane quantiles instead and not leant (split_sum_oblique.py).
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
        // Beckmann seen off the normal: the nodes at its lobe's in-plane quantiles (the off-specular
        // shift included, so no lean; split_sum_oblique.py IN_PLANE_OFFSETS)
        bool in_plane = oblique && l.dist == DIST_BECKMANN;
        float smooth_part = 1.0 - clamp(alpha, 0.0, 1.0);  // the whole lobe's off-specular shift
        float lean = (in_plane || aniso_line) ? 1.0 : smooth_part * (sqrt(smooth_part) + (1.0 - smooth_part));
        float spread = sqrt(max(alpha * alpha - level_alpha * level_alpha, 0.0));
        vec2 major = oblique ? wo.xy / len_xy : (l.ax >= l.ay ? vec2(1.0, 0.0) : vec2(0.0, 1.0));
        float aniso_slopes[SPLIT_SUM_LINE_NODES];
        if (aniso_line) anisotropic_line_slopes(l, wo, major, a_min, a_max, aniso_slopes);
        float lod = split_sum_lod(l.dist, level_alpha, u_split_sum_max_level);
        vec3 radiance = vec3(0.0);
        vec3 radiance_all = vec3(0.0);  // every node, for a view whose whole line lies below the surface
        float weight_sum = 0.0;
        int nodes = line ? SPLIT_SUM_LINE_NODES : 1;
        for (int k = 0; k < nodes; ++k) {
            float slope = aniso_line ? aniso_slopes[k] : (line ? SPLIT_SUM_LINE_SLOPES[l.dist][k] * spread : 0.0);
            float weight = line ? SPLIT_SUM_LINE_WEIGHTS[k] : 1.0;
            vec3 h = normalize(vec3(-slope * major, 1.0));
            vec3 local_r = 2.0 * dot(h, wo) * h - wo;
            if (in_plane) {
                float theta = in_plane_angle(alpha, wo.z, k);
                local_r = vec3(sin(theta) * major, cos(theta));
            }
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
