// Bright sources taken out of the radiance cube (scenes/bright_sources.py), integrated per lobe
// (numpy reference: materials/cap_lights.py integrate_cap_light): a cap at most as wide as the
// lobe by a product Gauss rule over the cap, a wider one by deterministic two-strategy MIS of
// points uniform over the cap and points from the lobe's sampler, both on the golden-ratio
// lattice (the power heuristic; the balance heuristic with CAP_POINTS + CAP_LOBE_POINTS for the
// Rational and measured lobes, which have no width).
#define MAX_CAP_LIGHTS 8
#define CAP_POINTS 8
#define CAP_LOBE_POINTS 8

#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform int u_cap_light_count;                      // 0: none (and always 0 for the reference)
uniform int u_signed_residual;  // 1: the residual read keeps a source's shape beyond its cap (signed)
uniform vec4 u_cap_light_axis[MAX_CAP_LIGHTS];      // xyz: direction (world), w: cos(radius)
uniform vec4 u_cap_light_radiance[MAX_CAP_LIGHTS];  // rgb: radiance, w: the soft edge's inner fraction
#endif

// Footprint-aware lights (materials/cap_lights.py footprint_alpha2, issue 39 item 3): what one
// pixel's footprint adds to a lobe's alpha^2 for the lights, set by the fragment shader from the
// derivatives of its reflected direction (0: point-sampled lights, as the numpy twin tests).
#define FOOTPRINT_DIVISOR 12.0
#define MAX_FOOTPRINT_ALPHA2 0.1
float g_footprint_alpha2 = 0.0;
float g_footprint_dr2 = 0.0;  // |dr_x|^2 + |dr_y|^2
uniform int u_point_sampled_lights;  // 1: no footprint (tests against the per-pixel numpy twin)

float footprint_alpha2(vec3 dr_dx, vec3 dr_dy) {
    return min((dot(dr_dx, dr_dx) + dot(dr_dy, dr_dy)) / FOOTPRINT_DIVISOR, MAX_FOOTPRINT_ALPHA2);
}

// The direction whose screen derivatives give the footprint: the view's reflection about the
// interpolated normal (vertex data and per-pass uniforms only: a quad's helper invocations read
// them too). The fragment shader passes its dFdx / dFdy, in uniform control flow, to
// set_light_footprint (derivatives do not exist in the compute shaders that include this file).
vec3 light_footprint_direction(vec3 position, vec3 camera, vec3 interpolated_normal) {
    return reflect(normalize(position - camera), normalize(interpolated_normal));
}

void set_light_footprint(vec3 dr_dx, vec3 dr_dy) {
    g_footprint_alpha2 = u_point_sampled_lights == 1 ? 0.0 : footprint_alpha2(dr_dx, dr_dy);
    g_footprint_dr2 = dot(dr_dx, dr_dx) + dot(dr_dy, dr_dy);
}

// Whether the lobe has a microfacet width (materials/cap_lights.py lobe_width): the tabulated
// lobes, Rational and measured, have none.
bool lobe_has_width(Lobe l) {
#if defined(HAS_RATIONAL)
    if (l.type == LOBE_RATIONAL) return false;
#endif
#if defined(HAS_MEASURED)
    if (l.type == LOBE_MEASURED) return false;
#endif
    return true;
}

// The lobe as a light of 1 - cos(radius) = one_minus_cos sees it: its alphas widened by the
// pixel's footprint, less for caps wider than the footprint (materials/cap_lights.py
// footprint_alpha2); the tabulated lobes, Rational and measured, keep theirs: their shape is
// not an alpha.
Lobe footprint_lobe(Lobe l, float one_minus_cos) {
    if (g_footprint_alpha2 <= 0.0) return l;
    if (!lobe_has_width(l)) return l;
    float widening = g_footprint_alpha2 * g_footprint_dr2 / max(g_footprint_dr2 + 2.0 * one_minus_cos, 1e-30);
    l.ax = sqrt(l.ax * l.ax + widening);
    l.ay = sqrt(l.ay * l.ay + widening);
    return l;
}

// materials/patterns.py lattice_xi: ((i + 1/2) / n, frac(1/4 + i / golden ratio))
vec2 cap_lattice_point(int i, int n) {
    return vec2((float(i) + 0.5) / float(n), fract(0.25 + float(i) * 0.6180339887498949));
}

// materials/cap_lights.py symmetric_cap_xi: one point on the axis when n is odd, then antipodal
// pairs (pair j at u1 = (j + 1/2) / pairs, golden-ratio azimuth, the partner half a turn away).
vec2 symmetric_cap_point(int i, int n) {
    int odd = n & 1;
    if (odd == 1 && i == 0) return vec2(0.0);
    int k = i - odd;
    int pairs = n / 2;
    int j = k / 2;
    float azimuth = fract(0.25 + float(j) * 0.6180339887498949);
    if ((k & 1) == 1) azimuth = fract(azimuth + 0.5);
    return vec2((float(j) + 0.5) / float(max(pairs, 1)), azimuth);
}

// materials/cap_lights.py edge_profile: 1 up to the inner fraction f of the cap's area, then
// linear to 0 at the rim (a soft box); u = (1 - cos angle) / (1 - cos radius).
float cap_edge_profile(float u, float inner_fraction) {
    return u <= inner_fraction ? 1.0 : clamp((1.0 - u) / max(1.0 - inner_fraction, 1e-12), 0.0, 1.0);
}

// materials/cap_lights.py profile_area_fraction: the inverse of the profile's CDF.
float profile_area_fraction(float xi, float inner_fraction) {
    float s = xi * 0.5 * (1.0 + inner_fraction);
    if (s <= inner_fraction) return s;
    float w = max(1.0 - inner_fraction, 1e-30);
    return inner_fraction + w * (1.0 - sqrt(max(1.0 - 2.0 * (s - inner_fraction) / w, 0.0)));
}

// One strategy's term: h f cos / (a + b), a = M h / Omega_lit, b = K p, h the edge profile; with
// the power heuristic h f cos a' / (a^2 + b^2), a' = a for a cap point, b for a lobe point
// (materials/cap_lights.py _weighted_sum).
vec3 cap_light_term(Lobe l, vec3 wi, vec3 wo, float cap_density, int lobe_points, float profile, bool power, bool cap_point) {
    vec3 f = lobe_eval(l, wi, wo);
    if (!any(greaterThan(f, vec3(0.0)))) return vec3(0.0);
    float a = cap_density * profile;
    float b = lobe_points > 0 ? float(lobe_points) * lobe_sample_pdf(l, wi, wo) : 0.0;
    float denominator = power ? (a * a + b * b) / max(cap_point ? a : b, 1e-30) : a + b;
    return f * (profile * abs(wi.z) / denominator);
}

// materials/cap_lights.py cap_point_counts: (cap points, lobe points, 1: the power heuristic)
// of the two-strategy sum, for caps with q >= NARROW_FROM (narrower ones: gauss_cap_rule) and
// for lobes without a width.
#define NARROW_LOBE_POINTS 16
#define NARROW_CAP_POINTS 8
#define SOFT_CAP_POINTS 16  // soft-edged caps of lobes without a width (materials/cap_lights.py SOFT_*)
#define SOFT_LOBE_POINTS 16
#define MIN_VIEW_COSINE 0.1
ivec3 cap_point_counts(Lobe l, float inner_fraction) {
    bool soft = inner_fraction < 1.0;
    ivec3 without_width = soft ? ivec3(SOFT_CAP_POINTS, SOFT_LOBE_POINTS, 0) : ivec3(CAP_POINTS, CAP_LOBE_POINTS, 0);
    if (!lobe_has_width(l)) return without_width;
    return ivec3(NARROW_CAP_POINTS, NARROW_LOBE_POINTS, 1);
}

// materials/cap_lights.py gauss_cap_rule: (rings, azimuths) of the product Gauss rule for a cap
// not much wider than the lobe or than its distance from the lobe's peak (cap_peak_distance), (0, 0)
// where the two-strategy sum integrates it.
ivec2 gauss_cap_rule(Lobe l, float radius, float cos_theta_o, float peak_distance) {
    if (!lobe_has_width(l)) return ivec2(0);
    float lobe_width = 2.0 * atan(2.0 * sqrt(l.ax * l.ay));
    float width = max(lobe_width, peak_distance);
    float ratio = radius / max(width * max(cos_theta_o, MIN_VIEW_COSINE), 1e-6);
    // GRAZING_AZIMUTH_FACTOR: below MIN_VIEW_COSINE the azimuths double
    int grazing = cos_theta_o < MIN_VIEW_COSINE ? 2 : 1;
    if (ratio < 0.05) return ivec2(1, 1);  // GAUSS_RULES
    if (peak_distance > lobe_width) {  // TAIL_GAUSS_RULES
        if (ratio < 0.3) return ivec2(1, 4 * grazing);
        if (ratio < 0.6) return ivec2(2, 6 * grazing);
        if (ratio < 1.0) return ivec2(3, 8 * grazing);
        return ivec2(0);
    }
    if (ratio < 0.2) return ivec2(1, 4 * grazing);
    if (ratio < 0.35) return ivec2(2, 6 * grazing);
    if (ratio < 0.6) return ivec2(3, 6 * grazing);
    if (ratio < 1.0) return ivec2(3, 8 * grazing);
    return ivec2(0);  // NARROW_FROM
}

// materials/cap_lights.py cap_negligible: a Beckmann lobe's tail below e^-40 of its peak over
// the whole cap (the half vector at least half the cap's peak distance from the normal).
#define BECKMANN_NEGLIGIBLE_EXPONENT 40.0
bool cap_negligible(Lobe l, float peak_distance) {
    if (!lobe_has_width(l)) return false;
    if (l.dist != DIST_BECKMANN) return false;
    float t = tan(min(0.5 * peak_distance, 1.5));
    float widest = max(l.ax, l.ay);
    return t * t > BECKMANN_NEGLIGIBLE_EXPONENT * widest * widest;
}

// materials/bsdf.py gauss_legendre_unit: node i of the n-point rule on [0, 1] (xy: node,
// weight), n = 1..3.
vec2 gauss_node(int i, int n) {
    if (n == 1) return vec2(0.5, 1.0);
    if (n == 2) return vec2(i == 0 ? 0.21132486540518713 : 0.7886751345948129, 0.5);
    if (i == 1) return vec2(0.5, 0.4444444444444444);
    return vec2(i == 0 ? 0.1127016653792583 : 0.8872983346207417, 0.2777777777777778);
}

// The integral of f cos h over the cap (axis, cos_radius) of unit radiance and edge profile h
// (inner_fraction 1: uniform); one_minus_cos = 1 - cos_radius, passed in because a distant
// lamp's tiny cap needs it without cancellation. The cap points follow the profile.
vec3 cap_integral(Lobe lobe, vec3 wo, mat3 tbn, vec3 axis, float cos_radius, float one_minus_cos, float inner_fraction) {
    Lobe l = footprint_lobe(lobe, one_minus_cos);
    mat3 to_local = transpose(tbn);
    vec3 sum = vec3(0.0);
    // materials/cap_lights.py cap_below_horizon and cap_peak_distance, in the lobe's reflected frame
    vec3 axis_reflected = reflected_wi(l, to_local * axis);
    float sin_radius = sqrt(max(one_minus_cos * (2.0 - one_minus_cos), 0.0));
    if (axis_reflected.z <= -sin_radius) return sum;  // every lobe is 0 there
    float radius = acos(clamp(cos_radius, -1.0, 1.0));
    float to_peak = acos(clamp(dot(axis_reflected, vec3(-wo.xy, wo.z)), -1.0, 1.0));
    float peak_distance = max(to_peak - radius, 0.0);
    if (cap_negligible(l, peak_distance)) return sum;
    // the distance sets a GGX lobe's rule only for a cap wholly above the horizon, and at most
    // the cap's gap above it (materials/cap_lights.py cap_peak_distance)
    float above_horizon = asin(clamp(axis_reflected.z, -1.0, 1.0)) - radius;
    float rule_distance = above_horizon > 0.0 && l.dist == DIST_GGX ? min(peak_distance, above_horizon) : 0.0;
    // the cap's own frame, for its points (after the early returns: half the caps need none)
    vec3 helper = abs(axis.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 t = normalize(cross(helper, axis));
    vec3 b = cross(axis, t);
    float lit_solid_angle = 2.0 * PI * one_minus_cos * (0.5 * (1.0 + inner_fraction));
    ivec2 rule = gauss_cap_rule(l, radius, wo.z, rule_distance);
    if (rule.x > 0) {  // materials/cap_lights.py gauss_cap_integral
        for (int i = 0; i < rule.x; ++i) {
            vec2 node = gauss_node(i, rule.x);
            // one point: on the axis
            float u1 = rule.y == 1 ? 0.0 : profile_area_fraction(node.x, inner_fraction);
            float cos_t = 1.0 - u1 * one_minus_cos;
            float sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
            vec3 ring = vec3(0.0);
            for (int j = 0; j < rule.y; ++j) {
                float phi = 2.0 * PI * (float(j) + 0.5) / float(rule.y);
                vec3 wi = to_local * (sin_t * (cos(phi) * t + sin(phi) * b) + cos_t * axis);
                vec3 f = lobe_eval(l, wi, wo);
                ring += f * abs(wi.z);
            }
            sum += ring * node.y;
        }
        return sum * (lit_solid_angle / float(rule.y));
    }
    ivec3 counts = cap_point_counts(l, inner_fraction);
    bool power = counts.z == 1;
    float cap_density = float(counts.x) / lit_solid_angle;
    for (int i = 0; i < counts.x; ++i) {
        // materials/cap_lights.py cap_xi: symmetric without lobe points, the lattice with them
        vec2 u = counts.y == 0 || counts.x == 1 ? symmetric_cap_point(i, counts.x) : cap_lattice_point(i, counts.x);
        u.x = profile_area_fraction(u.x, inner_fraction);
        float cos_t = 1.0 - u.x * one_minus_cos;
        float sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
        float phi = 2.0 * PI * u.y;
        vec3 world = sin_t * (cos(phi) * t + sin(phi) * b) + cos_t * axis;
        sum += cap_light_term(l, to_local * world, wo, cap_density, counts.y, cap_edge_profile(u.x, inner_fraction), power, true);
    }
    for (int j = 0; j < counts.y; ++j) {
        float p;
        vec3 wi = lobe_sample_and_pdf(l, cap_lattice_point(j, counts.y), wo, p);
        float cos_to_axis = dot(tbn * wi, axis);
        if (p <= 0.0 || cos_to_axis < cos_radius) continue;
        float profile = cap_edge_profile((1.0 - cos_to_axis) / one_minus_cos, inner_fraction);
        if (profile <= 0.0) continue;
        sum += cap_light_term(l, wi, wo, cap_density, counts.y, profile, power, false);
    }
    return sum;
}

vec3 cap_light_radiance(Lobe l, vec3 wo, mat3 tbn, int k) {
    float cos_radius = u_cap_light_axis[k].w;
    vec4 light = u_cap_light_radiance[k];
    return cap_integral(l, wo, tbn, u_cap_light_axis[k].xyz, cos_radius, 1.0 - cos_radius, light.w) * light.rgb;
}

vec3 cap_lights_radiance(Lobe l, vec3 wo, mat3 tbn) {
    vec3 sum = vec3(0.0);
    if (wo.z <= 0.0) return sum;
    // A light the object's own surface hides from this point (self_occlusion.glsl): the object
    // is seen there instead, which the residual cube's lookups already count. The visible share
    // is the cap's own (its solid angle as the footprint).
    for (int k = 0; k < u_cap_light_count; ++k) {
        vec3 light = cap_light_radiance(l, wo, tbn, k);
        if (!any(greaterThan(light, vec3(0.0)))) continue;  // below the horizon: no visibility to look up
        float cap_solid_angle = 2.0 * PI * (1.0 - u_cap_light_axis[k].w);
        sum += self_visibility(u_cap_light_axis[k].xyz, cap_solid_angle) * light;
    }
    return sum;
}
