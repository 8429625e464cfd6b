// Specular self-occlusion (numpy twin: scenes/self_visibility.py horizon_visibility and
// self_occluded_incident). The cube map holds what the object's surroundings send, not the
// object itself: a direction below the shading point's horizon at its azimuth (HORIZON_SECTORS
// sectors about the normal; SELF_NO_OCCLUSION in the cone's w: nothing hidden) sees the object
// instead, whose radiance is g_self_radiance there. Directions below the surface (transmission)
// pass. scene.frag sets these per pixel; their defaults leave every lookup as it is (the preview,
// RSIBR's bake).
const float SELF_NO_OCCLUSION = -2.0;
const float HORIZON_SOFT_EDGE = 0.08;
const int HORIZON_SECTORS = 8;
const vec3 HORIZON_AXIS = vec3(1.0, 2.0, 3.0) / sqrt(14.0);
vec4 g_self_cone = vec4(0.0, 0.0, 1.0, SELF_NO_OCCLUSION);
vec3 g_self_normal = vec3(0.0, 0.0, 1.0);
vec3 g_self_tangent = vec3(1.0, 0.0, 0.0);  // the horizon's frame about g_self_normal (set_self_normal)
vec3 g_self_bitangent = vec3(0.0, 1.0, 0.0);
vec3 g_self_radiance = vec3(0.0);
float g_self_horizon[HORIZON_SECTORS] = float[](0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);

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

float self_visibility(vec3 dir) {
    if (g_self_cone.w <= SELF_NO_OCCLUSION + 1e-3) return 1.0;
    vec3 d = normalize(dir);
    float sin_e = dot(d, g_self_normal);
    if (!(sin_e > 0.0)) return 1.0;  // below the surface, or a degenerate normal (NaN)
    float phi = atan(dot(d, g_self_bitangent), dot(d, g_self_tangent));
    float x = mod(phi / (2.0 * PI) * float(HORIZON_SECTORS) - 0.5, float(HORIZON_SECTORS));
    int first = clamp(int(floor(x)) % HORIZON_SECTORS, 0, HORIZON_SECTORS - 1);  // never out of bounds
    float h = mix(g_self_horizon[first], g_self_horizon[(first + 1) % HORIZON_SECTORS], fract(x));
    return smoothstep(h - HORIZON_SOFT_EDGE, h + HORIZON_SOFT_EDGE, sin_e);
}

vec3 self_occluded(vec3 dir, vec3 radiance) {
    float visible = self_visibility(dir);
    return visible * radiance + (1.0 - visible) * g_self_radiance;
}
