#version 450 core
// One MIP level of a split-sum prefiltered cube map (viewer/prefiltered.py).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
#include "prefilter.glsl"
layout(rgba32f, binding = 0) uniform writeonly imageCube u_target;
uniform int u_size;   // face size of this level
uniform int u_row;    // kernel row in u_nodes

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    float sc = 2.0 * (float(id.x) + 0.5) / float(u_size) - 1.0;
    float tc = 2.0 * (float(id.y) + 0.5) / float(u_size) - 1.0;
    vec3 d = normalize(cube_face_direction(id.z, sc, tc));
    imageStore(u_target, id, vec4(prefilter(d, u_row), 1.0));
}
