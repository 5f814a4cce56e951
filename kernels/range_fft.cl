/* Range FFT of a whole radar frame in one launch (paper §3.2, eq. 11).
 *
 * Equivalent to radarcl.reference.range_profile(samples, N_FFT, window=..., output=...,
 * gain=scale * sum(window)) in float32, plus radarcl.reference.beam_flags(samples, clip_level).
 *
 * Work mapping: one work-group per JOB. For real input a job is a PAIR of beams (2g, 2g+1)
 * packed as z = a + i b into one complex FFT and separated on store:
 *     A[k] = (Z[k] + conj Z[N-k]) / 2,   B[k] = (Z[k] - conj Z[N-k]) / 2i,
 * which halves the arithmetic. For complex (I/Q) input a job is one beam.
 * get_group_id(0) = job, get_local_id(0) = worker; LOCAL_SIZE workers loop over the butterflies.
 *
 * Zero padding is pruned: with N_FFT = P * M and M >= N_SAMPLES, bin P m + q of the padded
 * transform is the M-point FFT of z_j W_N^{jq}, so the P sub-transforms skip the zeros
 * entirely (the first log2 P decimation-in-frequency stages would only multiply by twiddles).
 * Each M-point transform is a Stockham autosort FFT in local memory: one radix-2 pass when
 * log2 M is odd, then radix-4 passes. Twiddles come from a float64-exact table.
 *
 * -D constants (set by radarcl/stages/range_fft.py):
 *   N_FFT, N_SAMPLES, M, LOG2_M, P, LOG2_P, N_BINS  sizes as above; N_BINS = N_FFT/2 (real) or N_FFT
 *   LOCAL_SIZE   work-group size, a power of two dividing N_FFT/4; a constant so that the
 *                butterfly loops have fixed trip counts and PoCL vectorises across workers
 *   INPUT_KIND   0 float32 real, 1 int16 real, 2 complex64 (float2)
 *   WINDOWED     1: multiply samples by window[] on load; 0: rectangular, no load
 *   POWER        1: |X|^2 on store; 0: |X|
 *   CHECK_FINITE 1 for float inputs: a NaN/Inf sample is replaced by 0 for the FFT (so it
 *                cannot spoil the paired beam) and its beam is flagged and written as NaN
 */
#include "radarcl_common.h"

#if INPUT_KIND == 2
#define COMPLEX_INPUT 1
typedef float2 sample_t;
#define BEAMS_PER_JOB 1
#else
#define COMPLEX_INPUT 0
#if INPUT_KIND == 1
typedef short sample_t;
#else
typedef float sample_t;
#endif
#define BEAMS_PER_JOB 2
#endif

/* Read one sample as float, set flags for NaN/Inf and clipping. */
inline float load_part(float v, float clip_level, int *bad)
{
#if CHECK_FINITE
    if (!isfinite(v)) { *bad |= FLAG_NONFINITE; return 0.0f; }
#endif
    if (fabs(v) >= clip_level) *bad |= FLAG_CLIPPED;
    return v;
}

__kernel __attribute__((reqd_work_group_size(LOCAL_SIZE, 1, 1)))
void range_fft(
    const __global sample_t *samples, /* (n_beams, N_SAMPLES) raw beat samples [ADC units] */
    const __global float *window,     /* (N_SAMPLES) window coefficients, unused unless WINDOWED */
    const __global float2 *twiddle,   /* (N_FFT) exp(-2 pi i j / N_FFT), rounded from float64 */
    const __global float *scale,      /* (N_BINS) per-bin output factor: calibration x r^k gain */
    const float clip_level,           /* |sample| >= this flags the beam CLIPPED [ADC units] */
    const int n_beams,                /* beams in the frame (n_az * n_el) */
    __global float *profiles,         /* (n_beams, N_BINS) magnitude or power */
    __global uchar *flags)            /* (n_beams) FLAG_* bits */
{
    __local float2 buf0[N_FFT];
    __local float2 buf1[N_FFT];
    __local int job_flags[2];

    const int lid = get_local_id(0);
    const int beam_a = get_group_id(0) * BEAMS_PER_JOB;
    const int has_b = !COMPLEX_INPUT && beam_a + 1 < n_beams;
    const __global sample_t *row_a = samples + (size_t)beam_a * N_SAMPLES;

    if (lid == 0) { job_flags[0] = 0; job_flags[1] = 0; }   /* local size may be 1 */
    barrier(CLK_LOCAL_MEM_FENCE);

    /* Load each sample once: buf0[q M + j] = w_j z_j W_N^{j q} for the P blocks, zero beyond
     * the samples. */
    int bad_a = 0, bad_b = 0;
    for (int j = lid; j < M; j += LOCAL_SIZE) {
        float2 z = (float2)(0.0f, 0.0f);
        if (j < N_SAMPLES) {
#if COMPLEX_INPUT
            const float2 s = row_a[j];
            z = (float2)(load_part(s.x, clip_level, &bad_a), load_part(s.y, clip_level, &bad_a));
#else
            z.x = load_part((float)row_a[j], clip_level, &bad_a);
            if (has_b) z.y = load_part((float)row_a[N_SAMPLES + j], clip_level, &bad_b);
#endif
#if WINDOWED
            z *= window[j];
#endif
        }
        buf0[j] = z;
        for (int q = 1; q < P; q++)
            buf0[q * M + j] = cmul(z, twiddle[j * q]);
    }
    if (bad_a) atomic_or(&job_flags[0], bad_a);
    if (bad_b) atomic_or(&job_flags[1], bad_b);
    barrier(CLK_LOCAL_MEM_FENCE);

    /* Stockham passes over the P blocks at once; p = length of the finished sub-transforms. */
    __local float2 *src = buf0;
    __local float2 *dst = buf1;
    int p = 1;
#if LOG2_M & 1
    for (int i = lid; i < N_FFT / 2; i += LOCAL_SIZE) {
        const int base = (i >> (LOG2_M - 1)) << LOG2_M;   /* block q * M */
        const int ii = i & (M / 2 - 1);
        const float2 u0 = src[base + ii];
        const float2 u1 = src[base + ii + M / 2];
        dst[base + 2 * ii] = u0 + u1;                      /* p = 1: no twiddle */
        dst[base + 2 * ii + 1] = u0 - u1;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    { __local float2 *t = src; src = dst; dst = t; }
    p = 2;
#endif
    for (; p < M; p <<= 2) {
        const int tw_step = N_FFT / (4 * p);                /* W_{4p}^k = W_N^{k N / 4p} */
        for (int i = lid; i < N_FFT / 4; i += LOCAL_SIZE) {
            const int base = (i >> (LOG2_M - 2)) << LOG2_M;
            const int ii = i & (M / 4 - 1);
            const int k = ii & (p - 1);
            float2 u0 = src[base + ii];
            float2 u1 = src[base + ii + M / 4];
            float2 u2 = src[base + ii + M / 2];
            float2 u3 = src[base + ii + 3 * M / 4];
            const int t = k * tw_step;
            u1 = cmul(u1, twiddle[t]);
            u2 = cmul(u2, twiddle[2 * t]);
            u3 = cmul(u3, twiddle[3 * t]);
            const float2 v0 = u0 + u2, v1 = u0 - u2, v2 = u1 + u3, v3 = cmul_minus_i(u1 - u3);
            const int j = base + ((ii - k) << 2) + k;
            dst[j] = v0 + v2;
            dst[j + p] = v1 + v3;
            dst[j + 2 * p] = v0 - v2;
            dst[j + 3 * p] = v1 - v3;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        { __local float2 *t = src; src = dst; dst = t; }
    }

    /* Store: Z[P m + q] sits at src[q M + m]. */
    const int fa = job_flags[0], fb = job_flags[1];
    if (lid == 0) {
        flags[beam_a] = (uchar)fa;
        if (has_b) flags[beam_a + 1] = (uchar)fb;
    }
    __global float *out_a = profiles + (size_t)beam_a * N_BINS;
    for (int k = lid; k < N_BINS; k += LOCAL_SIZE) {
        const float2 zk = src[((k & (P - 1)) << LOG2_M) + (k >> LOG2_P)];
#if COMPLEX_INPUT
        const float2 xa = zk;
#else
        const int kn = (N_FFT - k) & (N_FFT - 1);
        const float2 zn = conj2(src[((kn & (P - 1)) << LOG2_M) + (kn >> LOG2_P)]);
        const float2 xa = 0.5f * (zk + zn);
        const float2 xb = cmul_minus_i(0.5f * (zk - zn));
#endif
#if POWER
        float va = dot(xa, xa) * scale[k];
#else
        float va = sqrt(dot(xa, xa)) * scale[k];
#endif
        out_a[k] = (fa & FLAG_NONFINITE) ? NAN : va;
#if !COMPLEX_INPUT
        if (has_b) {
#if POWER
            float vb = dot(xb, xb) * scale[k];
#else
            float vb = sqrt(dot(xb, xb)) * scale[k];
#endif
            out_a[N_BINS + k] = (fb & FLAG_NONFINITE) ? NAN : vb;
        }
#endif
    }
}
