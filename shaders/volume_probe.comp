#version 450 core
// Probe of shaders/volume.glsl for tests (tests/test_volume.py): per invocation, read (view,
// thickness), (normal, extent), (ior, path length, 0, 0) and write the exit direction, the exit
// offset, the path length, the rotation of -view onto the exit direction applied to a test
// vector, the attenuation over the given length, the exit transmittance, the plate's share and
// crossing length and its interreflection gains; and volume_shading's factors for the volume of
// u_volume (one per run) seen along (view, normal).
layout(local_size_x = 64) in;
#include "bsdf.glsl"
#include "volume.glsl"

layout(std430, binding = 2) readonly buffer ProbeIn { vec4 probe_in[]; };    // 3 per item
layout(std430, binding = 3) writeonly buffer ProbeOut { vec4 probe_out[]; }; // 8 per item
uniform int u_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    vec3 view = probe_in[3 * i].xyz;
    float thickness = probe_in[3 * i].w;
    vec3 n = probe_in[3 * i + 1].xyz;
    float extent = probe_in[3 * i + 1].w;
    float ior = probe_in[3 * i + 2].x;
    float given_length = probe_in[3 * i + 2].y;
    VolumePath path = volume_path(view, n, ior, thickness, extent);
    mat3 bend = bend_rotation(-view, path.exit_direction);
    float exit_t = volume_exit_transmittance(dot(view, n), vec3(0.04, 0.05, 0.03), 0.9);
    vec3 reflection_gain, transmission_gain;
    slab_gains(1.0 - exit_t, volume_attenuation(path.slab_length), reflection_gain, transmission_gain);
    probe_out[8 * i] = vec4(path.exit_direction, path.path_length);
    probe_out[8 * i + 1] = vec4(path.exit_offset, exit_t);
    probe_out[8 * i + 2] = vec4(bend * n, path.slab_weight);
    probe_out[8 * i + 3] = vec4(volume_attenuation(given_length), path.slab_length);
    probe_out[8 * i + 4] = vec4(reflection_gain, 0.0);
    probe_out[8 * i + 5] = vec4(transmission_gain, 0.0);
    vec3 helper = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 t = normalize(cross(helper, n));
    VolumeShading shading = volume_shading(view, mat3(t, cross(n, t), n), vec3(0.04, 0.05, 0.03), 0.9);
    probe_out[8 * i + 6] = vec4(shading.transmitted, shading.enabled ? 1.0 : 0.0);
    probe_out[8 * i + 7] = vec4(shading.reflected, 0.0);
}
