// Thick transmission (KHR_materials_volume): the GLSL twin of materials/volume.py, which says
// what the models are. A glTF transmission lobe of a volume is turned by the rotation taking -V
// to the direction the light leaves the volume towards, read from the exit point, and attenuated
// along the path and by the exit interface (shaders/scene.frag, and shade() in integrate.glsl
// for the object preview). Included by integrate.glsl after incident.glsl.

#if !defined(OBJECT_LOBE_RECORDS)  // per object in viewer/object_records.py
// x: thickness in world units (0: thin-walled), y: the object's middle bounding-box extent,
// z: ior, w: 1 / attenuationDistance (0: no attenuation)
uniform vec4 u_volume;
uniform vec3 u_volume_attenuation;  // attenuationColor
#endif

const float VOLUME_SPHERE_RATIO_LOW = 0.25;   // materials/volume.py SPHERE_RATIO_LOW / _HIGH
const float VOLUME_SPHERE_RATIO_HIGH = 0.75;
const float VOLUME_MIN_COS_VIEW = 1e-4;

struct VolumePath {
    vec3 exit_direction;  // unit, world
    vec3 exit_offset;     // exit point - entry point
    float path_length;
    float slab_weight;    // the plate model's share
    float slab_length;    // the plate's crossing length (slab_gains)
};

VolumePath volume_path(vec3 view, vec3 n, float ior, float thickness, float extent) {
    float eta = ior >= 1.0 ? ior : 1.0;
    float cos_i = clamp(dot(view, n), VOLUME_MIN_COS_VIEW, 1.0);
    float sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    float cos_t = sqrt(max(1.0 - sin2_t, 0.0));
    vec3 inside = -view / eta + (cos_i / eta - cos_t) * n;
    // Sphere of diameter `thickness` tangent at the entry: chord, exit normal, refraction out.
    float chord = thickness * cos_t;
    vec3 exit_normal = 2.0 * cos_t * inside + n;
    vec3 sphere_exit = normalize(eta * inside - (eta * cos_t - cos_i) * exit_normal);
    // Slab of that thickness: out parallel to the view ray.
    float slab_length = thickness / max(cos_t, 1e-6);
    float w = smoothstep(VOLUME_SPHERE_RATIO_LOW, VOLUME_SPHERE_RATIO_HIGH, thickness / max(extent, 1e-30));
    VolumePath path;
    path.exit_direction = normalize(mix(-view, sphere_exit, w));
    path.path_length = mix(slab_length, chord, w);
    path.exit_offset = path.path_length * inside;
    path.slab_weight = 1.0 - w;
    path.slab_length = slab_length;
    return path;
}

// The rotation taking unit `source` to unit `target` (Rodrigues; never opposite here).
mat3 bend_rotation(vec3 source, vec3 target) {
    vec3 a = cross(source, target);
    float c = dot(source, target);
    mat3 k = mat3(0.0, a.z, -a.y,   // GLSL matrices are column-major: columns of [a]x
                  -a.z, 0.0, a.x,
                  a.y, -a.x, 0.0);
    return mat3(1.0) + k + (k * k) / max(1.0 + c, 1e-12);
}

vec3 volume_attenuation(float path_length) {
    if (u_volume.w <= 0.0) return vec3(1.0);
    return exp(log(max(u_volume_attenuation, vec3(1e-30))) * (path_length * u_volume.w));
}

// A plate's interreflections (materials/volume.py slab_gains): the gains on the front reflection
// F and on the single-pass transmission, for the faces' reflectance f and one crossing's a.
void slab_gains(float f, vec3 a, out vec3 reflection_gain, out vec3 transmission_gain) {
    vec3 denominator = 1.0 - f * f * a * a;
    reflection_gain = 1.0 + (1.0 - f) * (1.0 - f) * a * a / denominator;
    transmission_gain = 1.0 / denominator;
}

float volume_exit_transmittance(float cos_view, vec3 dielectric_f0, float specular_weight) {
    float c = clamp(cos_view, VOLUME_MIN_COS_VIEW, 1.0);
    float f0 = max(dielectric_f0.r, max(dielectric_f0.g, dielectric_f0.b));
    return 1.0 - specular_weight * (f0 + (1.0 - f0) * pow(1.0 - c, 5.0));
}

// What a volume does to this pixel's lobes (scene.frag and the preview's shade() alike): the turned
// frame of its transmission lobe, what the volume lets through (attenuation, the exit's Fresnel,
// a plate's interreflections), the plate's gain on the reflection, the exit point's offset.
struct VolumeShading {
    bool enabled;
    mat3 tbn;
    vec3 transmitted;
    vec3 reflected;
    vec3 exit_offset;
};

VolumeShading volume_shading(vec3 view, mat3 tbn, vec3 dielectric_f0, float specular_weight) {
    VolumeShading v;
    v.enabled = u_volume.x > 0.0;
    v.tbn = tbn;
    v.transmitted = vec3(1.0);
    v.reflected = vec3(1.0);
    v.exit_offset = vec3(0.0);
    if (!v.enabled) return v;
    VolumePath path = volume_path(view, tbn[2], u_volume.z, u_volume.x, u_volume.y);
    v.tbn = bend_rotation(-view, path.exit_direction) * tbn;
    float exit_t = volume_exit_transmittance(dot(view, tbn[2]), dielectric_f0, specular_weight);
    vec3 reflection_gain, transmission_gain;
    slab_gains(1.0 - exit_t, volume_attenuation(path.slab_length), reflection_gain, transmission_gain);
    v.transmitted = volume_attenuation(path.path_length) * exit_t * mix(vec3(1.0), transmission_gain, path.slab_weight);
    v.reflected = mix(vec3(1.0), reflection_gain, path.slab_weight);
    v.exit_offset = path.exit_offset;
    return v;
}

// Lobe l's frame and factor under the volume (tbn and 1 for lobes it does not change); a
// transmission lobe's incident lookups start at the exit point (the caller resets the position).
void volume_lobe(VolumeShading v, Lobe l, mat3 tbn, vec3 position, out mat3 lobe_tbn, out vec3 through) {
    lobe_tbn = tbn;
    through = vec3(1.0);
    if (!v.enabled) return;
    if (l.type == LOBE_GLTF_TRANSMISSION) {
        lobe_tbn = v.tbn;
        through = v.transmitted;
#if defined(PARALLAX) || defined(MIRROR)
        g_shading_position = position + v.exit_offset;
#endif
    } else if (l.type == LOBE_GLTF_SPECULAR) {
        through = v.reflected;
    }
}
