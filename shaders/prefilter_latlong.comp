#version 450 core
// One elevation slice of a Kautz-McCool lobe map: a 3D texture, equirectangular in x-y, the
// view elevation cos(theta_o) in z (viewer/prefiltered.py).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
#include "prefilter.glsl"
layout(rgba32f, binding = 0) uniform writeonly image3D u_target;
uniform ivec2 u_size;
uniform int u_slice;

void main() {
    ivec2 id = ivec2(gl_GlobalInvocationID.xy);
    if (id.x >= u_size.x || id.y >= u_size.y) return;
    vec2 uv = (vec2(id) + 0.5) / vec2(u_size);
    vec3 d = latlong_to_direction(uv);
    imageStore(u_target, ivec3(id, u_slice), vec4(prefilter(d, u_slice), 1.0));
}
