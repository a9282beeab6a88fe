// Wind on a leaf (leaf.vert under LEAF_WIND): the turbulent load of Geng, Hu & Zhang 2014, eq. 5
// with time as the sampling variable, fBm N of eqs 1-2 resampled as N(r t + c) (eq. 3); the petiole
// turned by the root of eq. 4, the midrib bent as a loaded cantilever, the blade fluttering.
// Everything in leaf space, before the model matrix. numpy twin, line for line:
// leafview/deform/wind.py (displace); the Wind block is filled by leafview/gpu/wind.py.
#ifndef LEAFVIEW_LEAF_WIND_GLSL
#define LEAFVIEW_LEAF_WIND_GLSL
#include "fbm.glsl"
#include "generated/wind_block.glsl"

const float WIND_SAMPLES = 256.0;        // SIGNAL_SAMPLES
const float WIND_PETIOLE = 0.8;          // PETIOLE_COMPLIANCE
const float WIND_MIDRIB = 1.2;           // MIDRIB_COMPLIANCE
const float WIND_MIDRIB_SAT = 0.5;       // MIDRIB_SATURATION
const float WIND_FLUTTER_LOAD = 2.0;     // FLUTTER_LOAD_MAX
const float WIND_GUST_W = 0.8;           // GUST_WEIGHT
const float WIND_LEAF_W = 0.6;           // LEAF_WEIGHT
const float WIND_FLUTTER_WAVE = 2.0;     // FLUTTER_WAVE
const float WIND_FLUTTER_OFFSET = 97.0;  // FLUTTER_OFFSET
const int WIND_NEWTON_STEPS = 8;         // NEWTON_STEPS

float wind_sample(int i) {
    return wind.signal[i >> 2][i & 3];
}

// Catmull-Rom value and d/dt of the periodic wind signal (leafview.deform.fbm.sample_periodic)
vec2 wind_signal(float t) {
    float fi = floor(t);
    float x = t - fi;
    int n = int(WIND_SAMPLES);
    int i = int(mod(fi, WIND_SAMPLES));
    float p0 = wind_sample((i + n - 1) % n);
    float p1 = wind_sample(i);
    float p2 = wind_sample((i + 1) % n);
    float p3 = wind_sample((i + 2) % n);
    float c1 = 0.5 * (p2 - p0);
    float c2 = p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3;
    float c3 = 0.5 * (p3 - p0) + 1.5 * (p1 - p2);
    return vec2(((c3 * x + c2) * x + c1) * x + p1, (3.0 * c3 * x + 2.0 * c2) * x + c1);
}

// eq. 4 for one segment: phi in [0, theta0] with a sin(theta0 - phi) = phi (petiole_angle)
float wind_petiole_angle(float a, float theta0) {
    float lo = 0.0, hi = theta0;
    float phi = a * theta0 / (1.0 + a);
    for (int k = 0; k < WIND_NEWTON_STEPS; ++k) {
        float g = a * sin(theta0 - phi) - phi;
        if (g > 0.0) lo = phi; else hi = phi;
        float nphi = phi - g / (-a * cos(theta0 - phi) - 1.0);
        phi = (nphi >= lo && nphi <= hi) ? nphi : 0.5 * (lo + hi);
    }
    return phi;
}

vec3 wind_rotate(vec3 v, vec3 axis, float angle) {
    float c = cos(angle), s = sin(angle);
    return v * c + cross(axis, v) * s + axis * dot(axis, v) * (1.0 - c);
}

// the leaf at leaf-space point p with upper-side normal n, placed by model, scene index leaf_index
void wind_displace(inout vec3 p, inout vec3 n, mat4 model, uint leaf_index) {
    float speed = wind.wind.z;
    if (speed <= 0.0) return;
    vec3 heading = vec3(wind.wind.xy, 0.0);
    float theta_leaf = hash_uniform(uint(wind.ids.x), leaf_index, 0u) * WIND_SAMPLES;
    // the load Q (eq. 5 in time): the gust carried downwind and the leaf's own turbulence
    float g = wind_signal(wind.gust.w - dot(model[3].xyz, heading) * wind.gust.z).x;
    float turb = wind_signal(wind.flutter.x + theta_leaf).x;
    float q = wind.gust.x * (1.0 + wind.gust.y * (WIND_GUST_W * g + WIND_LEAF_W * turb));
    vec3 d = normalize(transpose(mat3(model)) * heading);
    vec3 fhat = q < 0.0 ? -d : d;
    vec3 cr = cross(vec3(0.0, 1.0, 0.0), fhat);
    float sin0 = length(cr);
    float theta0 = atan(sin0, fhat.y);
    vec3 axis = sin0 > 1e-7 ? cr / sin0 : vec3(1.0, 0.0, 0.0);
    float load = abs(q);
    float phi = wind_petiole_angle(WIND_PETIOLE * load, theta0);
    float qm = load * sin(theta0 - phi);
    float km = WIND_MIDRIB * qm / (1.0 + WIND_MIDRIB_SAT * qm) / 24.0;
    // flutter along the normal
    float amp = wind.flutter.z * load / (1.0 + load / WIND_FLUTTER_LOAD);
    vec2 nf = wind_signal(wind.flutter.y + theta_leaf + WIND_FLUTTER_OFFSET - WIND_FLUTTER_WAVE * p.y);
    float h = 3.0 * p.x * p.x * (0.5 + p.y);
    vec3 grad_a = amp * vec3(6.0 * p.x * (0.5 + p.y) * nf.x, 3.0 * p.x * p.x * nf.x - h * nf.y * WIND_FLUTTER_WAVE, 0.0);
    vec3 p1 = p + (amp * h * nf.x) * n;
    // the rotation field about the base: petiole turn phi plus the midrib's chord angle w(s) / s
    float s = length(p1);
    float psi = phi + km * s * (6.0 - 4.0 * s + s * s);
    float dpsi = km * (6.0 - 8.0 * s + 3.0 * s * s);
    vec3 b_x_p = cross(axis, p1);
    vec3 radial = s > 1e-12 ? p1 / s : vec3(0.0);
    // normals: two tangents through the Jacobian, crossed
    vec3 ref = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 ta = normalize(cross(n, ref));
    vec3 tb = cross(n, ta);
    vec3 ja = ta + n * dot(grad_a, ta);
    ja = wind_rotate(ja + dpsi * dot(radial, ja) * b_x_p, axis, psi);
    vec3 jb = tb + n * dot(grad_a, tb);
    jb = wind_rotate(jb + dpsi * dot(radial, jb) * b_x_p, axis, psi);
    n = normalize(cross(ja, jb));
    p = wind_rotate(p1, axis, psi);
}

#endif
