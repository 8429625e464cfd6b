// GLSL twin of lobeview.materials (microfacet.py, fresnel.py, thesis.py, conductor.py,
// gltf.py, patterns.py). Local shading frame: n = +z, tangent = +x; wi towards the light,
// wo towards the viewer. Tests hold every function here against the numpy reference by
// rendering through the real pipeline (tests/test_render_vs_numpy.py).

#include "cube.glsl"
const float COS_EPS = 1e-7;

// The shared constants (MAX_LOBES, LOBE_ROWS, XI_BORDER, ...) and type codes (LOBE_*, DIST_*,
// FRESNEL_*) are #defines injected from viewer/interface.py (SHADER_CONSTANTS); the Lobe type and
// get_lobe come from LOBE_LAYOUT there (generated: lobe_layout.glsl), as the Python packing does.
#include "lobe_layout.glsl"

#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform int u_lobe_count;
#endif

bool lobe_is_transmission(Lobe l) { return l.type == LOBE_KURT_TRANSMISSION || l.type == LOBE_GLTF_TRANSMISSION; }

// ---- microfacet distribution (microfacet.py) ----------------------------------------------

float D_eval(Lobe l, vec3 h) {
    if (h.z <= 0.0) return 0.0;
    float x2 = h.x * h.x / (l.ax * l.ax);
    float y2 = h.y * h.y / (l.ay * l.ay);
    float z2 = h.z * h.z;
    if (l.dist == DIST_GGX) {
        float d = x2 + y2 + z2;
        return 1.0 / (PI * l.ax * l.ay * d * d);
    }
    // Thesis Eq. 3.3; exp underflows to 0 long before cos^4 does.
    float e = (x2 + y2) / max(z2, 1e-30);
    if (e > 80.0) return 0.0;
    return exp(-e) / (PI * l.ax * l.ay * z2 * z2);
}

// Numerical Recipes erfcc: fractional error < 1.2e-7 everywhere.
float erfc_nr(float x) {
    float t = 1.0 / (1.0 + 0.5 * x);
    return t * exp(-x * x - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 +
           t * (-0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 +
           t * (-0.82215223 + t * 0.17087277)))))))));
}

float lambda_smith(Lobe l, vec3 w) {
    float z2 = max(w.z * w.z, 1e-30);
    float s = (l.ax * l.ax * w.x * w.x + l.ay * l.ay * w.y * w.y) / z2;
    if (l.dist == DIST_GGX) return s / (2.0 * (sqrt(1.0 + s) + 1.0));
    if (s <= 0.0) return 0.0;
    float a = inversesqrt(s);
    if (a >= 2.6) {
        // Asymptotic series of erfc: Lambda = e^{-a^2}/(2 a sqrt(pi)) (1/(2a^2) - 3/(4a^4) + 15/(8a^6))
        float ia2 = 1.0 / (a * a);
        return exp(-a * a) / (2.0 * a * sqrt(PI)) * (0.5 * ia2 - 0.75 * ia2 * ia2 + 1.875 * ia2 * ia2 * ia2);
    }
    return max((exp(-a * a) / (a * sqrt(PI)) - erfc_nr(a)) * 0.5, 0.0);
}

float G1_smith(Lobe l, vec3 w) { return 1.0 / (1.0 + lambda_smith(l, w)); }

float phi_from_xi(Lobe l, float xi2) {
    // Eq. 4.5 / 4.12, quadrant-correct.
    float angle = 2.0 * PI * xi2;
    return atan(l.ay * sin(angle), l.ax * cos(angle));
}

float tan2_theta_from_xi(Lobe l, float xi1, float phi) {
    // Eq. 4.6 (Beckmann: -ln xi1; GGX: (1 - xi1)/xi1), xi1 in (0, 1].
    xi1 = clamp(xi1, 1e-30, 1.0);
    float t = (l.dist == DIST_BECKMANN) ? -log(xi1) : (1.0 - xi1) / xi1;
    float c = cos(phi);
    float s = sin(phi);
    float inv_alpha2 = c * c / (l.ax * l.ax) + s * s / (l.ay * l.ay);
    return t / inv_alpha2;
}

vec3 spherical_dir(float theta, float phi) {
    float s = sin(theta);
    return vec3(s * cos(phi), s * sin(phi), cos(theta));
}

vec3 half_vector_from_xi(Lobe l, float xi1, float xi2) {
    float phi = phi_from_xi(l, xi2);
    float tan2 = tan2_theta_from_xi(l, xi1, phi);
    float cos_t = inversesqrt(1.0 + tan2);
    float sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
    return vec3(sin_t * cos(phi), sin_t * sin(phi), cos_t);
}

vec3 cosine_hemisphere(vec2 u) {
    // Malley's method on Shirley's concentric disk (same map as materials/vec.py).
    float a = 2.0 * u.x - 1.0;
    float b = 2.0 * u.y - 1.0;
    float r, phi;
    if (a == 0.0 && b == 0.0) {
        r = 0.0;
        phi = 0.0;
    } else if (abs(a) > abs(b)) {
        r = a;
        phi = 0.25 * PI * (b / a);
    } else {
        r = b;
        phi = 0.5 * PI - 0.25 * PI * (a / b);
    }
    vec2 d = r * vec2(cos(phi), sin(phi));
    return vec3(d, sqrt(max(1.0 - dot(d, d), 0.0)));
}

#if defined(HAS_RATIONAL)
// Only programs drawing a Rational BRDF compile it: llvmpipe runs untaken branches' loops under
// the execution mask, which made every other material's reference 8x slower.
#include "rational.glsl"
#endif
#if defined(HAS_MEASURED)
// A measured BRDF's table and tabulated sampler (materials/measured.py), likewise only where drawn.
#include "measured.glsl"
#endif

// GGX visible normals (Heitz 2018).
vec3 sample_visible_normal(Lobe l, vec3 wo, vec2 u) {
    vec3 vh = normalize(vec3(l.ax * wo.x, l.ay * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0 ? vec3(-vh.y, vh.x, 0.0) * inversesqrt(lensq) : vec3(1.0, 0.0, 0.0);
    vec3 t2 = cross(vh, t1);
    float r = sqrt(u.x);
    float phi = 2.0 * PI * u.y;
    float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    float s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2;
    vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0)) * vh;
    return normalize(vec3(l.ax * nh.x, l.ay * nh.y, max(nh.z, 0.0)));
}

// ---- Fresnel (fresnel.py) ------------------------------------------------------------------

vec3 schlick(float u, vec3 r0) {
    float m = 1.0 - clamp(u, 0.0, 1.0);
    float m2 = m * m;
    return r0 + (1.0 - r0) * (m2 * m2 * m);
}

vec3 fresnel_conductor(float cos_theta, vec3 eta, vec3 k) {
    float c = clamp(cos_theta, 0.0, 1.0);
    float c2 = c * c;
    float s2 = 1.0 - c2;
    vec3 t0 = eta * eta - k * k - s2;
    vec3 a2plusb2 = sqrt(t0 * t0 + 4.0 * eta * eta * k * k);
    vec3 a = sqrt(max(0.5 * (a2plusb2 + t0), 0.0));
    vec3 t1 = a2plusb2 + c2;
    vec3 t2 = 2.0 * c * a;
    vec3 rs = (t1 - t2) / max(t1 + t2, vec3(1e-30));
    vec3 t3 = c2 * a2plusb2 + s2 * s2;
    vec3 t4 = t2 * s2;
    vec3 rp = rs * (t3 - t4) / max(t3 + t4, vec3(1e-30));
    return clamp(0.5 * (rp + rs), 0.0, 1.0);
}

// What a glTF dielectric's reflection leaves for the diffuse or the transmission below it:
// 1 - specular max(F_d(V.H)) (fresnel_mix; materials/gltf.py _GltfDielectric.kept).
float dielectric_kept(vec3 f0, float specular, float v_dot_h) {
    vec3 f = schlick(v_dot_h, f0);
    return 1.0 - specular * max(f.r, max(f.g, f.b));
}

vec3 lobe_fresnel(Lobe l, float wo_h) {
    if (l.type == LOBE_GLTF_SPECULAR) {
        return (1.0 - l.metallic) * l.specular_weight * schlick(abs(wo_h), l.dielectric_f0) +
               l.metallic * schlick(abs(wo_h), l.r0);
    }
    if (l.type == LOBE_GLTF_TRANSMISSION) {
        // What the dielectric's reflection leaves, tinted (l.k holds the transmission factor).
        return (1.0 - l.metallic) * l.r0 * dielectric_kept(l.dielectric_f0, l.specular_weight, abs(wo_h));
    }
    if (l.fresnel == FRESNEL_SCHLICK) return schlick(wo_h, l.r0);
    if (l.fresnel == FRESNEL_CONDUCTOR) return fresnel_conductor(wo_h, l.eta, l.kappa);
    return vec3(1.0);
}

// The Fresnel value at grazing (V.H = 0) of lobe_fresnel's Schlick mix: the B term of the DFG
// split (integral of F f cos = f0 A + f90 B).
float lobe_f90(Lobe l) {
    return l.type == LOBE_GLTF_SPECULAR ? (1.0 - l.metallic) * l.specular_weight + l.metallic : 1.0;
}

// KHR_materials_sheen, approximated (materials/gltf.py GltfSheen): sheenColor E_s(N.V) / pi lit
// like the diffuse, E_s the white sheen lobe's albedo at N.V = (i + 0.5) / SHEEN_TABLE_SIZE.
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform vec3 u_sheen_color;
uniform float u_sheen_albedo[SHEEN_TABLE_SIZE];
#endif
// The pixel's sheenColorTexture texel (scene.frag sets it; white everywhere else).
vec3 g_sheen_texel = vec3(1.0);

float sheen_albedo(float cos_o) {
    float x = clamp(cos_o * float(SHEEN_TABLE_SIZE) - 0.5, 0.0, float(SHEEN_TABLE_SIZE - 1));
    int i0 = min(int(floor(x)), SHEEN_TABLE_SIZE - 2);
    return mix(u_sheen_albedo[i0], u_sheen_albedo[i0 + 1], x - float(i0));
}

// sheenColor E_s(N.V): the sheen's radiance under irradiance pi.
vec3 sheen_term(float cos_o) { return u_sheen_color * g_sheen_texel * sheen_albedo(cos_o); }

// What the sheen leaves of the base: 1 - max(sheenColor) E_s(N.V) (the extension's scaling).
float sheen_attenuation(float cos_o) {
    vec3 sheen = u_sheen_color * g_sheen_texel;
    return 1.0 - max(sheen.r, max(sheen.g, sheen.b)) * sheen_albedo(cos_o);
}

// What the layers leave of the glTF base: 1 - clearcoat F_c(N_c.V) (KHR_materials_clearcoat,
// N_c the coat's normal: coat_cos < 0 takes the base's N.V) times the sheen's attenuation
// (materials/gltf.py BaseLayers.attenuation).
float base_attenuation(float coat, float coat_cos, float cos_o) {
    float coat_view = coat_cos < 0.0 ? cos_o : coat_cos;
    return (1.0 - coat * schlick(coat_view, vec3(0.04)).x) * sheen_attenuation(cos_o);
}

// base_attenuation for the lobes under the layers (glTF specular and transmission), 1 otherwise.
float gltf_coat_attenuation(Lobe l, float cos_o) {
    bool base = l.type == LOBE_GLTF_SPECULAR || l.type == LOBE_GLTF_TRANSMISSION;
    return base ? base_attenuation(l.coat, l.coat_cos, cos_o) : 1.0;
}

// The albedo tables' axes hold nodes k / (count - 1) (materials/prefilter.py node_position): [0, 1]
// maps onto the texel centres, so roughness 1 reads alpha 1 (clamped at the last centre it read
// alpha 0.97: GGX 1.0's albedo 4.7 % too high).
float node_coordinate(float value, int count) {
    return (clamp(value, 0.0, 1.0) * float(count - 1) + 0.5) / float(count);
}

// The DFG table (materials/prefilter.py dfg_table, dfg_lookup): cos(theta_o) along x, roughness along y.
vec2 dfg_coordinates(float cos_o, float roughness, ivec2 size) {
    return vec2(node_coordinate(cos_o, size.x), node_coordinate(roughness, size.y));
}

// A lobe's directional albedo from the DFG table's (A, B) at its roughness (split-sum and the
// per-pixel glTF albedo): f0 A + f90 B times its scale; the clearcoat's Fresnel is at N.V, so
// its albedo is clearcoat F_c(N.V) (A + B).
vec3 lobe_dfg_albedo(Lobe l, vec2 ab, float cos_o) {
    if (l.type == LOBE_GLTF_CLEARCOAT) return l.k * schlick(cos_o, l.r0) * (ab.x + ab.y);
    if (l.type == LOBE_GLTF_TRANSMISSION) {
        // tint (1 - specular max F): max over channels of Schlick is Schlick of the largest f0.
        float f0 = max(l.dielectric_f0.r, max(l.dielectric_f0.g, l.dielectric_f0.b));
        float kept = (ab.x + ab.y) - l.specular_weight * (f0 * ab.x + ab.y);
        return l.k * (1.0 - l.metallic) * l.r0 * kept * gltf_coat_attenuation(l, cos_o);
    }
    vec3 scale = l.type == LOBE_GLTF_SPECULAR ? vec3(gltf_coat_attenuation(l, cos_o)) : l.k;
    return (lobe_fresnel(l, 1.0) * ab.x + lobe_f90(l) * ab.y) * scale;
}

// ---- lobes (thesis.py, conductor.py, gltf.py) -----------------------------------------------

// The incident direction as the reflection formulas see it (Eq. 3.5 mirrors transmission).
vec3 reflected_wi(Lobe l, vec3 wi) { return lobe_is_transmission(l) ? vec3(wi.xy, -wi.z) : wi; }

vec3 lobe_eval(Lobe l, vec3 wi, vec3 wo) {
#if defined(HAS_RATIONAL)
    // The Rational BRDF (l.k.r: its fitted domain's theta_max, radians).
    if (l.type == LOBE_RATIONAL) return rational_brdf(wi, wo, l.k.r);
#endif
#if defined(HAS_MEASURED)
    if (l.type == LOBE_MEASURED) return measured_brdf(wi, wo);
#endif
    vec3 wr = reflected_wi(l, wi);
    if (wo.z <= COS_EPS || wr.z <= COS_EPS) return vec3(0.0);
    vec3 h = normalize(wr + wo);
    float wo_h = max(dot(wo, h), COS_EPS);
    float d = D_eval(l, h);
    if (l.type == LOBE_KURT_REFLECTION || l.type == LOBE_KURT_TRANSMISSION) {
        vec3 f = schlick(wo_h, l.r0);
        if (lobe_is_transmission(l)) f = 1.0 - f;
        // Eq. 3.4: F D / (4 (wo.h) ((wi.n)(wo.n))^alpha)
        float denom = 4.0 * wo_h * exp(l.alpha * (log(wr.z) + log(wo.z)));
        return l.k * f * (d / denom);
    }
    float g2 = 1.0 / (1.0 + lambda_smith(l, wr) + lambda_smith(l, wo));
    if (dot(wr, h) <= 0.0) g2 = 0.0;
    // The clearcoat's Fresnel is evaluated at N.V (KHR_materials_clearcoat), the others' at V.H.
    vec3 fresnel = l.type == LOBE_GLTF_CLEARCOAT ? schlick(wo.z, l.r0) : lobe_fresnel(l, wo_h);
    return l.k * fresnel * (d * g2 / (4.0 * wr.z * wo.z)) * gltf_coat_attenuation(l, wo.z);
}

// Half-vector density D(h) cos(theta_h) / (4 wo.h) (Eq. 4.9), mirrored for transmission.
float lobe_half_pdf(Lobe l, vec3 wi, vec3 wo) {
    vec3 wr = reflected_wi(l, wi);
    if (wo.z <= COS_EPS || wr.z <= COS_EPS) return 0.0;
    vec3 h = normalize(wr + wo);
    return D_eval(l, h) * h.z / (4.0 * max(dot(wo, h), COS_EPS));
}

bool lobe_uses_vndf(Lobe l) {
    return (l.type == LOBE_MICROFACET || l.type == LOBE_GLTF_SPECULAR || l.type == LOBE_GLTF_CLEARCOAT ||
            l.type == LOBE_GLTF_TRANSMISSION) && l.dist == DIST_GGX;
}

// Density of lobe_sample().
float lobe_sample_pdf(Lobe l, vec3 wi, vec3 wo) {
#if defined(HAS_RATIONAL)
    if (l.type == LOBE_RATIONAL) return rational_sample_pdf(wi, wo);
#endif
#if defined(HAS_MEASURED)
    if (l.type == LOBE_MEASURED) return measured_sample_pdf(wi, wo);
#endif
    if (!lobe_uses_vndf(l)) return lobe_half_pdf(l, wi, wo);
    vec3 wr = reflected_wi(l, wi);  // a transmission lobe's samples are mirrored reflections
    if (wo.z <= COS_EPS || wr.z <= COS_EPS) return 0.0;
    vec3 h = normalize(wr + wo);
    float wo_h = max(dot(wo, h), COS_EPS);
    float d_vis = G1_smith(l, wo) * wo_h * D_eval(l, h) / wo.z;
    return d_vis / (4.0 * wo_h);
}

// Importance sample of the lobe (Eq. 4.5-4.8, or GGX visible normals); check the pdf > 0.
vec3 lobe_sample(Lobe l, vec2 u, vec3 wo) {
    vec3 h = lobe_uses_vndf(l) ? sample_visible_normal(l, wo, u) : half_vector_from_xi(l, 1.0 - u.x, u.y);
    vec3 wr = 2.0 * dot(wo, h) * h - wo;
    return reflected_wi(l, wr);
}

// lobe_sample and lobe_sample_pdf of the sampled direction together: the Rational BRDF reads
// its density from the sample's own derivatives instead of inverting its CDFs.
vec3 lobe_sample_and_pdf(Lobe l, vec2 u, vec3 wo, out float pdf) {
#if defined(HAS_RATIONAL)
    if (l.type == LOBE_RATIONAL) return rational_sample(u, wo, false, pdf);  // inverse CDFs (Eq. 7-9)
#endif
#if defined(HAS_MEASURED)
    if (l.type == LOBE_MEASURED) return measured_sample(u, wo, pdf);  // tabulated CDFs
#endif
    vec3 wi = lobe_sample(l, u, wo);
    pdf = lobe_sample_pdf(l, wi, wo);
    return wi;
}

// ---- glTF diffuse (gltf.py GltfDiffuse) -------------------------------------------------------

#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform float u_gltf_diffuse;  // 1: the material's diffuse is glTF's, under a dielectric layer
uniform vec3 u_dielectric_f0;  // KHR_materials_ior/_specular f0 (0.04 without them)
uniform float u_specular_weight;
uniform float u_clearcoat;
uniform float u_transmission;  // KHR_materials_transmission: the diffuse keeps 1 - transmission
#endif

// The weight of the diffuse term: glTF's 1 - specular max(F_d(V.H)) (Appendix B fresnel_mix, with
// the KHR_materials_ior/_specular f0 and weight) times the clearcoat's 1 - clearcoat F_c(N.V);
// 1 for every other model. gltf_diffuse_weight takes the layers explicitly (scene.frag's
// per-pixel values, coat_cos < 0: the coat shares the normal).
float gltf_diffuse_weight(vec3 f0, float specular, float clearcoat, float coat_cos, float v_dot_h, float n_dot_v) {
    return dielectric_kept(f0, specular, v_dot_h) * base_attenuation(clearcoat, coat_cos, n_dot_v);
}

vec3 diffuse_weight(float v_dot_h, float n_dot_v) {
    if (u_gltf_diffuse <= 0.5) return vec3(1.0);
    return vec3(gltf_diffuse_weight(u_dielectric_f0, u_specular_weight, u_clearcoat, -1.0, v_dot_h, n_dot_v));
}

// E[(1 - V.H)^5] over incident directions distributed as cos / pi at N.V (gltf.py
// schlick_cosine_average: a degree-4 fit to the integral, error <= 6e-6).
float schlick_cosine_average(float n_dot_v) {
    float mu = clamp(n_dot_v, 0.0, 1.0);
    return 0.0281612 + mu * (-0.0798007 + mu * (0.0862515 + mu * (-0.0433788 + mu * 0.0088488)));
}

// dielectric_kept averaged over cosine-distributed incident directions (gltf.py kept_irradiance):
// what a diffuse lit from every direction at once (lightmap, irradiance map, SH) keeps. Schlick
// grows with f0, so the max over RGB is the largest f0's.
float dielectric_kept_irradiance(vec3 f0, float specular, float n_dot_v) {
    float f0_max = max(f0.r, max(f0.g, f0.b));
    return 1.0 - specular * (f0_max + (1.0 - f0_max) * schlick_cosine_average(n_dot_v));
}

// The diffuse weight for a diffuse lit by an irradiance (gltf.py GltfDiffuse.view_weight): the
// V.H weight averaged over the hemisphere, exact under uniform light. The view-direction value
// F(N.V) darkened a white rough sphere to 0.6 of Cycles at its rim (issue 40).
float gltf_irradiance_diffuse_weight(vec3 f0, float specular, float clearcoat, float coat_cos, float n_dot_v) {
    return dielectric_kept_irradiance(f0, specular, n_dot_v) * base_attenuation(clearcoat, coat_cos, n_dot_v);
}

vec3 irradiance_diffuse_weight(float n_dot_v) {
    if (u_gltf_diffuse <= 0.5) return vec3(1.0);
    return vec3(gltf_irradiance_diffuse_weight(u_dielectric_f0, u_specular_weight, u_clearcoat, -1.0, n_dot_v));
}
