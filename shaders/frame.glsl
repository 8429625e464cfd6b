// Shading frame from interpolated vertex attributes, robust to degenerate input.

// Any unit vector orthogonal to n (Duff et al. 2017, branchless ONB).
vec3 orthogonal_tangent(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    return vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
}

// Columns: tangent, bitangent, normal. A zero/NaN normal falls back to the geometric normal,
// a tangent parallel to the normal (or missing) to an arbitrary orthogonal one.
mat3 shading_frame(vec3 normal, vec4 tangent, vec3 geometric_normal) {
    vec3 n = normal;
    if (!(dot(n, n) > 1e-12)) n = geometric_normal;
    n = normalize(n);
    vec3 t = tangent.xyz - n * dot(n, tangent.xyz);
    if (!(dot(t, t) > 1e-10)) t = orthogonal_tangent(n);
    t = normalize(t);
    float handedness = tangent.w < 0.0 ? -1.0 : 1.0;
    vec3 b = cross(n, t) * handedness;
    return mat3(t, b, n);
}

// KHR_materials_anisotropy's direction: the frame turned by `angle` about its normal, tangent
// towards the bitangent (materials/gltf.py anisotropy_frame). u_tangent_rotation is the
// material's (PackedMaterial.tangent_rotation); 0 leaves the frame as it is.
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform float u_tangent_rotation;
#endif

mat3 rotate_tangent(mat3 tbn, float angle) {
    float c = cos(angle), s = sin(angle);
    return mat3(c * tbn[0] + s * tbn[1], -s * tbn[0] + c * tbn[1], tbn[2]);
}

// The viewer direction in the local frame. Surfaces are two-sided: a frame facing away from
// the viewer is flipped (normal and bitangent), and grazing views are kept just above the
// horizon so no lobe formula sees wo.z <= 0.
vec3 view_in_frame(inout mat3 tbn, vec3 view_world) {
    vec3 wo = transpose(tbn) * view_world;
    if (wo.z < 0.0) {
        tbn[2] = -tbn[2];
        tbn[1] = -tbn[1];
        wo = transpose(tbn) * view_world;
    }
    wo.z = max(wo.z, 1e-4);
    return normalize(wo);
}
