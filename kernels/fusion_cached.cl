/* A still radar's frame from its recorded table (fusion_common.h: the still table): each voxel sums
 * rint(evidence[entry] * weight) over its entries, the same integers the gather (fusion.cl) gives
 * (the weights are the gather's own float32 values; with DETSTATS, its quantised rho2 and class
 * for NODE_LERP), streaming the table instead of testing beams. A work-item takes the gather's
 * block of the same id, row by row. The first entries are dense (one per voxel, read as vectors:
 * on a regular lattice almost every voxel lies in one beam); the further entries are read as
 * vectors too: a row's m-th further entries lie together, one block of VEC (a spinning radar's
 * voxels mostly lie in two beams). Every entry is rounded on its own and the sums are integers,
 * so the order the entries are added in does not change them.
 *
 * -D: the gather's (radarcl.stages.fusion builds both with the same); this kernel reads VEC,
 *     BRICK_Z, DETSTATS, CLASSES and NO_INT64.
 */
#include "fusion_common.h"

#define vload_ucharV CAT(vload, VEC)
#define intV2 CAT(int, VEC2)
#define vloadV2 CAT(vload, VEC2)

/* row `row` of work-item id's block: the sums its voxels take from the frame, the evidence into
 * *sum and, with DETSTATS, the knowledge into *ksum and minus the looks with an opportunity into
 * *nsum (each 0 where no beam reaches the row) */
static inline __attribute__((always_inline)) void row_sums(
    int row, int id, const __global int *dense, const __global uchar *counts, const __global int *row_start,
    const __global int2 *extras, const __global int *evidence, const __global int2 *nodes,
    intV *sum_out, intV *ksum_out, intV *nsum_out)
{
    *sum_out = *ksum_out = *nsum_out = 0;
    const intV2 pairs = vloadV2(0, dense + row * VEC * 2);       /* idx, weight, idx, weight, ... */
    const intV bits = pairs.odd;
    if (!or_lanes(bits))                   /* no beam reaches the row */
        return;
    const intV index = pairs.even;
#ifdef DETSTATS
    /* q + 1 in place of the weight (0: no beam), the class in bit 16, the sign bit "more
     * entries follow" */
    const intV q = (bits & 0xFFFF) - 1;                     /* -1 (no beam): masked below */
    const intV cls = (bits >> 16) & 1;
    const intV reached = (bits != 0) & TAKES(cls);          /* CLASSES 1: not a terrain voxel */
    const intV seg = (q >> 12) & (SEGMENTS - 1);            /* q = -1: segment 3, in bounds */
    const intV f = q & 4095;
    const intV at = NODE_AT(index, cls, seg);
    intV sum, ksum;
    LERP_NODES(sum, ksum, nodes, at, f);
    sum &= reached;
    ksum &= reached;
    intV nsum = -(ksum > 0);
#else
    /* the weight's sign bit says "more entries follow" (weights are positive) */
    const floatV product = convert_floatV(GATHER(evidence, index)) * as_floatV(bits & 0x7FFFFFFF);
    intV sum = RINT_INTV(product);
#endif
    if (or_lanes(bits) < 0) {              /* voxels several beams reach */
        /* their further entries, the row's m-th ones as one vector: lane l of the row's m-th
         * block; a spinning radar's voxels mostly lie in two beams, so this is the common
         * path there, not the exception */
        const size_t t = (size_t)id * BLOCK_ROWS + row;
        const intV more = CAT(convert_int, VEC)(vload_ucharV(0, counts + t * VEC)) - 1;
        const intV n_extra = more & ~(more >> 31);                    /* max(count - 1, 0) */
        const __global int *blocks = (const __global int *)(extras + (size_t)row_start[t] * VEC);
        for (int m = 0; or_lanes((intV)m - n_extra) < 0; ++m) {       /* some lane has an m-th */
            const intV live = (intV)m < n_extra;
            const intV2 pairs_m = vloadV2(0, blocks + m * VEC * 2);  /* the lanes' m-th entries, (0, 0) past a lane's last */
            const intV ei = pairs_m.even, ew = pairs_m.odd;
#ifdef DETSTATS
            const intV qe = (ew & 0xFFFF) - 1;
            const intV ce = (ew >> 16) & 1;
            const intV ate = NODE_AT(ei, ce, (qe >> 12) & (SEGMENTS - 1)) & live;
            const intV takes = live & TAKES(ce);
            intV xe, xk;
            LERP_NODES(xe, xk, nodes, ate, qe & 4095);
            sum += xe & takes;
            const intV kn = xk & takes;
            ksum += kn;
            nsum -= kn > 0;                                       /* true is -1 */
#else
            const intV ie = ei & live;
            const floatV p = convert_floatV(GATHER(evidence, ie)) * as_floatV(ew);
            sum += RINT_INTV(p) & live;
#endif
        }
    }
    *sum_out = sum;
#ifdef DETSTATS
    *ksum_out = ksum;
    *nsum_out = nsum;
#endif
}

/* row `row`'s sums into the grid (cells: the block's first cell of each channel) */
static inline __attribute__((always_inline)) void store_row(
    int row, intV sum, intV ksum, intV nsum, __global int *cells, __global int *kcells, __global int *lcells)
{
    const int at = (ROW_DZ(row) * 8 + ROW_DY(row)) * 8;
#ifdef DETSTATS
    if (or_lanes(ksum)) {
        const intV v = vloadV(0, kcells + at) + ksum;
        vstoreV(v > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : v, 0, kcells + at);
        const intV e0 = vloadV(0, cells + at);                 /* before its store */
        const intV c = vloadV(0, lcells + at) + (nsum & ~STUCK(e0, sum));
        vstoreV(c > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : c, 0, lcells + at);
    }
#endif
    if (or_lanes(sum)) {
        /* |sum| < 255 beams x 2^14 (RECORD refuses more) and |cell| <= GRID_LIMIT = 2^30: no
         * int32 overflow to saturate */
        const intV v = vloadV(0, cells + at) + sum;
        vstoreV(v > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : (v < (intV)-GRID_LIMIT ? (intV)-GRID_LIMIT : v), 0, cells + at);
    }
}

__kernel void fusion_cached(
    const __global int *evidence,     // (n_beams, N_BINS) eq. 12 updates [logodds units]
    const __global int4 *bricks,      // (n_listed,) bx, by, bz, slot: the recorded plan's
    const __global uchar *counts,     // (n_items * BLOCK_ROWS * VEC,) entries per voxel (RECORD 1)
    const __global int *row_start,    // (n_items * BLOCK_ROWS,) first block of extras of each table row
    const __global int2 *first,       // (n_items * BLOCK_ROWS * VEC,) each voxel's first entry (RECORD 2)
    const __global int2 *extras,      // the further entries, in blocks of VEC (RECORD 2)
    const int n_items,                // the gather's work-items: listed bricks x SUBS
    const __global int2 *nodes,       // DETSTATS: (n_beams, N_BINS, CLASSES, SEGMENTS) packed node pairs (the class
                                      //   of each entry is in its record; CLASSES 1: terrain entries take nothing)
    __global int *knowledge,          // DETSTATS: (slots, 8, 8, 8) detection opportunity
    __global int *looks,              // DETSTATS: (slots, 8, 8, 8) updates with an opportunity
    __global int *pool)               // (slots, 8, 8, 8) the grid's bricks [logodds units]
{
    const int id = get_global_id(0);
    if (id >= n_items)
        return;
    const int4 brick = bricks[id / SUBS];
    const int sub = id % SUBS;
    const int3 corner = CORNER(sub);
    const size_t block = brick.w * BRICK_CELLS + (corner.z * 8 + corner.y) * 8 + corner.x;
    __global int *cells = pool + block;
#ifdef DETSTATS
    __global int *kcells = knowledge + block, *lcells = looks + block;
#else
    __global int *kcells = pool, *lcells = pool;              /* not read */
#endif
    const __global int *dense = (const __global int *)first + (size_t)id * BLOCK_ROWS * VEC * 2;
#if BRICK_Z == 1
    /* A planar block's eight rows: every row's entries first, then every row's cells. A spinning
     * radar's node pairs lie beyond the cache, and its voxels take two entries each: the rows'
     * gathers wait on memory together instead of one row's at a time. (An 8^3 brick's 16 rows
     * held so spill, and its frames were slower.) */
    intV sum[BLOCK_ROWS], ksum[BLOCK_ROWS], nsum[BLOCK_ROWS];
    for (int row = 0; row < BLOCK_ROWS; ++row)
        row_sums(row, id, dense, counts, row_start, extras, evidence, nodes, sum + row, ksum + row, nsum + row);
    for (int row = 0; row < BLOCK_ROWS; ++row)
        store_row(row, sum[row], ksum[row], nsum[row], cells, kcells, lcells);
#else
    for (int row = 0; row < BLOCK_ROWS; ++row) {
        intV sum, ksum, nsum;
        row_sums(row, id, dense, counts, row_start, extras, evidence, nodes, &sum, &ksum, &nsum);
        store_row(row, sum, ksum, nsum, cells, kcells, lcells);
    }
#endif
}
