// Incident radiance towards a shading point: the twin of scenes/reflection_proxy.py (PARALLAX,
// thesis 4.4.1: the secondary ray meets the proxy and the cube map is read toward the hit) and of
// scenes/planar_mirror.py (MIRROR, thesis 4.5: two-step tangent-plane projection into the mirror
// and see-through buffers, averaged tangent planes of Fig. 4.46b). incident() is what every
// estimator in integrate.glsl reads; lookup() the unfiltered cube-map read of the reference.

#if defined(PARALLAX) || defined(MIRROR)
vec3 g_shading_position;                        // world position, set by the fragment shader
#endif

#if defined(PARALLAX)
// Reflected-geometry correction (thesis 4.4.1; scenes/reflection_proxy.py): the secondary ray
// from the shading point is intersected with the object's proxy (bounding planes or a box seen
// from inside) and the cube map is read toward the hit point as seen from its centre.
#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform vec3 u_cube_centre;
uniform int u_proxy_kind;                       // PROXY_PLANES or PROXY_BOX
uniform int u_proxy_plane_count;
uniform vec4 u_proxy_planes[MAX_PROXY_PLANES];  // unit normal n, d: n.x + d = 0
uniform vec3 u_proxy_box_min;
uniform vec3 u_proxy_box_max;
#endif

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

vec3 lookup(vec3 dir_world, float lod, float footprint) {
    float lod_offset;
    vec3 d = proxy_direction(dir_world, lod_offset);
#if !defined(METHOD_MC)
    lod += lod_offset;  // filtered methods only; mc-N and the reference read level 0
#endif
    return self_occluded(dir_world, RADIANCE_LOD(d, max(lod, 0.0)).rgb, footprint);
}
#else
vec3 lookup(vec3 dir_world, float lod, float footprint) {
    return self_occluded(dir_world, RADIANCE_LOD(dir_world, max(lod, 0.0)).rgb, footprint);
}
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
// Where the cube's bright sources are lights, a filtered read covers at least the pixel's
// reflected footprint (cap_lights.glsl set_light_footprint): the residual holds, signed, what a
// source has beyond its cap (scenes/bright_sources.py), and the caps are integrated against the
// lobe widened by the same footprint; a read narrower than the caps' sees that signed detail at a
// point while the cap is spread over the footprint. |dr_x|^2 + |dr_y|^2 = 2 d^2 for a square
// footprint d wide.
float residual_read_solid_angle(float solid_angle) {
    if (solid_angle > 0.0 && u_signed_residual == 1 && u_point_sampled_lights == 0)
        return max(solid_angle, 0.5 * g_footprint_dr2);
    return solid_angle;
}

vec3 incident(vec3 dir, float solid_angle) {
    solid_angle = residual_read_solid_angle(solid_angle);
#if defined(MIRROR)
    return mirror_incident(normalize(dir), solid_angle);
#else
    return lookup(dir, solid_angle > 0.0 ? cube_lod(dir, solid_angle, u_face_size) + u_lod_bias : 0.0, solid_angle);
#endif
}
