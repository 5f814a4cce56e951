/* Beam-to-voxel fusion of one whole frame: eq. 9 with the beam volume of §3.4 (Fig. 7c).
 *
 * Equivalent to radarcl.oracle.fusion(...): every voxel whose centre lies inside a beam's
 * volume takes that beam's eq. 12 update for the range bin of its centre, scaled by the two-way
 * weight (GAUSSIAN) and rounded half to even; the grid adds the voxel's sum of updates once.
 * See radarcl/geometry.py for the frames and the beam volume, radarcl/grid.py for the storage.
 *
 * A gather: each voxel is owned by one work-item, which tests each candidate beam once, sums
 * its updates in registers and writes the sum once. So each voxel gets at most one update per
 * beam, no atomics are needed, and the integer grid does not depend on any ordering.
 *   get_global_id(0) = listed brick * SUBS + sub-brick, a block of the brick (fusion_common.h);
 *   the work-item walks its BLOCK_ROWS rows of VEC voxels along x, ROWS rows at a time as the lanes of
 *   one vector (a unit: LN = VEC x ROWS voxels; ROWS = 2 fills AVX-512's 16 lanes with rows
 *   y, y + 1, which are contiguous in the brick). Any local size is correct.
 * Candidates: the host gives each listed brick a conservative window of beams (i, k)
 * (radarcl.stages.fusion_plan.candidate_windows). Each work-item first drops the candidates whose
 * volume cannot reach its sub-brick's bounding sphere: |y_c| - R > W_az(d_c + R) (or the same
 * in elevation) means no point of the sphere is inside, since |y| is 1-Lipschitz and W grows
 * with d.
 *
 * -D: VEC (4 or 8), ROWS (1, or 2 with VEC 8), N_AZ, N_EL, N_BINS (frame shape); BRICK_Z (voxels per brick
 *     along z: 8, or 1 for a planar sensor's bricks; default 8); NEAR_FIELD (cylinder of the antenna's cross-section),
 *     GAUSSIAN (two-way weight), PER_BEAM_POSES (each beam measures range from its own origin),
 *     AZ_WRAP (the azimuths span a full turn, windows may run past either end),
 *     RECORD (1 or 2: instead of fusing, record the still table that fusion_cached.cl streams
 *     (its layout: fusion_common.h); 1 counts each voxel's beams into counts[], 2 writes each
 *     voxel's first entry into first[] and the rest into extras[] from row_start[]; with DETSTATS
 *     both leave out an entry in a segment whose nodes never carry anything (live[]; a terrain
 *     entry of a scene without that class is kept, and takes nothing), and 2 sets
 *     in node_use[] the classes whose node pairs the entries read: the node kernel computes those
 *     alone for the table's frames);
 *     DETSTATS (the detection-statistics model: each voxel interpolates its bin's node pairs at
 *     its quantised rho2 and class, fusion_common.h, and writes the knowledge and looks channels
 *     beside the evidence). PACKED_LOOKS (DETSTATS, set by the host when a frame's knowledge of one voxel,
 *     n_beams x KNOWLEDGE_SCALE, stays below 2^PACKED_LOOKS and its looks below 2^(31 - PACKED_LOOKS)):
 *     the gather keeps knowledge and looks in one accumulator (sum + count << PACKED_LOOKS), one
 *     register per unit fewer of the 32 AVX-512 holds. NO_INT64 (a device without 64-bit integers,
 *     optional in the embedded profile): DETSTATS gathers a node pair as an int2 per lane, not
 *     as lanes of one ulong vector. DEAD_SEGMENTS (DETSTATS, set by the host where live[] says some
 *     segment of the window never carries anything): the fusing gather skips a unit whose lanes all
 *     lie in such segments (it would add nothing).
 */
#include "fusion_common.h"

#ifndef ROWS
#define ROWS 1
#endif
/* a unit's lanes: x offset LX and y offset LY (lane = y offset * VEC + x offset) */
#if VEC == 4 && ROWS == 1
#define LN 4
#define LX ((int4)(0, 1, 2, 3))
#define LY ((int4)0)
#define GATHER_L GATHER
#elif VEC == 8 && ROWS == 1
#define LN 8
#define LX ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#define LY ((int8)0)
#define GATHER_L GATHER
#elif VEC == 8 && ROWS == 2
#define LN 16
#define LX ((int16)(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7))
#define LY ((int16)(0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1))
#define GATHER_L(p, j) ((int16)(p[j.s0], p[j.s1], p[j.s2], p[j.s3], p[j.s4], p[j.s5], p[j.s6], p[j.s7], \
                                p[j.s8], p[j.s9], p[j.sa], p[j.sb], p[j.sc], p[j.sd], p[j.se], p[j.sf]))
#else
#error "ROWS must be 1, or 2 with VEC 8"
#endif
#define UNITS (BLOCK_ROWS / ROWS)             /* units per block */
#define floatL CAT(float, LN)
#define intL CAT(int, LN)
#define convert_floatL CAT(convert_float, LN)
#define convert_intL CAT(convert_int, LN)
#define vloadL CAT(vload, LN)
#define vstoreL CAT(vstore, LN)
#define as_intL CAT(as_int, LN)
#define as_floatL CAT(as_float, LN)
/* Builtin-free forms for the hot loop (PoCL may call builtins out of line; see weight_nb):
 * component-wise max / min / select by the ternary, round half to even by the 1.5 x 2^23 trick
 * (exact for |x| < 2^22, far beyond any evidence update) */
#define MAXF(a, b) ((a) > (b) ? (a) : (b))
#define MINF(a, b) ((a) < (b) ? (a) : (b))
#define RINT_INTL(x) (as_intL((x) + 12582912.0f) - 0x4B400000)
#if LN == 16
static inline int or_unit(int16 v)
{
    return or_lanes(v.lo | v.hi);
}
#else
#define or_unit or_lanes
#endif
#define vstore_ucharL CAT(vstore, LN)
#define convert_ucharL_sat CAT(CAT(convert_uchar, LN), _sat)
#define LAST CAT(s, CAT(VEC, _LAST))
#define s4_LAST s3
#define s8_LAST s7
/* row r of a sub-brick is y offset ROW_DY(r), z offset ROW_DZ(r); a block of 8 rows repeats
 * them in lanes 8-15 (whose bits no unit reads) */
#if BLOCK_ROWS == 16
#define ROW_Y ((float16)(0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3))
#define ROW_Z ((float16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3))
#else
#define ROW_Y ((float16)(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7))
#define ROW_Z ((float16)0)
#endif
#ifdef DETSTATS
/* node pairs as 64-bit loads, split after (G2_ is the same per int2): the node pairs of a unit's
 * lanes in one long vector (GATHER_U64: PoCL then gathers whole vectors instead of inserting 2 LN
 * lanes one by one), split into their even and odd 32-bit words (two permutes, where narrowing
 * each half was six instructions) */
#if LN == 16
#define SPLIT_NODES(pe, pk, g) { const int16 lo_ = as_int16(g.lo), hi_ = as_int16(g.hi); \
    pe = (int16)(lo_.even, hi_.even); pk = (int16)(lo_.odd, hi_.odd); }
#else
#define SPLIT_NODES(pe, pk, g) { const CAT(int, VEC2) w_ = CAT(as_int, VEC2)(g); pe = w_.even; pk = w_.odd; }
#endif
#ifdef NO_INT64
/* a device without 64-bit integers (optional in the embedded profile): one int2 per lane */
#define G2_16(pe, pk, p, at) G2_8(pe, pk, p, at) G2_(pe, pk, p, at, 8) G2_(pe, pk, p, at, 9) G2_(pe, pk, p, at, a) \
    G2_(pe, pk, p, at, b) G2_(pe, pk, p, at, c) G2_(pe, pk, p, at, d) G2_(pe, pk, p, at, e) G2_(pe, pk, p, at, f)
#define GATHER_NODES(pe, pk, p, at) CAT(G2_, LN)(pe, pk, p, at)
#else
#define GATHER_NODES(pe, pk, p, at) { const CAT(ulong, LN) g_ = GATHER_U64(LN, p, at); SPLIT_NODES(pe, pk, g_) }
#endif
#endif
/* bit r set where lane r of an int16 mask is true */
#define ROW_BITS(m) ((uint)(as_uint(m.s0) & 1u) | (as_uint(m.s1) & 2u) | (as_uint(m.s2) & 4u) | (as_uint(m.s3) & 8u) \
    | (as_uint(m.s4) & 16u) | (as_uint(m.s5) & 32u) | (as_uint(m.s6) & 64u) | (as_uint(m.s7) & 128u) \
    | (as_uint(m.s8) & 256u) | (as_uint(m.s9) & 512u) | (as_uint(m.sa) & 1024u) | (as_uint(m.sb) & 2048u) \
    | (as_uint(m.sc) & 4096u) | (as_uint(m.sd) & 8192u) | (as_uint(m.se) & 16384u) | (as_uint(m.sf) & 32768u))

/* 4^-t for t in [0, 1] (the two-way Gaussian weight) without a builtin call: a degree-6
 * polynomial in t (weighted least squares on Chebyshev nodes, rounded to float32), evaluated
 * by Horner with fused multiply-adds: |relative error| < 6e-7 on [0, 1] (the degree-11 Taylor
 * series of exp(-t ln 4) it replaced: 8e-7 in float32, six more operations per voxel). */
static inline floatL weight_nb(floatL t)
{
    floatL p = (floatL)0.004845182877033949f;
    p = p * t - 0.036285415291786194f;
    p = p * t + 0.14953838288784027f;
    p = p * t - 0.4424431324005127f;
    p = p * t + 0.9606195092201233f;
    p = p * t - 1.3862742185592651f;
    return p * t + 0.9999997615814209f;
}

__kernel void fusion(
    const __global int *evidence,     // (n_beams, N_BINS) eq. 12 updates [logodds units]
    const __global float4 *beams,     // (n_beams, 3): u, v, w axes in grid coordinates; .w of the
                                      //   three = the beam's origin x, y, z [m, from the grid origin]
    const __global int4 *bricks,      // (n_listed,) bx, by, bz, slot
    const __global int4 *windows,     // (n_listed,) candidate beams i_lo, i_hi, k_lo, k_hi
    const float voxel,                // voxel edge [m]
    const float inv_spacing,          // 1 / range bin spacing [1/m]
    const int first_bin,              // bins that give evidence: [first_bin, last_bin]
    const int last_bin,
    const int nx,                     // grid shape [voxels]
    const int ny,
    const int nz,
    const float tan_half_az,          // tan(half-power beamwidth / 2), azimuth
    const float tan_half_el,          //   and elevation
    const float a_az,                 // half apertures [m] (0 without NEAR_FIELD)
    const float a_el,
    const int n_items,                // listed bricks x SUBS: work-items past it do nothing
    __global uchar *counts,           // RECORD: (n_items * BLOCK_ROWS * VEC,) beams per voxel (out with 1)
    const __global int *row_start,    // RECORD 2: (n_items * BLOCK_ROWS,) first block of extras of each table row
    __global int2 *first,             // RECORD 2: out, per voxel its first (beam * N_BINS + bin,
                                      //   as_int(weight)); (0, 0) where no beam reaches
    __global int2 *extras,            // RECORD 2: out, the voxels' further entries, in blocks of VEC (fusion_common.h)
    const __global int2 *nodes,       // DETSTATS: (n_beams, N_BINS, CLASSES, SEGMENTS) packed node pairs (fusion_common.h)
    const float terrain_dz,           // DETSTATS: voxels with z - beam origin z below this are terrain [m]
    __global int *knowledge,          // DETSTATS: (slots, 8, 8, 8) detection opportunity [KNOWLEDGE_SCALE units]
    __global int *looks,              // DETSTATS: (slots, 8, 8, 8) updates with an opportunity [count]
    __global uint *node_use,          // RECORD 2 with DETSTATS: (n_beams, N_BINS), or'd into: bit c where a voxel
                                      //   reads class c's node pairs of that beam's bin (the node kernel's work)
    const __global int *live,         // DETSTATS: (N_BINS, CLASSES) bit s: segment s may carry an update
                                      //   (node_pairs.live_segments); an entry in another is left out of the table
                                      //   (RECORD), a unit with no lane in one skipped (DEAD_SEGMENTS)
    __global int *pool)               // (slots, 8, 8, 8) the grid's bricks [logodds units]
{
    const int id = get_global_id(0);
    if (id >= n_items)
        return;
    const int4 brick = bricks[id / SUBS];
    const int4 w = windows[id / SUBS];
    const int sub = id % SUBS;
    const int3 corner = CORNER(sub);                                                         /* in the brick */
    const int3 base = brick.xyz * (int3)(8, 8, BRICK_Z) + corner;                            /* in the grid */
    const float3 centre = (convert_float3(base) + (float3)(0.5f * VEC, 0.5f * SUB_Y, 0.5f * SUB_Z)) * voxel;
    const float radius = 0.5f * sqrt((float)(VEC * VEC + SUB_Y * SUB_Y + SUB_Z * SUB_Z)) * voxel;
    /* unit u holds rows ROWS u .. ROWS u + ROWS - 1: y offset ROW_DY(ROWS u) + LY, z offset ROW_DZ(ROWS u) */
    const floatL px = (convert_floatL(base.x + LX) + 0.5f) * voxel;
    const floatL ly = convert_floatL(LY);
    const intL in_x = base.x + LX < nx;
    intL acc[UNITS];
    for (int u = 0; u < UNITS; ++u)
        acc[u] = 0;
#if defined(DETSTATS) && !RECORD && defined(PACKED_LOOKS)
    intL kacc[UNITS];                 /* the knowledge channel's sums + the looks' counts << PACKED_LOOKS */
    for (int u = 0; u < UNITS; ++u)
        kacc[u] = 0;
#elif defined(DETSTATS) && !RECORD
    intL kacc[UNITS], nacc[UNITS];    /* the knowledge channel's sums, the looks' counts */
    for (int u = 0; u < UNITS; ++u)
        kacc[u] = nacc[u] = 0;
#endif
#ifndef PER_BEAM_POSES
    /* one origin for the frame: one bin per voxel, -1 where no evidence can come; computed when
     * the first beam reaches the block (a quarter of the kernel's time went here, for blocks
     * no beam reaches as well) */
    intL bins[UNITS];
#endif
    int touched = 0;
    for (int k = w.s2; k <= w.s3; ++k) {
        for (int ii = w.s0; ii <= w.s1; ++ii) {
#ifdef AZ_WRAP
            const int i = ii < 0 ? ii + N_AZ : (ii >= N_AZ ? ii - N_AZ : ii);
#else
            const int i = ii;
#endif
            const int b = i * N_EL + k;
            const float4 U = beams[3 * b], V = beams[3 * b + 1], W = beams[3 * b + 2];
            const float3 o = (float3)(U.w, V.w, W.w);
            /* can this beam reach the sub-brick's bounding sphere? */
            const float3 c = centre - o;
            const float dc = c.x * U.x + c.y * U.y + c.z * U.z + radius;
#ifdef NEAR_FIELD
            const float wa_c = MAXF(dc * tan_half_az, a_az), we_c = MAXF(dc * tan_half_el, a_el);
#else
            const float wa_c = dc * tan_half_az, we_c = dc * tan_half_el;
#endif
            const float yc = c.x * V.x + c.y * V.y + c.z * V.z, zc = c.x * W.x + c.y * W.y + c.z * W.z;
            if (dc <= 0.0f || (yc < 0.0f ? -yc : yc) - radius > wa_c || (zc < 0.0f ? -zc : zc) - radius > we_c)
                continue;
#ifndef PER_BEAM_POSES
            if (!touched) {
                const float3 o0 = (float3)(beams[0].w, beams[1].w, beams[2].w);
                const floatL qx0 = px - o0.x;
                for (int u = 0; u < UNITS; ++u) {
                    const int r0 = ROWS * u;
                    const floatL qy = ((float)(base.y + ROW_DY(r0)) + 0.5f + ly) * voxel - o0.y;
                    const float qz = (base.z + ROW_DZ(r0) + 0.5f) * voxel - o0.z;
                    /* clamped below 2^22 for RINT_INTL: a bin that far is past last_bin anyway */
                    const floatL x = MINF(sqrt(qx0 * qx0 + (qy * qy + qz * qz)) * inv_spacing, (floatL)4194303.0f);
                    const intL bin = RINT_INTL(x);
                    const intL ok = in_x & (base.y + ROW_DY(r0) + LY < ny) & (base.z + ROW_DZ(r0) < nz ? -1 : 0);
                    bins[u] = ok & (bin >= first_bin) & (bin <= last_bin) ? bin : (intL)-1;
                }
            }
#endif
            touched = 1;
#ifdef DETSTATS
            const __global int2 *row_nodes = nodes + (size_t)b * N_BINS * CLASSES * SEGMENTS;
#else
            const __global int *row_ev = evidence + b * N_BINS;
#endif
            const floatL qx = px - o.x;
            const floatL dx = qx * U.x, yx = qx * V.x, zx = qx * W.x;
            /* Rows that may hold an inside voxel. Inside needs d > 0 and |y| <= W_az(d) <=
             * a_az + tan_az d (and the same for z): linear in x along a row, so a row whose
             * first and last voxels both break one of these breaks it everywhere. */
            const float16 qy16 = (ROW_Y + (float)base.y + 0.5f) * voxel - o.y;
            const float16 qz16 = (ROW_Z + (float)base.z + 0.5f) * voxel - o.z;
            const float16 d0 = dx.s0 + qy16 * U.y + qz16 * U.z, d1 = d0 + (dx.LAST - dx.s0);
            const float16 y0 = yx.s0 + qy16 * V.y + qz16 * V.z, y1 = y0 + (yx.LAST - yx.s0);
            const float16 z0 = zx.s0 + qy16 * W.y + qz16 * W.z, z1 = z0 + (zx.LAST - zx.s0);
            const float16 wa0 = a_az + tan_half_az * d0, wa1 = a_az + tan_half_az * d1;
            const float16 we0 = a_el + tan_half_el * d0, we1 = a_el + tan_half_el * d1;
            const int16 maybe = (MAXF(d0, d1) > 0.0f) & (MINF(y0 - wa0, y1 - wa1) <= 0.0f)
                              & (MINF(-y0 - wa0, -y1 - wa1) <= 0.0f) & (MINF(z0 - we0, z1 - we1) <= 0.0f)
                              & (MINF(-z0 - we0, -z1 - we1) <= 0.0f);
            uint rows = ROW_BITS(maybe);
#if ROWS == 2
            rows |= rows >> 1;                            /* bit 2u: row 2u or 2u + 1 may be inside */
            /* and units u, u + 2 (z, z + 1) decided together: about half of the units a beam's
             * block tests pass, so a branch per unit was a coin toss to predict; fewer, surer
             * branches beat the work they add */
            rows = ((rows | (rows >> 4)) & 0x0505u) * 17u;
#endif
            /* a loop of fixed trip count over the units, unrolled: acc[] and bins[] indexed by
             * constants stay in registers (indexed by a row found at run time they go through
             * memory) */
#pragma unroll
            for (int u = 0; u < UNITS; ++u) {
                const int r0 = ROWS * u;
                if (!(rows & (1u << r0)))
                    continue;
                const floatL qy = ((float)(base.y + ROW_DY(r0)) + 0.5f + ly) * voxel - o.y;
                const float qz = (base.z + ROW_DZ(r0) + 0.5f) * voxel - o.z;
#if defined(DETSTATS) && !RECORD && CLASSES == 1
                if (qz < terrain_dz)          /* terrain voxels, of a class this scene has not: they take nothing */
                    continue;
#endif
#ifdef PER_BEAM_POSES
                const floatL x = MINF(sqrt(qx * qx + (qy * qy + qz * qz)) * inv_spacing, (floatL)4194303.0f);
                const intL raw = RINT_INTL(x);
                const intL ok = in_x & (base.y + ROW_DY(r0) + LY < ny) & (base.z + ROW_DZ(r0) < nz ? -1 : 0);
                const intL bin = ok & (raw >= first_bin) & (raw <= last_bin) ? raw : (intL)-1;
#else
                const intL bin = bins[u];
#endif
                const floatL d = dx + (qy * U.y + qz * U.z);
                const floatL y = yx + (qy * V.y + qz * V.z);
                const floatL z = zx + (qy * W.y + qz * W.z);
#ifdef NEAR_FIELD
                const floatL wa = MAXF(d * tan_half_az, a_az), we = MAXF(d * tan_half_el, a_el);
#else
                const floatL wa = d * tan_half_az, we = d * tan_half_el;
#endif
                /* rho2 = (y / wa)^2 + (z / we)^2 <= 1, without dividing by a vanishing width */
                const floatL wa2 = wa * wa, we2 = we * we;
                const floatL num = y * y * we2 + z * z * wa2, den = wa2 * we2;
                intL inside = (bin >= 0) & (d > 0.0f) & (den > 0.0f) & (num <= den);   /* RECORD drops dead lanes */
#if RECORD && defined(DETSTATS)
                /* the entries' quantised rho2 and class, as the gather's (fusion_common.h). An entry
                 * in a segment whose nodes never carry anything adds nothing, ever: left out. A
                 * terrain voxel of a scene without that class (cls == CLASSES) is kept, as before:
                 * its entries take nothing (TAKES), and the table's tests count them */
                const intL q = convert_intL(MINF(num / den * Q_ONE, Q_MAX));
                const int cls = qz < terrain_dz;
                if (cls < CLASSES)
                    for (int lane = 0; lane < LN; ++lane)
                        if (((const int *)&inside)[lane]) {
                            const int jl = ((const int *)&bin)[lane], sl = ((const int *)&q)[lane] >> 12;
                            if (!((live[jl * CLASSES + cls] >> sl) & 1))
                                ((int *)&inside)[lane] = 0;
                        }
#endif
#if RECORD
                if (!or_unit(inside))
                    continue;
#endif
                /* no branch on "any lane inside" when fusing: 40 % of the units tested have none,
                 * too many for the branch predictor; the mask zeroes them */
                const intL j = bin & ~(bin >> 31);                /* max(bin, 0) without the builtin */
#if RECORD == 1
                acc[u] -= inside;                                 /* inside is -1 */
#elif RECORD == 2
  #if defined(DETSTATS)
                const floatL wt = as_floatL((q + 1) | (cls << 16));             /* the table entry: fusion_common.h */
  #elif defined(GAUSSIAN)
                const floatL wt = weight_nb(num / den);
  #else
                const floatL wt = (floatL)1.0f;
  #endif
                const size_t v0 = ((size_t)id * BLOCK_ROWS + r0) * VEC;  /* the unit's first voxel in the table */
  #if defined(DETSTATS)
                int used = -1;                                /* the last bin this unit marked used (lanes run along x) */
  #endif
                for (int lane = 0; lane < LN; ++lane) {
                    if (((const int *)&inside)[lane]) {
                        const int written = ((const int *)&acc[u])[lane];
                        const int2 entry = (int2)(b * N_BINS + ((const int *)&j)[lane], as_int(((const float *)&wt)[lane]));
  #if defined(DETSTATS)
                        if (entry.x != used) {                /* neighbours along x may share a bin: one atomic */
                            atomic_or(node_use + entry.x, 1u << cls);
                            used = entry.x;
                        }
  #endif
                        if (written == 0) {                   /* sign bit: more entries follow */
                            first[v0 + lane] = counts[v0 + lane] > 1 ? (int2)(entry.x, entry.y | (int)0x80000000) : entry;
                        } else {                              /* the row's extras: its (written)-th block, this lane */
                            const int block = row_start[(size_t)id * BLOCK_ROWS + r0 + lane / VEC] + written - 1;
                            extras[(size_t)block * VEC + lane % VEC] = entry;
                        }
                    }
                }
                acc[u] -= inside;                                 /* inside is -1 */
#elif defined(DETSTATS)
                /* rho2 quantised, in [0, Q_MAX] (num >= 0 and den >= 0; 0 / 0 is NaN, which MINF
                 * takes to Q_MAX; outside lanes' junk is masked below) */
                const intL q = convert_intL(MINF(num / den * Q_ONE, Q_MAX));
                const intL seg = q >> 12;
                const intL f = q & 4095;
                const intL at = NODE_AT(j, qz < terrain_dz, seg);
  #ifdef DEAD_SEGMENTS
                {
                    /* a unit whose inside lanes all lie in segments that never carry anything
                     * (far terrain a tilted radar cannot see) adds nothing: its node gather is
                     * skipped. (With CLASSES 1, terrain units never get here: see above.) */
                    const __global int *lc = live + ((qz < terrain_dz) & (CLASSES - 1));
                    const intL lj = j * CLASSES;
                    if (!or_unit(inside & (((GATHER_L(lc, lj) >> seg) & 1) != 0)))
                        continue;
                }
  #endif
                intL pe, pk;
                GATHER_NODES(pe, pk, row_nodes, at);
                acc[u] += NODE_LERP(pe, f) & inside;
                const intL kn = NODE_LERP(pk, f) & inside;
  #ifdef PACKED_LOOKS
                kacc[u] += kn + ((kn > 0) & (intL)(1 << PACKED_LOOKS));
  #else
                kacc[u] += kn;
                nacc[u] -= kn > 0;                            /* true is -1 */
  #endif
#else
                intL e = GATHER_L(row_ev, j);
  #ifdef GAUSSIAN
                const floatL product = convert_floatL(e) * weight_nb(num / den);
                e = RINT_INTL(product);
  #endif
                acc[u] += e & inside;
#endif
            }
        }
    }
#if RECORD == 1
    for (int u = 0; u < UNITS; ++u)
        vstore_ucharL(convert_ucharL_sat(acc[u]), 0, counts + ((size_t)id * BLOCK_ROWS + ROWS * u) * VEC);
    return;
#elif RECORD == 2
    return;
#endif
    if (!touched)
        return;
    __global int *cells = pool + brick.w * BRICK_CELLS + (corner.z * 8 + corner.y) * 8 + corner.x;
    for (int u = 0; u < UNITS; ++u) {
#if defined(DETSTATS) && !RECORD
        if (or_unit(kacc[u])) {       /* non-negative, saturating at GRID_LIMIT: order does not matter */
            const int r0 = ROWS * u;
            __global int *cell = knowledge + brick.w * BRICK_CELLS + (corner.z * 8 + corner.y) * 8 + corner.x
                                 + (ROW_DZ(r0) * 8 + ROW_DY(r0)) * 8;
  #ifdef PACKED_LOOKS
            const intL ksum = kacc[u] & (intL)((1 << PACKED_LOOKS) - 1), nsum = kacc[u] >> PACKED_LOOKS;
  #else
            const intL ksum = kacc[u], nsum = nacc[u];
  #endif
            const intL v = vloadL(0, cell) + ksum;
            vstoreL(v > (intL)GRID_LIMIT ? (intL)GRID_LIMIT : v, 0, cell);
            /* before the evidence's store: a voxel whose sum saturated before this frame and is
             * pushed no way back counts no more looks (STUCK), or its reading E / (n / look_limit)
             * would fade as 1 / n */
            const intL e0 = vloadL(0, cells + (ROW_DZ(r0) * 8 + ROW_DY(r0)) * 8);
            __global int *count = looks + (cell - knowledge);
            const intL c = vloadL(0, count) + (nsum & ~STUCK(e0, acc[u]));
            vstoreL(c > (intL)GRID_LIMIT ? (intL)GRID_LIMIT : c, 0, count);
        }
#endif
        if (or_unit(acc[u])) {
            /* |acc| < n_beams x 2^14 <= 2^31 - 2^30 - 1 (Fusion refuses larger lattices) and |cell| <=
             * GRID_LIMIT = 2^30: the sum cannot overflow int32, so no add_sat. A unit's rows are
             * contiguous in the brick (ROWS 2 comes with VEC 8, the brick's edge). */
            const int r0 = ROWS * u;
            __global int *cell = cells + (ROW_DZ(r0) * 8 + ROW_DY(r0)) * 8;
            const intL v = vloadL(0, cell) + acc[u];
            vstoreL(v > (intL)GRID_LIMIT ? (intL)GRID_LIMIT : (v < (intL)-GRID_LIMIT ? (intL)-GRID_LIMIT : v), 0, cell);
        }
    }
}
