// lobe-N+norm+fit's coarse reads from the blur stack (materials/blur_stack.py, twin of read_stack;
// built by shaders/blur_stack.comp): the padded face of a direction's major axis, read bilinearly,
// two layers blended linearly in variance (layer k holds sigma_0^2 2^k).
#if defined(MIRROR)
#error "the blur stack is a cube's: not for the mirror buffers"
#endif
#if !defined(OBJECT_RECORDS)
// One object's draw: its cube's stack. Multi-draws (object_records.glsl) declare the group's array
// of stacks instead, and each object's record holds these two.
uniform sampler2DArray u_blur_stack;
uniform int u_has_blur_stack;  // 0: not built yet (a budgeted frame) or no fitted lobe: the chain
uniform float u_stack_layer;  // the stack's first layer in u_blur_stack (0: the cube's own)
#endif

int blur_stack_face(vec3 d, out vec2 st) {
    vec3 a = abs(d);
    int face;
    float major;
    if (a.x >= a.y && a.x >= a.z) {
        face = d.x > 0.0 ? 0 : 1;
        major = a.x;
        st = face == 0 ? vec2(-d.z, -d.y) : vec2(d.z, -d.y);
    } else if (a.y >= a.z) {
        face = d.y > 0.0 ? 2 : 3;
        major = a.y;
        st = face == 2 ? vec2(d.x, d.z) : vec2(d.x, -d.z);
    } else {
        face = d.z > 0.0 ? 4 : 5;
        major = a.z;
        st = face == 4 ? vec2(d.x, -d.y) : vec2(-d.x, -d.y);
    }
    st /= major;
    return face;
}

vec3 blur_stack_layer(vec3 d, int k) {
    vec2 st;
    int face = blur_stack_face(d, st);
    vec2 uv = ((st + 1.0) * (0.5 * float(BLUR_STACK_FACE)) + float(BLUR_STACK_PAD))
              / float(BLUR_STACK_FACE + 2 * BLUR_STACK_PAD);
    return textureLod(u_blur_stack, vec3(uv, u_stack_layer + float(6 * k + face)), 0.0).rgb;
}

vec3 blur_stack_read(vec3 d, float sigma) {
    float first = BLUR_STACK_SIGMA0 * BLUR_STACK_SIGMA0;
    float variance = clamp(sigma * sigma, first, first * exp2(float(BLUR_STACK_LAYERS - 1)));
    int k = clamp(int(floor(log2(variance / first))), 0, BLUR_STACK_LAYERS - 2);
    float low = first * exp2(float(k));
    float t = clamp((variance - low) / low, 0.0, 1.0);  // layer k + 1 holds twice layer k's variance
    return mix(blur_stack_layer(d, k), blur_stack_layer(d, k + 1), t);
}
