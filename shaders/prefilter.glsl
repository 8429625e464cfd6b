// Prefiltering with a radially symmetric kernel (numpy reference: materials/prefilter.py):
// M(d) = integral p(angle(d, l)) L(l) dl, as a sum over cells around d (RadialProfile.cells):
// each cell is a filtered lookup at angle psi from d and azimuth beta, covering its solid angle
// omega, weighted by the kernel's mass over the cell.
#include "cube.glsl"

uniform samplerCube u_source;      // radiance with a full MIP chain
uniform float u_source_face;       // size of its MIP level 0
uniform sampler2D u_cells;         // (psi, beta, omega, weight) per cell (x) and kernel row (y)
uniform int u_cell_count;          // cells per row; a row ends early at a weight of 0
uniform float u_lod_bias;

vec3 prefilter(vec3 d, int row) {
    vec3 helper = abs(d.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 t = normalize(cross(helper, d));
    vec3 b = cross(d, t);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < u_cell_count; ++k) {
        vec4 cell = texelFetch(u_cells, ivec2(k, row), 0);
        if (cell.w <= 0.0) break;
        float s = sin(cell.x);
        vec3 l = cos(cell.x) * d + s * (cos(cell.y) * t + sin(cell.y) * b);
        float lod = cube_lod(l, cell.z, u_source_face) + u_lod_bias;
        sum += cell.w * textureLod(u_source, l, max(lod, 0.0)).rgb;
    }
    return sum;
}
