// Bézier curves in Bernstein form (Chaurasia & Beardsley 2017, eq. 1) and their derivatives.
// numpy reference: leafview/core/bezier.py
#ifndef LEAFVIEW_BEZIER_GLSL
#define LEAFVIEW_BEZIER_GLSL

vec3 bernstein2(float t) {
    float s = 1.0 - t;
    return vec3(s * s, 2.0 * s * t, t * t);
}

vec4 bernstein3(float t) {
    float s = 1.0 - t;
    return vec4(s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
}

// d/dt of bernstein3: the hodograph weights n (b_{i+1} - b_i) folded back onto the points
vec4 bernstein3_dt(float t) {
    vec3 b = bernstein2(t);
    return vec4(-3.0 * b.x, 3.0 * (b.x - b.y), 3.0 * (b.y - b.z), 3.0 * b.z);
}

vec3 quadratic(vec3 p0, vec3 p1, vec3 p2, float t) {
    vec3 b = bernstein2(t);
    return b.x * p0 + b.y * p1 + b.z * p2;
}

vec3 cubic(vec3 p0, vec3 p1, vec3 p2, vec3 p3, float t) {
    vec4 b = bernstein3(t);
    return b.x * p0 + b.y * p1 + b.z * p2 + b.w * p3;
}

vec3 cubic_dt(vec3 p0, vec3 p1, vec3 p2, vec3 p3, float t) {
    return 3.0 * quadratic(p1 - p0, p2 - p1, p3 - p2, t);
}

vec3 cubic_dt2(vec3 p0, vec3 p1, vec3 p2, vec3 p3, float t) {
    vec3 q0 = 3.0 * (p1 - p0), q1 = 3.0 * (p2 - p1), q2 = 3.0 * (p3 - p2);
    return 2.0 * mix(q1 - q0, q2 - q1, t);
}

vec3 quartic(vec3 p0, vec3 p1, vec3 p2, vec3 p3, vec3 p4, float t) {
    float s = 1.0 - t;
    float s2 = s * s, t2 = t * t;
    return s2 * s2 * p0 + 4.0 * s2 * s * t * p1 + 6.0 * s2 * t2 * p2 + 4.0 * s * t2 * t * p3 + t2 * t2 * p4;
}

vec3 quartic_dt(vec3 p0, vec3 p1, vec3 p2, vec3 p3, vec3 p4, float t) {
    return 4.0 * cubic(p1 - p0, p2 - p1, p3 - p2, p4 - p3, t);
}

// eq. 2: the axis tangent rotated +90 degrees in the xy plane, z dropped, normalised
vec3 axis_normal(vec3 d) {
    vec3 m = vec3(-d.y, d.x, 0.0);
    return m / length(m);
}

// The unit in-plane normal n = normalize((-A'_y, A'_x, 0)) of a curve at t and dn/dt, from A'(t)
// and A''(t). Where the tangent vanishes (a midrib whose a1 sits on the base, or a2 on the apex)
// its limit direction, +A'' towards t = 0 and -A'' towards t = 1, stands in, with dn = 0.
// numpy reference: leafview/core/bezier.py, in_plane_normal.
void in_plane_normal(vec3 d1, vec3 d2, float t, out vec3 n, out vec3 dn) {
    vec3 m = vec3(-d1.y, d1.x, 0.0);
    vec3 dm = vec3(-d2.y, d2.x, 0.0);
    float ml = length(m);
    if (ml < 1e-12) {
        m = (t < 0.5 ? 1.0 : -1.0) * dm;
        dm = vec3(0.0);
        ml = length(m);
    }
    n = m / ml;
    dn = (dm - n * dot(n, dm)) / ml;
}

#endif
