#version 450 core
// Copy a buffer (faces, rows, columns) into one MIP level of a cube map: the disk cache's way
// back (moderngl writes level 0 of cube maps only).
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba32f, binding = 0) writeonly uniform imageCube u_image;
layout(std430, binding = 0) readonly buffer Texels { vec4 texels[]; };
uniform int u_size;
void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    imageStore(u_image, id, texels[(id.z * u_size + id.y) * u_size + id.x]);
}
