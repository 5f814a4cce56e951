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
 * radarcl.oracle.interpret_detstats; -D NODES is node_pairs.NODES, the rho2 nodes per class):
 * evidence[] is (n_beams, N_BINS, CLASSES, 4 segments)
 * int2 node pairs (node_pairs.pack_nodes) of the evidence e [logodds units] and the detection
 * opportunity d [KNOWLEDGE_SCALE units] at rho2 = 0, 1/4, ..., 1, per class of target:
 *   tau = exp(-X), X the blocking of the pulses that ended before the bin (a pulse's summed
 *       (r/n - 1)+ times blocking[] at its peak); delta = tau opportunity[bin, class, node];
 *   no detection: e = ln(1 - delta) = ln((1 - tau) + tau miss[bin, class, node]);
 *   detection: e = ln(1 + delta (r / r_peak) c_det), c_det = (1 - P_fa) / P_fa;
 *   d = delta.
 * Until the first pulse (tau = 1) a noise bin copies unblocked[] (the host's exact nodes).
 * Logs without builtins (log10_nb); one exp and expm1 per pulse. eq. 12's constants are unused.
 *
 * With -D GRADED=1 as well ("snr" evidence, radarcl.sensor_model.SnrTable), the walk leaves
 * the nodes to kernels/interpret_nodes.cl, which reads each bin's e from the table of the
 * measured power over the beam's noise floor: here, each beam's floor N (the ((last - first + 1)
 * / 2)-th smallest power of the window, found exactly by bisection on the float's bits, / ln 2,
 * at least noise_floor) into ln_floors[], and each bin's blocked X and tau = exp(-X) into
 * state[], a pulse blocking by its summed (x - 1)+, x = r / N; bins of a pulse take the tau in
 * front of it, as without GRADED.
 *
 * -D constants (set by radarcl/stages/interpret.py):
 *   N_BINS      bins per profile
 *   MAX_PULSES  pulse rows kept per beam; more are counted and still give evidence
 *   OCCLUSION   0: the paper's eq. 12; 1: the occlusion-aware variant above
 *   DETSTATS    0, or 1: the detection-statistics model above (with OCCLUSION 0)
 *   GRADED      DETSTATS only: 0, or 1 for "snr" evidence (above)
 *   CLASSES     DETSTATS only: the classes of target kept, 1 (upright; a scene without a terrain
 *               class, whose nodes would all be 0) or 2 (and terrain)
 */
#include "interpret_common.h"

/* 1 where any of the eight mask bytes at p is set: two 32-bit words, since 64-bit integers are
 * optional on embedded-profile devices (compilers join the two into one 64-bit test where they can) */
static inline uint any8(const __global uchar *p)
{
    const uint2 w = as_uint2(vload8(0, p));
    return (w.x | w.y) != 0u;
}

#if DETSTATS
#if !defined(CLASSES) || CLASSES < 1 || CLASSES > 2
#error "CLASSES (1 or 2) comes from radarcl/stages/interpret.py"
#endif
#define TABLE_ROW (2 * NODES)         /* opportunity[] and miss[] per bin: both classes, whichever are kept */

/* a node value in fixed point: rint(clamp(v, -limit, limit) x scale), without builtins */
static inline int fixed_nb(float v, float scale)
{
    v = v > EVIDENCE_LIMIT_NATS ? EVIDENCE_LIMIT_NATS : (v < -EVIDENCE_LIMIT_NATS ? -EVIDENCE_LIMIT_NATS : v);
    return as_int(v * scale + 12582912.0f) - 0x4B400000;       /* rint, half to even, as logodds.to_fixed */
}

/* one bin's node pairs: for each class kept, the five nodes of e and d packed per segment */
static inline void write_nodes(__global int2 *out, const __global float *opp, const __global float *miss,
                               float tau, float omt, int detected, float share_c)
{
    for (int c = 0; c < CLASSES; ++c) {
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
 * counted as +0.0 by dropping the sign bit), counting sixteen bins at a time (a vector a full
 * register wide on a CPU: the counting is most of the walk's time) */
static float kth_power(const __global float *r, int first, int last, int k)
{
    uint lo = 0u, hi = 0x7F800000u;             /* +inf: every checked profile lies below */
    while (lo < hi) {
        const uint mid = lo + ((hi - lo) >> 1);
        int16 below16 = 0;
        int j = first;
        for (; j + 16 <= last + 1; j += 16)
            below16 += as_int16((as_uint16(vload16(0, r + j)) & 0x7FFFFFFFu) <= (uint16)mid);   /* -1 where true */
        const int8 below8 = below16.lo + below16.hi;
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
    const __global int2 *unblocked,     // DETSTATS: (N_BINS, NODE_WORDS) a noise bin's node pairs at tau = 1
    const float c_det,                  // DETSTATS: (1 - P_fa) / P_fa, P_fa the achieved false-alarm rate
    const float noise_floor,            // GRADED: the least noise floor [power] (the CFAR's)
    __global float *state,              // GRADED: (n_beams, 2, N_BINS) out, each bin's blocked and tau for interpret_nodes
    __global float *ln_floors,          // GRADED: (n_beams,) out, ln of the beam's noise floor
    const int n_beams,
    __global int *evidence,           // (n_beams, N_BINS) out [logodds units]; DETSTATS: (n_beams, N_BINS, NODE_WORDS) int2
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
    /* the nodes are interpret_nodes.cl's: here each bin's blocking and the beam's floor */
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
                    write_nodes(nd + j * NODE_WORDS, opportunity + j * TABLE_ROW, miss + j * TABLE_ROW, tau, omt, 0, 0.0f);
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
                write_nodes(nd + i * NODE_WORDS, opportunity + i * TABLE_ROW, miss + i * TABLE_ROW, tau, omt, 1, r[i] * scale);
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
