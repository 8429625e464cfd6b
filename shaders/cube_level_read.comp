#version 450 core
// Copy one MIP level of a cube map into a buffer (faces, rows, columns): for the disk cache.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba32f, binding = 0) readonly uniform imageCube u_image;
layout(std430, binding = 0) writeonly buffer Texels { vec4 texels[]; };
uniform int u_size;
void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (id.x >= u_size || id.y >= u_size) return;
    texels[(id.z * u_size + id.y) * u_size + id.x] = imageLoad(u_image, id);
}
