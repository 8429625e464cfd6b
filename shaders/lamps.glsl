// KHR_lights_punctual lamps reflected by the lobes (numpy twin: scenes/lamps.py lamp_cap, and
// materials/cap_lights.py integrate_cap_light per cap): a point or spot lamp is a sphere of
// radius u_lamp_shape.z whose radiance gives the extension's intensity (L = I / (pi r^2)), a
// directional one a disc of the sun's size; each is a cap of directions from the shading point,
// integrated like the bright sources (cap_lights.glsl cap_integral). The cube maps and mirror
// buffers never hold them (no double counting), so every method adds them, the reference
// included. Their diffuse light is the lightmap's where there is one, else lamps_irradiance's.
// Shadows per object: u_lamp_visibility.
#define MAX_LAMPS 16
uniform int u_lamp_count;
uniform vec4 u_lamp_position[MAX_LAMPS];  // xyz: position (point, spot) or towards the lamp (directional), w: LAMP_* kind
uniform vec4 u_lamp_colour[MAX_LAMPS];    // rgb: colour x intensity, w: range (0: none)
uniform vec4 u_lamp_spot[MAX_LAMPS];      // xyz: the direction the lamp shines along, w: cos(outer cone)
uniform vec4 u_lamp_shape[MAX_LAMPS];     // x: 1 / max(1e-3, cos inner - cos outer), y: sin(angular radius) of a
                                          // directional lamp, z: sphere radius, w: unused
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform float u_lamp_visibility[MAX_LAMPS];  // fraction of the object from which each lamp is seen
#endif
#define LAMP_POINT 0
#define LAMP_SPOT 1
#define LAMP_DIRECTIONAL 2

// The lamps' irradiance at world position x on a surface of normal n (scenes/baker.py
// lamp_irradiance: E = I cos / d^2 with the range window and spot cone; E cos for a directional
// lamp), times the object's visibility: the diffuse lamp light of objects without a lightmap.
vec3 lamps_irradiance(vec3 x, vec3 n) {
    vec3 sum = vec3(0.0);
    for (int k = 0; k < u_lamp_count; ++k) {
        float visibility = u_lamp_visibility[k];
        if (visibility <= 0.0) continue;
        vec3 e = u_lamp_colour[k].rgb * visibility;
        if (int(u_lamp_position[k].w + 0.5) == LAMP_DIRECTIONAL) {
            sum += e * max(dot(n, u_lamp_position[k].xyz), 0.0);
            continue;
        }
        vec3 to_lamp = u_lamp_position[k].xyz - x;
        float d2 = max(dot(to_lamp, to_lamp), 1e-30);
        float d = sqrt(d2);
        float range = u_lamp_colour[k].w;
        if (range > 0.0) e *= clamp(1.0 - pow(d / range, 4.0), 0.0, 1.0);
        if (int(u_lamp_position[k].w + 0.5) == LAMP_SPOT) {
            float t = clamp((dot(-to_lamp / d, u_lamp_spot[k].xyz) - u_lamp_spot[k].w) * u_lamp_shape[k].x, 0.0, 1.0);
            e *= t * t;
        }
        sum += e * (max(dot(n, to_lamp) / d, 0.0) / d2);
    }
    return sum;
}

#if defined(SPECULAR)
// The lamps' light reflected by lobe l toward wo at world position x (shading frame tbn).
vec3 lamps_radiance(Lobe l, vec3 wo, mat3 tbn, vec3 x) {
    vec3 sum = vec3(0.0);
    if (wo.z <= 0.0) return sum;
    for (int k = 0; k < u_lamp_count; ++k) {
        float visibility = u_lamp_visibility[k];
        if (visibility <= 0.0) continue;
        int kind = int(u_lamp_position[k].w + 0.5);
        vec3 axis;
        float sin_r;
        vec3 radiance = u_lamp_colour[k].rgb * visibility;
        if (kind == LAMP_DIRECTIONAL) {
            axis = u_lamp_position[k].xyz;
            sin_r = u_lamp_shape[k].y;
            radiance /= PI * sin_r * sin_r;  // irradiance E at normal incidence: L = E / (pi sin^2)
        } else {
            vec3 to_lamp = u_lamp_position[k].xyz - x;
            float d = length(to_lamp);
            float r = u_lamp_shape[k].z;
            if (d <= r) continue;  // inside the bulb
            axis = to_lamp / d;
            sin_r = r / d;
            float range = u_lamp_colour[k].w;
            if (range > 0.0) radiance *= clamp(1.0 - pow(d / range, 4.0), 0.0, 1.0);
            if (kind == LAMP_SPOT) {
                float t = clamp((dot(-axis, u_lamp_spot[k].xyz) - u_lamp_spot[k].w) * u_lamp_shape[k].x, 0.0, 1.0);
                radiance *= t * t;
            }
            radiance /= PI * r * r;  // intensity I of a sphere of radius r: L = I / (pi r^2)
        }
        if (!any(greaterThan(radiance, vec3(0.0)))) continue;
        float sin2 = sin_r * sin_r;
        float cos_r = sqrt(max(1.0 - sin2, 0.0));
        // 1 - cos computed as sin^2 / (1 + cos): no cancellation for a distant lamp's tiny cap.
        radiance *= self_visibility(axis, 0.0);  // the object's own surface hiding the lamp (self_occlusion.glsl)
        sum += cap_integral(l, wo, tbn, axis, cos_r, sin2 / (1.0 + cos_r), 1.0) * radiance;  // a uniform cap
    }
    return sum;
}
#endif
