// prefiltered-rsibr: reflection-space image-based rendering per pixel (Cabral, Olano and Nemec
// 1999, seed 004; numpy twin materials/rsibr.py rsibr_radiance). The maps of the three views of
// the icosahedron triangle holding this pixel's view direction are read at its mirror direction r
// (the mirror warp, section 3.3) and blended with spherical barycentric weights (3.4), each faded
// near its singular texel r = -v_j and scaled by the albedo ratio of the pixel's and the map's
// elevation; anisotropic materials mix the two tangent-angle slices around the pixel's tangent;
// the object's own surface hides what lies below its horizons (self_occlusion.glsl).
#include "rsibr_common.glsl"

uniform sampler2DArray u_rsibr_maps;  // layer (view j, slice k) = j K + k: 2H x H, equirectangular in r
uniform int u_rsibr_lobes;         // bit i: lobe i is in the maps (0: no maps)
uniform int u_rsibr_slices;        // K
uniform int u_rsibr_face_count;
uniform vec3 u_rsibr_views[RSIBR_MAX_VIEWS];
uniform ivec3 u_rsibr_faces[RSIBR_MAX_FACES];
// The baked lobes' directional albedo at n.v = (i / (size - 1))^2 (materials/rsibr.py albedo_table).
uniform vec3 u_rsibr_albedo[RSIBR_ALBEDO_SIZE];
uniform vec3 u_rsibr_edges[3 * RSIBR_MAX_FACES];  // unit normals of each face's edge planes

bool rsibr_lobe(int i) { return (u_rsibr_lobes & (1 << i)) != 0; }

// Spherical excess (Van Oosterom and Strackee 1983; materials/rsibr.py triangle_area).
float rsibr_area(vec3 a, vec3 b, vec3 c) {
    return 2.0 * atan(abs(dot(a, cross(b, c))), 1.0 + dot(a, b) + dot(b, c) + dot(c, a));
}

vec3 rsibr_tile(int tile, vec3 r) {
    return textureLod(u_rsibr_maps, vec3(direction_to_latlong(r), float(tile)), 0.0).rgb;
}

vec3 rsibr_albedo(float cos_view) {
    float x = sqrt(clamp(cos_view, 0.0, 1.0)) * float(RSIBR_ALBEDO_SIZE - 1);
    int i0 = min(int(floor(x)), RSIBR_ALBEDO_SIZE - 2);
    return mix(u_rsibr_albedo[i0], u_rsibr_albedo[i0 + 1], x - float(i0));
}

// Elevation correction E(n.v) / E(n_j.v_j) (materials/rsibr.py albedo_ratio).
vec3 rsibr_albedo_ratio(vec3 pixel, float cos_map) {
    vec3 source = rsibr_albedo(cos_map);
    vec3 ratio = pixel / max(source, vec3(1e-6));
    return min(mix(vec3(0.0), ratio, greaterThan(source, vec3(1e-6))), vec3(RSIBR_MAX_ALBEDO_RATIO));
}

float rsibr_confidence(vec3 r, vec3 view) {
    return smoothstep(0.0, RSIBR_FADE, 0.5 * length(view + r));
}

vec3 rsibr_radiance(vec3 wo, mat3 tbn) {
    vec3 v = normalize(tbn * wo);
    vec3 n = tbn[2];
    vec3 r = 2.0 * dot(v, n) * n - v;
    int face = 0;
    float best = -2.0;
    for (int f = 0; f < u_rsibr_face_count; ++f) {
        float d = min(min(dot(v, u_rsibr_edges[3 * f]), dot(v, u_rsibr_edges[3 * f + 1])), dot(v, u_rsibr_edges[3 * f + 2]));
        if (d > best) {
            best = d;
            face = f;
        }
    }
    ivec3 views = u_rsibr_faces[face];
    vec3 a = u_rsibr_views[views.x], b = u_rsibr_views[views.y], c = u_rsibr_views[views.z];
    vec3 bary = vec3(rsibr_area(v, b, c), rsibr_area(a, v, c), rsibr_area(a, b, v));
    bary /= bary.x + bary.y + bary.z;
    vec3 w = bary * vec3(rsibr_confidence(r, a), rsibr_confidence(r, b), rsibr_confidence(r, c));
    float total = w.x + w.y + w.z;
    w = total > 1e-6 ? w / total : bary;
    int slices = u_rsibr_slices;
    vec3 r_lookup = r;
#if defined(PARALLAX)
    // The object's reflection proxy moves the direction the maps are read in, as for the other
    // prefiltered lookups (the maps themselves assume a distant environment).
    float unused_offset;
    r_lookup = proxy_direction(r, unused_offset);
#endif
    vec3 pixel_albedo = rsibr_albedo(dot(v, n));
    vec3 sum = vec3(0.0);
    for (int i = 0; i < 3; ++i) {
        int base = views[i] * slices;
        vec3 value;
        if (slices > 1) {
            // Map i's slices are about its own warped normal, in its own tangent field: the
            // pixel's tangent is carried there.
            vec3 source = u_rsibr_views[views[i]];
            vec3 map_normal = rsibr_warped_normal(r, source);
            vec3 carried = rsibr_transported_tangent(tbn[0], n, map_normal);
            float s = rsibr_slice_coordinate(carried, map_normal, source, slices);
            int k0 = int(floor(s)) % slices;
            value = mix(rsibr_tile(base + k0, r_lookup), rsibr_tile(base + (k0 + 1) % slices, r_lookup), s - floor(s));
        } else {
            value = rsibr_tile(base, r_lookup);
        }
        sum += w[i] * value * rsibr_albedo_ratio(pixel_albedo, 0.5 * length(u_rsibr_views[views[i]] + r));
    }
    // The object's own surface hides part of the baked lobes from this point (self_occlusion.glsl;
    // the maps hold the surroundings only): each baked lobe's visible share through its split-sum
    // footprint at the mirror direction from the point, the mean over the baked lobes, and the
    // hidden part sees the object (g_self_radiance) through the baked lobes' albedo at n.v, as the
    // split-sum lookups do (prefiltered.glsl). Without a cone (the preview, a convex object) it is 1.
    float visible = 0.0;
    int baked = 0;
    g_self_below_hidden = true;  // reflection lobes only (materials/rsibr.py)
    for (int i = 0; i < u_lobe_count; ++i) {
        if (!rsibr_lobe(i)) continue;
        Lobe l = get_lobe(i);
        visible += self_visibility(r, split_sum_footprint(l.dist, sqrt(l.ax * l.ay)));
        baked += 1;
    }
    visible = baked > 0 ? visible / float(baked) : 1.0;
    return visible * sum + (1.0 - visible) * g_self_radiance * pixel_albedo;
}
