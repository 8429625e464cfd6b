// GLSL twin of materials/patterns.py: the thesis' deterministic lobe patterns (Eq. 4.10-4.15)
// and lobeview's per-lobe albedo table for the energy normalisation of Eq. 4.25 (AlbedoTable).

// XI_BORDER (Eq. 4.10) and MAX_ELLIPSE_ANGLE (80 degrees, the footprint's widest lobe) come from patterns.py.

// Eq. 4.10 with Beckmann's border for both distributions (GGX: its core; patterns.theta_thresh).
float theta_thresh(Lobe l, float phi) {
    float c = cos(phi);
    float s = sin(phi);
    float inv_alpha2 = c * c / (l.ax * l.ax) + s * s / (l.ay * l.ay);
    return atan(sqrt(-log(XI_BORDER) / inv_alpha2));
}

vec3 pattern_half_vector(Lobe l, vec2 xi) {
    float phi = phi_from_xi(l, xi.y);
    return spherical_dir((1.0 - xi.x) * theta_thresh(l, phi), phi);
}

// Whether this pixel's lobe takes the line pattern: anisotropic by ANISOTROPY_LINE_RATIO or more
// (patterns.py uses_line_pattern; roughness and anisotropy textures change it from pixel to pixel).
bool uses_line_pattern(Lobe l) {
    return max(l.ax, l.ay) >= ANISOTROPY_LINE_RATIO * min(l.ax, l.ay);
}

// Wide lobes' lookups filter up to WIDE_LOBE_MAX_LEVELS coarser (patterns.py wide_lobe_footprint_scale).
float wide_lobe_footprint_scale(Lobe l) {
    float levels = clamp((sqrt(l.ax * l.ay) - WIDE_LOBE_ALPHA) * WIDE_LOBE_LEVELS_PER_ALPHA, 0.0, WIDE_LOBE_MAX_LEVELS);
    return exp2(2.0 * levels);
}

// Eq. 4.14-4.15 divided by n: solid angle of one sample, the ellipse with the equal-area
// radii 2 sin(angle / 2) instead of the thesis' tan(angle); on the line pattern at least a disc
// of half the short semi-axis (patterns.py lobe_sample_area, LINE_MIN_FOOTPRINT_FRACTION).
float lobe_sample_area(Lobe l, vec3 wo, int n) {
    vec3 centre = vec3(-wo.xy, wo.z);
    vec3 hu = spherical_dir(theta_thresh(l, 0.0), 0.0);
    vec3 hv = spherical_dir(theta_thresh(l, 0.5 * PI), 0.5 * PI);
    vec3 wu = 2.0 * dot(wo, hu) * hu - wo;
    vec3 wv = 2.0 * dot(wo, hv) * hv - wo;
    float au = min(acos(clamp(dot(wu, centre), -1.0, 1.0)), MAX_ELLIPSE_ANGLE);
    float av = min(acos(clamp(dot(wv, centre), -1.0, 1.0)), MAX_ELLIPSE_ANGLE);
    float area = PI * 4.0 * sin(0.5 * au) * sin(0.5 * av) / float(n);
    // The line pattern (integrate.glsl lobe_pattern_xi): not narrower than the lobe's width.
    if (uses_line_pattern(l)) {
        float across = 2.0 * sin(0.5 * min(au, av));
        area = max(area, PI * across * across * LINE_MIN_FOOTPRINT_FRACTION);
    }
    return area * wide_lobe_footprint_scale(l);
}

// (A, B) of anisotropic GGX lobes (materials/prefilter.py anisotropic_dfg_table: glTF's
// alpha_x = mix(alpha, 1, strength^2) along local x, alpha_y = alpha): normalised lobe-N's per-pixel
// glTF albedo below and prefiltered.glsl's split-sum of every anisotropic GGX lobe.
uniform sampler3D u_dfg_anisotropic;    // rg: GGX (A, B); x = cos, y = azimuth, z = roughness, strength

// Twin of materials/prefilter.py anisotropic_dfg_lookup: hardware-linear in sqrt(cos) (nodes at the texel centres),
// azimuth and strength (nodes, the strength inside one roughness block), by hand in roughness.
vec2 anisotropic_dfg(float cos_o, vec2 azimuth, float roughness, float strength) {
    float folded = atan(abs(azimuth.y), abs(azimuth.x)) / (0.5 * PI);
    float y = node_coordinate(folded, ANISO_DFG_PHI);
    float r = clamp(roughness, 0.0, 1.0) * float(ANISO_DFG_ROUGHNESS - 1);
    float r0 = min(floor(r), float(ANISO_DFG_ROUGHNESS - 2));
    float s = clamp(strength, 0.0, 1.0) * float(ANISO_DFG_STRENGTH - 1) + 0.5;
    float depth = float(ANISO_DFG_ROUGHNESS * ANISO_DFG_STRENGTH);
    float x = node_coordinate(sqrt(max(cos_o, 0.0)), ANISO_DFG_COS);  // uniform in sqrt(cos theta_o)
    vec2 low = textureLod(u_dfg_anisotropic, vec3(x, y, (r0 * float(ANISO_DFG_STRENGTH) + s) / depth), 0.0).rg;
    vec2 high = textureLod(u_dfg_anisotropic, vec3(x, y, ((r0 + 1.0) * float(ANISO_DFG_STRENGTH) + s) / depth), 0.0).rg;
    return mix(low, high, r - r0);
}

// The table's (A, B) for an anisotropic GGX lobe of any alphas: its wider axis is the table's x,
// strength^2 = (alpha_max - alpha_min) / (1 - alpha_min), clamped at 1 (alpha_max >= 1).
vec2 anisotropic_ggx_dfg(Lobe l, vec3 wo) {
    float a_min = min(l.ax, l.ay);
    float a_max = max(l.ax, l.ay);
    float strength = sqrt(clamp((a_max - a_min) / max(1.0 - a_min, 1e-6), 0.0, 1.0));
    return anisotropic_dfg(wo.z, l.ax >= l.ay ? wo.xy : wo.yx, sqrt(a_min), strength);
}

#if defined(LOBE_NORMALIZE)
// Per-lobe directional albedo over (cos theta_o, phi_o), blocks of ALBEDO_ROWS rows per lobe
// (materials/patterns.py AlbedoTable); linear filtering between texel centres.
const int ALBEDO_ROWS = ALBEDO_PHI + 1;
uniform sampler2D u_albedo;
#if !defined(ALBEDO_AT)  // a multi-draw reads its material's layer of one array (viewer/object_records.py)
#define ALBEDO_AT(uv) textureLod(u_albedo, uv, 0.0)
#endif
// A glTF lobe whose base colour, metallic or roughness come from textures has its own albedo
// at every pixel: integral of f cos = F0 A + F90 B with (A, B) from the GGX DFG table
// (materials/prefilter.py dfg_table; Schlick Fresnel is linear in F0), bsdf.glsl lobe_dfg_albedo;
// an anisotropic one (KHR_materials_anisotropy: alpha_x = mix(alpha, 1, strength^2) along local x)
// from the anisotropic table over the view, roughness and strength (anisotropic_dfg_table): the
// isotropic table at the geometric-mean alpha was 45 % too bright at strength 1.
#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
uniform int u_albedo_per_pixel;
#endif
uniform sampler2D u_dfg;                // rg: Beckmann (A, B), ba: GGX; x = cos, y = roughness

// The tables have one level: read at LOD 0 (a multi-draw's helper invocations hold no record
// values, so implicit derivatives of coordinates made from them are meaningless).
vec3 lobe_albedo(Lobe l, int lobe_index, vec3 wo) {
    // The clearcoat too: its factor and roughness textures change it per pixel (ClearCoatTest's
    // striped coat rendered as a whole coat, its rough-to-smooth coat at the factor's roughness 1).
    if (u_albedo_per_pixel == 1 && (l.type == LOBE_GLTF_SPECULAR || l.type == LOBE_GLTF_TRANSMISSION ||
                                    l.type == LOBE_GLTF_CLEARCOAT)) {
        // scene.frag's glTF lobe: alpha_y = roughness^2, alpha_x = mix(alpha_y, 1, strength^2)
        if (l.dist == DIST_GGX && l.ax != l.ay) return lobe_dfg_albedo(l, anisotropic_ggx_dfg(l, wo), wo.z);
        vec4 dfg = textureLod(u_dfg, dfg_coordinates(wo.z, sqrt(sqrt(l.ax * l.ay)), textureSize(u_dfg, 0)), 0.0);
        vec2 ab = l.dist == DIST_GGX ? dfg.ba : dfg.rg;
        return lobe_dfg_albedo(l, ab, wo.z);
    }
    float phi = atan(wo.y, wo.x) / (2.0 * PI);
    phi = phi - floor(phi);
    float row = float(lobe_index * ALBEDO_ROWS) + phi * float(ALBEDO_PHI) + 0.5;
    // Columns are uniform in sqrt(cos theta_o) (AlbedoTable: dense near grazing).
    return ALBEDO_AT(vec2(sqrt(max(wo.z, 0.0)), row / float(MAX_LOBES * ALBEDO_ROWS))).rgb;
}
#endif
