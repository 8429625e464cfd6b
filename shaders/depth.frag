#version 450 core
// Depth only (viewer/occlusion.py): no colour target, the depth test does the work.
void main() {}
