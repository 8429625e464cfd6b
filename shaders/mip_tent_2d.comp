#version 450 core
// One MIP level of a 2D radiance buffer (the planar mirror passes) from the level above it with
// the separable tent [1 3 3 1] / 8 of shaders/mip_tent_cube.comp (viewer/mip_chain.py): four
// bilinear reads at +-0.75 source texels around each destination texel centre, clamped at the
// buffer's edges (the sampler clamps; numpy: scenes/env_sampling.py tent_downsample_face).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba32f, binding = 0) uniform writeonly image2D u_target;
uniform sampler2D u_source;
uniform ivec2 u_size;        // size of the level written
uniform vec2 u_source_size;  // size of the level read
uniform float u_source_lod;  // the level read (integer)

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (id.x >= u_size.x || id.y >= u_size.y) return;
    vec2 centre = (vec2(id) + 0.5) / vec2(u_size);
    vec2 d = 0.75 / u_source_size;
    vec4 sum = vec4(0.0);
    for (int k = 0; k < 4; ++k) {
        vec2 o = vec2((k & 1) == 0 ? -d.x : d.x, (k & 2) == 0 ? -d.y : d.y);
        sum += textureLod(u_source, centre + o, u_source_lod);
    }
    imageStore(u_target, id, sum * 0.25);
}
