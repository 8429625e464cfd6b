// Specular self-occlusion (numpy twin: scenes/self_visibility.py horizon_visibility and
// self_occluded_incident). The cube map holds what the object's surroundings send, not the
// object itself: a direction below the shading point's horizon at its azimuth (HORIZON_SECTORS
// sectors about the normal; SELF_NO_OCCLUSION in the cone's w: nothing hidden) sees the object
// instead, whose radiance is g_self_radiance there. A lookup that averages the cube over a
// footprint sees the horizon through it (self_visibility's footprint). Directions below the
// surface pass for a transmission lobe and are hidden for a reflection lobe (g_self_below_hidden:
// they point into the object). scene.frag sets these per pixel and lobe; their defaults leave
// every lookup as it is (the preview, RSIBR's bake).
const float SELF_NO_OCCLUSION = -2.0;
const vec3 HORIZON_AXIS = vec3(1.0, 2.0, 3.0) / sqrt(14.0);
vec4 g_self_cone = vec4(0.0, 0.0, 1.0, SELF_NO_OCCLUSION);
vec3 g_self_normal = vec3(0.0, 0.0, 1.0);
vec3 g_self_tangent = vec3(1.0, 0.0, 0.0);  // the horizon's frame about g_self_normal (set_self_normal)
vec3 g_self_bitangent = vec3(0.0, 1.0, 0.0);
vec3 g_self_radiance = vec3(0.0);
// The shading point's horizons: HORIZON_SECTORS of them from its vertices', MAP_HORIZON_SECTORS
// from a horizon map (g_self_sectors says which).
float g_self_horizon[MAP_HORIZON_SECTORS] = float[](0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                                   0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
int g_self_sectors = HORIZON_SECTORS;
bool g_self_below_hidden = false;  // the lobe looked up reflects (scene.frag, per lobe)
// The normal of the reflection lobe looked up where a normal map tilts it from g_self_normal
// (set_self_lobe_normal, per lobe): a read's share is taken over the part of its footprint the
// lobe covers, above this normal's surface.
vec3 g_self_lobe_normal = vec3(0.0, 0.0, 1.0);
bool g_self_lobe_tilted = false;

// The frame the horizon's azimuths are measured in (self_visibility.py horizon_frame).
void horizon_frame(vec3 n, out vec3 t, out vec3 b) {
    t = cross(HORIZON_AXIS, n);
    if (length(t) <= 1e-6) t = cross(vec3(1.0, 0.0, 0.0), n);
    t = normalize(t);
    b = cross(n, t);
}

// The shading point's normal and its horizon frame, once a pixel (not once a lookup).
void set_self_normal(vec3 n) {
    g_self_normal = n;
    horizon_frame(n, g_self_tangent, g_self_bitangent);
}

// The lobe's normal for the lookups that follow: tilted when a reflection lobe's frame leans away
// from the surface's normal (a normal map), otherwise the surface's own (nothing changes).
void set_self_lobe_normal(vec3 lobe_normal) {
    g_self_lobe_normal = lobe_normal;
    g_self_lobe_tilted = g_self_below_hidden && dot(lobe_normal, g_self_normal) < 1.0 - SELF_LOBE_TILT_MIN;
}

// Solid angle of the intersection of two spherical caps of angular radii a and b whose centres
// lie d apart (Tovchigrechko and Vakser 2001, eq. 4; self_visibility.py cap_intersection_solid_angle).
float cap_intersection_solid_angle(float a, float b, float d) {
    if (d >= a + b) return 0.0;
    float cos_a = cos(a), cos_b = cos(b), cos_d = cos(d);
    if (d <= abs(a - b)) return 2.0 * PI * (1.0 - max(cos_a, cos_b));
    float sin_a = max(sin(a), 1e-12), sin_b = max(sin(b), 1e-12), sin_d = max(sin(d), 1e-12);
    float t_d = acos(clamp((cos_d - cos_a * cos_b) / (sin_a * sin_b), -1.0, 1.0));
    float t_a = acos(clamp((cos_b - cos_d * cos_a) / (sin_d * sin_a), -1.0, 1.0));
    float t_b = acos(clamp((cos_a - cos_d * cos_b) / (sin_d * sin_b), -1.0, 1.0));
    return max(2.0 * (PI - t_d - t_a * cos_a - t_b * cos_b), 0.0);
}

// Angular radius of the cap a lookup averaging `footprint` sr about a direction of elevation sine
// sin_e is taken as: its own cap and the soft edge's (a sine, 1 / cos e in angle) in quadrature
// (self_visibility.py footprint_radius).
float footprint_radius(float footprint, float sin_e) {
    float own = acos(clamp(1.0 - footprint / (2.0 * PI), -1.0, 1.0));
    float soft = HORIZON_SOFT_EDGE / max(sqrt(max(1.0 - sin_e * sin_e, 0.0)), HORIZON_MIN_COS);
    return min(sqrt(own * own + soft * soft), MAX_FOOTPRINT_RADIUS);
}

// The solid angle a split-sum lookup of roughness alpha averages, for its self-occlusion: a cap of
// radius k alpha (at most SPLIT_SUM_MAX_RADIUS) about the lookup direction, k fitted per
// distribution against the lobe's own share above a horizon (self_visibility.py split_sum_footprint).
float split_sum_footprint(int dist, float alpha) {
    float radius = (dist == DIST_GGX ? SPLIT_SUM_RADIUS_PER_ALPHA_GGX : SPLIT_SUM_RADIUS_PER_ALPHA_BECKMANN) * alpha;
    return 2.0 * PI * (1.0 - cos(min(radius, SPLIT_SUM_MAX_RADIUS)));
}

// The horizon's sine at azimuth phi: linear between the sectors' centres.
float horizon_at(float phi) {
    float x = mod(phi / (2.0 * PI) * float(g_self_sectors) - 0.5, float(g_self_sectors));
    int first = clamp(int(floor(x)) % g_self_sectors, 0, g_self_sectors - 1);  // never out of bounds
    return mix(g_self_horizon[first], g_self_horizon[(first + 1) % g_self_sectors], fract(x));
}

// The visible share of a lookup toward `dir` that averages `footprint` sr (0: one direction).
float self_visibility(vec3 dir, float footprint) {
    if (g_self_cone.w <= SELF_NO_OCCLUSION + 1e-3) return 1.0;
    vec3 d = normalize(dir);
    float sin_e = dot(d, g_self_normal);
    if (sin_e <= 0.0) return g_self_below_hidden ? 0.0 : 1.0;  // below the surface
    if (!(sin_e > 0.0)) return 1.0;  // a degenerate normal (NaN)
    float phi = atan(dot(d, g_self_bitangent), dot(d, g_self_tangent));
    float radius = footprint_radius(footprint, sin_e);
    float from_normal = acos(min(sin_e, 1.0));
    // the cap spans the azimuths phi -+ span (all once it holds the normal); its horizon is the
    // sectors' mean over them, weighed by the cap's width (3-point Gauss-Chebyshev, second kind)
    float span = radius >= from_normal ? PI : asin(clamp(sin(radius) / max(sin(from_normal), 1e-12), 0.0, 1.0));
    float h = 0.5 * horizon_at(phi) + 0.25 * (horizon_at(phi - AZIMUTH_TAP * span) + horizon_at(phi + AZIMUTH_TAP * span));
    // the lookup's cap against the directions above the horizon (a cap about the normal), over
    // its part above the surface
    float above = cap_intersection_solid_angle(acos(clamp(h, -1.0, 1.0)), radius, from_normal);
    float above_surface = cap_intersection_solid_angle(0.5 * PI, radius, from_normal);
    if (g_self_lobe_tilted && footprint > 0.0) {
        // over the part the tilted lobe covers instead: what lies below the surface but above
        // the lobe's horizon points into the object (the two hidden parts taken as nested). A
        // point lookup (the reference's) is hidden by where it points: its cap is only the
        // horizon's soft edge, which across the surface itself would hide half of what clears it.
        float from_lobe_normal = acos(clamp(dot(d, g_self_lobe_normal), -1.0, 1.0));
        float above_lobe = cap_intersection_solid_angle(0.5 * PI, radius, from_lobe_normal);
        return clamp(min(above, above_lobe) / max(above_lobe, 1e-12), 0.0, 1.0);
    }
    return clamp(above / max(above_surface, 1e-12), 0.0, 1.0);
}

vec3 self_occluded(vec3 dir, vec3 radiance, float footprint) {
    float visible = self_visibility(dir, footprint);
    return visible * radiance + (1.0 - visible) * g_self_radiance;
}
