#version 450 core
// What the viewer shows while refining (viewer/refinement.py): per pixel, the refinement's running
// mean and the real-time frame mixed by the weight the last two-half estimate gave the mean,
// w = bias^2 / (bias^2 + noise^2), the convex combination of least expected squared error.
in vec2 v_uv;
uniform sampler2D u_refined;   // rgb: sum of weight x radiance, a: sum of weights
uniform sampler2D u_realtime;  // the same layout, one real-time frame
uniform sampler2D u_weight;    // r: the mean's weight in [0, 1]
out vec4 out_color;
vec3 mean_of(vec4 sums) { return sums.a > 0.0 ? sums.rgb / sums.a : vec3(0.0); }
void main() {
    vec3 refined = mean_of(texture(u_refined, v_uv));
    vec3 realtime = mean_of(texture(u_realtime, v_uv));
    out_color = vec4(mix(realtime, refined, clamp(texture(u_weight, v_uv).r, 0.0, 1.0)), 1.0);
}
