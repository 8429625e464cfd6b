#version 450 core
// Frustum culling on the GPU (issue 42): sets the instance count (1 drawn, 0 not) of every
// multi-draw command of a pass (viewer/object_batches.py ObjectBatches). A command's object is
// its baseInstance; it is drawn when the pass enables it and its world-space bounding box is
// not entirely beyond one clip plane - the test of viewer/camera.py outside_frustum_many, made
// conservative by a relative margin so that float32 never culls what the float64 test keeps.
layout(local_size_x = 64) in;

struct DrawCommand {
    uint count;
    uint instance_count;
    uint first_index;
    int base_vertex;
    uint base_instance;
};

layout(std430, binding = 0) buffer Commands { DrawCommand commands[]; };
layout(std430, binding = 1) readonly buffer Boxes { vec4 boxes[]; };  // per object: min, max (xyz)
layout(std430, binding = 2) readonly buffer Enabled { uint enabled[]; };

uniform mat4 u_cull_view_projection;
uniform int u_command_count;
uniform int u_frustum_culling;

const float CULL_MARGIN = 1e-5;

bool outside_frustum(vec3 low, vec3 high) {
    bvec3 above = bvec3(true), below = bvec3(true);
    for (int corner = 0; corner < 8; ++corner) {
        vec3 p = vec3((corner & 1) != 0 ? high.x : low.x, (corner & 2) != 0 ? high.y : low.y,
                      (corner & 4) != 0 ? high.z : low.z);
        vec4 clip = u_cull_view_projection * vec4(p, 1.0);
        vec3 margin = CULL_MARGIN * (abs(clip.xyz) + abs(clip.w));
        bvec3 beyond_high = greaterThan(clip.xyz, vec3(clip.w) + margin);
        bvec3 beyond_low = lessThan(clip.xyz, vec3(-clip.w) - margin);
        above = bvec3(above.x && beyond_high.x, above.y && beyond_high.y, above.z && beyond_high.z);
        below = bvec3(below.x && beyond_low.x, below.y && beyond_low.y, below.z && beyond_low.z);
    }
    return any(above) || any(below);
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= uint(u_command_count)) return;
    uint object = commands[i].base_instance;
    bool drawn = enabled[object] != 0u;
    if (drawn && u_frustum_culling != 0)
        drawn = !outside_frustum(boxes[2u * object].xyz, boxes[2u * object + 1u].xyz);
    commands[i].instance_count = drawn ? 1u : 0u;
}
