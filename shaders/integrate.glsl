// Integration of incident light over the lobes of a material (thesis 4.4), for one shading
// point: the methods of docs/methods.md chosen by #define.
//   METHOD_LOBE  lobe-N: deterministic pattern, MIP level per sample, Eq. 4.25 (Eq. 4.24 with
//                LOBE_EQ424)
//   METHOD_FIS   fis-N: the same N quasi-random importance samples at every pixel, each
//                filtered with Colbert & Krivanek's lod = 0.5 log2(omega_s / omega_p) + bias
//   METHOD_MC    mc-N / reference: importance samples from a Sobol sequence with a per-pixel
//                Cranley-Patterson rotation, no filtering (unbiased; accumulated over passes).
//                With ENV_SAMPLING (the reference method) every BSDF sample is paired with a
//                sample of the environment's importance map, combined by multiple importance
//                sampling with the power heuristic (Veach 1997), so suns converge, and, where
//                the cube's bright sources were separated (cap_lights.glsl's uniforms), with a
//                point on one of their caps as a third strategy (env_sampling.glsl).
#include "bsdf.glsl"
#include "patterns.glsl"
#include "self_occlusion.glsl"
#include "cap_lights.glsl"

#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform samplerCube u_radiance;     // incident radiance, full MIP chain (RADIANCE_LOD reads it)
uniform float u_face_size;          // size of MIP level 0 of u_radiance
#define RADIANCE_LOD(dir, lod) textureLod(u_radiance, dir, lod)
#endif
uniform samplerCube u_irradiance;   // irradiance E(n) for the diffuse term (lobe-N, fis-N)
uniform sampler2D u_sobol;          // 4D Sobol points (RGBA), row-major, u_sobol_count of them
uniform int u_sobol_count;
uniform int u_sample_offset;        // first Sobol index of this pass (progressive refinement)
uniform int u_samples;              // N
uniform float u_lod_bias;
#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform vec2 u_pattern[MAX_LOBES * MAX_PATTERN];  // per-lobe ring pattern (xi1, xi2): lobe_pattern_xi
#endif
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform vec3 u_kd;                  // Lambert kd, or (1 - metallic) baseColor for glTF
#endif
uniform uint u_seed;

uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Deterministic per-pixel, per-lobe rotation in [0, 1)^2 (documented scrambling).
vec2 pixel_rotation(uvec2 pixel, int lobe) {
    uint h1 = pcg_hash(pixel.x + pcg_hash(pixel.y + pcg_hash(uint(lobe) + 17u * u_seed)));
    uint h2 = pcg_hash(h1 ^ 0x9e3779b9u);
    return vec2(float(h1 >> 8u), float(h2 >> 8u)) / 16777216.0;
}

vec4 sobol_point4(int index) {
    int i = index % u_sobol_count;
    ivec2 size = textureSize(u_sobol, 0);
    return texelFetch(u_sobol, ivec2(i % size.x, i / size.x), 0);
}

vec2 sobol_point(int index) { return sobol_point4(index).xy; }

#include "env_sampling.glsl"

#include "incident.glsl"
#include "volume.glsl"

vec3 diffuse_eval(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    return (u_kd * diffuse_weight(abs(dot(wo, normalize(wi + wo))), wo.z) + sheen_term(wo.z)) / PI;
}

#if defined(METHOD_LOBE)

// Pattern coordinates (xi1, xi2) of sample i of n (materials/patterns.py choose_pattern and
// pattern_xi), chosen per pixel: a line along the longer axis when this pixel's lobe is
// anisotropic by ANISOTROPY_LINE_RATIO or more (roughness and anisotropy textures change the
// ratio from pixel to pixel), else the ring or multi-ring of u_pattern (material_gpu.py).
vec2 lobe_pattern_xi(Lobe l, int lobe_index, int i, int n) {
    if (uses_line_pattern(l)) {
        float s = (2.0 * float(i) + 1.0) / float(n) - 1.0;
        bool along_y = l.ay > l.ax;
        float xi2 = s < 0.0 ? (along_y ? 0.25 : 0.0) : (along_y ? 0.75 : 0.5);
        return vec2(1.0 - abs(s), xi2);
    }
    return u_pattern[lobe_index * MAX_PATTERN + i];
}

#if defined(HAS_RATIONAL)
// lobe-N of a lobe sampled through its own inverse CDFs (materials/patterns.py step 6,
// integrate_sampled_lobe): u_pattern holds the golden-ratio lattice (lattice_xi), mapped by the
// Rational sampler so that samples are distributed by its density p; each is filtered over its
// solid angle 1 / (N p) and weighted by f cos / p (importance quadrature; self-normalised and
// scaled to the albedo with LOBE_NORMALIZE).
vec3 sampled_estimate(Lobe l, int lobe_index, vec3 wo, mat3 tbn, bool tangent) {
    int n = u_samples;
    vec3 sum = vec3(0.0);
    vec3 weight_sum = vec3(0.0);
    for (int i = 0; i < n; ++i) {
        float p;
        vec3 wi = rational_sample(u_pattern[lobe_index * MAX_PATTERN + i], wo, tangent, p);
        if (p <= 0.0 || wi.z <= 0.0) continue;
        vec3 weight = lobe_eval(l, wi, wo) * (wi.z / p);
        sum += incident(tbn * wi, 1.0 / (float(n) * p)) * weight;
        weight_sum += weight;
    }
#if defined(LOBE_NORMALIZE)
    vec3 target = lobe_albedo(l, lobe_index, wo);
    return vec3(weight_sum.r > 0.0 ? sum.r * target.r / weight_sum.r : 0.0,
                weight_sum.g > 0.0 ? sum.g * target.g / weight_sum.g : 0.0,
                weight_sum.b > 0.0 ? sum.b * target.b / weight_sum.b : 0.0);
#else
    return sum / float(n);
#endif
}

// Near the normal the lattice is anchored in the tangent frame (a lattice turning with the view
// azimuth drew a pinwheel there), from TANGENT_ANCHOR_HIGH_DEG on to the view; blended between
// (materials/rational_brdf.py RationalLobe.tangent_anchor_weight).
vec3 integrate_sampled_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    float theta_v = degrees(acos(clamp(wo.z, 0.0, 1.0)));
    float tangent = clamp((TANGENT_ANCHOR_HIGH_DEG - theta_v) / (TANGENT_ANCHOR_HIGH_DEG - TANGENT_ANCHOR_LOW_DEG), 0.0, 1.0);
    vec3 out_value = vec3(0.0);
    if (tangent > 0.0) out_value += tangent * sampled_estimate(l, lobe_index, wo, tbn, true);
    if (tangent < 1.0) out_value += (1.0 - tangent) * sampled_estimate(l, lobe_index, wo, tbn, false);
    return out_value;
}
#endif

#if defined(LOBE_FITTED) && defined(LOBE_NORMALIZE)
#include "fitted.glsl"
#endif

vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
#if defined(HAS_RATIONAL)
    if (l.type == LOBE_RATIONAL) return integrate_sampled_lobe(l, lobe_index, wo, tbn);
#endif
#if defined(LOBE_FITTED) && defined(LOBE_NORMALIZE)
    if (fitted_lobe(l)) return integrate_fitted(l, lobe_index, wo, tbn);
#endif
    int n = u_samples;
    float area = lobe_sample_area(l, wo, n);
    vec3 num = vec3(0.0);
    vec3 den = vec3(0.0);
    vec3 num_unit = vec3(0.0);  // Eq. 4.25's numerator for L = 1 (normalisation)
    for (int i = 0; i < n; ++i) {
        vec3 h = pattern_half_vector(l, lobe_pattern_xi(l, lobe_index, i, n));
        vec3 wr = 2.0 * dot(wo, h) * h - wo;   // Eq. 4.8
        if (wr.z <= 0.0) continue;              // below the horizon: discarded
        vec3 wi = reflected_wi(l, wr);
        vec3 world = tbn * wi;
        vec3 f = lobe_eval(l, wi, wo);
        float p = lobe_half_pdf(l, wi, wo);
        if (p <= 0.0) continue;
        float c = abs(wi.z);
        vec3 li = incident(world, area);
        vec3 fc = f * c;
#if defined(LOBE_EQ424)
        // Eq. 4.24 (the derived quadrature, thesis Fig. 4.24): sum L c^2 f / sum p c.
        num += li * fc * c;
        den += vec3(p * c);
#else
        // Eq. 4.25: sum L c^2 f^2 / p / sum f c, written as (f c / p) (f c) to stay in range.
        num += li * (fc / p) * fc;
        num_unit += (fc / p) * fc;
        den += fc;
#endif
    }
#if defined(LOBE_NORMALIZE)
    // lobeview's energy normalisation: Eq. 4.25 rescaled to be exact under uniform light.
    vec3 target = lobe_albedo(l, lobe_index, wo);
    vec3 core = vec3(num_unit.r > 0.0 ? num.r / num_unit.r : 0.0, num_unit.g > 0.0 ? num.g / num_unit.g : 0.0,
                     num_unit.b > 0.0 ? num.b / num_unit.b : 0.0);
    if (l.dist != DIST_GGX) return core * target;
    // GGX's tail beyond the pattern's core (patterns.py step 7, ggx_tail_terms and
    // ggx_tail_integral): per quarter of the tail, its share of the albedo by quadrature over
    // GGX_TAIL_RADIAL bands x GGX_TAIL_AZIMUTHAL microfacet normals (slopes stretched by the lobe's
    // own alphas, its D the density that placed them; each its band's share of the
    // projected mass, ggx_tail_quadrature, times f cos / p; zero at and below the horizon),
    // and one lookup at the f cos-weighted mean direction of its points above the horizon over
    // their share of its reflected annulus (not clamped at 80 deg: ggx_tail_solid_angle); the
    // core's radiance over the rest of the albedo. Exact under uniform light, continuous in wo.
    float a = sqrt(l.ax * l.ay);
    float inner = 2.0 * atan(sqrt(-log(XI_BORDER)) * a);
    float outer = 2.0 * atan(GGX_TAIL_OUTER_TAN * a);
    float tail_area = 2.0 * PI * (cos(inner) - cos(outer)) / float(GGX_TAIL_SAMPLES) * wide_lobe_footprint_scale(l);
    vec3 quarter_share[GGX_TAIL_SAMPLES];
    vec3 direction_sum[GGX_TAIL_SAMPLES];
    float visible_mass[GGX_TAIL_SAMPLES];
    for (int k = 0; k < GGX_TAIL_SAMPLES; ++k) {
        quarter_share[k] = vec3(0.0);
        direction_sum[k] = vec3(0.0);
        visible_mass[k] = 0.0;
    }
    for (int r = 0; r < GGX_TAIL_RADIAL; ++r) {
        // band r of ggx_tail_quadrature: the mass beyond its edges is GGX_TAIL_FRACTION (1 - s)^2
        float s_in = 1.0 - float(r) / float(GGX_TAIL_RADIAL);
        float s_out = 1.0 - float(r + 1) / float(GGX_TAIL_RADIAL);
        float beyond_in = GGX_TAIL_FRACTION * s_in * s_in;
        float beyond_out = GGX_TAIL_FRACTION * s_out * s_out;
        float q = 1.0 - 0.5 * (beyond_in + beyond_out);
        float rho = sqrt(q / (1.0 - q));  // the slope's radius in the lobe's stretched space
        float mass = (beyond_in - beyond_out) / float(GGX_TAIL_SAMPLES * GGX_TAIL_AZIMUTHAL);
        for (int k = 0; k < GGX_TAIL_SAMPLES; ++k) {
            for (int j = 0; j < GGX_TAIL_AZIMUTHAL; ++j) {
                float phi = 2.0 * PI * (float(k) + (float(j) + 0.5) / float(GGX_TAIL_AZIMUTHAL)) / float(GGX_TAIL_SAMPLES);
                vec3 slope = vec3(l.ax * rho * cos(phi), l.ay * rho * sin(phi), 1.0);
                float cos_theta = inversesqrt(dot(slope, slope));
                vec3 h = slope * cos_theta;
                float cos2 = cos_theta * cos_theta;
                float d_placed = 1.0 / (PI * l.ax * l.ay * cos2 * cos2 * (1.0 + rho * rho) * (1.0 + rho * rho));
                float wo_h = dot(wo, h);
                vec3 wr = 2.0 * wo_h * h - wo;
                if (wr.z <= 0.0) continue;
                vec3 wi = reflected_wi(l, wr);
                float p = d_placed * cos_theta / (4.0 * max(wo_h, 1e-12));
                vec3 share = mass * lobe_eval(l, wi, wo) * (abs(wi.z) / p);
                visible_mass[k] += mass;
                quarter_share[k] += share;
                direction_sum[k] += (share.r + share.g + share.b) * wi;
            }
        }
    }
    vec3 tail_sum = vec3(0.0);
    vec3 carried = vec3(0.0);
    float quarter_mass = GGX_TAIL_FRACTION / float(GGX_TAIL_SAMPLES);
    for (int k = 0; k < GGX_TAIL_SAMPLES; ++k) {
        if (quarter_share[k].r + quarter_share[k].g + quarter_share[k].b <= 0.0) continue;
        vec3 direction = normalize(direction_sum[k]);
        tail_sum += quarter_share[k] * incident(tbn * direction, tail_area * visible_mass[k] / quarter_mass);
        carried += quarter_share[k];
    }
    vec3 value = max(target - carried, vec3(0.0)) * core + tail_sum;
    return vec3(carried.r > target.r ? value.r * target.r / carried.r : value.r,
                carried.g > target.g ? value.g * target.g / carried.g : value.g,
                carried.b > target.b ? value.b * target.b / carried.b : value.b);
#else
    return vec3(den.r > 0.0 ? num.r / den.r : 0.0, den.g > 0.0 ? num.g / den.g : 0.0,
                den.b > 0.0 ? num.b / den.b : 0.0);
#endif
}
#elif defined(METHOD_PREFILTERED)
#include "prefiltered.glsl"
#elif defined(ENV_SAMPLING)
// A sample that a world-space strategy (the environment's importance map, a bright source's cap)
// drew with density p_own: f cos L / p_own, weighted by the power heuristic against the BSDF
// sampler and the other world-space strategy's density p_other.
vec3 world_sample_term(Lobe l, vec3 world, vec3 wo, mat3 tbn, float p_own, float p_other) {
    vec3 wi = transpose(tbn) * world;
    vec3 f = lobe_eval(l, wi, wo);
    if (!any(greaterThan(f, vec3(0.0)))) return vec3(0.0);
    float w = power_heuristic3(p_own, lobe_sample_pdf(l, wi, wo), p_other);
    return lookup(world, 0.0, 0.0) * f * (abs(wi.z) * w / max(p_own, 1e-30));
}

vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    vec3 sum = vec3(0.0);
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index);
    vec2 rotation_env = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index + 2 * MAX_LOBES);
    vec2 rotation_light = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index + 4 * MAX_LOBES);
    choose_cap_lights(l, wo, tbn);
    for (int i = 0; i < u_samples; ++i) {
        vec4 q = sobol_point4(u_sample_offset + i);
        // BSDF sample, MIS-weighted against the environment and light samplers.
        float p_bsdf;
        vec3 wi = lobe_sample_and_pdf(l, fract(q.xy + rotation), wo, p_bsdf);
        if (p_bsdf > 0.0) {
            vec3 world = tbn * wi;
            float w = power_heuristic3(p_bsdf, env_pdf(world), cap_light_pdf(world));
            sum += lookup(world, 0.0, 0.0) * lobe_eval(l, wi, wo) * (abs(wi.z) * w / p_bsdf);
        }
        // Environment sample, MIS-weighted against the BSDF and light samplers.
        vec3 world_e = env_sample(fract(q.zw + rotation_env));
        sum += world_sample_term(l, world_e, wo, tbn, env_pdf(world_e), cap_light_pdf(world_e));
        // Bright-source sample (a point on a separated light's cap), MIS-weighted against both.
        if (u_cap_light_count > 0) {
            vec3 world_l = cap_light_sample(fract(q.xy + rotation_light));
            sum += world_sample_term(l, world_l, wo, tbn, cap_light_pdf(world_l), env_pdf(world_l));
        }
    }
    return sum / float(u_samples);
}
#else
vec3 integrate_lobe(Lobe l, int lobe_index, vec3 wo, mat3 tbn) {
    vec3 sum = vec3(0.0);
    int n = u_samples;
#if defined(METHOD_MC)
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), lobe_index);
#endif
    for (int i = 0; i < n; ++i) {
#if defined(METHOD_MC)
        vec2 u = fract(sobol_point(u_sample_offset + i) + rotation);
#else
        vec2 u = sobol_point(i);
#endif
        float p;
        vec3 wi = lobe_sample_and_pdf(l, u, wo, p);
        if (p <= 0.0) continue;
        vec3 world = tbn * wi;
#if defined(METHOD_FIS)
        // omega_s = 1 / (N p); texel solid angle omega_p = 4 max|w|^3 / face^2 (cube_lod).
        float solid_angle = 1.0 / (float(n) * p);
#else
        float solid_angle = 0.0;
#endif
        sum += incident(world, solid_angle) * lobe_eval(l, wi, wo) * (abs(wi.z) / p);
    }
    return sum / float(n);
}
#endif

vec3 integrate_diffuse(vec3 wo, mat3 tbn) {
#if defined(METHOD_MC)
    vec3 sum = vec3(0.0);
    vec2 rotation = pixel_rotation(uvec2(gl_FragCoord.xy), MAX_LOBES);
#if defined(ENV_SAMPLING)
    vec2 rotation_env = pixel_rotation(uvec2(gl_FragCoord.xy), 3 * MAX_LOBES);
#endif
    for (int i = 0; i < u_samples; ++i) {
        vec4 q = sobol_point4(u_sample_offset + i);
        vec3 wi = cosine_hemisphere(fract(q.xy + rotation));
        if (wi.z > 0.0) {
            // f cos / pdf with pdf = cos / pi
            vec3 world = tbn * wi;
#if defined(ENV_SAMPLING)
            float w = power_heuristic(wi.z / PI, env_pdf(world));
#else
            float w = 1.0;
#endif
            sum += lookup(world, 0.0, 0.0) * diffuse_eval(wi, wo) * (PI * w);
        }
#if defined(ENV_SAMPLING)
        vec3 world_e = env_sample(fract(q.zw + rotation_env));
        vec3 wi_e = transpose(tbn) * world_e;
        if (wi_e.z > 0.0) {
            float p_env = env_pdf(world_e);
            float w = power_heuristic(p_env, wi_e.z / PI);
            sum += lookup(world_e, 0.0, 0.0) * diffuse_eval(wi_e, wo) * (wi_e.z * w / p_env);
        }
#endif
    }
    return sum / float(u_samples);
#else
    // kd E / pi (Eq. 4.1) with E from the irradiance map; glTF's (1 - F(V.H)) factor averaged
    // over the hemisphere (exact under uniform light).
    vec3 e = textureLod(u_irradiance, tbn[2], 0.0).rgb;
    return (u_kd * irradiance_diffuse_weight(wo.z) + sheen_term(wo.z)) / PI * e;
#endif
}

// Outgoing radiance towards wo (local) for the frame tbn (columns: tangent, bitangent, normal).
vec3 shade(vec3 wo, mat3 tbn) {
    vec3 result = vec3(0.0);
#if defined(HAS_DIFFUSE)
    result += integrate_diffuse(wo, tbn);
#endif
#if defined(METHOD_PREFILTERED)
    // prefiltered-rsibr: the lobes baked into the reflection-space maps in one blended lookup
    if (u_rsibr_lobes != 0) result += rsibr_radiance(wo, tbn);
#endif
    // KHR_materials_volume (volume.glsl): the preview's object as a volume (u_volume set by
    // viewer/preview.py from the material's thickness; 0: thin-walled).
    VolumeShading volume = volume_shading(tbn * wo, tbn, u_dielectric_f0, u_specular_weight);
    for (int i = 0; i < u_lobe_count; ++i) {
#if defined(METHOD_PREFILTERED)
        if (rsibr_lobe(i)) continue;
#endif
        Lobe l = get_lobe(i);
        mat3 lobe_tbn;
        vec3 through;
        volume_lobe(volume, l, tbn, vec3(0.0), lobe_tbn, through);  // the preview has no proxy: no position
        result += through * integrate_lobe(l, i, wo, lobe_tbn);
    }
    // The bright sources the cube no longer holds, for every lobe (RSIBR's included: its maps
    // are baked from the same cube).
    // The reference reads the whole cube: its caps are only proposals (env_sampling.glsl).
#if !defined(ENV_SAMPLING)
    for (int i = 0; i < u_lobe_count && u_cap_light_count > 0; ++i) {
        Lobe l = get_lobe(i);
        mat3 lobe_tbn;
        vec3 through;
        volume_lobe(volume, l, tbn, vec3(0.0), lobe_tbn, through);
        result += through * cap_lights_radiance(l, wo, lobe_tbn);
    }
#endif
    // >= 0: the residual cube is signed (a source's shape beyond its cap; bright_sources.py), and
    // reads of it that miss the cap's own core can leave a small negative sum
    return max(result, vec3(0.0));
}
