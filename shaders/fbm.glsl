// fBm helpers shared by the synthesis pass (fbm.comp) and the leaf vertex shader.
// numpy reference: leafview/deform/fbm.py (pcg, hash_uniform, spectrum, sample_periodic).
#ifndef LEAFVIEW_FBM_GLSL
#define LEAFVIEW_FBM_GLSL

const float FBM_TWO_PI = 6.283185307179586;

// PCG hash (RXS-M-XS) of a 32-bit word
uint pcg(uint x) {
    uint state = x * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// uniform in (0, 1) for frequency f and stream s (0, 1: Gaussian, 2: phase)
float hash_uniform(uint seed, uint f, uint s) {
    uint h = pcg(pcg(seed) + f * 3u + s);
    return (float(h >> 8u) + 0.5) / 16777216.0;
}

// Catmull-Rom value (x) and d/dt (y) of the periodic signal stored at signals[base .. base+n)
#define FBM_SAMPLE_PERIODIC(SIGNALS, base, n, t, out_vs)                                        \
    {                                                                                          \
        float fi_ = floor(t);                                                                  \
        float x_ = (t) - fi_;                                                                  \
        int i_ = int(mod(fi_, float(n)));                                                      \
        float p0_ = SIGNALS[(base) + (i_ + (n) - 1) % (n)];                                    \
        float p1_ = SIGNALS[(base) + i_];                                                      \
        float p2_ = SIGNALS[(base) + (i_ + 1) % (n)];                                          \
        float p3_ = SIGNALS[(base) + (i_ + 2) % (n)];                                          \
        float c1_ = 0.5 * (p2_ - p0_);                                                         \
        float c2_ = p0_ - 2.5 * p1_ + 2.0 * p2_ - 0.5 * p3_;                                   \
        float c3_ = 0.5 * (p3_ - p0_) + 1.5 * (p1_ - p2_);                                     \
        out_vs = vec2(((c3_ * x_ + c2_) * x_ + c1_) * x_ + p1_,                                \
                      (3.0 * c3_ * x_ + 2.0 * c2_) * x_ + c1_);                                 \
    }

#endif
