/* The down-range interpreter, eq. 12, on a whole frame in one launch (paper §3.3, Fig. 10).
 *
 * Equivalent to radarcl.oracle.interpret(profiles, noise, mask, config, bin_spacing, flags):
 *   pulse bins (mask = 1):                  k_occ * log10(r / n), clamped to [0, 16 nat]
 *   noise bins before the first wide pulse: E_h;   after its last bin: E_l
 *   bins outside [FIRST_BIN, LAST_BIN]:     0
 * in int32 fixed-point log-odds (radarcl.logodds: LOGODDS_SCALE units per nat, rounded to
 * nearest even). Pulses are runs of detections inside [FIRST_BIN, LAST_BIN]; a pulse of at
 * least WIDE_BINS bins is wide (physics.wide_pulse_width). log10(r) - log10(n) instead of
 * log10(r / n): the ratio of a 1e30 echo over a floored noise overflows float32, the logs never.
 *
 * Work mapping: get_global_id(0) = beam. One work-item walks its beam's bins in order, since
 * whether a noise bin gets E_h or E_l depends on every pulse before it; a frame has 256 beams of
 * 512 bins, a fraction of the CFAR's work. Any local size works.
 *
 * Beams flagged upstream with a NO_EVIDENCE_FLAGS flag, or found here to hold a NaN, Inf,
 * negative or larger than PROFILE_LIMIT bin (FLAG_BAD_PROFILE: CFAR's float32 sums would
 * overflow) or only zeros (FLAG_SILENT), give 0 evidence and no pulses.
 *
 * With -D OCCLUSION=1, the occlusion-aware variant (beyond the paper; radarcl's own):
 *   noise bins before the first SURFACE: E_h interpolated in range, e_high at first_bin to
 *       e_high_far at last_bin (integer arithmetic, truncated: "no echo" means less far away,
 *       where a surface's echo may be below the noise);
 *   noise bins after it: E_l (0 or a weak value chosen by calibration: behind the first
 *       surface the radar cannot tell);
 *   a pulse is a surface when it is wide (the paper's rule) or its peak log10(r / n) reaches
 *   surface_decades (a calibrated test: a strong narrow echo is a tree, a post, a drum).
 * OCCLUSION=0 is eq. 12 exactly; e_high_far and surface_decades are then unused.
 *
 * With -D DETSTATS=1, the detection-statistics model (radarcl.sensor_model; equivalent to
 * radarcl.oracle.interpret_detstats; -D NODES is sensor_model.NODES, the rho2 nodes per class):
 * evidence[] is (n_beams, N_BINS, 2 classes, 4 segments)
 * int2 node pairs (sensor_model.pack_nodes) of the evidence e [logodds units] and the detection
 * opportunity d [KNOWLEDGE_SCALE units] at rho2 = 0, 1/4, ..., 1, per class of target:
 *   tau = exp(-X), X the blocking of the pulses that ended before the bin (a pulse's summed
 *       (r/n - 1)+ times blocking[] at its peak); delta = tau opportunity[bin, class, node];
 *   no detection: e = ln(1 - delta) = ln((1 - tau) + tau miss[bin, class, node]);
 *   detection: e = ln(1 + delta (r / r_peak) c_det), c_det = (1 - P_fa) / P_fa;
 *   d = delta.
 * Until the first pulse (tau = 1) a noise bin copies unblocked[] (the host's exact nodes).
 * Logs without builtins (log10_nb); one exp and expm1 per pulse. eq. 12's constants are unused.
 *
 * With -D GRADED=1 as well ("snr" evidence, radarcl.sensor_model.SnrTable), every bin's e is
 * read from the table of the measured power instead: x = r / N, N the beam's noise floor (the
 * ((last - first + 1) / 2)-th smallest power of the window, found exactly by bisection on the
 * float's bits, / ln 2, at least noise_floor); e = table(ln x, ln tau + ln_snr[bin, class, node]),
 * bilinear on the SNR_U x SNR_V grid, clamped to it; a pulse blocks by its summed (x - 1)+; d as
 * above. Bins of a pulse take the tau in front of it, as without GRADED. Behind nearer echoes
 * (blocked > 0) with blocker_gap g > 0 (a partial blocker): L_b and L_0 from the table read at
 * ln tau + ln_snr and at ln_snr, e = ln(L / (1 - q + q L)) of L = (1 - g) L_b + g L_0, and d =
 * ((1 - w) tau + w) delta where the gap's posterior w = g L_0 / L is above 1/2 (exp_nb8, log10_nb8).
 * Every look's e lies within +-known x snr_cap[bin, class, node] (tau, or the gap's, times what a
 * detection says at the node's opportunity: snr_evidence.bounded). A node whose d rounds to 0
 * gets e = 0, with either evidence (the reading counts only looks with knowledge). Two launches:
 * interpret walks each beam (flags, pulses, the floor and each bin's blocked and tau, into
 * state[] and ln_floors[]), then interpret_nodes computes the nodes, eight bins a work-item.
 *
 * -D constants (set by radarcl/stages/interpret.py):
 *   N_BINS      bins per profile
 *   MAX_PULSES  pulse rows kept per beam; more are counted and still give evidence
 *   OCCLUSION   0: the paper's eq. 12; 1: the occlusion-aware variant above
 *   DETSTATS    0, or 1: the detection-statistics model above (with OCCLUSION 0)
 *   GRADED      DETSTATS only: 0, or 1 for "snr" evidence; SNR_NU, SNR_NV, SNR_U0, SNR_V0 and
 *               SNR_U_SCALE, SNR_V_SCALE (grid points per unit of u, v) give its table's grid,
 *               GAP_CAP (snr_evidence.GAP_CAP) the gap mixture's cap on e^e below 1 / q
 */
#include "radarcl_common.h"

/* 1 where any of the eight mask bytes at p is set: two 32-bit words, since 64-bit integers are
 * optional on embedded-profile devices (compilers join the two into one 64-bit test where they can) */
static inline uint any8(const __global uchar *p)
{
    const uint2 w = as_uint2(vload8(0, p));
    return (w.x | w.y) != 0u;
}

/* log10 of x >= 0 without a builtin call (PoCL may call its builtins out of line): the
 * exponent, and ln of the mantissa in [sqrt(1/2), sqrt(2)) by the atanh series to t^9 (error
 * < 1e-9); float32 rounding of the sum dominates, ~4e-6 decades at 1e38, 1e-7 near 1.
 * Subnormals are scaled by 2^64 first; log10(0) = -inf as log10's. */
static inline float log10_nb(float x)
{
    int bias = 0;
    if (x < 1.17549435e-38f) {                  /* FLT_MIN */
        if (x <= 0.0f)
            return x == 0.0f ? -INFINITY : NAN;
        x *= 18446744073709551616.0f;          /* 2^64 */
        bias = -64;
    }
    const int i = as_int(x);
    int e = ((i >> 23) & 255) - 127 + bias;
    float m = as_float((i & 0x7FFFFF) | 0x3F800000);
    if (m > 1.41421356f) {
        m *= 0.5f;
        e += 1;
    }
    const float t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
    const float ln_m = 2.0f * t * (1.0f + t2 * (1.0f / 3.0f + t2 * (0.2f + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f)))));
    return (float)e * 0.30102999566f + ln_m * 0.43429448190f;
}

/* log10_nb on eight bins at once, lane for lane the same floats (the same operations, the
 * branches as selects): a chunk of bins holding a detection takes its logs this way. */
static inline float8 log10_nb8(float8 x)
{
    const int8 sub = x < 1.17549435e-38f;                       /* FLT_MIN; also 0 and below */
    const float8 xs = sub ? x * 18446744073709551616.0f : x;     /* 2^64 */
    const int8 i = as_int8(xs);
    int8 e = ((i >> 23) & 255) - 127 + (sub & -64);
    float8 m = as_float8((i & 0x7FFFFF) | 0x3F800000);
    const int8 big = m > 1.41421356f;
    m = big ? m * 0.5f : m;
    e -= big;                                                    /* big is -1 */
    const float8 t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
    const float8 ln_m = 2.0f * t * (1.0f + t2 * (1.0f / 3.0f + t2 * (0.2f + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f)))));
    const float8 y = convert_float8(e) * 0.30102999566f + ln_m * 0.43429448190f;
    return x == 0.0f ? (float8)(-INFINITY) : (x < 0.0f ? (float8)(NAN) : y);
}

#if DETSTATS
#define NODE_WORDS 8                  /* int2 per bin: 2 classes x 4 segments */
#define LN10 2.302585093f

/* a node value in fixed point: rint(clamp(v, -limit, limit) x scale), without builtins */
static inline int fixed_nb(float v, float scale)
{
    v = v > EVIDENCE_LIMIT_NATS ? EVIDENCE_LIMIT_NATS : (v < -EVIDENCE_LIMIT_NATS ? -EVIDENCE_LIMIT_NATS : v);
    return as_int(v * scale + 12582912.0f) - 0x4B400000;       /* rint, half to even, as logodds.to_fixed */
}

/* one bin's node pairs: for each class, the five nodes of e and d packed per segment */
static inline void write_nodes(__global int2 *out, const __global float *opp, const __global float *miss,
                               float tau, float omt, int detected, float share_c)
{
    for (int c = 0; c < 2; ++c) {
        int e[NODES], d[NODES];
        for (int k = 0; k < NODES; ++k) {
            const float delta = tau * opp[c * NODES + k];
            const float arg = detected ? 1.0f + delta * share_c : omt + tau * miss[c * NODES + k];
            d[k] = as_int(delta * (float)KNOWLEDGE_SCALE + 12582912.0f) - 0x4B400000;
            e[k] = d[k] ? fixed_nb(log10_nb(arg) * LN10, LOGODDS_SCALE) : 0;   /* no look, no evidence */
        }
        for (int k = 0; k < 4; ++k)
            out[c * 4 + k] = (int2)((e[k] & 0xFFFF) | (e[k + 1] << 16), (d[k] & 0xFFFF) | (d[k + 1] << 16));
    }
}

#if GRADED
/* the k-th smallest (0-based) of r[first .. last], exactly: bisection on the bits of the
 * non-negative floats (ordered as their bits; -0.0, which the profile check lets through, is
 * counted as +0.0 by dropping the sign bit), counting eight bins at a time */
static float kth_power(const __global float *r, int first, int last, int k)
{
    uint lo = 0u, hi = 0x7F800000u;             /* +inf: every checked profile lies below */
    while (lo < hi) {
        const uint mid = lo + ((hi - lo) >> 1);
        int8 below8 = 0;
        int j = first;
        for (; j + 8 <= last + 1; j += 8)
            below8 += as_int8((as_uint8(vload8(0, r + j)) & 0x7FFFFFFFu) <= (uint8)mid);   /* -1 where true */
        int below = -(below8.s0 + below8.s1 + below8.s2 + below8.s3 + below8.s4 + below8.s5 + below8.s6 + below8.s7);
        for (; j <= last; j++)
            below += (as_uint(r[j]) & 0x7FFFFFFFu) <= mid;
        if (below >= k + 1)
            hi = mid;
        else
            lo = mid + 1u;
    }
    return as_float(lo);
}

/* "snr" evidence's nodes, eight bins at a time (interpret_nodes): each function below is the
 * scalar computation written once over float8 lanes, the branches as selects, so that every
 * lane computes the floats one bin's scalar code would (the same operations in the same order,
 * and so the same contractions); ternaries on vectors select per lane, without builtins. */
#define GATHER8(p, i) ((float8)(p[(i).s0], p[(i).s1], p[(i).s2], p[(i).s3], p[(i).s4], p[(i).s5], p[(i).s6], p[(i).s7]))
/* the floats at i and i + 1 of each lane, as (p[i.s0], p[i.s0 + 1], p[i.s1], ...): one two-float load a lane */
#define PAIRS8(p, i) ((float16)(vload2(0, p + (i).s0), vload2(0, p + (i).s1), vload2(0, p + (i).s2), vload2(0, p + (i).s3), \
                                vload2(0, p + (i).s4), vload2(0, p + (i).s5), vload2(0, p + (i).s6), vload2(0, p + (i).s7)))

/* a grid position clamped to [0, n - 1] (-inf and NaN to 0) */
static inline float8 grid_position8(float8 x, float x0, float scale, int n)
{
    const float8 f = (x - x0) * scale;
    return f > 0.0f ? (f < (float)(n - 1) ? f : (float8)(n - 1)) : (float8)0.0f;
}

/* the table's bilinear read at rows iu, iu + 1 (offsets i0 = iu * SNR_NV) and fraction du, column ln v */
static inline float8 table_at8(const __global float *table, int8 i0, float8 du, float8 lnv)
{
    const float8 fv = grid_position8(lnv, SNR_V0, SNR_V_SCALE, SNR_NV);
    const int8 t = convert_int8(fv);                   /* fv >= 0: truncation is floor */
    const int8 iv = t < SNR_NV - 2 ? t : (int8)(SNR_NV - 2);
    const float8 dv = fv - convert_float8(iv);
    const int8 a = i0 + iv, c = a + SNR_NV;
    const float16 lo = PAIRS8(table, a), hi = PAIRS8(table, c);      /* columns iv, iv + 1 of rows iu, iu + 1 */
    return (lo.even * (1.0f - dv) + lo.odd * dv) * (1.0f - du)
         + (hi.even * (1.0f - dv) + hi.odd * dv) * du;
}

/* e^x for x in [-87, 88]: 2^n e^r, n = rint(x / ln 2), |r| <= ln 2 / 2, e^r by its Taylor
 * series to r^7 (series error < 6e-9; r itself, x - n ln 2 in one float32 step, carries
 * ~ulp(n ln 2) / 2: 5e-7 relative at the table's |e| ~ 14, 4e-6 near 88) */
static inline float8 exp_nb8(float8 x)
{
    x = x > 88.0f ? (float8)88.0f : (x < -87.0f ? (float8)-87.0f : x);
    const float8 y = x * 1.44269504089f;
    const int8 n = as_int8(y + 12582912.0f) - 0x4B400000;        /* rint, as fixed_nb */
    const float8 r = x - convert_float8(n) * 0.69314718056f;
    const float8 p = 1.0f + r * (1.0f + r * (0.5f + r * (1.0f / 6.0f + r * (1.0f / 24.0f + r * (1.0f / 120.0f
                   + r * (1.0f / 720.0f + r * (1.0f / 5040.0f)))))));
    return p * as_float8((n + 127) << 23);
}

/* L of the evidence e = ln(L / (1 - q + q L)), e^e capped below its bound 1 / q (as
 * snr_evidence.likelihood_ratio; the mixture below as snr_evidence.gap_mixture) */
static inline float8 likelihood_ratio8(float8 e, float q)
{
    const float8 x = exp_nb8(e);
    const float most = (1.0f - GAP_CAP) / q;
    const float8 t = most < x ? (float8)most : x;
    return t * (1.0f - q) / (1.0f - q * t);
}

/* rint(clamp(v, -limit, limit) x scale), as fixed_nb */
static inline int8 fixed_nb8(float8 v, float scale)
{
    v = v > EVIDENCE_LIMIT_NATS ? (float8)EVIDENCE_LIMIT_NATS : (v < -EVIDENCE_LIMIT_NATS ? (float8)-EVIDENCE_LIMIT_NATS : v);
    return as_int8(v * scale + 12582912.0f) - 0x4B400000;
}

/* the node pairs of bins j0 .. j0 + 7 (lanes; the tail's at bins jt, the per-node tables (2, NODES,
 * N_BINS)) from the SNR table: u = ln x, ln tau = -blocked; behind nearer echoes (blocked > 0)
 * the mixture with a gap of chance gap (q: the table's); every look within its known share of
 * the node's cap, either way. Lanes not in `write` store nothing. */
static inline void write_graded8(__global int2 *out, int8 write, const __global float *ln_snr,
                                 const __global float *opportunity, const __global float *snr_cap,
                                 const __global float *table, int j0, int8 jt, float8 u, float8 blocked, float8 tau,
                                 float gap, float q)
{
    const float8 fu = grid_position8(u, SNR_U0, SNR_U_SCALE, SNR_NU);
    const int8 t = convert_int8(fu);
    const int8 iu = t < SNR_NU - 2 ? t : (int8)(SNR_NU - 2);
    const float8 du = fu - convert_float8(iu);
    const int8 i0 = iu * SNR_NV;
    const int8 behind = (gap > 0.0f ? (int8)-1 : (int8)0) & (blocked > 0.0f);
    for (int c = 0; c < 2; ++c) {
        int8 e[NODES], d[NODES];
        for (int k = 0; k < NODES; ++k) {
            const int node = (c * NODES + k) * N_BINS;
            const int whole = j0 + 8 <= N_BINS;
            const float8 opp = whole ? vload8(0, opportunity + node + j0) : GATHER8(opportunity, node + jt);
            const float8 ln_s = whole ? vload8(0, ln_snr + node + j0) : GATHER8(ln_snr, node + jt);
            const float8 cap = whole ? vload8(0, snr_cap + node + j0) : GATHER8(snr_cap, node + jt);
            /* knowledge is at most opp (tau, w <= 1): a node it rounds to 0 for is a look that is
             * not one, with no evidence (below); where it does in all eight bins (far bins of
             * the terrain class), nothing to compute */
            const int8 none = opp * (float)KNOWLEDGE_SCALE <= 0.5f;
            if (none.s0 & none.s1 & none.s2 & none.s3 & none.s4 & none.s5 & none.s6 & none.s7) {
                e[k] = d[k] = (int8)0;
                continue;
            }
            float8 v = table_at8(table, i0, du, ln_s - blocked);
            float8 known = tau;
            /* only behind an echo, and only for a target there is (ln_s at the table's first
             * column, e.g. terrain without a ground plane: both reads are 0, the mixture too);
             * the lanes of a node without one compute it and drop it */
            const int8 mix = behind & (ln_s > SNR_V0);
            if (mix.s0 | mix.s1 | mix.s2 | mix.s3 | mix.s4 | mix.s5 | mix.s6 | mix.s7) {
                const float8 lb = likelihood_ratio8(v, q);
                const float8 l0 = likelihood_ratio8(table_at8(table, i0, du, ln_s), q);
                const float8 lm = (1.0f - gap) * lb + gap * l0;
                const float8 w = gap * l0 / lm;       /* the gap's posterior chance */
                v = mix ? log10_nb8(lm / (1.0f - q + q * lm)) * LN10 : v;
                known = (mix & (w > 0.5f)) ? (1.0f - w) * tau + w : tau;   /* see the oracle */
            }
            const float8 most = known * cap;    /* no more than a detection would say, either way */
            v = v < most ? (v > -most ? v : -most) : most;
            d[k] = none ? (int8)0 : as_int8(known * opp * (float)KNOWLEDGE_SCALE + 12582912.0f) - 0x4B400000;
            e[k] = d[k] != 0 ? fixed_nb8(v, LOGODDS_SCALE) : (int8)0;   /* no evidence from a look that is not one */
        }
        int8 pe[4], pd[4];
        for (int k = 0; k < 4; ++k) {
            pe[k] = (e[k] & 0xFFFF) | (e[k + 1] << 16);
            pd[k] = (d[k] & 0xFFFF) | (d[k + 1] << 16);
        }
        /* bin l's four pairs of this class are eight ints in a row: lane l of the eight vectors */
#define PAIRS(l) (int8)(pe[0].s##l, pd[0].s##l, pe[1].s##l, pd[1].s##l, pe[2].s##l, pd[2].s##l, pe[3].s##l, pd[3].s##l)
#define STORE(l) if (write.s##l) vstore8(PAIRS(l), 0, (__global int *)(out + l * NODE_WORDS + c * 4));
        STORE(0) STORE(1) STORE(2) STORE(3) STORE(4) STORE(5) STORE(6) STORE(7)
#undef STORE
#undef PAIRS
    }
}
#endif
#endif

__kernel void interpret(
    const __global float *profiles,   // (n_beams, N_BINS) power r_i
    const __global float *noise,      // (n_beams, N_BINS) CFAR noise estimate n_i (floored)
    const __global uchar *mask,       // (n_beams, N_BINS) CFAR detections
    const __global uchar *flags_in,   // (n_beams,) flags from range processing
    const float k_occ,                // eq. 12 gain [nat per decade of r/n]
    const int e_high,                 // E_h [logodds units], noise before the first wide pulse
    const int e_low,                  // E_l [logodds units], noise after it
    const int first_bin,              // evidence interval [first_bin, last_bin], inclusive
    const int last_bin,
    const int wide_bins,              // a pulse this wide or wider is wide [bins]
    const int e_high_far,             // OCCLUSION: E_h at last_bin [logodds units]
    const float surface_decades,      // OCCLUSION: a pulse whose peak log10(r/n) reaches this is a surface
    const __global float *opportunity,  // DETSTATS: (N_BINS, 2, NODES) delta at tau = 1 per class and node
    const __global float *miss,         // DETSTATS: (N_BINS, 2, NODES) 1 - opportunity, exact from the host
    const __global float *blocking,     // DETSTATS: (N_BINS,) a pulse's blocking per unit of (r/n - 1)+ at its peak
    const __global int2 *unblocked,     // DETSTATS: (N_BINS, 8) a noise bin's node pairs at tau = 1
    const float c_det,                  // DETSTATS: (1 - P_fa) / P_fa, P_fa the achieved false-alarm rate
    const __global float *ln_snr,       // GRADED: (N_BINS, 2, NODES) ln of the typical target's median SNR at tau = 1
    const __global float *snr_table,    // GRADED: (SNR_NU, SNR_NV) evidence [nat] over (ln x, ln s)
    const __global float *snr_cap,      // GRADED: (N_BINS, 2, NODES) what a detection says at tau = 1 [nat]
    const float noise_floor,            // GRADED: the least noise floor [power] (the CFAR's)
    const float blocker_gap,            // GRADED: the chance of a gap in nearer echoes (0: hard blocking)
    const float snr_q,                  // GRADED: the table's q (the evidence's bound is ln(1 / q))
    __global float *state,              // GRADED: (n_beams, 2, N_BINS) out, each bin's blocked and tau for interpret_nodes
    __global float *ln_floors,          // GRADED: (n_beams,) out, ln of the beam's noise floor
    const int n_beams,
    __global int *evidence,           // (n_beams, N_BINS) out [logodds units]; DETSTATS: (n_beams, N_BINS, 8) int2
    __global int4 *pulses,            // (n_beams, MAX_PULSES) out: start, end, peak, wide; -1 unused
    __global int *n_pulses,           // (n_beams,) out: pulses found (may exceed MAX_PULSES)
    __global uchar *flags_out)        // (n_beams,) out: flags_in | BAD_PROFILE | SILENT
{
    const int beam = get_global_id(0);
    if (beam >= n_beams)
        return;
    const size_t row = (size_t)beam * N_BINS;
    const __global float *r = profiles + row;
    const __global float *n = noise + row;
    const __global uchar *m = mask + row;
    __global int *ev = evidence + row;
    __global int4 *pl = pulses + (size_t)beam * MAX_PULSES;

    uchar flags = flags_in[beam];
    int bad = 0, any_signal = 0;
    /* eight bins at a time (PoCL does not vectorise a work-item's loop), then the tail */
    int8 bad8 = 0, signal8 = 0;
    int j0 = 0;
    for (; j0 + 8 <= N_BINS; j0 += 8) {
        const float8 v = vload8(0, r + j0);
        bad8 |= ~((v >= 0.0f) & (v <= PROFILE_LIMIT));       /* false for NaN; +Inf is beyond */
        signal8 |= v != 0.0f;
    }
    const int4 b4 = bad8.lo | bad8.hi, s4 = signal8.lo | signal8.hi;
    bad = (b4.x | b4.y | b4.z | b4.w) != 0;
    any_signal = (s4.x | s4.y | s4.z | s4.w) != 0;
    for (int j = j0; j < N_BINS; j++) {
        bad |= !(r[j] >= 0.0f && r[j] <= PROFILE_LIMIT);
        any_signal |= r[j] != 0.0f;
    }
    flags |= (bad ? FLAG_BAD_PROFILE : 0) | (any_signal ? 0 : FLAG_SILENT);
    flags_out[beam] = flags;
    for (int k = 0; k < MAX_PULSES; k++)
        pl[k] = (int4)(-1);
#if DETSTATS
#if GRADED
    /* the nodes are interpret_nodes' (below): here each bin's blocking and the beam's floor */
    __global float *st = state + 2 * row;                   /* this beam's blocked[], then its tau[] */
    if (flags & NO_EVIDENCE_FLAGS) {
        n_pulses[beam] = 0;
        return;
    }
#else
    __global int2 *nd = (__global int2 *)evidence + (size_t)beam * N_BINS * NODE_WORDS;
    if (flags & NO_EVIDENCE_FLAGS) {
        for (int j = 0; j < N_BINS * NODE_WORDS; j++)
            nd[j] = (int2)(0);
        n_pulses[beam] = 0;
        return;
    }
    for (int j = 0; j < first_bin && j < N_BINS; j++)
        for (int w = 0; w < NODE_WORDS; w++)
            nd[j * NODE_WORDS + w] = (int2)(0);
#endif
    {
#if GRADED
        /* "snr" evidence: the measured power over the beam's noise floor, the window's median / ln 2 */
        const float median = first_bin <= last_bin ? kth_power(r, first_bin, last_bin, (last_bin - first_bin + 1) / 2)
                                                   : 0.0f;
        const float floor_power = median / 0.69314718056f > noise_floor ? median / 0.69314718056f : noise_floor;
        ln_floors[beam] = log10_nb(floor_power) * LN10;
#define NOISE(j) floor_power
#else
#define NOISE(j) n[j]
#endif
        int count = 0, j = first_bin;
        float blocked = 0.0f, tau = 1.0f, omt = 0.0f;
        while (j <= last_bin) {
            if (!m[j]) {
#if GRADED
                st[j] = blocked;
                st[N_BINS + j] = tau;
#else
                if (blocked == 0.0f) {
                    for (int w = 0; w < NODE_WORDS; w++)
                        nd[j * NODE_WORDS + w] = unblocked[j * NODE_WORDS + w];
                } else {
                    write_nodes(nd + j * NODE_WORDS, opportunity + j * 10, miss + j * 10, tau, omt, 0, 0.0f);
                }
#endif
                j++;
                continue;
            }
            const int start = j;
            int peak = j;
            float energy = 0.0f;
            for (; j <= last_bin && m[j]; j++) {
                if (r[j] > r[peak])
                    peak = j;
                const float excess = r[j] / NOISE(j) - 1.0f;
                energy += excess > 0.0f ? excess : 0.0f;
            }
            const int end = j - 1;
#if GRADED
            for (int i = start; i <= end; i++) {            /* a pulse's bins: the tau in front of it */
                st[i] = blocked;
                st[N_BINS + i] = tau;
            }
#else
            const float scale = c_det / r[peak];
            for (int i = start; i <= end; i++)
                write_nodes(nd + i * NODE_WORDS, opportunity + i * 10, miss + i * 10, tau, omt, 1, r[i] * scale);
#endif
            if (count < MAX_PULSES)
                pl[count] = (int4)(start, end, peak, end - start + 1 >= wide_bins);
            count++;
            blocked += energy * blocking[peak];
            tau = exp(-blocked);                  /* builtins, once per pulse */
#if !GRADED
            omt = -expm1(-blocked);           /* 1 - tau, for the binary outcome's nodes */
#endif
        }
#undef NOISE
#if !GRADED
        for (int jj = max(last_bin + 1, 0); jj < N_BINS; jj++)
            for (int w = 0; w < NODE_WORDS; w++)
                nd[jj * NODE_WORDS + w] = (int2)(0);
#endif
        n_pulses[beam] = count;
        return;
    }
#endif
    if (flags & NO_EVIDENCE_FLAGS) {
        for (int j = 0; j < N_BINS; j++)
            ev[j] = 0;
        n_pulses[beam] = 0;
        return;
    }

    for (int j = 0; j < first_bin && j < N_BINS; j++)
        ev[j] = 0;
    int count = 0, after_wide = 0, start = -1, peak = -1;
    float strongest = -INFINITY;                 /* OCCLUSION: the pulse's largest log10(r / n) */
    union { float8 v; float s[8]; } logs;        /* log10(r / n) of bins chunk .. chunk + 7 */
    int chunk = -16;
    const int span = max(last_bin - first_bin, 1);
    for (int j = first_bin; j <= last_bin; j++) {
        /* Eight noise bins at once where no pulse is open and none starts: most of a profile
         * (PoCL does not vectorise a work-item's loop; the bins' values are as below). */
        while (start < 0 && j + 8 <= last_bin + 1 && !any8(m + j)) {
#if OCCLUSION
            const int8 e = after_wide ? (int8)e_low
                : e_high + (e_high_far - e_high) * ((int8)(j - first_bin) + (int8)(0, 1, 2, 3, 4, 5, 6, 7)) / span;
#else
            const int8 e = (int8)(after_wide ? e_low : e_high);
#endif
            vstore8(e, 0, ev + j);
            j += 8;
        }
        if (j > last_bin)
            break;
        /* this bin and the next seven: their logs at once where a detection lies among them
         * (a pulse's bins come in runs; one at a time, the logs were most of the kernel) */
        if (j >= chunk + 8) {
            chunk = j;
            if (j + 8 <= N_BINS && any8(m + j))
                logs.v = log10_nb8(vload8(0, r + j)) - log10_nb8(vload8(0, n + j));
            else
                chunk = -16;                                     /* no logs held */
        }
        if (m[j]) {
            const float decades = j < chunk + 8 ? logs.s[j - chunk] : log10_nb(r[j]) - log10_nb(n[j]);
            ev[j] = convert_int_rte(clamp(k_occ * decades, 0.0f, EVIDENCE_LIMIT_NATS) * LOGODDS_SCALE);
            strongest = start < 0 ? decades : fmax(strongest, decades);
            if (start < 0) {
                start = j;
                peak = j;
            } else if (r[j] > r[peak]) {
                peak = j;
            }
        } else if (after_wide) {
            ev[j] = e_low;
        } else {
#if OCCLUSION
            ev[j] = e_high + (e_high_far - e_high) * (j - first_bin) / span;
#else
            ev[j] = e_high;
#endif
        }
        /* A pulse ends at the last detected bin of a run, or at the last bin of the interval. */
        if (start >= 0 && (j == last_bin || !m[j + 1])) {
            const int wide = j - start + 1 >= wide_bins;
            if (count < MAX_PULSES)
                pl[count] = (int4)(start, j, peak, wide);
            count++;
#if OCCLUSION
            after_wide |= wide || strongest >= surface_decades;    /* "after the first surface" */
#else
            after_wide |= wide;
#endif
            start = -1;
        }
    }
    for (int j = max(last_bin + 1, 0); j < N_BINS; j++)
        ev[j] = 0;
    n_pulses[beam] = count;
}


/* "snr" evidence's nodes, one work-item per eight bins of a beam (get_global_id(0) = beam *
 * n_chunks + chunk, the chunks that meet the window [first_bin, last_bin]; the bins outside it
 * hold 0 from the evidence array's allocation, and nothing writes them): the bins of a beam depend on each other only through
 * its blocking (blocked, tau), which interpret walks in order and leaves in state[]; the table
 * reads, the gap mixture and the caps are most of the model's work and independent per bin, so
 * they run here as vectors of eight bins (one work-item walking a beam's bins ran them one at a
 * time), each lane the floats of that bin's scalar computation. Built with every interpret (a
 * program holds all the kernels its source declares), empty but for DETSTATS and GRADED, the
 * only builds that launch it. */
__kernel void interpret_nodes(
    const __global float *profiles,     // (n_beams, N_BINS) power r_i
    const __global uchar *flags_out,    // (n_beams,) interpret's flags
    const __global float *state,        // (n_beams, 2, N_BINS) interpret's blocked and tau per bin
    const __global float *ln_floors,    // (n_beams,) interpret's ln noise floor per beam
    const __global float *opportunity,  // (2, NODES, N_BINS) interpret's tables, bins last (one vector load per node)
    const __global float *ln_snr,
    const __global float *snr_cap,
    const __global float *snr_table,
    const int first_bin,
    const int last_bin,
    const float blocker_gap,
    const float snr_q,
    const int n_chunks,                 // chunks of eight bins from bin first_bin & ~7 that meet the window
    const int n_beams,
    __global int2 *evidence)            // (n_beams, N_BINS, 8) out: node pairs
{
#if DETSTATS && GRADED
    const int id = get_global_id(0);
    if (id >= n_beams * n_chunks)
        return;
    const int beam = id / n_chunks, j0 = (first_bin & ~7) + (id - beam * n_chunks) * 8;
    const int8 j = j0 + (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    const int8 jt = j < N_BINS ? j : (int8)(N_BINS - 1);           /* the tail's lanes read the last bin */
    const int8 in_range = (j >= first_bin) & (j <= last_bin) & (j < N_BINS);
    const size_t row = (size_t)beam * N_BINS;
    __global int2 *nd = evidence + (row + j0) * NODE_WORDS;
    const int valid = !(flags_out[beam] & NO_EVIDENCE_FLAGS);
    const int8 zero = valid ? (j < N_BINS) & ~in_range : (j < N_BINS);
    for (int l = 0; l < 8; ++l)
        if (((const int *)&zero)[l])
            for (int w = 0; w < NODE_WORDS; w++)
                nd[l * NODE_WORDS + w] = (int2)(0);
    if (!valid || !(in_range.s0 | in_range.s1 | in_range.s2 | in_range.s3 | in_range.s4 | in_range.s5 | in_range.s6
                    | in_range.s7))
        return;
    const __global float *r = profiles + row, *st = state + 2 * row;
    float8 power, blocked, tau;
    if (j0 + 8 <= N_BINS) {
        power = vload8(0, r + j0);
        blocked = vload8(0, st + j0);
        tau = vload8(0, st + N_BINS + j0);
    } else {                                                        /* the tail's lanes read the last bin */
        power = GATHER8(r, jt);
        blocked = GATHER8(st, jt);
        tau = GATHER8((st + N_BINS), jt);
    }
    write_graded8(nd, in_range, ln_snr, opportunity, snr_cap, snr_table, j0, jt,
                  log10_nb8(power) * LN10 - ln_floors[beam], blocked, tau, blocker_gap, snr_q);
#endif
}
