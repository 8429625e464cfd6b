#version 450 core
// textureLod on a cube map for arbitrary (direction, lod) queries: lets the numpy reference
// read incident radiance through exactly the filtering the renderer uses.
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer Queries { vec4 queries[]; };
layout(std430, binding = 1) writeonly buffer Results { vec4 results[]; };
uniform samplerCube u_cube;
uniform int u_count;
void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= uint(u_count)) return;
    vec4 q = queries[i];
    results[i] = vec4(textureLod(u_cube, q.xyz, max(q.w, 0.0)).rgb, 1.0);
}
