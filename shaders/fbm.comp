#version 450
// Batched fBm synthesis (Geng, Hu & Zhang 2014, sec. 3, eqs 1-2): one work group per signal. Each signal has
// a seed, beta and length n (even, <= 2048) and is written, normalised to zero mean and unit
// standard deviation, to signals[offset .. offset + n). numpy reference: leafview/deform/fbm.py.
layout(local_size_x = 64) in;
#include "fbm.glsl"
#include "generated/fbm_job.glsl"

layout(std430, binding = FBM_JOBS_BINDING) readonly buffer Jobs { FbmJob jobs[]; };
layout(std430, binding = SIGNALS_BINDING) buffer Signals { float signals[]; };

shared float amp[1024];
shared float phase[1024];
shared float part_sum[64];
shared float part_sq[64];

void main() {
    FbmJob job = jobs[gl_WorkGroupID.x];
    uint lid = gl_LocalInvocationID.x;
    uint half_n = job.n / 2u;

    // the spectrum: a_f = g_f / f^(beta/2), random phase (eqs 1-2)
    for (uint f = 1u + lid; f <= half_n; f += 64u) {
        float u0 = hash_uniform(job.seed, f, 0u);
        float u1 = hash_uniform(job.seed, f, 1u);
        float u2 = hash_uniform(job.seed, f, 2u);
        float g = sqrt(-2.0 * log(u0)) * cos(FBM_TWO_PI * u1);
        amp[f - 1u] = g / pow(float(f), 0.5 * job.beta);
        phase[f - 1u] = FBM_TWO_PI * u2;
    }
    barrier();

    // direct synthesis N(t) = sum_f a_f cos(2 pi f t / n + phi_f); (f t mod n) keeps angles small
    float s = 0.0, sq = 0.0;
    for (uint t = lid; t < job.n; t += 64u) {
        float acc = 0.0;
        for (uint f = 1u; f <= half_n; ++f) {
            float angle = FBM_TWO_PI * float((f * t) % job.n) / float(job.n) + phase[f - 1u];
            acc += amp[f - 1u] * cos(angle);
        }
        signals[job.offset + t] = acc;
        s += acc;
        sq += acc * acc;
    }
    part_sum[lid] = s;
    part_sq[lid] = sq;
    barrier();
    if (lid == 0u) {
        float total = 0.0, total_sq = 0.0;
        for (uint k = 0u; k < 64u; ++k) {
            total += part_sum[k];
            total_sq += part_sq[k];
        }
        float mean = total / float(job.n);
        part_sum[0] = mean;
        part_sq[0] = inversesqrt(max(total_sq / float(job.n) - mean * mean, 1e-30));
    }
    barrier();
    float mean = part_sum[0], inv_std = part_sq[0];
    for (uint t = lid; t < job.n; t += 64u) {
        signals[job.offset + t] = (signals[job.offset + t] - mean) * inv_std;
    }
}
