/* Range FFT of a whole radar frame in one launch (paper §3.2, eq. 11).
 *
 * Equivalent to radarcl.oracle.range_profile(samples, N_FFT, window=..., output=...,
 * gain=scale * sum(window)) in float32, plus radarcl.oracle.beam_flags(samples, clip_level).
 *
 * Work mapping: get_group_id(0) = g handles VEC jobs g*VEC + l, one per vector LANE l, so every
 * butterfly is SIMD across jobs and twiddles are scalars shared by the lanes (VEC = 4 or 8 on
 * CPUs, where PoCL does not vectorise across work-items; VEC = 1 on GPUs). For real input a job is
 * a PAIR of beams (2j, 2j+1) packed as z = a + i b into one complex FFT and separated on store:
 *     A[k] = (Z[k] + conj Z[N-k]) / 2,   B[k] = (Z[k] - conj Z[N-k]) / 2i,
 * which halves the arithmetic. For complex (I/Q) input a job is one beam.
 * get_local_id(0) = worker; LOCAL_SIZE workers loop over the butterflies of the group's jobs.
 *
 * Zero padding is pruned: with N_FFT = P * M and M >= N_SAMPLES, bin P m + q of the padded
 * transform is the M-point FFT of z_j W_N^{jq}, so the P sub-transforms skip the zeros
 * entirely (the first log2 P decimation-in-frequency stages would only multiply by twiddles).
 * Each M-point transform is a Stockham autosort FFT between two work buffers of N_FFT x VEC
 * complex: one radix-2 pass when log2 M is odd, then radix-4 passes. Twiddles come from a
 * float64-exact table.
 *
 * Work buffers: in local memory where they fit the device's (SCRATCH_GLOBAL 0, the faster path);
 * otherwise (SCRATCH_GLOBAL 1) in work-group g's own slice of a global buffer, scratch[g][2][N_FFT],
 * so every n_fft runs on a device with little local memory. The job flags and peaks stay in local
 * memory on both paths, and both do the same arithmetic in the same order.
 *
 * -D constants (set by radarcl/stages/range_fft.py):
 *   N_FFT, N_SAMPLES, M, LOG2_M, P, LOG2_P, N_BINS  sizes as above; N_BINS = N_FFT/2 (real) or N_FFT
 *   VEC          jobs per work-group, one per SIMD lane: 1, 2, 4 or 8
 *   LOCAL_SIZE   work-group size, a power of two dividing N_FFT/4 and within the built kernel's
 *                CL_KERNEL_WORK_GROUP_SIZE; a constant so that the butterfly loops have fixed
 *                trip counts
 *   SCRATCH_GLOBAL 1: work buffers in scratch[], 2 N_FFT cvec of __global memory per work-group;
 *                0 or unset: in __local memory, 2 N_FFT cvec beside the flags
 *   INPUT_KIND   0 float32 real, 1 int16 real, 2 complex64 (float2)
 *   WINDOWED     1: multiply samples by window[] on load; 0: rectangular, no load
 *   POWER        1: |X|^2 on store; 0: |X|
 *   CHECK_FINITE 1 for float inputs: a NaN/Inf sample, or one beyond SAMPLE_LIMIT (whose power
 *                would overflow float32), is replaced by 0 for the FFT (so it cannot spoil the
 *                paired beam) and its beam is flagged and written as NaN
 *   SAMPLE_LIMIT oracle.sample_limit(N_SAMPLES), float inputs only
 * Shared: PAIR_RATIO (a pair's weaker beam is flagged FLAG_CROSSTALK beyond it), flags.
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

/* VEC complex numbers: .lo holds the real parts of the lanes, .hi the imaginary parts. With
 * VEC = 1 this is the plain float2 (re, im). */
#if VEC == 1
typedef float rvec;
typedef float2 cvec;
#elif VEC == 2
typedef float2 rvec;
typedef float4 cvec;
#elif VEC == 4
typedef float4 rvec;
typedef float8 cvec;
#elif VEC == 8
typedef float8 rvec;
typedef float16 cvec;
#else
#error "VEC must be 1, 2, 4 or 8"
#endif
typedef union { rvec v; float s[VEC]; } lanes_t;

/* Where the two work buffers live, and the fence a barrier needs to order them. The flags are
 * always local, so the global path's barriers fence both spaces. */
#if SCRATCH_GLOBAL
#define WORK __global
#define WORK_FENCE (CLK_GLOBAL_MEM_FENCE | CLK_LOCAL_MEM_FENCE)
#else
#define WORK __local
#define WORK_FENCE CLK_LOCAL_MEM_FENCE
#endif
#if VEC == 2
typedef int2 ivec;
#define EVEN_BEAMS(p) ((float2)((float)(p)[0], (float)(p)[2 * N_SAMPLES]))
#define ODD_BEAMS(p) ((float2)((float)(p)[N_SAMPLES], (float)(p)[3 * N_SAMPLES]))
#elif VEC == 4
typedef int4 ivec;
#define EVEN_BEAMS(p) ((float4)((float)(p)[0], (float)(p)[2 * N_SAMPLES], (float)(p)[4 * N_SAMPLES], \
                                (float)(p)[6 * N_SAMPLES]))
#define ODD_BEAMS(p) EVEN_BEAMS((p) + N_SAMPLES)
#elif VEC == 8
typedef int8 ivec;
#define EVEN_BEAMS(p) ((float8)((float)(p)[0], (float)(p)[2 * N_SAMPLES], (float)(p)[4 * N_SAMPLES], \
                                (float)(p)[6 * N_SAMPLES], (float)(p)[8 * N_SAMPLES], (float)(p)[10 * N_SAMPLES], \
                                (float)(p)[12 * N_SAMPLES], (float)(p)[14 * N_SAMPLES]))
#define ODD_BEAMS(p) EVEN_BEAMS((p) + N_SAMPLES)
#endif
#if VEC > 1
typedef union { ivec v; int s[VEC]; } ilanes_t;
#endif
/* |x| and max by the ternary (PoCL may call fabs / fmax out of line) */
#define ABSV(x) ((x) < 0.0f ? -(x) : (x))
#define MAXV(a, b) ((a) > (b) ? (a) : (b))

/* Lanes times one scalar twiddle t. */
inline cvec cmul_tw(cvec a, float2 t)
{
    return (cvec)(a.lo * t.x - a.hi * t.y, a.lo * t.y + a.hi * t.x);
}

/* Lanes times -i: the forward radix-4 quarter turn, exact. */
inline cvec cmul_minus_i_v(cvec a)
{
    return (cvec)(a.hi, -a.lo);
}

/* Read one sample as float, set flags for NaN/Inf, out-of-range values and clipping, and keep
 * the largest |sample| loaded (for the pair check). A NaN, Inf or out-of-range sample enters
 * the FFT as 0, so it cannot spoil the paired beam. */
inline float load_part(float v, float clip_level, int *bad, float *peak)
{
#if CHECK_FINITE
    if (!isfinite(v)) { *bad |= FLAG_NONFINITE; return 0.0f; }
    if (v > SAMPLE_LIMIT || v < -SAMPLE_LIMIT) { *bad |= FLAG_OVERRANGE; return 0.0f; }
#endif
    const float m = v < 0.0f ? -v : v;
    if (m >= clip_level) *bad |= FLAG_CLIPPED;
    if (m > *peak) *peak = m;
    return v;
}

/* Sample row j of the group's jobs into the P blocks: buf[q M + j] = w_j z_j W_N^{j q}. */
inline void put_row(WORK cvec *buf, int j, cvec z, const __global float *window, const __global float2 *twiddle)
{
#if WINDOWED
    if (j < N_SAMPLES) z *= window[j];
#endif
    buf[j] = z;
    for (int q = 1; q < P; q++)
        buf[q * M + j] = cmul_tw(z, twiddle[j * q]);
}

/* |x| or |x|^2 per lane. */
inline rvec detect(cvec x)
{
    const rvec p = x.lo * x.lo + x.hi * x.hi;
#if POWER
    return p;
#else
    return sqrt(p);
#endif
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
    __global uchar *flags,            /* (n_beams) FLAG_* bits */
    __global cvec *scratch)           /* (work-groups, 2, N_FFT) work buffers if SCRATCH_GLOBAL, else unused */
{
#if SCRATCH_GLOBAL
    __global cvec *buf0 = scratch + (size_t)get_group_id(0) * (2 * N_FFT);
    __global cvec *buf1 = buf0 + N_FFT;
#else
    __local cvec buf0[N_FFT];
    __local cvec buf1[N_FFT];
#endif
    __local int job_flags[BEAMS_PER_JOB * VEC];
    __local int job_peak[BEAMS_PER_JOB * VEC];       /* largest |sample| loaded, float bits */

    const int lid = get_local_id(0);
    const int beam0 = get_group_id(0) * VEC * BEAMS_PER_JOB;   /* first beam of lane 0 */

    if (lid == 0)                                               /* local size may be 1 */
        for (int b = 0; b < BEAMS_PER_JOB * VEC; b++) job_flags[b] = job_peak[b] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);

    /* Load each sample once: buf0[q M + j] = w_j z_j W_N^{j q} for the P blocks, zero beyond
     * the samples and beyond the last beam. */
#if !COMPLEX_INPUT && VEC > 1
    /* A group whose beams all exist (all but perhaps the last): each sample row loaded as two
     * vectors, the even and the odd beams, with the checks and the peaks per lane (lane by lane
     * with branches, as below, the loads took half the kernel's time). The same values and
     * flags as the general path: the clip test is max |sample| >= clip_level. */
    if (beam0 + 2 * VEC <= n_beams) {
        const __global sample_t *s0 = samples + (size_t)beam0 * N_SAMPLES;
        rvec peak_a = 0.0f, peak_b = 0.0f;
#if CHECK_FINITE
        ivec nonfinite_a = 0, nonfinite_b = 0, over_a = 0, over_b = 0;
#endif
        for (int j = lid; j < M; j += LOCAL_SIZE) {
            rvec a = 0.0f, b = 0.0f;
            if (j < N_SAMPLES) {
                a = EVEN_BEAMS(s0 + j);
                b = ODD_BEAMS(s0 + j);
#if CHECK_FINITE
                const ivec inf_a = ABSV(a) == INFINITY, nan_a = a != a;
                const ivec inf_b = ABSV(b) == INFINITY, nan_b = b != b;
                const ivec big_a = ABSV(a) > SAMPLE_LIMIT & ~inf_a, big_b = ABSV(b) > SAMPLE_LIMIT & ~inf_b;
                nonfinite_a |= inf_a | nan_a;
                nonfinite_b |= inf_b | nan_b;
                over_a |= big_a & ~nan_a;
                over_b |= big_b & ~nan_b;
                a = (inf_a | nan_a | big_a) ? (rvec)0.0f : a;       /* enters the FFT as 0 */
                b = (inf_b | nan_b | big_b) ? (rvec)0.0f : b;
#endif
                peak_a = MAXV(peak_a, ABSV(a));
                peak_b = MAXV(peak_b, ABSV(b));
            }
            put_row(buf0, j, (cvec)(a, b), window, twiddle);
        }
        lanes_t pa, pb;
        pa.v = peak_a;
        pb.v = peak_b;
#if CHECK_FINITE
        ilanes_t na, nb, oa, ob;
        na.v = nonfinite_a; nb.v = nonfinite_b; oa.v = over_a; ob.v = over_b;
#endif
        for (int l = 0; l < VEC; l++) {
            int fa = pa.s[l] >= clip_level ? FLAG_CLIPPED : 0, fb = pb.s[l] >= clip_level ? FLAG_CLIPPED : 0;
#if CHECK_FINITE
            fa |= (na.s[l] ? FLAG_NONFINITE : 0) | (oa.s[l] ? FLAG_OVERRANGE : 0);
            fb |= (nb.s[l] ? FLAG_NONFINITE : 0) | (ob.s[l] ? FLAG_OVERRANGE : 0);
#endif
            if (fa) atomic_or(&job_flags[2 * l], fa);
            if (fb) atomic_or(&job_flags[2 * l + 1], fb);
            if (pa.s[l] > 0.0f) atomic_max(&job_peak[2 * l], as_int(pa.s[l]));
            if (pb.s[l] > 0.0f) atomic_max(&job_peak[2 * l + 1], as_int(pb.s[l]));
        }
    } else
#endif
    {
        int bad[BEAMS_PER_JOB * VEC];
        float peak[BEAMS_PER_JOB * VEC];
        for (int b = 0; b < BEAMS_PER_JOB * VEC; b++) { bad[b] = 0; peak[b] = 0.0f; }
        for (int j = lid; j < M; j += LOCAL_SIZE) {
            lanes_t re, im;
            for (int l = 0; l < VEC; l++) {
                const int beam = beam0 + l * BEAMS_PER_JOB;
                float a = 0.0f, b = 0.0f;
                if (j < N_SAMPLES && beam < n_beams) {
#if COMPLEX_INPUT
                    const float2 s = samples[(size_t)beam * N_SAMPLES + j];
                    a = load_part(s.x, clip_level, &bad[l], &peak[l]);
                    b = load_part(s.y, clip_level, &bad[l], &peak[l]);
#else
                    a = load_part((float)samples[(size_t)beam * N_SAMPLES + j], clip_level, &bad[2 * l],
                                  &peak[2 * l]);
                    if (beam + 1 < n_beams)
                        b = load_part((float)samples[(size_t)(beam + 1) * N_SAMPLES + j], clip_level,
                                      &bad[2 * l + 1], &peak[2 * l + 1]);
#endif
                }
                re.s[l] = a;
                im.s[l] = b;
            }
            put_row(buf0, j, (cvec)(re.v, im.v), window, twiddle);
        }
        for (int b = 0; b < BEAMS_PER_JOB * VEC; b++) {
            if (bad[b]) atomic_or(&job_flags[b], bad[b]);
            if (peak[b] > 0.0f) atomic_max(&job_peak[b], as_int(peak[b]));   /* >= 0: int order = float order */
        }
    }
    barrier(WORK_FENCE);
#if !COMPLEX_INPUT
    /* The weaker beam of a pair takes the stronger's rounding (oracle.beam_flags). The passes
     * below end with barriers, so the store sees these flags. */
    if (lid == 0)
        for (int l = 0; l < VEC; l++) {
            const float pa = as_float(job_peak[2 * l]), pb = as_float(job_peak[2 * l + 1]);
            if (pa > PAIR_RATIO * pb) job_flags[2 * l + 1] |= FLAG_CROSSTALK;
            if (pb > PAIR_RATIO * pa) job_flags[2 * l] |= FLAG_CROSSTALK;
        }
#endif

    /* Stockham passes over the P blocks at once; p = length of the finished sub-transforms. */
    WORK cvec *src = buf0;
    WORK cvec *dst = buf1;
    int p = 1;
#if LOG2_M & 1
    for (int i = lid; i < N_FFT / 2; i += LOCAL_SIZE) {
        const int base = (i >> (LOG2_M - 1)) << LOG2_M;   /* block q * M */
        const int ii = i & (M / 2 - 1);
        const cvec u0 = src[base + ii];
        const cvec u1 = src[base + ii + M / 2];
        dst[base + 2 * ii] = u0 + u1;                      /* p = 1: no twiddle */
        dst[base + 2 * ii + 1] = u0 - u1;
    }
    barrier(WORK_FENCE);
    { WORK cvec *t = src; src = dst; dst = t; }
    p = 2;
#endif
#if LOG2_M >= 2
    for (; p < M; p <<= 2) {
        const int tw_step = N_FFT / (4 * p);                /* W_{4p}^k = W_N^{k N / 4p} */
        for (int i = lid; i < N_FFT / 4; i += LOCAL_SIZE) {
            const int base = (i >> (LOG2_M - 2)) << LOG2_M;
            const int ii = i & (M / 4 - 1);
            const int k = ii & (p - 1);
            const int t = k * tw_step;
            const cvec u0 = src[base + ii];
            const cvec u1 = cmul_tw(src[base + ii + M / 4], twiddle[t]);
            const cvec u2 = cmul_tw(src[base + ii + M / 2], twiddle[2 * t]);
            const cvec u3 = cmul_tw(src[base + ii + 3 * M / 4], twiddle[3 * t]);
            const cvec v0 = u0 + u2, v1 = u0 - u2, v2 = u1 + u3, v3 = cmul_minus_i_v(u1 - u3);
            const int j = base + ((ii - k) << 2) + k;
            dst[j] = v0 + v2;
            dst[j + p] = v1 + v3;
            dst[j + 2 * p] = v0 - v2;
            dst[j + 3 * p] = v1 - v3;
        }
        barrier(WORK_FENCE);
        { WORK cvec *t = src; src = dst; dst = t; }
    }
#endif

    /* Store: Z[P m + q] sits at src[q M + m]. */
    if (lid == 0)
        for (int b = 0; b < BEAMS_PER_JOB * VEC; b++)
            if (beam0 + b < n_beams) flags[beam0 + b] = (uchar)job_flags[b];
    for (int k = lid; k < N_BINS; k += LOCAL_SIZE) {
        const cvec zk = src[((k & (P - 1)) << LOG2_M) + (k >> LOG2_P)];
        const float s = scale[k];
        lanes_t va, vb;
#if COMPLEX_INPUT
        va.v = detect(zk) * s;
#else
        const int kn = (N_FFT - k) & (N_FFT - 1);
        const cvec zn_raw = src[((kn & (P - 1)) << LOG2_M) + (kn >> LOG2_P)];
        const cvec zn = (cvec)(zn_raw.lo, -zn_raw.hi);          /* conj Z[N-k] */
        va.v = detect(0.5f * (zk + zn)) * s;
        vb.v = detect(cmul_minus_i_v(0.5f * (zk - zn))) * s;
#endif
        for (int l = 0; l < VEC; l++) {
            const int beam = beam0 + l * BEAMS_PER_JOB;
            if (beam < n_beams)
                profiles[(size_t)beam * N_BINS + k] =
                    (job_flags[l * BEAMS_PER_JOB] & (FLAG_NONFINITE | FLAG_OVERRANGE)) ? NAN : va.s[l];
#if !COMPLEX_INPUT
            if (beam + 1 < n_beams)
                profiles[(size_t)(beam + 1) * N_BINS + k] =
                    (job_flags[2 * l + 1] & (FLAG_NONFINITE | FLAG_OVERRANGE)) ? NAN : vb.s[l];
#endif
        }
    }
}
