// Reflection-space IBR frames (numpy twin: materials/rsibr.py), shared by the bake
// (rsibr_bake.comp) and the lookup (rsibr.glsl).

// The mirror warp: the normal that reflects `view` into r (materials/rsibr.py warped_normal); at
// the singular r = -view any normal perpendicular to the view (its map weight is 0 there).
vec3 rsibr_warped_normal(vec3 r, vec3 view) {
    vec3 h = view + r;
    float len = length(h);
    return len > 1e-6 ? h / len : normalize(cross(abs(view.z) < 0.9 ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0), view));
}

// t0(n) = normalize(Z x n), X x n near the poles (materials/rsibr.py canonical_tangent).
vec3 rsibr_canonical_tangent(vec3 n) {
    vec3 t = cross(vec3(0.0, 0.0, 1.0), n);
    if (length(t) < 1e-3) t = cross(vec3(1.0, 0.0, 0.0), n);
    return normalize(t);
}

// The tangent carried from normal n to normal m by the smallest rotation (materials/rsibr.py
// transported_tangent): a map's slices are about its own warped normal.
vec3 rsibr_transported_tangent(vec3 t, vec3 n, vec3 m) {
    return normalize(t - dot(t, m) / max(1.0 + dot(n, m), 1e-6) * (n + m));
}

// Map view's tangent field: t0(view) carried to n (materials/rsibr.py map_tangent; smooth over
// the map's warped normals, where the global field turns fast around its poles).
vec3 rsibr_map_tangent(vec3 n, vec3 view) {
    return rsibr_transported_tangent(rsibr_canonical_tangent(view), view, n);
}

// Slice coordinate in [0, K) of tangent t about normal n in map view's field (tangent_angle).
float rsibr_slice_coordinate(vec3 t, vec3 n, vec3 view, int slices) {
    vec3 t0 = rsibr_map_tangent(n, view);
    return mod(atan(dot(t, cross(n, t0)), dot(t, t0)), PI) / PI * float(slices);
}

// Columns (t, b, n), t = map view's t0(n) turned by `angle` about n (materials/rsibr.py slice_frame).
mat3 rsibr_slice_frame(vec3 n, float angle, vec3 view) {
    vec3 t0 = rsibr_map_tangent(n, view);
    vec3 t = cos(angle) * t0 + sin(angle) * cross(n, t0);
    return mat3(t, cross(n, t), n);
}
