#version 450 core
// The reflectors' occlusion test in one multi-draw (viewer/occlusion.py): each fragment that
// passes the depth test adds one to its object's count, as a samples-passed query per object
// would (one sample per pixel). The test runs before this shader (early fragment tests), so a
// hidden fragment never counts.
layout(early_fragment_tests) in;
flat in uint v_object;
layout(std430, binding = 0) buffer VisibleSamples {
    uint visible_samples[];
};

void main() {
    atomicAdd(visible_samples[v_object], 1u);
}
