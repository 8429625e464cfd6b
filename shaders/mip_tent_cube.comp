#version 450 core
// One MIP level of a radiance cube from the level above it with a separable tent [1 3 3 1] / 8
// (viewer/mip_chain.py tent_mipmaps): four bilinear reads at +-0.75 source texels around each
// destination texel centre, across face edges through seamless cube filtering.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
#include "cube.glsl"
layout(rgba32f, binding = 0) uniform writeonly imageCube u_target;
uniform samplerCube u_source;
uniform int u_size;          // face size of the level written
uniform float u_source_lod;  // the level read (integer)

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    float texel = 2.0 / float(u_size);  // one destination texel in face coordinates
    float sc = (float(id.x) + 0.5) * texel - 1.0;
    float tc = (float(id.y) + 0.5) * texel - 1.0;
    float d = 0.375 * texel;  // 0.75 source texels
    vec4 sum = vec4(0.0);
    for (int k = 0; k < 4; ++k) {
        vec2 o = vec2((k & 1) == 0 ? -d : d, (k & 2) == 0 ? -d : d);
        sum += textureLod(u_source, normalize(cube_face_direction(id.z, sc + o.x, tc + o.y)), u_source_lod);
    }
    imageStore(u_target, id, sum * 0.25);
}
