#version 450 core
// Display: accumulated radiance / weight -> exposure -> curve -> sRGB (viewer/tonemap.py is
// the numpy twin used for files).
in vec2 v_uv;
uniform sampler2D u_source;
uniform float u_exposure;   // stops
uniform int u_operator;     // 0 aces, 1 reinhard, 2 none
out vec4 out_color;

vec3 srgb(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), x));
}

void main() {
    vec4 acc = texture(u_source, v_uv);
    vec3 x = acc.a > 0.0 ? acc.rgb / acc.a : vec3(0.0);
    x = max(x, vec3(0.0)) * exp2(u_exposure);
    if (u_operator == 0) x = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
    else if (u_operator == 1) x = x / (1.0 + x);
    out_color = vec4(srgb(x), 1.0);
}
