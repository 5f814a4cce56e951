/* "snr" evidence's node pairs (the detection-statistics model with -D GRADED=1 in interpret.cl):
 * the second of the interpreter's two launches, after the beam walk.
 *
 * Equivalent, with the walk, to radarcl.oracle.interpret_detstats with "snr" evidence
 * (radarcl.sensor_model.SnrTable): every bin's e is read from the table of the measured power,
 * x = r / N, N the beam's noise floor (the walk's ln_floors[]): e = table(ln x, ln tau +
 * ln_snr[class, node, bin]), bilinear on the SNR_NU x SNR_NV grid, clamped to it, tau = exp(-X)
 * and X the blocking of the pulses before the bin (the walk's state[]). Behind nearer echoes
 * (X > 0) with blocker_gap g > 0 (a partial blocker): L_b and L_0 from the table read at
 * ln tau + ln_snr and at ln_snr, e = ln(L / (1 - q + q L)) of L = (1 - g) L_b + g L_0, and the
 * knowledge ((1 - w) tau + w) opportunity where the gap's posterior w = g L_0 / L is above 1/2,
 * tau opportunity elsewhere. Every look's e lies within +-known x snr_cap[class, node, bin] (tau,
 * or the gap's, times what a detection says at the node's opportunity: snr_evidence.bounded). A
 * node whose knowledge d rounds to 0 gets e = 0 (the reading counts only looks with knowledge).
 * The node pairs are int2 (node_pairs.pack_nodes) of e [logodds units] and d [KNOWLEDGE_SCALE
 * units] at rho2 = 0, 1/4, ..., 1, per class of target (upright, terrain).
 *
 * Only the first CLASSES classes are computed and stored (NODE_WORDS int2 per bin): with CLASSES
 * = 1 (a scene without a terrain class: its opportunity is 0 at every bin and node, so each of its
 * nodes would be 0 by the rule above) the array holds the upright class alone.
 *
 * Work mapping: get_global_id(0) = beam x n_chunks + chunk, a chunk being LANES bins (from bin
 * first_bin & ~(LANES - 1); the chunks that meet the window [first_bin, last_bin]); any local
 * size works. The bins of a beam depend on each other only through its blocking, which the walk
 * leaves per bin; the table reads, the gap mixture and the caps are most of the model's work and
 * independent per bin, so they run here as vectors of LANES bins. Each function below is the
 * computation of one bin written once over the lanes, the branches as selects, so that every lane
 * computes the floats one bin's scalar code would (the same operations in the same order, and so
 * the same contractions), whatever LANES is; ternaries on vectors select per lane, without
 * builtins. Bins outside the window hold 0 from the evidence array's allocation (nothing writes
 * them but the zeroing of a flagged beam's and a chunk's outside bins).
 *
 * Only what the frame's voxels read (selective: a still plan's node_use, or a moving frame's bound
 * of it from its beams, node_reach.cl): a chunk computes and stores only the classes some voxel
 * reads in one of its bins; the pairs of the others keep what an earlier frame left there, which
 * no voxel of this plan reads. Nodes a voxel reads are the same floats either way.
 *
 * -D constants (set by radarcl/stages/interpret_nodes.py):
 *   N_BINS      bins per profile
 *   NODES       node_pairs.NODES, the rho2 nodes per class
 *   CLASSES     1 (upright targets only) or 2 (and terrain)
 *   LANES       bins per work-item: 8 or 16
 *   SNR_NU, SNR_NV, SNR_U0, SNR_V0, SNR_U_SCALE, SNR_V_SCALE   the table's grid (grid points per
 *               unit of u = ln x and v = ln s; snr_evidence.SNR_U, SNR_V)
 *   GAP_CAP     snr_evidence.GAP_CAP: the gap mixture's cap on e^e below 1 / q
 */
#include "interpret_common.h"

#if !defined(CLASSES) || CLASSES < 1 || CLASSES > 2
#error "CLASSES (1 or 2) comes from radarcl/stages/interpret_nodes.py"
#endif

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define floatV CAT(float, LANES)
#define intV CAT(int, LANES)
#define vloadV CAT(vload, LANES)
#define as_intV CAT(as_int, LANES)
#define as_floatV CAT(as_float, LANES)
#define convert_intV CAT(convert_int, LANES)
#define convert_floatV CAT(convert_float, LANES)

/* the floats at i and i + 1 of eight lanes, as (p[i.s0], p[i.s0 + 1], p[i.s1], ...): one two-float
 * load a lane (TABLE_PAIRS: split into the lanes' p[i] and p[i + 1]) */
#define PAIRS8(p, i) ((float16)(vload2(0, p + (i).s0), vload2(0, p + (i).s1), vload2(0, p + (i).s2), vload2(0, p + (i).s3), \
                                vload2(0, p + (i).s4), vload2(0, p + (i).s5), vload2(0, p + (i).s6), vload2(0, p + (i).s7)))
/* LOG10_NB: log10_nb of each lane, as the header's log10_nb8 / log10_nb16, one vector of LANES */
#if LANES == 8
#define LANE_IDS (intV)(0, 1, 2, 3, 4, 5, 6, 7)
#define GATHER(p, i) ((floatV)(p[(i).s0], p[(i).s1], p[(i).s2], p[(i).s3], p[(i).s4], p[(i).s5], p[(i).s6], p[(i).s7]))
#define EACH_LANE(M) M(0) M(1) M(2) M(3) M(4) M(5) M(6) M(7)
#define TABLE_PAIRS(p, i, at_i, at_next) { const float16 f = PAIRS8(p, i); at_i = f.even; at_next = f.odd; }
#define LOG10_NB(x) log10_nb8(x)
#elif LANES == 16
#define LANE_IDS (intV)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
#define GATHER(p, i) ((floatV)(p[(i).s0], p[(i).s1], p[(i).s2], p[(i).s3], p[(i).s4], p[(i).s5], p[(i).s6], p[(i).s7], \
                               p[(i).s8], p[(i).s9], p[(i).sa], p[(i).sb], p[(i).sc], p[(i).sd], p[(i).se], p[(i).sf]))
#define EACH_LANE(M) M(0) M(1) M(2) M(3) M(4) M(5) M(6) M(7) M(8) M(9) M(a) M(b) M(c) M(d) M(e) M(f)
#define TABLE_PAIRS(p, i, at_i, at_next) { const float16 f0 = PAIRS8(p, (i).lo), f1 = PAIRS8(p, (i).hi); \
                                     at_i = (floatV)(f0.even, f1.even); at_next = (floatV)(f0.odd, f1.odd); }
#define LOG10_NB(x) log10_nb16(x)
#else
#error "LANES (8 or 16) comes from radarcl/stages/interpret_nodes.py"
#endif
/* any and all lanes of a comparison's result (-1 or 0 per lane), without builtins */
#define OR_LANE(l) | v.s##l
#define AND_LANE(l) & v.s##l
static inline int any_lane(intV v) { return 0 EACH_LANE(OR_LANE); }
static inline int all_lanes(intV v) { return -1 EACH_LANE(AND_LANE); }

/* a grid position clamped to [0, n - 1] (-inf and NaN to 0) */
static inline floatV grid_position(floatV x, float x0, float scale, int n)
{
    const floatV f = (x - x0) * scale;
    return f > 0.0f ? (f < (float)(n - 1) ? f : (floatV)(n - 1)) : (floatV)0.0f;
}

/* the table's bilinear read at rows iu, iu + 1 (offsets i0 = iu * SNR_NV) and fraction du, column ln v.
 * Inlined by force: PoCL's LLVM called it out of line (it is read twice a node), spilling the
 * caller's vector registers around each call (docs/measured-figures.md) */
static inline __attribute__((always_inline)) floatV table_at(const __global float *table, intV i0, floatV du, floatV lnv)
{
    const floatV fv = grid_position(lnv, SNR_V0, SNR_V_SCALE, SNR_NV);
    const intV t = convert_intV(fv);                   /* fv >= 0: truncation is floor */
    const intV iv = t < SNR_NV - 2 ? t : (intV)(SNR_NV - 2);
    const floatV dv = fv - convert_floatV(iv);
    const intV a = i0 + iv, c = a + SNR_NV;            /* columns iv, iv + 1 of rows iu (a), iu + 1 (c) */
    floatV lo_even, lo_odd, hi_even, hi_odd;
    TABLE_PAIRS(table, a, lo_even, lo_odd);
    TABLE_PAIRS(table, c, hi_even, hi_odd);
    return (lo_even * (1.0f - dv) + lo_odd * dv) * (1.0f - du)
         + (hi_even * (1.0f - dv) + hi_odd * dv) * du;
}

/* e^x for x in [-87, 88]: 2^n e^r, n = rint(x / ln 2), |r| <= ln 2 / 2, e^r by its Taylor
 * series to r^7 (series error < 6e-9; r itself, x - n ln 2 in one float32 step, carries
 * ~ulp(n ln 2) / 2: 5e-7 relative at the table's |e| ~ 14, 4e-6 near 88) */
static inline floatV exp_nb(floatV x)
{
    x = x > 88.0f ? (floatV)88.0f : (x < -87.0f ? (floatV)-87.0f : x);
    const floatV y = x * 1.44269504089f;
    const intV n = as_intV(y + 12582912.0f) - 0x4B400000;        /* rint, as fixed_nb */
    const floatV r = x - convert_floatV(n) * 0.69314718056f;
    const floatV p = 1.0f + r * (1.0f + r * (0.5f + r * (1.0f / 6.0f + r * (1.0f / 24.0f + r * (1.0f / 120.0f
                   + r * (1.0f / 720.0f + r * (1.0f / 5040.0f)))))));
    return p * as_floatV((n + 127) << 23);
}

/* L of the evidence e = ln(L / (1 - q + q L)), e^e capped below its bound 1 / q (as
 * snr_evidence.likelihood_ratio; the mixture below as snr_evidence.gap_mixture) */
static inline floatV likelihood_ratio(floatV e, float q)
{
    const floatV x = exp_nb(e);
    const float most = (1.0f - GAP_CAP) / q;
    const floatV t = most < x ? (floatV)most : x;
    return t * (1.0f - q) / (1.0f - q * t);
}

/* a node value in fixed point: rint(clamp(v, -limit, limit) x scale), half to even as
 * logodds.to_fixed, without builtins */
static inline intV fixed_nb(floatV v, float scale)
{
    v = v > EVIDENCE_LIMIT_NATS ? (floatV)EVIDENCE_LIMIT_NATS : (v < -EVIDENCE_LIMIT_NATS ? (floatV)-EVIDENCE_LIMIT_NATS : v);
    return as_intV(v * scale + 12582912.0f) - 0x4B400000;
}

/* the node pairs of bins j0 .. j0 + LANES - 1 (lanes; the tail's at bins jt, the per-node tables
 * (2, NODES, N_BINS)) from the SNR table: u = ln x, ln tau = -blocked; behind nearer echoes
 * (blocked > 0) the mixture with a gap of chance gap (q: the table's); every look within its
 * known share of the node's cap, either way. Lanes not in `write` store nothing. */
static inline void write_graded(__global int2 *out, intV write, int classes, const __global float *ln_snr,
                                const __global float *opportunity, const __global float *snr_cap,
                                const __global float *table, int j0, intV jt, floatV u, floatV blocked, floatV tau,
                                float gap, float q)
{
    const floatV fu = grid_position(u, SNR_U0, SNR_U_SCALE, SNR_NU);
    const intV t = convert_intV(fu);
    const intV iu = t < SNR_NU - 2 ? t : (intV)(SNR_NU - 2);
    const floatV du = fu - convert_floatV(iu);
    const intV i0 = iu * SNR_NV;
    const intV behind = (gap > 0.0f ? (intV)-1 : (intV)0) & (blocked > 0.0f);
    const int whole = j0 + LANES <= N_BINS;
    for (int c = 0; c < CLASSES; ++c) {
        if (!((classes >> c) & 1))                       /* no voxel reads this class's pairs here */
            continue;
        /* each segment's pair words made as soon as its second node is: the five nodes' e and d
         * vectors held to the end spilled registers */
        intV pe[4], pd[4], e_last = (intV)0, d_last = (intV)0;
        for (int k = 0; k < NODES; ++k) {
            intV ek, dk;
            const int node = (c * NODES + k) * N_BINS;
            const floatV opp = whole ? vloadV(0, opportunity + node + j0) : GATHER(opportunity, node + jt);
            /* knowledge is at most opp (tau, w <= 1): a node it rounds to 0 for is a look that is
             * not one, with no evidence (below); where it does in all the lanes (far bins of the
             * terrain class), nothing to compute */
            const intV none = opp * (float)KNOWLEDGE_SCALE <= 0.5f;
            if (all_lanes(none)) {
                ek = dk = (intV)0;
            } else {
                const floatV ln_s = whole ? vloadV(0, ln_snr + node + j0) : GATHER(ln_snr, node + jt);
                const floatV cap = whole ? vloadV(0, snr_cap + node + j0) : GATHER(snr_cap, node + jt);
                floatV v = table_at(table, i0, du, ln_s - blocked);
                floatV known = tau;
                /* only behind an echo, and only for a target there is (ln_s at the table's first
                 * column, e.g. terrain without a ground plane: both reads are 0, the mixture too);
                 * the lanes of a node without one compute it and drop it */
                const intV mix = behind & (ln_s > SNR_V0);
                if (any_lane(mix)) {
                    const floatV lb = likelihood_ratio(v, q);
                    const floatV l0 = likelihood_ratio(table_at(table, i0, du, ln_s), q);
                    const floatV lm = (1.0f - gap) * lb + gap * l0;
                    const floatV w = gap * l0 / lm;       /* the gap's posterior chance */
                    v = mix ? LOG10_NB(lm / (1.0f - q + q * lm)) * LN10 : v;
                    known = (mix & (w > 0.5f)) ? (1.0f - w) * tau + w : tau;   /* see the oracle */
                }
                const floatV most = known * cap;    /* no more than a detection would say, either way */
                v = v < most ? (v > -most ? v : -most) : most;
                dk = none ? (intV)0 : as_intV(known * opp * (float)KNOWLEDGE_SCALE + 12582912.0f) - 0x4B400000;
                ek = dk != 0 ? fixed_nb(v, LOGODDS_SCALE) : (intV)0;   /* no evidence from a look that is not one */
            }
            if (k > 0) {                                 /* segment k - 1: nodes k - 1 and k */
                pe[k - 1] = (e_last & 0xFFFF) | (ek << 16);
                pd[k - 1] = (d_last & 0xFFFF) | (dk << 16);
            }
            e_last = ek;
            d_last = dk;
        }
        /* bin l's four pairs of this class are eight ints in a row: lane l of the eight vectors */
#define PAIRS(l) (int8)(pe[0].s##l, pd[0].s##l, pe[1].s##l, pd[1].s##l, pe[2].s##l, pd[2].s##l, pe[3].s##l, pd[3].s##l)
#define STORE(l) if (write.s##l) vstore8(PAIRS(l), 0, (__global int *)(out + 0x##l * NODE_WORDS + c * 4));
        EACH_LANE(STORE)
#undef STORE
#undef PAIRS
    }
}

__kernel void interpret_nodes(
    const __global float *profiles,     // (n_beams, N_BINS) power r_i
    const __global uchar *flags_out,    // (n_beams,) the walk's flags
    const __global float *state,        // (n_beams, 2, N_BINS) the walk's blocked and tau per bin
    const __global float *ln_floors,    // (n_beams,) the walk's ln noise floor per beam
    const __global float *opportunity,  // (2, NODES, N_BINS) delta at tau = 1 per class and node, bins last
    const __global float *ln_snr,       // (2, NODES, N_BINS) ln of the typical target's median SNR at tau = 1
    const __global float *snr_cap,      // (2, NODES, N_BINS) what a detection says at tau = 1 [nat]
    const __global float *snr_table,    // (SNR_NU, SNR_NV) evidence [nat] over (ln x, ln s)
    const int first_bin,                // the window [first_bin, last_bin], inclusive
    const int last_bin,
    const float blocker_gap,            // the chance of a gap in nearer echoes (0: hard blocking)
    const float snr_q,                  // the table's q (the evidence's bound is ln(1 / q))
    const int n_chunks,                 // chunks of LANES bins from bin first_bin & ~(LANES - 1) that meet the window
    const int n_beams,
    const __global uint *node_use,      // (n_beams, N_BINS) bit c: some voxel reads class c's pairs of the bin
    const int selective,                //   (a still plan's table, fusion.cl's RECORD 2, or node_reach.cl's bound);
                                        //   0: every class everywhere
    __global int2 *evidence)            // (n_beams, N_BINS, NODE_WORDS) out: node pairs
{
    const int id = get_global_id(0);
    if (id >= n_beams * n_chunks)
        return;
    const int beam = id / n_chunks, j0 = (first_bin & ~(LANES - 1)) + (id - beam * n_chunks) * LANES;
    const intV j = j0 + LANE_IDS;
    const intV jt = j < N_BINS ? j : (intV)(N_BINS - 1);           /* the tail's lanes read the last bin */
    const intV in_range = (j >= first_bin) & (j <= last_bin) & (j < N_BINS);
    const size_t row = (size_t)beam * N_BINS;
    __global int2 *nd = evidence + (row + j0) * NODE_WORDS;
    const int valid = !(flags_out[beam] & NO_EVIDENCE_FLAGS);
    const intV zero = valid ? (j < N_BINS) & ~in_range : (j < N_BINS);
    for (int l = 0; l < LANES; ++l)
        if (((const int *)&zero)[l])
            for (int w = 0; w < NODE_WORDS; w++)
                nd[l * NODE_WORDS + w] = (int2)(0);
    if (!valid || !any_lane(in_range))
        return;
    int classes = (1 << CLASSES) - 1;
    if (selective) {                    /* only the classes some voxel reads in the chunk's bins */
        intV use;
        if (j0 + LANES <= N_BINS)
            use = as_intV(vloadV(0, node_use + row + j0));
        else {
#define USE_LANE(l) use.s##l = (int)node_use[row + jt.s##l];
            EACH_LANE(USE_LANE)
#undef USE_LANE
        }
        classes &= any_lane(use & in_range);
        if (!classes)
            return;
    }
    const __global float *r = profiles + row, *st = state + 2 * row;
    floatV power, blocked, tau;
    if (j0 + LANES <= N_BINS) {
        power = vloadV(0, r + j0);
        blocked = vloadV(0, st + j0);
        tau = vloadV(0, st + N_BINS + j0);
    } else {                                                        /* the tail's lanes read the last bin */
        power = GATHER(r, jt);
        blocked = GATHER(st, jt);
        tau = GATHER((st + N_BINS), jt);
    }
    write_graded(nd, in_range, classes, ln_snr, opportunity, snr_cap, snr_table, j0, jt,
                 LOG10_NB(power) * LN10 - ln_floors[beam], blocked, tau, blocker_gap, snr_q);
}
