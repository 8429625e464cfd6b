// prefiltered-rsibr: reflection-space image-based rendering per pixel (Cabral, Olano and Nemec
// 1999, seed 004; numpy twin materials/rsibr.py rsibr_radiance). The maps of the three views of
// the icosahedron triangle holding this pixel's view direction are read at its mirror direction r
// (the mirror warp, section 3.3) and blended with spherical barycentric weights (3.4), each faded
// near its singular texel r = -v_j; anisotropic materials mix the two tangent-angle slices around
// the pixel's tangent.
#include "rsibr_common.glsl"

uniform sampler2D u_rsibr_maps;    // tile (view j, slice k) = j K + k, rows tile H .. tile H + H - 1
uniform int u_rsibr_lobes;         // bit i: lobe i is in the maps (0: no maps)
uniform int u_rsibr_rows;          // H
uniform int u_rsibr_slices;        // K
uniform int u_rsibr_tiles;
uniform int u_rsibr_face_count;
uniform vec3 u_rsibr_views[RSIBR_MAX_VIEWS];
uniform ivec3 u_rsibr_faces[RSIBR_MAX_FACES];
uniform vec3 u_rsibr_edges[3 * RSIBR_MAX_FACES];  // unit normals of each face's edge planes

bool rsibr_lobe(int i) { return (u_rsibr_lobes & (1 << i)) != 0; }

// Spherical excess (Van Oosterom and Strackee 1983; materials/rsibr.py triangle_area).
float rsibr_area(vec3 a, vec3 b, vec3 c) {
    return 2.0 * atan(abs(dot(a, cross(b, c))), 1.0 + dot(a, b) + dot(b, c) + dot(c, a));
}

vec3 rsibr_tile(int tile, vec3 r) {
    vec2 uv = direction_to_latlong(r);
    float rows = float(u_rsibr_rows);
    float y = (float(tile) * rows + clamp(uv.y * rows, 0.5, rows - 0.5)) / (rows * float(u_rsibr_tiles));
    return textureLod(u_rsibr_maps, vec2(uv.x, y), 0.0).rgb;
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
    int k0 = 0, k1 = 0;
    float f = 0.0;
    if (slices > 1) {
        vec3 t0 = rsibr_canonical_tangent(n);
        float angle = mod(atan(dot(tbn[0], cross(n, t0)), dot(tbn[0], t0)), PI);
        float s = angle / PI * float(slices);
        k0 = int(floor(s)) % slices;
        k1 = (k0 + 1) % slices;
        f = s - floor(s);
    }
#if defined(PARALLAX)
    // The object's reflection proxy moves the direction the maps are read in, as for the other
    // prefiltered lookups (the maps themselves assume a distant environment).
    float unused_offset;
    r = proxy_direction(r, unused_offset);
#endif
    vec3 sum = vec3(0.0);
    for (int i = 0; i < 3; ++i) {
        int base = views[i] * slices;
        vec3 value = rsibr_tile(base + k0, r);
        if (slices > 1) value = mix(value, rsibr_tile(base + k1, r), f);
        sum += w[i] * value;
    }
    return sum;
}
