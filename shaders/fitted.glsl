// lobe-N+norm+fit: reads fitted to the lobe (GLSL twin of materials/fitted_pattern.py
// integrate_fitted; the table: viewer/fitted_gpu.py). An isotropic microfacet reflection lobe seen
// at theta_o takes the table's reads, bilinear between the four nodes around (log alpha, theta_o)
// (table_reads), each a direction at tangent-plane offset (a, b) from the mirror direction (a in the
// plane of incidence towards the normal, b across it; the exponential map) read at the MIP level
// whose blur is its sigma (lod_for_sigma), weighted by its weight; times the lobe's albedo. With
// BLUR_STACK a read of sigma >= BLUR_STACK_SIGMA0 reads the cube's blur stack instead
// (materials/blur_stack.py: the chain's coarse levels are undersampled for their blur).

#if defined(BLUR_STACK)
#include "blur_stack.glsl"
#endif
uniform sampler3D u_fitted_patterns;  // x: slot (0 the lobe's shape), y: view node, z: distribution x alpha node

// fitted_pattern.has_fitted_pattern: isotropic microfacet reflections (the glTF specular and
// clearcoat lobes too: D G times factors of the view alone); transmission keeps the thesis pattern.
bool fitted_lobe(Lobe l) {
    bool reflection = l.type == LOBE_MICROFACET || l.type == LOBE_GLTF_SPECULAR || l.type == LOBE_GLTF_CLEARCOAT;
    return reflection && l.ax == l.ay;
}

vec4 fitted_node(int slot, int view, int alpha_node, int dist) {
    return texelFetch(u_fitted_patterns, ivec3(slot, view, dist * FITTED_ALPHAS + alpha_node), 0);
}

vec4 fitted_blend(int slot, ivec2 node, vec2 f, int dist) {
    vec4 low = mix(fitted_node(slot, node.y, node.x, dist), fitted_node(slot, node.y + 1, node.x, dist), f.y);
    vec4 high = mix(fitted_node(slot, node.y, node.x + 1, dist), fitted_node(slot, node.y + 1, node.x + 1, dist), f.y);
    return mix(low, high, f.x);
}

vec3 integrate_fitted(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    const float alphas[FITTED_ALPHAS] = FITTED_ALPHA_NODES;
    // (log alpha, theta_o) -> the node below and the fractions, clamped at the table's edges
    float alpha = clamp(l.ax, alphas[0], alphas[FITTED_ALPHAS - 1]);
    int i = 0;
    for (int k = 1; k < FITTED_ALPHAS - 1; ++k) {
        if (alpha >= alphas[k]) i = k;
    }
    float fa = clamp(log(alpha / alphas[i]) / log(alphas[i + 1] / alphas[i]), 0.0, 1.0);
    float theta = degrees(acos(clamp(wo.z, 0.0, 1.0)));
    float view = clamp(theta / FITTED_VIEW_STEP_DEG, 0.0, float(FITTED_VIEWS - 1));
    int j = min(int(view), FITTED_VIEWS - 2);
    ivec2 node = ivec2(i, j);
    vec2 f = vec2(fa, view - float(j));
    int dist = l.dist;
    vec3 shape = fitted_blend(0, node, f, dist).xyz;  // mean_a, spread_a, spread_b (radians)
    // the frame of fitted_pattern.mirror_frame turned to wo's azimuth
    vec3 r = vec3(-wo.xy, wo.z);
    float s = length(wo.xy);
    vec3 e_b = s > 1e-7 ? vec3(-wo.y, wo.x, 0.0) / s : vec3(0.0, 1.0, 0.0);
    vec3 e_a = cross(e_b, r);
    float narrow = min(shape.y, shape.z);
    float cube_texel2 = 4.0 / (u_face_size * u_face_size);
    vec3 sum = vec3(0.0);
    float weight_sum = 0.0;
    // fitted_pattern.read_count: N reads for Beckmann, N + 4 for GGX (the slots beyond are unused)
    int reads = min(u_samples + (dist == DIST_GGX ? 4 : 0), textureSize(u_fitted_patterns, 0).x - 1);
    for (int k = 1; k <= reads; ++k) {
        vec4 read = fitted_blend(k, node, f, dist);
        if (read.z <= 0.0) continue;
        float a = shape.x + read.x * shape.y;
        float b = read.y * shape.z;
        float rho = length(vec2(a, b));
        float sinc = rho > 1e-6 ? sin(rho) / rho : 1.0;
        vec3 d = cos(rho) * r + (a * e_a + b * e_b) * sinc;
        vec3 world = tbn * d;
        float sigma = read.w * narrow;
        // lod_for_sigma (cube.glsl): passed through incident()'s solid angle (cube_lod: 0.5 log2(area
        // / m^3 face^2 / 4), plus the method's LOD bias, taken back out: the sigma is the blur wanted).
        float lod = lod_for_sigma(world, sigma, u_face_size);
        vec3 m = abs(normalize(world));
        float texel2 = cube_texel2 * pow(max(max(m.x, m.y), m.z), 3.0);
        float area = exp2(2.0 * (lod - u_lod_bias)) * texel2;
#if defined(BLUR_STACK)
        // a read the MIP chain's coarse levels would make lumpy: the blur stack (blur_stack.glsl)
        vec3 stack_dir = normalize(world);
        float stack_sigma = sigma;
#if defined(PARALLAX)
        // the proxy's hit seen from the cube's centre, and the read's angle from there (lookup()'s
        // lod_offset: log2 of the distance ratio, one level per doubling of an angle)
        float lod_offset;
        stack_dir = proxy_direction(world, lod_offset);
        stack_sigma *= exp2(lod_offset);
#endif
        if (u_has_blur_stack != 0 && stack_sigma >= BLUR_STACK_SIGMA0) {
            sum += read.z * self_occluded(world, blur_stack_read(stack_dir, stack_sigma), area);
            weight_sum += read.z;
            continue;
        }
#endif
        sum += read.z * incident(world, area);
        weight_sum += read.z;
    }
    return weight_sum > 0.0 ? lobe_albedo(l, lobe_index, wo) * sum / weight_sum : vec3(0.0);
}
