#version 450 core
// Adds weight * radiance of one pass into the float accumulation buffer (additive blending):
// resampled bilinearly, or with u_box = K > 1 (a supersampled frame, K times this buffer's size
// each way: viewer/display.py Accumulator.add) the mean of the K x K source texels of this pixel.
in vec2 v_uv;
uniform sampler2D u_source;
uniform float u_weight;
uniform int u_box = 1;
out vec4 out_color;
void main() {
    vec3 radiance;
    if (u_box > 1) {
        radiance = vec3(0.0);
        ivec2 first = ivec2(gl_FragCoord.xy) * u_box;
        for (int j = 0; j < u_box; ++j)
            for (int i = 0; i < u_box; ++i) radiance += texelFetch(u_source, first + ivec2(i, j), 0).rgb;
        radiance /= float(u_box * u_box);
    } else {
        radiance = texture(u_source, v_uv).rgb;
    }
    out_color = vec4(radiance * u_weight, u_weight);
}
