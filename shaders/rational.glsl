// GLSL twin of lobeview.materials.rational (RationalFunction) and rational_brdf (RationalLobe):
// the Rational BRDF of Pacanowski et al. 2012 (seed 002) and its inverse-CDF sampling.
//
// The material's functions live in a storage buffer (viewer/material_gpu.py pack_rational):
// RATIONAL_FUNCTIONS blocks of RATIONAL_STRIDE vec4s, block f = function f (0-2: the BRDF's
// R, G, B; 3: theta_l = CDF^-1(theta_v, mu), Eq. 8; 4: dphi = CDF^-1(theta_v, theta_l, tau),
// Eq. 9), each: (numerator count, denominator count, 0, 0), (domain lower xyz), (domain upper
// xyz), then one vec4 (coefficient, exponent x, exponent y, exponent z) per numerator term and
// per denominator term. A storage buffer, not uniforms or a sampler: a fragment program of the
// scene renderer already holds most of the 32 samplers a GPU guarantees.

layout(std430, binding = RATIONAL_BINDING) readonly buffer RationalData { vec4 rational_data[]; };

// (p, q, dp/du_v, dq/du_v) of function f at x (domain units), u the variables mapped to [-1, 1];
// variable < 0 skips the derivatives.
vec4 rational_parts(int f, vec3 x, int variable) {
    int base = f * RATIONAL_STRIDE;
    vec4 head = rational_data[base];
    vec3 lo = rational_data[base + 1].xyz;
    vec3 hi = rational_data[base + 2].xyz;
    vec3 u = 2.0 * (x - lo) / max(hi - lo, vec3(1e-30)) - 1.0;
    float px[RATIONAL_MAX_DEGREE + 1];
    float py[RATIONAL_MAX_DEGREE + 1];
    float pz[RATIONAL_MAX_DEGREE + 1];
    px[0] = 1.0;
    py[0] = 1.0;
    pz[0] = 1.0;
    for (int e = 1; e <= RATIONAL_MAX_DEGREE; ++e) {
        px[e] = px[e - 1] * u.x;
        py[e] = py[e - 1] * u.y;
        pz[e] = pz[e - 1] * u.z;
    }
    int counts[2] = int[2](int(head.x + 0.5), int(head.y + 0.5));
    vec4 out_parts = vec4(0.0);
    int offset = base + 3;
    for (int part = 0; part < 2; ++part) {
        float value = 0.0;
        float slope = 0.0;
        for (int k = 0; k < counts[part]; ++k) {
            vec4 t = rational_data[offset + k];
            ivec3 e = ivec3(t.yzw + 0.5);
            value += t.x * px[e.x] * py[e.y] * pz[e.z];
            if (variable == 0 && e.x > 0) slope += t.x * float(e.x) * px[e.x - 1] * py[e.y] * pz[e.z];
            if (variable == 1 && e.y > 0) slope += t.x * float(e.y) * px[e.x] * py[e.y - 1] * pz[e.z];
            if (variable == 2 && e.z > 0) slope += t.x * float(e.z) * px[e.x] * py[e.y] * pz[e.z - 1];
        }
        out_parts[part] = value;
        out_parts[part + 2] = slope;
        offset += counts[part];
    }
    return out_parts;
}

// d(u_v)/d(x_v) of function f's unit map.
float rational_unit_slope(int f, int variable) {
    int base = f * RATIONAL_STRIDE;
    return 2.0 / max(rational_data[base + 2][variable] - rational_data[base + 1][variable], 1e-30);
}

// Inverse CDF of theta_l (Eq. 8): r = pi/2 mu + mu (1 - mu) p/q; .y = dr/dmu.
vec2 rational_theta(float theta_v, float mu) {
    vec4 pq = rational_parts(3, vec3(theta_v, mu, 0.0), 1);
    float s = pq.x / pq.y;
    float ds = (pq.z - s * pq.w) / pq.y * rational_unit_slope(3, 1);
    float b = mu * (1.0 - mu);
    return vec2(0.5 * PI * mu + b * s, 0.5 * PI + (1.0 - 2.0 * mu) * s + b * ds);
}

// Inverse CDF of |phi_l - phi_v| (Eq. 9): r = pi tau + tau (1 - tau) theta_v theta_l p/q; .y = dr/dtau.
vec2 rational_phi(float theta_v, float theta_l, float tau) {
    vec4 pq = rational_parts(4, vec3(theta_v, theta_l, tau), 2);
    float s = pq.x / pq.y;
    float ds = (pq.z - s * pq.w) / pq.y * rational_unit_slope(4, 2);
    float g = theta_v * theta_l;
    float b = tau * (1.0 - tau) * g;
    return vec2(PI * tau + b * s, PI + (1.0 - 2.0 * tau) * g * s + b * ds);
}

// The Rational BRDF (R, G, B functions of (theta_h, theta_d), clamped to the fitted domain
// theta_max and to >= 0 like materials/rational_brdf.py evaluate_brdf).
vec3 rational_brdf(vec3 wi, vec3 wo, float theta_max) {
    if (wi.z <= COS_EPS || wo.z <= COS_EPS) return vec3(0.0);
    vec3 h = normalize(wi + wo);
    float theta_h = min(acos(clamp(h.z, -1.0, 1.0)), theta_max);
    float theta_d = min(acos(clamp(dot(wi, h), -1.0, 1.0)), theta_max);
    vec3 rgb;
    for (int c = 0; c < 3; ++c) {
        vec4 pq = rational_parts(c, vec3(theta_h, theta_d, 0.0), -1);
        rgb[c] = pq.x / pq.y;
    }
    return max(rgb, vec3(0.0));
}

// Sample wi from (u.x = mu, u.y: the side and tau), materials/rational_brdf.py RationalLobe._sample;
// pdf = 1 / (2 dtheta/dmu dphi/dtau sin theta_l) read from the derivatives at (mu, tau) (Eq. 7),
// 0 where they are not positive.
vec3 rational_sample(vec2 u, vec3 wo, bool tangent, out float pdf) {
    float theta_v = acos(clamp(wo.z, 0.0, 1.0));
    float phi_v = atan(wo.y, wo.x);
    vec2 theta = rational_theta(theta_v, u.x);
    float theta_l = clamp(theta.x, 0.0, 0.5 * PI);
    // tangent: u.y runs once around the circle (both sides meet at dphi = pi), turned by the view
    // azimuth, so lobe-N's lattice keeps its azimuths in the tangent frame (materials/rational_brdf.py
    // _sample: a lattice turning with phi_v drew a pinwheel near the normal).
    float around = tangent ? fract(u.y - phi_v / (2.0 * PI)) : u.y;
    bool plus = around < 0.5;
    float tau = plus ? 2.0 * around : (tangent ? 2.0 - 2.0 * around : 2.0 * around - 1.0);
    vec2 phi = rational_phi(theta_v, theta_l, tau);
    float dphi = clamp(phi.x, 0.0, PI);
    float jacobian = 2.0 * theta.y * phi.y * sin(theta_l);
    pdf = (theta.y > 0.0 && phi.y > 0.0 && jacobian > 0.0) ? 1.0 / jacobian : 0.0;
    return spherical_dir(theta_l, phi_v + (plus ? dphi : -dphi));
}

// The (mu, dr/dmu) with r(mu) = target of an increasing inverse CDF (function 3: theta_l given
// theta_v; 4: dphi given theta_v, theta_l): Newton steps kept inside a shrinking bracket (a
// bisection step where Newton would leave it). Few evaluations matter: llvmpipe stops a shader's
// loops after 65535 iterations in all (gallivm's loop limiter), which bisection exhausted.
vec2 rational_invert(int f, float theta_v, float theta_l, float target) {
    float lo = 0.0, hi = 1.0;
    float u = 0.5;
    vec2 r = vec2(0.0);
    for (int i = 0; i < RATIONAL_NEWTON_STEPS; ++i) {
        r = f == 3 ? rational_theta(theta_v, u) : rational_phi(theta_v, theta_l, u);
        float err = r.x - target;
        if (err < 0.0) lo = u; else hi = u;
        // Bisection first (the inverse CDFs have steep and flat stretches where Newton from the
        // middle overshoots), then Newton inside the bracket.
        float next = (i >= RATIONAL_BISECTION_STEPS && r.y > 0.0) ? u - err / r.y : 0.5 * (lo + hi);
        u = (next > lo && next < hi) ? next : 0.5 * (lo + hi);
    }
    r = f == 3 ? rational_theta(theta_v, u) : rational_phi(theta_v, theta_l, u);
    return vec2(u, r.y);
}

// Density per solid angle of rational_sample at an arbitrary wi (multiple importance sampling).
float rational_sample_pdf(vec3 wi, vec3 wo) {
    if (wi.z <= COS_EPS || wo.z <= COS_EPS) return 0.0;
    float theta_v = acos(clamp(wo.z, 0.0, 1.0));
    float theta_l = acos(clamp(wi.z, 0.0, 1.0));
    float dphi = abs(mod(atan(wi.y, wi.x) - atan(wo.y, wo.x) + PI, 2.0 * PI) - PI);
    float d_theta = rational_invert(3, theta_v, 0.0, theta_l).y;
    float d_phi = rational_invert(4, theta_v, theta_l, dphi).y;
    float jacobian = 2.0 * d_theta * d_phi * sin(theta_l);
    return (d_theta > 0.0 && d_phi > 0.0 && jacobian > 0.0) ? 1.0 / jacobian : 0.0;
}
