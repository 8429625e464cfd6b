// Specular self-occlusion (numpy twin: scenes/self_visibility.py cone_visibility and
// self_occluded_incident). The cube map holds what the object's surroundings send, not the
// object itself: a direction outside the shading point's visibility cone (bent normal,
// cos of the half angle; SELF_NO_OCCLUSION: no cone) sees the object instead, whose radiance
// is g_self_radiance there. Directions below the surface (transmission) pass. scene.frag sets
// these per pixel; their defaults leave every lookup as it is (the preview, RSIBR's bake).
const float SELF_NO_OCCLUSION = -2.0;
const float SELF_SOFT_EDGE = 0.1;
vec4 g_self_cone = vec4(0.0, 0.0, 1.0, SELF_NO_OCCLUSION);
vec3 g_self_normal = vec3(0.0, 0.0, 1.0);
vec3 g_self_radiance = vec3(0.0);

float self_visibility(vec3 dir) {
    if (g_self_cone.w <= SELF_NO_OCCLUSION + 1e-3) return 1.0;
    vec3 d = normalize(dir);
    if (dot(d, g_self_normal) <= 0.0) return 1.0;
    return smoothstep(g_self_cone.w - SELF_SOFT_EDGE, g_self_cone.w + SELF_SOFT_EDGE, dot(d, g_self_cone.xyz));
}

vec3 self_occluded(vec3 dir, vec3 radiance) {
    float visible = self_visibility(dir);
    return visible * radiance + (1.0 - visible) * g_self_radiance;
}
