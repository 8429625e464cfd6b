#version 450 core
// Light-mapped scene: diffuse kd E / pi from the lightmap (thesis Eq. 4.1) plus emission; with
// SPECULAR the view-dependent lobes integrated from the object's cube map (thesis 4.4).
// OBJECT_RECORDS (viewer/object_batches.py ObjectBatches): the per-object uniforms come from the
// object's record in a storage buffer instead, so one multi-draw shades many objects; included
// first, its #defines stand for the uniforms in every file below.
#include "object_records.glsl"
#include "frame.glsl"
#include "integrate.glsl"
#include "material_maps.glsl"
#include "lamps.glsl"

in vec3 v_position;
in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv0;
in vec2 v_uv1;
in vec4 v_visibility;  // scenes/self_visibility.py (interpolated)
in vec4 v_horizon0;
in vec4 v_horizon1;

uniform vec3 u_camera_position;
uniform sampler2D u_lightmap;
uniform int u_self_occlusion;  // 1: the visibility cones apply (RenderSettings.self_occlusion)
// The horizons per lightmap texel (scenes/horizon_maps.py): layers 0 and 1 hold sectors 0-3 and
// 4-7, read at the lightmap coordinate (or, for an object without a lightmap, at its texture
// coordinate) in place of the vertices' horizons where the object has one.
uniform sampler2DArray u_horizon_map;
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform int u_has_horizon_map;        // 1: u_horizon_map holds this object's horizons (its lightmap's or its own)
uniform int u_horizon_map_uv;         // the coordinates it is read at: 1 TEXCOORD_1, 0 TEXCOORD_0
uniform int u_lightmap_texcoord;      // 0 or 1; -1: no lightmap, the environment's irradiance
uniform float u_lightmap_intensity;
uniform vec3 u_emission;              // emissive factor x KHR_materials_emissive_strength
#endif
// glTF metallic-roughness per pixel (Appendix B): with u_gltf_model the textures' base colour,
// metallic and roughness replace the material's in the diffuse term and in its glTF lobe;
// otherwise the base-colour texture multiplies kd (thesis and microfacet models).
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform int u_gltf_model;
uniform vec4 u_base_color_factor;     // rgb: the material's base colour, a: baseColorFactor alpha
uniform float u_metallic_factor;
uniform float u_anisotropy;           // KHR_materials_anisotropy strength (0: isotropic)
uniform float u_roughness_factor;
uniform float u_normal_scale;
uniform float u_occlusion_strength;
#endif
// The occlusion texture on a lightmapped surface: ao / (ao averaged over one lightmap texel), the
// mean floored (an all-black region would divide by 0) and the ratio capped (its detail can
// brighten a pixel, but not arbitrarily); a lightmap texel is averaged over at most 4096 pixels.
const float MIN_OCCLUSION_MEAN = 1.0 / 255.0;
const float MAX_OCCLUSION_DETAIL = 4.0;
const float MAX_LIGHTMAP_TEXEL_PIXELS = 4096.0;
// KHR material extensions per pixel (their textures x these factors; u_clearcoat, u_specular_weight,
// u_transmission and u_sheen_color are bsdf.glsl's): materials/gltf.py and scenes/texturing.py.
#if !defined(OBJECT_RECORDS)  // per object in viewer/object_records.py
uniform float u_clearcoat_roughness;
uniform float u_clearcoat_normal_scale;
uniform vec3 u_specular_f0_raw;       // ((ior - 1) / (ior + 1))^2 specularColorFactor, before min(., 1)
uniform int u_alpha_mode;             // ALPHA_OPAQUE, ALPHA_MASK (u_alpha_cutoff), ALPHA_BLEND
uniform float u_alpha_cutoff;
uniform float u_object_id;            // for picking: written + 1 into the normal buffer's w
#endif

layout(location = 0) out vec4 out_radiance;
layout(location = 1) out vec4 out_position;
layout(location = 2) out vec4 out_normal;
layout(location = 3) out vec4 out_tangent;
// Averaged tangent planes (integrate.glsl), 4-5 and 6-7. Every variant writes them: in a
// refinement pass on reflectors (viewer/frame.py state framebuffers) an object drawn over a
// reflector's pixel must leave no plane there, and an output a shader does not write is undefined
// (llvmpipe left a varying value that the next pass averaged in). Other framebuffers have no
// attachments at these locations and drop them.
layout(location = 4) out vec4 out_plane_point[2];
layout(location = 6) out vec4 out_plane_normal[2];

// The bright sources the object's cube no longer holds (viewer/cubemap.py: its residual is
// bound; the reference's whole cube has them as sampling proposals only), for one lobe as this
// pixel has it.
// A reflector shaded from its mirror buffer reads the whole scene and sky there: no lights.
#if defined(SPECULAR)
vec3 scene_cap_lights(Lobe l, vec3 wo, mat3 tbn) {
#if defined(MIRROR) || defined(ENV_SAMPLING)
    return vec3(0.0);  // the reference reads the whole cube: its caps are only proposals
#else
    return u_cap_light_count > 0 ? cap_lights_radiance(l, wo, tbn) : vec3(0.0);
#endif
}
#endif

void main() {
#if defined(PARALLAX) || defined(MIRROR)
    g_shading_position = v_position;
#endif
#if defined(PLANE_AVERAGE)
    plane_average_load();
#endif
    vec3 geometric_normal = normalize(cross(dFdx(v_position), dFdy(v_position)));
#if defined(SPECULAR)
    vec3 footprint_r = light_footprint_direction(v_position, u_camera_position, v_normal);  // cap_lights.glsl
    set_light_footprint(dFdx(footprint_r), dFdy(footprint_r));
#endif
    // Every texture is read before the alpha test: derivatives need the whole 2x2 quad.
    vec4 base_texel = sample_map(MAP_BASE_COLOR, v_uv0, v_uv1, vec4(1.0));
    vec4 mr_texel = sample_map(MAP_METALLIC_ROUGHNESS, v_uv0, v_uv1, vec4(1.0));
    vec4 normal_texel = sample_map(MAP_NORMAL, v_uv0, v_uv1, vec4(0.5, 0.5, 1.0, 1.0));
    vec4 occlusion_texel = sample_map(MAP_OCCLUSION, v_uv0, v_uv1, vec4(1.0));
    // The lightmap's texel and the derivatives of its coordinates. With OBJECT_RECORDS the UV set
    // is chosen by a per-object value that a quad's helper invocations may not read
    // (material_maps.glsl): the derivatives come from the UV sets themselves, taken in uniform
    // control flow.
#if defined(OBJECT_RECORDS)
    vec2 lightmap_dx = u_lightmap_texcoord == 1 ? dFdx(v_uv1) : dFdx(v_uv0);
    vec2 lightmap_dy = u_lightmap_texcoord == 1 ? dFdy(v_uv1) : dFdy(v_uv0);
    // Both sets read with implicit derivatives, as the per-object variant reads its one (the
    // same texels bit for bit; textureGrad's LOD differs in the last bits on llvmpipe).
    vec3 lightmap_texel_uv0 = texture(u_lightmap, v_uv0).rgb;
    vec3 lightmap_texel_uv1 = texture(u_lightmap, v_uv1).rgb;
    vec3 lightmap_texel = u_lightmap_texcoord == 1 ? lightmap_texel_uv1 : lightmap_texel_uv0;
#else
    vec2 lightmap_uv = u_lightmap_texcoord == 1 ? v_uv1 : v_uv0;
    vec2 lightmap_dx = dFdx(lightmap_uv);
    vec2 lightmap_dy = dFdy(lightmap_uv);
    vec3 lightmap_texel = texture(u_lightmap, lightmap_uv).rgb;  // a white texel without a lightmap
#endif
    // The occlusion texture averaged over one lightmap texel: how many pixels a lightmap texel
    // spans here (>= 1). Without an occlusion texture the mean is the absent texel's 1 and none
    // of this is needed.
    float lightmap_texel_pixels = 1.0;
    if (u_lightmap_texcoord >= 0 && u_map_texcoord[MAP_OCCLUSION] >= 0) {
        vec2 texels = vec2(textureSize(u_lightmap, 0));
        float texels_per_pixel = max(length(lightmap_dx * texels), length(lightmap_dy * texels));
        lightmap_texel_pixels = clamp(1.0 / max(texels_per_pixel, 1e-6), 1.0, MAX_LIGHTMAP_TEXEL_PIXELS);
    }
    vec4 occlusion_mean = sample_map_widened(MAP_OCCLUSION, v_uv0, v_uv1, vec4(1.0), lightmap_texel_pixels);
    vec4 emissive_texel = sample_map(MAP_EMISSIVE, v_uv0, v_uv1, vec4(1.0));
    // Absent textures read as the texel that leaves the factor as it is (direction +x, strength 1).
    vec4 anisotropy_texel = sample_map(MAP_ANISOTROPY, v_uv0, v_uv1, vec4(1.0, 0.5, 1.0, 1.0));
    vec4 clearcoat_texel = sample_map(MAP_CLEARCOAT, v_uv0, v_uv1, vec4(1.0));
    vec4 coat_normal_texel = sample_map(MAP_CLEARCOAT_NORMAL, v_uv0, v_uv1, vec4(0.5, 0.5, 1.0, 1.0));
    vec4 specular_texel = sample_map(MAP_SPECULAR, v_uv0, v_uv1, vec4(1.0));
    vec4 transmission_texel = sample_map(MAP_TRANSMISSION, v_uv0, v_uv1, vec4(1.0));
    vec4 sheen_texel = sample_map(MAP_SHEEN_COLOR, v_uv0, v_uv1, vec4(1.0));
    float coverage = u_alpha_mode == ALPHA_OPAQUE ? 1.0 : clamp(u_base_color_factor.a * base_texel.a, 0.0, 1.0);
    if (u_alpha_mode == ALPHA_MASK && coverage < u_alpha_cutoff) discard;

    mat3 vertex_tbn = shading_frame(v_normal, v_tangent, geometric_normal);
    float handedness = v_tangent.w < 0.0 ? -1.0 : 1.0;
    mat3 tbn = vertex_tbn;
    if (u_map_texcoord[MAP_NORMAL] >= 0) {
        vec3 n = mapped_normal(vertex_tbn, normal_texel.rgb, u_normal_scale);
        tbn = shading_frame(n, vec4(vertex_tbn[0], handedness), geometric_normal);
    }
    // before view_in_frame may turn tbn to the viewer's side (vertex_tbn stays as it is)
    float normal_map_tilt_cos = dot(tbn[2], vertex_tbn[2]);
    // KHR_materials_anisotropy: the texture's direction (RG in [-1, 1] of the tangent frame)
    // turned by the material's rotation; its strength (B) scales anisotropyStrength.
    float tangent_angle = u_tangent_rotation;
    vec2 anisotropy_direction = anisotropy_texel.rg * 2.0 - 1.0;
    if (u_map_texcoord[MAP_ANISOTROPY] >= 0 && dot(anisotropy_direction, anisotropy_direction) > 1e-12)
        tangent_angle += atan(anisotropy_direction.y, anisotropy_direction.x);
    tbn = rotate_tangent(tbn, tangent_angle);
    vec3 view = normalize(u_camera_position - v_position);
    vec3 wo = view_in_frame(tbn, view);
    // KHR_materials_clearcoat: the coat has its own normal map, or the vertex normal (the base's
    // normal map does not reach it); its Fresnel over the base is at N_c.V.
    mat3 coat_tbn = vertex_tbn;
    if (u_map_texcoord[MAP_CLEARCOAT_NORMAL] >= 0) {
        vec3 n = mapped_normal(vertex_tbn, coat_normal_texel.rgb, u_clearcoat_normal_scale);
        coat_tbn = shading_frame(n, vec4(vertex_tbn[0], handedness), geometric_normal);
    }
    vec3 coat_wo = view_in_frame(coat_tbn, view);

    // Without a lightmap: the environment's irradiance at the shading normal (viewer/cubemap.py
    // irradiance_cube: exact per texel, bilinear between; nothing occludes it).
    vec3 irradiance = textureLod(u_irradiance, tbn[2], 0.0).rgb;
    if (u_lightmap_texcoord >= 0) irradiance = lightmap_texel * u_lightmap_intensity;
    // The bake integrated around the vertex normal; a mapped normal leans part of its cosine
    // lobe below the surface: (1 + cos tilt) / 2 of it (scenes/texturing.py lightmap_tilt_share).
    if (u_lightmap_texcoord >= 0 && u_map_texcoord[MAP_NORMAL] >= 0)
        irradiance *= 0.5 * (1.0 + clamp(normal_map_tilt_cos, -1.0, 1.0));
    // Occlusion darkens the indirect diffuse only: mix(1, ao, strength) (spec 3.9.3). A baked
    // lightmap already holds the occlusion of the geometry at its texel size (the bake traced
    // it; Cycles, path tracing the same geometry, ignores the texture), so on a lightmapped
    // surface only the texture's detail within a lightmap texel applies: ao over its mean across
    // the texel keeps the crevices and the bake's mean; multiplying both made a baked
    // FlightHelmet 21 % darker than Cycles (issue 40).
    float occlusion = occlusion_texel.r;
    if (u_lightmap_texcoord >= 0)
        occlusion = min(occlusion / max(occlusion_mean.r, MIN_OCCLUSION_MEAN), MAX_OCCLUSION_DETAIL);
    irradiance *= 1.0 + u_occlusion_strength * (occlusion - 1.0);
    // Lamps light an object without a lightmap directly (the bake holds them where there is one);
    // direct light, so the occlusion texture (indirect light only, spec 3.9.3) does not darken it.
    if (u_lightmap_texcoord < 0) irradiance += lamps_irradiance(v_position, tbn[2]);
    vec3 base_color = u_base_color_factor.rgb * base_texel.rgb;
    float metallic = clamp(u_metallic_factor * mr_texel.b, 0.0, 1.0);
    float roughness = clamp(u_roughness_factor * mr_texel.g, 0.0, 1.0);
    // The extensions' factors at this pixel (each texture multiplies its factor).
    float anisotropy = u_anisotropy * anisotropy_texel.b;
    float clearcoat = u_clearcoat * clearcoat_texel.r;
    float coat_roughness = u_clearcoat_roughness * clearcoat_texel.g;
    float coat_alpha = max(coat_roughness * coat_roughness, ALPHA_MIN);
    vec3 dielectric_f0 = min(u_specular_f0_raw * specular_texel.rgb, vec3(1.0));
    float specular_weight = u_specular_weight * specular_texel.a;
    float transmission = u_transmission * transmission_texel.r;
    g_sheen_texel = sheen_texel.rgb;
    vec3 albedo = u_gltf_model == 1 ? (1.0 - metallic) * (1.0 - transmission) * base_color : u_kd * base_texel.rgb;
    vec3 diffuse = albedo / PI * irradiance;
    diffuse *= u_gltf_model == 1
                   ? vec3(gltf_irradiance_diffuse_weight(dielectric_f0, specular_weight, clearcoat, coat_wo.z, wo.z))
                   : irradiance_diffuse_weight(wo.z);
    diffuse += sheen_term(wo.z) / PI * irradiance;  // KHR_materials_sheen, lit like the diffuse
    vec3 radiance = u_emission * emissive_texel.rgb + diffuse;
#if defined(SPECULAR)
    bool texel_horizons = u_has_horizon_map == 1;
    if (u_self_occlusion != 0 && (texel_horizons || v_visibility.w > SELF_NO_OCCLUSION + 1e-3)) {
        // What a hidden direction sees: the object itself, taken to look like this point (its
        // diffuse and its specular reflectance at normal incidence, lit by its irradiance).
        vec3 specular_reflectance = u_gltf_model == 1
            ? mix(dielectric_f0 * specular_weight, base_color, metallic) : vec3(0.0);
        g_self_cone = vec4(normalize(v_visibility.xyz), texel_horizons ? 0.0 : v_visibility.w);
        set_self_normal(normalize(v_normal));
        if (texel_horizons) {
            // bilinear at level 0 (no MIP chain: a read inside this branch needs no derivatives)
            vec2 horizon_uv = u_horizon_map_uv == 0 ? v_uv0 : v_uv1;
            g_self_sectors = MAP_HORIZON_SECTORS;
            for (int layer = 0; layer < MAP_HORIZON_SECTORS / 4; ++layer) {
                vec4 four = textureLod(u_horizon_map, vec3(horizon_uv, float(layer)), 0.0);
                for (int k = 0; k < 4; ++k) g_self_horizon[4 * layer + k] = four[k];
            }
        } else {
            g_self_sectors = HORIZON_SECTORS;
            for (int k = 0; k < 4; ++k) {
                g_self_horizon[k] = v_horizon0[k];
                g_self_horizon[k + 4] = v_horizon1[k];
            }
        }
        g_self_radiance = (albedo + specular_reflectance) / PI * irradiance;
    }
#if defined(METHOD_PREFILTERED)
    // prefiltered-rsibr (materials whose lobes no texture changes: viewer/rsibr.py)
    if (u_rsibr_lobes != 0) radiance += rsibr_radiance(wo, tbn);
#endif
    // KHR_materials_volume (shaders/volume.glsl, materials/volume.py): the path through the
    // volume behind this pixel, for its transmission and reflection lobes.
    VolumeShading volume = volume_shading(view, tbn, dielectric_f0, specular_weight);
    volume.enabled = volume.enabled && u_gltf_model == 1;
    for (int i = 0; i < u_lobe_count; ++i) {
        Lobe l = get_lobe(i);
        g_self_below_hidden = !lobe_is_transmission(l);  // self_occlusion.glsl
        set_self_lobe_normal(tbn[2]);  // a normal map's tilt (the coat's and a volume's below)
#if defined(METHOD_PREFILTERED)
        if (rsibr_lobe(i)) {  // RSIBR's maps are baked from the residual, without lamps
            radiance += scene_cap_lights(l, wo, tbn) + lamps_radiance(l, wo, tbn, v_position);
            continue;
        }
#endif
        if (u_gltf_model == 1 && (l.type == LOBE_GLTF_SPECULAR || l.type == LOBE_GLTF_TRANSMISSION)) {
            // alpha = roughness^2 per pixel, stretched along the anisotropy direction (local x)
            // by KHR_materials_anisotropy (materials/gltf.py anisotropic_alphas).
            l.r0 = base_color;
            l.metallic = metallic;
            float alpha = max(roughness * roughness, ALPHA_MIN);
            l.ax = mix(alpha, 1.0, anisotropy * anisotropy);
            l.ay = alpha;
            l.dielectric_f0 = dielectric_f0;
            l.specular_weight = specular_weight;
            l.coat = clearcoat;
            l.coat_cos = coat_wo.z;
            if (l.type == LOBE_GLTF_TRANSMISSION) l.k = vec3(transmission);
        }
        if (u_gltf_model == 1 && l.type == LOBE_GLTF_CLEARCOAT) {
            l.k = vec3(clearcoat);
            l.ax = coat_alpha;
            l.ay = coat_alpha;
            set_self_lobe_normal(coat_tbn[2]);
            // >= 0: the residual cube is signed (a source's shape beyond its cap; bright_sources.py)
            radiance += max(integrate_lobe(l, i, coat_wo, coat_tbn) + scene_cap_lights(l, coat_wo, coat_tbn), vec3(0.0));
            radiance += lamps_radiance(l, coat_wo, coat_tbn, v_position);
            continue;
        }
        // KHR_materials_volume: a transmission lobe turned to where the light leaves the volume,
        // read from the exit point, attenuated on the way; a plate's interreflections.
        mat3 lobe_tbn = tbn;
        vec3 through = vec3(1.0);
        volume_lobe(volume, l, tbn, v_position, lobe_tbn, through);
        set_self_lobe_normal(lobe_tbn[2]);
        radiance += through * max(integrate_lobe(l, i, wo, lobe_tbn) + scene_cap_lights(l, wo, lobe_tbn)
                                  + lamps_radiance(l, wo, lobe_tbn, v_position), vec3(0.0));
#if defined(PARALLAX) || defined(MIRROR)
        g_shading_position = v_position;
#endif
    }
#endif
    bool bad = any(isnan(radiance)) || any(isinf(radiance));
    out_radiance = bad ? vec4(0.0, 0.0, 0.0, -1.0) : vec4(radiance, 1.0);
    out_position = vec4(v_position, 1.0);
    out_normal = vec4(tbn[2], u_object_id + 1.0);
    out_tangent = vec4(tbn[0], 1.0);
    if (u_alpha_mode == ALPHA_BLEND) {
        // Drawn after the opaque objects, back to front, with blend (ONE, ONE_MINUS_SRC_ALPHA) on
        // every target: radiance premultiplied by coverage; zero (alpha 0) in the G-buffer
        // targets keeps the opaque surface behind there (picking and refinement see through).
        out_radiance = bad ? vec4(0.0) : vec4(radiance * coverage, coverage);
        out_position = vec4(0.0);
        out_normal = vec4(0.0);
        out_tangent = vec4(0.0);
    }
#if defined(PLANE_AVERAGE)
    for (int side = 0; side < 2; ++side) {
        bool keep = u_alpha_mode != ALPHA_BLEND;
        out_plane_point[side] = keep ? g_plane_point_sum[side] : vec4(0.0);
        out_plane_normal[side] = keep ? vec4(g_plane_normal_sum[side], 0.0) : vec4(0.0);
    }
#else
    for (int side = 0; side < 2; ++side) {
        out_plane_point[side] = vec4(0.0);
        out_plane_normal[side] = vec4(0.0);
    }
#endif
}
