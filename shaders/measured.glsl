// GLSL twin of lobeview.materials.measured (MeasuredLobe, TabulatedSampler): a MERL table read
// at its nearest cell, importance-sampled from CDFs tabulated over half-vector cells per view
// elevation, with a MEASURED_DEFENSIVE_COSINE share of cosine-weighted samples.
//
// u_measured_table: RGB 3D texture (phi_d 180, theta_d 90, theta_h 90), read with texelFetch.
// The storage buffer (viewer/material_gpu.py pack_measured, TabulatedSampler.pack): per view bin
// k the row CDF over t (MEASURED_T_CELLS + 1 floats), then per bin and row the cumulative mass
// over phi (MEASURED_PHI_CELLS + 1 floats each).
uniform sampler3D u_measured_table;
layout(std430, binding = MEASURED_BINDING) readonly buffer MeasuredCdf { float measured_cdf[]; };

#define MEASURED_ROW(k, i) ((k) * (MEASURED_T_CELLS + 1) + (i))
#define MEASURED_CELL(k, i, j) \
    (MEASURED_THETA_O_BINS * (MEASURED_T_CELLS + 1) + ((k) * MEASURED_T_CELLS + (i)) * (MEASURED_PHI_CELLS + 1) + (j))

// atan(v.y, v.x), 0 on the pole (GLSL leaves atan(0, 0) undefined; numpy's arctan2 gives 0).
float measured_azimuth(vec3 v) { return (v.x == 0.0 && v.y == 0.0) ? 0.0 : atan(v.y, v.x); }

// MERL's std_coords_to_half_diff_coords (materials/measurement.py directions_to_half_diff):
// wi turned by -phi_h about n, then by -theta_h about y. Returns (theta_h, theta_d, phi_d).
vec3 measured_half_diff(vec3 wi, vec3 wo) {
    vec3 h = normalize(wi + wo);
    float theta_h = atan(length(h.xy), h.z);  // not acos: float32 acos near 1 loses small angles
    float phi_h = measured_azimuth(h);
    float c = cos(-phi_h), s = sin(-phi_h);
    vec3 d = vec3(wi.x * c - wi.y * s, wi.x * s + wi.y * c, wi.z);
    c = cos(-theta_h);
    s = sin(-theta_h);
    d = vec3(d.x * c + d.z * s, d.y, d.z * c - d.x * s);
    float theta_d = atan(length(d.xy), d.z);
    float phi_d = measured_azimuth(d);
    return vec3(theta_h, theta_d, phi_d);
}

vec3 measured_brdf(vec3 wi, vec3 wo) {
    if (wi.z <= COS_EPS || wo.z <= COS_EPS) return vec3(0.0);
    vec3 a = measured_half_diff(wi, wo);
    float phi_d = a.z < 0.0 ? a.z + PI : a.z;  // reciprocity: phi_d ~ phi_d + pi
    // MERL's index functions (materials/measurement.py merl_indices)
    int ih = clamp(int(sqrt(max(a.x, 0.0) / (0.5 * PI) * 90.0 * 90.0)), 0, 89);
    int id = clamp(int(a.y / (0.5 * PI) * 90.0), 0, 89);
    int ip = clamp(int(phi_d / PI * 180.0), 0, 179);
    return texelFetch(u_measured_table, ivec3(ip, id, ih), 0).rgb;
}

// The two view bins whose tables mix for wo and the weight of the second (_theta_o_position).
void measured_view_bins(vec3 wo, out int k0, out float w) {
    float theta_o = acos(clamp(wo.z, 0.0, 1.0));
    float x = clamp(theta_o / (0.5 * PI) * float(MEASURED_THETA_O_BINS) - 0.5, 0.0, float(MEASURED_THETA_O_BINS - 1));
    k0 = min(int(floor(x)), MEASURED_THETA_O_BINS - 2);
    w = x - float(k0);
}

float measured_row_cdf(int k0, float w, int i) {
    return mix(measured_cdf[MEASURED_ROW(k0, i)], measured_cdf[MEASURED_ROW(k0 + 1, i)], w);
}

float measured_cell_cdf(int k0, float w, int i, int j) {
    return mix(measured_cdf[MEASURED_CELL(k0, i, j)], measured_cdf[MEASURED_CELL(k0 + 1, i, j)], w);
}

// A cell probability p_cell as a density per solid angle of wi at the half vector h (t, theta_h):
// / (dt dphi |d omega_i / d(t, phi)|), d omega_i = 4 (wo.h) sin theta_h (pi t) dt dphi.
float measured_cells_to_solid_angle(float p_cell, float t, float theta_h, vec3 wo, vec3 h) {
    float jacobian = (1.0 / float(MEASURED_T_CELLS)) * (2.0 * PI / float(MEASURED_PHI_CELLS)) * PI * t * sin(theta_h) * 4.0 *
                     dot(wo, h);
    return jacobian > 0.0 ? max(p_cell, 0.0) / jacobian : 0.0;
}

// Density per solid angle of the cell tables alone at (wi, wo) (TabulatedSampler.density).
float measured_cell_density(vec3 wi, vec3 wo) {
    if (wi.z <= COS_EPS || wo.z <= COS_EPS) return 0.0;
    int k0;
    float w;
    measured_view_bins(wo, k0, w);
    vec3 h = normalize(wi + wo);
    if (h.z <= 0.0) return 0.0;
    float theta_h = atan(length(h.xy), h.z);  // the Jacobian ~ t^3 needs small angles exact
    float t = sqrt(clamp(theta_h / (0.5 * PI), 0.0, 1.0));
    float phi = mod(measured_azimuth(h) - measured_azimuth(wo), 2.0 * PI);
    int i = clamp(int(t * float(MEASURED_T_CELLS)), 0, MEASURED_T_CELLS - 1);
    int j = clamp(int(phi / (2.0 * PI) * float(MEASURED_PHI_CELLS)), 0, MEASURED_PHI_CELLS - 1);
    float p_cell = measured_cell_cdf(k0, w, i, j + 1) - measured_cell_cdf(k0, w, i, j);
    return measured_cells_to_solid_angle(p_cell, t, theta_h, wo, h);
}

float measured_sample_pdf(vec3 wi, vec3 wo) {
    if (wi.z <= COS_EPS || wo.z <= COS_EPS) return 0.0;
    return (1.0 - MEASURED_DEFENSIVE_COSINE) * measured_cell_density(wi, wo) + MEASURED_DEFENSIVE_COSINE * wi.z / PI;
}

vec3 measured_sample(vec2 u, vec3 wo, out float pdf) {
    if (u.x < MEASURED_DEFENSIVE_COSINE) {
        vec3 wi = cosine_hemisphere(vec2(u.x / MEASURED_DEFENSIVE_COSINE, u.y));
        pdf = measured_sample_pdf(wi, wo);
        return wi;
    }
    float u1 = min((u.x - MEASURED_DEFENSIVE_COSINE) / (1.0 - MEASURED_DEFENSIVE_COSINE), 1.0 - 1e-7);
    int k0;
    float w;
    measured_view_bins(wo, k0, w);
    // Row over t: cdf[lo] <= target < cdf[lo + 1] by bisection (materials/measured.py _search).
    float target = u1 * measured_row_cdf(k0, w, MEASURED_T_CELLS);
    int lo = 0, hi = MEASURED_T_CELLS;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (measured_row_cdf(k0, w, mid) <= target) lo = mid; else hi = mid;
    }
    int i = lo;
    float low = measured_row_cdf(k0, w, i), high = measured_row_cdf(k0, w, i + 1);
    float t = (float(i) + clamp((target - low) / max(high - low, 1e-30), 0.0, 1.0)) / float(MEASURED_T_CELLS);
    // Cell over phi within the row, u2 turned by -phi_v / 2 pi (anchored in the tangent frame).
    float phi_v = measured_azimuth(wo);
    target = fract(u.y - phi_v / (2.0 * PI)) * measured_cell_cdf(k0, w, i, MEASURED_PHI_CELLS);
    lo = 0;
    hi = MEASURED_PHI_CELLS;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (measured_cell_cdf(k0, w, i, mid) <= target) lo = mid; else hi = mid;
    }
    low = measured_cell_cdf(k0, w, i, lo);
    high = measured_cell_cdf(k0, w, i, lo + 1);
    float phi = (float(lo) + clamp((target - low) / max(high - low, 1e-30), 0.0, 1.0)) * (2.0 * PI / float(MEASURED_PHI_CELLS));
    phi += phi_v;
    float theta_h = t * t * 0.5 * PI;
    vec3 h = vec3(sin(theta_h) * cos(phi), sin(theta_h) * sin(phi), cos(theta_h));
    vec3 wi = 2.0 * dot(wo, h) * h - wo;
    pdf = wi.z <= COS_EPS || wo.z <= COS_EPS ? 0.0
        // from the cell the sample came from, not re-derived from wi (float32 puts a sample on a
        // cell's edge into its neighbour)
        : (1.0 - MEASURED_DEFENSIVE_COSINE) * measured_cells_to_solid_angle(high - low, t, theta_h, wo, h) +
          MEASURED_DEFENSIVE_COSINE * wi.z / PI;
    return wi;
}
