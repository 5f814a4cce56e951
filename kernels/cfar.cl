/* CFAR detection of a whole frame of power profiles in one launch (paper §3.3, Fig. 6).
 *
 * Equivalent to radarcl.oracle.cfar(profiles, config) in float32, edge rule "shift": every
 * cell uses exactly 2*TRAIN training cells inside the profile; the cells one side lacks near
 * an end are taken further out on the other side, outside the guard band (see
 * oracle.training_cells). The estimate is summed directly from the cells, never from
 * running or prefix sums, so a 120 dB echo elsewhere in the profile cannot cancel the digits of
 * a weak window.
 *
 * Work mapping: get_global_id(1) = beam; get_global_id(0) = g handles the VEC bins
 * g*VEC .. g*VEC+VEC-1, one per SIMD lane (PoCL does not vectorise this loop across
 * work-items by itself; GPUs take VEC = 1). Groups whose windows all lie inside the profile take
 * the vector path; the few at the ends take a vector path of their own (each cell broadcast to
 * the lanes whose windows hold it), except for OS-CFAR, and the tail past N_BINS goes lane by
 * lane through cfar_bin. All sum the cells in the same order, so the result does not depend on
 * the path (tests/test_cfar.py compares them bit for bit). Any local size works.
 *
 * -D constants (set by radarcl/stages/cfar.py):
 *   N_BINS        bins per profile, >= 1 + 2 GUARD + 2 TRAIN
 *   GUARD, TRAIN  guard and training cells per side
 *   KIND          0 CA (mean of all), 1 GO (greater half mean), 2 SO (smaller), 3 OS (rank)
 *   RANK          OS only: the k-th smallest training cell (1-based) is the estimate
 *   VEC           bins per work-item: 1, 2, 4, 8 or 16
 */
#include "radarcl_common.h"

#define KIND_CA 0
#define KIND_GO 1
#define KIND_SO 2
#define KIND_OS 3
#define N_TRAIN (2 * TRAIN)

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#if VEC == 1
typedef float floatv;
typedef int intv;
#define VLOAD(p) (*(p))
#define VSTORE(v, p) (*(p) = (v))
#define VTRUE(c) (c)
#else
typedef CAT(float, VEC) floatv;
typedef CAT(int, VEC) intv;
#define VLOAD(p) CAT(vload, VEC)(0, p)
#define VSTORE(v, p) CAT(vstore, VEC)(v, 0, p)
#define VTRUE(c) (-(c))             /* vector comparisons give -1 for true */
#endif
#define STRUE(c) (c)                 /* scalar comparisons give 1 for true */
#if VEC == 2
#define LANE_IDS ((int2)(0, 1))
#elif VEC == 4
#define LANE_IDS ((int4)(0, 1, 2, 3))
#elif VEC == 8
#define LANE_IDS ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#elif VEC == 16
#define LANE_IDS ((int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#endif
#define as_floatv CAT(as_float, VEC)
#define as_intv CAT(as_int, VEC)
/* min / max / clamp by the ternary (PoCL may call the builtins out of line) */
#define MINV(a, b) ((a) < (b) ? (a) : (b))
#define MAXV(a, b) ((a) > (b) ? (a) : (b))
#define CLAMPV(x, a, b) MINV(MAXV(x, a), b)
#define MINI(a, b) ((a) < (b) ? (a) : (b))
#define MAXI(a, b) ((a) > (b) ? (a) : (b))

/* The estimate of the cells c[0 .. 2 TRAIN-1] (increasing position; the first TRAIN are the
 * lower half). Written once for scalars and vectors of bins alike. */
#define ESTIMATE(T_FLOAT, T_INT, TRUE_IS_ONE, c, out)                                         \
    do {                                                                                      \
        if (KIND == KIND_OS) {                                                                \
            /* The k-th smallest: the cell c with #(x < c) < RANK <= #(x <= c). Counting keeps \
             * the trip counts fixed; NaN compares false and so ranks last, as in numpy's      \
             * sort; no such cell (too many NaN) leaves NaN. */                                \
            out = (T_FLOAT)(NAN);                                                             \
            for (int a = 0; a < N_TRAIN; a++) {                                               \
                T_INT less = 0, less_equal = 0;                                               \
                for (int b = 0; b < N_TRAIN; b++) {                                           \
                    less += TRUE_IS_ONE(c[b] < c[a]);                                         \
                    less_equal += TRUE_IS_ONE(c[b] <= c[a]);                                  \
                }                                                                             \
                out = select(out, c[a], TRUE_IS_ONE(less < RANK && RANK <= less_equal) != 0); \
            }                                                                                 \
        } else {                                                                              \
            T_FLOAT lower = 0.0f, upper = 0.0f;                                               \
            for (int u = 0; u < TRAIN; u++)                                                   \
                lower += c[u];                                                                \
            for (int u = TRAIN; u < N_TRAIN; u++)                                             \
                upper += c[u];                                                                \
            HALVES_TO_ESTIMATE(T_FLOAT, lower, upper, out);                                   \
        }                                                                                     \
    } while (0)

/* CA, GO or SO from the sums of the lower and upper halves. GO takes the greater half, SO the
 * smaller; a NaN half gives NaN (fmax/fmin would drop it, the oracle keeps it). */
#define HALVES_TO_ESTIMATE(T_FLOAT, lower, upper, out)                                         \
    do {                                                                                      \
        if (KIND == KIND_CA) {                                                                \
            out = (lower + upper) * (1.0f / N_TRAIN);                                         \
        } else {                                                                              \
            T_FLOAT pick = (KIND == KIND_GO) ? select(upper, lower, lower > upper)            \
                                             : select(upper, lower, lower < upper);           \
            out = select(pick, (T_FLOAT)(NAN), isnan(lower) || isnan(upper)) * (1.0f / TRAIN);\
        }                                                                                     \
    } while (0)

/* One bin, any position: the windows follow the "shift" edge rule. */
inline void cfar_bin(const __global float *p, int i, float alpha, float noise_floor,
                     __global float *noise, __global float *ratio, __global uchar *mask)
{
    /* Training cells u < n_below lie below the guard band, at below0 + u; the rest above it,
     * at above0 + u. */
    const int have_below = clamp(i - GUARD, 0, TRAIN);
    const int have_above = clamp(N_BINS - 1 - i - GUARD, 0, TRAIN);
    const int n_below = have_below + (TRAIN - have_above);
    const int below0 = i - GUARD - n_below;
    const int above0 = i + GUARD + 1 - n_below;
    float estimate;
#if KIND == KIND_OS
    float c[N_TRAIN];
    for (int u = 0; u < N_TRAIN; u++)
        c[u] = p[u < n_below ? below0 + u : above0 + u];
    ESTIMATE(float, int, STRUE, c, estimate);
#else
    /* the same cells summed as ESTIMATE sums them, without the private array (an edge bin
     * took 4x an interior one with it) */
#if KIND == KIND_CA
    /* CA needs no halves: the two contiguous runs, cells below0 .. below0 + n_below - 1 and
     * above0 + n_below .. above0 + N_TRAIN - 1 */
    float below = 0.0f, above = 0.0f;
    for (int u = 0; u < n_below; u++)
        below += p[below0 + u];
    for (int u = n_below; u < N_TRAIN; u++)
        above += p[above0 + u];
    HALVES_TO_ESTIMATE(float, below, above, estimate);
#else
    float lower = 0.0f, upper = 0.0f;
    for (int u = 0; u < TRAIN; u++)
        lower += p[u < n_below ? below0 + u : above0 + u];
    for (int u = TRAIN; u < N_TRAIN; u++)
        upper += p[u < n_below ? below0 + u : above0 + u];
    HALVES_TO_ESTIMATE(float, lower, upper, estimate);
#endif
#endif
    /* Comparisons, not fmax/fmin, so that NaN propagates as in the oracle. */
    const float n = estimate < noise_floor ? noise_floor : estimate;
    const float r = p[i];
    const float q = r / n;
    noise[i] = n;
    ratio[i] = q > FLT_MAX ? FLT_MAX : q;
    mask[i] = r > alpha * n;
}

__kernel void cfar(
    const __global float *profiles,   // (n_beams, N_BINS) power r_i [linear]
    const float alpha,                // threshold factor on the estimate (design P_fa)
    const float noise_floor,          // the estimate is at least this [power]
    const int n_beams,                // beams in the frame
    __global float *noise,            // (n_beams, N_BINS) out: n_i = max(estimate, floor)
    __global float *ratio,            // (n_beams, N_BINS) out: r_i / n_i, at most FLT_MAX
    __global uchar *mask)             // (n_beams, N_BINS) out: 1 where r_i > alpha n_i
{
    const int i0 = get_global_id(0) * VEC;
    const int beam = get_global_id(1);
    if (i0 >= N_BINS || beam >= n_beams)
        return;
    const size_t row = (size_t)beam * N_BINS;
    const __global float *p = profiles + row;
    noise += row;
    ratio += row;
    mask += row;

    floatv estimate;
    if (i0 - GUARD - TRAIN < 0 || i0 + VEC - 1 + GUARD + TRAIN > N_BINS - 1) {
#if KIND == KIND_OS || VEC == 1
        for (int lane = 0; lane < VEC && i0 + lane < N_BINS; lane++)
            cfar_bin(p, i0 + lane, alpha, noise_floor, noise, ratio, mask);
        return;
#else
        if (i0 + VEC > N_BINS) {              /* the tail group: lane by lane */
            for (int lane = 0; lane < VEC && i0 + lane < N_BINS; lane++)
                cfar_bin(p, i0 + lane, alpha, noise_floor, noise, ratio, mask);
            return;
        }
        /* An edge group as vectors: each lane's window is two runs of cells (cfar_bin's), and
         * every cell of the group's span is broadcast to the lanes whose runs hold it, added
         * in increasing position as cfar_bin adds them, so the sums are bit for bit
         * cfar_bin's. Lane by lane, these groups took 60 % of the kernel's time. */
        const intv i = i0 + LANE_IDS;
        const intv have_below = CLAMPV(i - GUARD, 0, TRAIN);
        const intv have_above = CLAMPV(N_BINS - 1 - i - GUARD, 0, TRAIN);
        const intv n_below = have_below + (TRAIN - have_above);
        const intv s1 = i - GUARD - n_below, e1 = i - GUARD;          /* run 1: [s1, e1) */
        const intv s2 = i + GUARD + 1, e2 = s2 + (N_TRAIN - n_below);  /* run 2: [s2, e2) */
#if KIND == KIND_CA
        /* CA sums the runs as cfar_bin does: below = run 1, above = run 2 */
        const intv l1 = s1, l2 = e1, l3 = s2, l4 = s2;                /* lower half: run 1 */
#else
        /* GO / SO: the lower half is the window's first TRAIN cells, the upper the rest */
        const intv l2 = MINV(e1, s1 + TRAIN), l1 = s1;
        const intv l3 = s2, l4 = s2 + MAXV(TRAIN - n_below, 0);
#endif
        const int lo = MAXI(i0 - GUARD - N_TRAIN, 0), hi = MINI(i0 + VEC - 1 + GUARD + N_TRAIN, N_BINS - 1);
        floatv lower = 0.0f, upper = 0.0f;
        for (int c = lo; c <= hi; c++) {
            const floatv x = (floatv)(p[c]);
            const intv in1 = (c >= s1) & (c < e1), in2 = (c >= s2) & (c < e2);
            const intv low = ((c >= l1) & (c < l2)) | ((c >= l3) & (c < l4));
            lower += as_floatv(as_intv(x) & (low & (in1 | in2)));
            upper += as_floatv(as_intv(x) & (~low & (in1 | in2)));
        }
        HALVES_TO_ESTIMATE(floatv, lower, upper, estimate);
#endif
    } else {                                  /* an interior group: straight vector loads */
#if KIND == KIND_OS
        floatv c[N_TRAIN];
        for (int u = 0; u < TRAIN; u++) {
            c[u] = VLOAD(p + i0 - GUARD - TRAIN + u);
            c[TRAIN + u] = VLOAD(p + i0 + GUARD + 1 + u);
        }
        ESTIMATE(floatv, intv, VTRUE, c, estimate);
#else
        /* Summed straight from the loads: a private array of cells costs PoCL a copy per
         * work-item. Same order as in cfar_bin. */
        floatv lower = 0.0f, upper = 0.0f;
        for (int u = 0; u < TRAIN; u++)
            lower += VLOAD(p + i0 - GUARD - TRAIN + u);
        for (int u = 0; u < TRAIN; u++)
            upper += VLOAD(p + i0 + GUARD + 1 + u);
        HALVES_TO_ESTIMATE(floatv, lower, upper, estimate);
#endif
    }
    const floatv n = select(estimate, (floatv)(noise_floor), estimate < noise_floor);
    const floatv r = VLOAD(p + i0);
    const floatv q = r / n;
    VSTORE(n, noise + i0);
    VSTORE(select(q, (floatv)(FLT_MAX), q > FLT_MAX), ratio + i0);
#if VEC == 1
    mask[i0] = r > alpha * n;
#else
    CAT(vstore, VEC)(CAT(convert_uchar, VEC)(-(r > alpha * n)), 0, mask + i0);
#endif
}
