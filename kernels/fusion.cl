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
 *   get_global_id(0) = listed brick * SUBS + sub-brick, a VEC x SUB_Y x SUB_Z block of the brick
 *   (VEC x 4 x 4 of an 8^3 brick; VEC x 8 x 1 of an 8 x 8 x 1 brick, BRICK_Z 1);
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
 *     RECORD (1 or 2: instead of fusing, record what each voxel takes, for fusion_cached below;
 *     1 counts each voxel's beams into counts[], 2 writes each voxel's first (beam * N_BINS +
 *     bin, weight) into first[] and the rest into extras[] from row_start[], the host's prefix
 *     sums of the counts beyond the first);
 *     DETSTATS (the detection-statistics model, radarcl.sensor_model): a bin's update is not
 *     e x weight(rho2) but a function of rho2 the interpreter tabulated at NODES rho2 = 0, 1/4,
 *     ..., 1 (the CFAR's P_d falls non-linearly with the voxel's two-way gain), for each of two
 *     classes of target (0 upright, 1 terrain: a voxel whose centre lies below its beam's origin by
 *     more than -terrain_dz, i.e. z - origin z < terrain_dz, near the ground plane). nodes[] holds
 *     per (beam, bin, class, segment s) the int2 (e_s | e_{s+1} << 16, d_s | d_{s+1} << 16) of the evidence
 *     e [logodds units] and the detection opportunity d [KNOWLEDGE_SCALE units] at the segment's
 *     two ends, one 8-byte gather per voxel. rho2 is quantised to q = floor(min(rho2 x 2^14, 2^14 - 1))
 *     (a float32 multiply by a power of two, then truncation; the cap puts rho2 = 1 at the end of
 *     the last segment, and a NaN of an empty beam width there too: every q indexes a node pair),
 *     the segment is q >> 12 and the interpolation integer: e_s + ((e_{s+1} - e_s) (q & 4095) + 2048)
 *     >> 12, so the gather and
 *     the still table give the same integers whatever the compiler contracts. The evidence goes
 *     to pool[], the opportunity to knowledge[] (the knowledge channel: "never observed" apart
 *     from "observed, undecided"), and looks[] counts the updates whose opportunity is not 0 (the
 *     reading counts correlated looks once: sensor_model.read_log_odds), except where the evidence
 *     sum sat at its limit before the frame and the frame does not pull it back (STUCK). The still table keeps
 *     q + 1 (never 0, whose bits mean "no beam") as an integer in place of the weight, and the
 *     class in bit 16. PACKED_LOOKS (DETSTATS, set by the host when a frame's knowledge of one voxel,
 *     n_beams x KNOWLEDGE_SCALE, stays below 2^PACKED_LOOKS and its looks below 2^(31 - PACKED_LOOKS)):
 *     the gather keeps knowledge and looks in one accumulator (sum + count << PACKED_LOOKS), one
 *     register per unit fewer of the 32 AVX-512 holds. NO_INT64 (a device without 64-bit integers,
 *     optional in the embedded profile): DETSTATS gathers a node pair as an int2 per lane, not
 *     as lanes of one ulong vector.
 *
 * fusion_cached: a still radar's frame from the recorded table: each voxel sums
 * rint(evidence[entry] * weight) over its entries, the same integers the gather gives (the
 * weights are the gather's own float32 values), streaming the table instead of testing beams.
 * Table rows are the gather's: row t = work-item t / BLOCK_ROWS, row t % BLOCK_ROWS of its block
 * (whatever ROWS the recording gather used: a unit's lanes are consecutive voxels of the table).
 * The first entries are dense (one per voxel, read as vectors: on a regular lattice almost every
 * voxel lies in one beam), the weight's sign bit set where more follow; the rest follow per row,
 * lane after lane, and are read as vectors too, each lane's next entry at a time (a spinning
 * radar's voxels mostly lie in two beams). Every entry is rounded on its own and the sums are
 * integers, so the order the entries are added in does not change them.
 */
#include "radarcl_common.h"

#ifndef BRICK_Z
#define BRICK_Z 8
#endif
#if BRICK_Z == 8
#define SUB_Y 4                               /* a work-item's block along y and z */
#define SUB_Z 4
#define SUBS ((8 / VEC) * 4)                  /* sub-bricks per brick */
#define CORNER(sub) ((int3)(((sub) >> 2) * VEC, ((sub) & 1) * SUB_Y, (((sub) >> 1) & 1) * SUB_Z))
#elif BRICK_Z == 1
#define SUB_Y 8
#define SUB_Z 1
#define SUBS (8 / VEC)
#define CORNER(sub) ((int3)((sub) * VEC, 0, 0))
#else
#error "BRICK_Z must be 8 or 1"
#endif
#define BLOCK_ROWS (SUB_Y * SUB_Z)            /* rows of VEC voxels per work-item: 16 or 8 */
#define BRICK_CELLS (64 * BRICK_Z)            /* voxels per brick */
#define ROW_DY(r) ((r) % SUB_Y)               /* row r of a block: y offset, z offset */
#define ROW_DZ(r) ((r) / SUB_Y)
#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define floatV CAT(float, VEC)
#define intV CAT(int, VEC)
#define convert_floatV CAT(convert_float, VEC)
#define vloadV CAT(vload, VEC)
#define vstoreV CAT(vstore, VEC)
#if VEC == 4
#define VEC2 8
#define GATHER(p, j) ((int4)(p[j.s0], p[j.s1], p[j.s2], p[j.s3]))
#elif VEC == 8
#define VEC2 16
#define GATHER(p, j) ((int8)(p[j.s0], p[j.s1], p[j.s2], p[j.s3], p[j.s4], p[j.s5], p[j.s6], p[j.s7]))
#else
#error "VEC must be 4 or 8"
#endif
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
#define as_intV CAT(as_int, VEC)
#define as_floatV CAT(as_float, VEC)
/* Builtin-free forms for the hot loop (PoCL may call builtins out of line; see weight_nb):
 * component-wise max / min / select by the ternary, round half to even by the 1.5 x 2^23 trick
 * (exact for |x| < 2^22, far beyond any evidence update) */
#define MAXF(a, b) ((a) > (b) ? (a) : (b))
#define MINF(a, b) ((a) < (b) ? (a) : (b))
#define RINT_INTV(x) (as_intV((x) + 12582912.0f) - 0x4B400000)
#define RINT_INTL(x) (as_intL((x) + 12582912.0f) - 0x4B400000)
/* the OR of an intV's or intL's lanes (any lane nonzero; any sign bit set), without any() */
static inline int or_lanes(intV v)
{
#if VEC == 8
    const int4 h = v.lo | v.hi;
    const int2 q = h.lo | h.hi;
#else
    const int2 q = v.lo | v.hi;
#endif
    return q.x | q.y;
}
/* lane l of the result: the sum of v's lanes before l (a scan by shifted adds, no builtin) */
static inline intV exclusive_prefix(intV v)
{
#if VEC == 8
    intV s = v + (int8)(0, v.s0, v.s1, v.s2, v.s3, v.s4, v.s5, v.s6);
    s += (int8)(0, 0, s.s0, s.s1, s.s2, s.s3, s.s4, s.s5);
    s += (int8)(0, 0, 0, 0, s.s0, s.s1, s.s2, s.s3);
#else
    intV s = v + (int4)(0, v.s0, v.s1, v.s2);
    s += (int4)(0, 0, s.s0, s.s1);
#endif
    return s - v;
}
#if LN == 16
static inline int or_unit(int16 v)
{
    return or_lanes(v.lo | v.hi);
}
#else
#define or_unit or_lanes
#endif
#define vstore_ucharL CAT(vstore, LN)
#define vload_ucharV CAT(vload, VEC)
#define intV2 CAT(int, VEC2)
#define vloadV2 CAT(vload, VEC2)
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
/* bit r set where lane r of an int16 mask is true */
/* one int2 per lane (a node pair, a table entry): its first half into pe, its second into pk */
#define G2_(pe, pk, p, at, l) { const int2 q_ = p[at.s##l]; pe.s##l = q_.x; pk.s##l = q_.y; }
#define G2_4(pe, pk, p, at) G2_(pe, pk, p, at, 0) G2_(pe, pk, p, at, 1) G2_(pe, pk, p, at, 2) G2_(pe, pk, p, at, 3)
#define G2_8(pe, pk, p, at) G2_4(pe, pk, p, at) G2_(pe, pk, p, at, 4) G2_(pe, pk, p, at, 5) G2_(pe, pk, p, at, 6) \
    G2_(pe, pk, p, at, 7)
#define GATHER_ENTRIES(ei, ew, p, at) CAT(G2_, VEC)(ei, ew, p, at)     /* still-table entries of a row's lanes */
#ifdef DETSTATS
/* the same as 64-bit loads, split after: the node pairs of a unit's lanes in one long vector (PoCL
 * then gathers whole vectors instead of inserting 2 LN lanes one by one), split into their even
 * and odd 32-bit words (two permutes, where narrowing each half was six instructions) */
#define GL_(p, at, l) p[at.s##l]
#define GL_4(p, at) GL_(p, at, 0), GL_(p, at, 1), GL_(p, at, 2), GL_(p, at, 3)
#define GL_8(p, at) GL_4(p, at), GL_(p, at, 4), GL_(p, at, 5), GL_(p, at, 6), GL_(p, at, 7)
#define GL_16(p, at) GL_8(p, at), GL_(p, at, 8), GL_(p, at, 9), GL_(p, at, a), GL_(p, at, b), GL_(p, at, c), \
    GL_(p, at, d), GL_(p, at, e), GL_(p, at, f)
#define ulongL CAT(ulong, LN)
#define as_uintL CAT(as_uint, LN)
#define convert_uintL CAT(convert_uint, LN)
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
#define GATHER_NODES(pe, pk, p, at) { const ulongL g_ = (ulongL)(CAT(GL_, LN)(((const __global ulong *)(p)), at)); \
    SPLIT_NODES(pe, pk, g_) }
#endif
#define GATHER_NODES_V(pe, pk, p, at) CAT(G2_, VEC)(pe, pk, p, at)
#define SEGMENTS 4                            /* node segments over rho2 in [0, 1] */
#define CLASSES 2                             /* target classes: upright, terrain */
/* lanes (-1) of a voxel whose evidence sum e0 sat at a limit before this frame and whose frame's
 * sum a does not pull it back: its looks are not counted (sensor_model.read_log_odds) */
#define STUCK(e0, a) ((((e0) >= GRID_LIMIT) & ((a) >= 0)) | (((e0) <= -GRID_LIMIT) & ((a) <= 0)))
#define Q_ONE 16384.0f                        /* rho2 = 1 in quantisation steps (2^14; 2^12 per segment) */
#define Q_MAX (Q_ONE - 1.0f)                  /* the last step: q stays in the last segment */
/* the interpolated value between the signed 16-bit halves of x at the fraction f / 4096 */
#define NODE_LERP(x, f) ((((x) << 16) >> 16) + (((((x) >> 16) - (((x) << 16) >> 16)) * (f) + 2048) >> 12))
#if !defined(KNOWLEDGE_SCALE)
#error "KNOWLEDGE_SCALE comes from radarcl.stages.COMMON_DEFINES"
#endif
#endif
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
    const __global int *row_start,    // RECORD 2: (n_items * BLOCK_ROWS,) first extra entry of each table row
    __global int2 *first,             // RECORD 2: out, per voxel its first (beam * N_BINS + bin,
                                      //   as_int(weight)); (0, 0) where no beam reaches
    __global int2 *extras,            // RECORD 2: out, the voxels' further entries, row by row
    const __global int2 *nodes,       // DETSTATS: (n_beams, N_BINS, CLASSES, SEGMENTS) packed node pairs (header)
    const float terrain_dz,           // DETSTATS: voxels with z - beam origin z below this are terrain [m]
    __global int *knowledge,          // DETSTATS: (slots, 8, 8, 8) detection opportunity [KNOWLEDGE_SCALE units]
    __global int *looks,              // DETSTATS: (slots, 8, 8, 8) updates with an opportunity [count]
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
                const intL inside = (bin >= 0) & (d > 0.0f) & (den > 0.0f) & (num <= den);
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
                const intL q = convert_intL(MINF(num / den * Q_ONE, Q_MAX));    /* as the gather's */
                const int cls = qz < terrain_dz;
                const floatL wt = as_floatL((q + 1) | (cls << 16));             /* see the header */
  #elif defined(GAUSSIAN)
                const floatL wt = weight_nb(num / den);
  #else
                const floatL wt = (floatL)1.0f;
  #endif
                const size_t v0 = ((size_t)id * BLOCK_ROWS + r0) * VEC;  /* the unit's first voxel in the table */
                for (int lane = 0; lane < LN; ++lane) {
                    if (((const int *)&inside)[lane]) {
                        const int written = ((const int *)&acc[u])[lane];
                        const int2 entry = (int2)(b * N_BINS + ((const int *)&j)[lane], as_int(((const float *)&wt)[lane]));
                        if (written == 0) {                   /* sign bit: more entries follow */
                            first[v0 + lane] = counts[v0 + lane] > 1 ? (int2)(entry.x, entry.y | (int)0x80000000) : entry;
                        } else {                              /* the row's extras, lane by lane */
                            const int row_lane0 = lane - lane % VEC;
                            int at = row_start[(size_t)id * BLOCK_ROWS + r0 + lane / VEC];
                            for (int l = row_lane0; l < lane; ++l)
                                at += max((int)counts[v0 + l] - 1, 0);
                            extras[at + written - 1] = entry;
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
                const intL at = (j * CLASSES + (qz < terrain_dz)) * SEGMENTS + seg;
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


__kernel void fusion_cached(
    const __global int *evidence,     // (n_beams, N_BINS) eq. 12 updates [logodds units]
    const __global int4 *bricks,      // (n_listed,) bx, by, bz, slot: the recorded plan's
    const __global uchar *counts,     // (n_items * BLOCK_ROWS * VEC,) entries per voxel (RECORD 1)
    const __global int *row_start,    // (n_items * BLOCK_ROWS,) first extra entry of each table row
    const __global int2 *first,       // (n_items * BLOCK_ROWS * VEC,) each voxel's first entry (RECORD 2)
    const __global int2 *extras,      // the further entries (RECORD 2)
    const int n_items,                // the gather's work-items: listed bricks x SUBS
    const __global int2 *nodes,       // DETSTATS: (n_beams, N_BINS, CLASSES, SEGMENTS) packed node pairs (the class
                                      //   of each entry is in its record)
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
    __global int *cells = pool + brick.w * BRICK_CELLS + (corner.z * 8 + corner.y) * 8 + corner.x;
#ifdef DETSTATS
    __global int *kcells = knowledge + brick.w * BRICK_CELLS + (corner.z * 8 + corner.y) * 8 + corner.x;
#endif
    const __global int *dense = (const __global int *)first + (size_t)id * BLOCK_ROWS * VEC * 2;
    for (int row = 0; row < BLOCK_ROWS; ++row) {
        const intV2 pairs = vloadV2(0, dense + row * VEC * 2);       /* idx, weight, idx, weight, ... */
        const intV bits = pairs.odd;
        if (!or_lanes(bits))                   /* no beam reaches the row */
            continue;
        const intV index = pairs.even;
#ifdef DETSTATS
        /* q + 1 in place of the weight (0: no beam), the class in bit 16, the sign bit "more
         * entries follow" */
        const intV q = (bits & 0xFFFF) - 1;                     /* -1 (no beam): masked below */
        const intV reached = bits != 0;
        const intV seg = (q >> 12) & (SEGMENTS - 1);            /* q = -1: segment 3, in bounds */
        const intV f = q & 4095;
        const intV at = (index * CLASSES + ((bits >> 16) & 1)) * SEGMENTS + seg;
        intV pe, pk;
        GATHER_NODES_V(pe, pk, nodes, at);
        intV sum = NODE_LERP(pe, f) & reached;
        intV ksum = NODE_LERP(pk, f) & reached;
        intV nsum = -(ksum > 0);
#else
        /* the weight's sign bit says "more entries follow" (weights are positive) */
        const floatV product = convert_floatV(GATHER(evidence, index)) * as_floatV(bits & 0x7FFFFFFF);
        intV sum = RINT_INTV(product);
#endif
        if (or_lanes(bits) < 0) {              /* voxels several beams reach */
            /* their further entries, one per lane at a time, as vectors: lane l's m-th extra is at
             * row_start + (the extras of lanes before l) + m; a spinning radar's voxels mostly
             * lie in two beams, so this is the common path there, not the exception */
            const size_t t = (size_t)id * BLOCK_ROWS + row;
            const intV more = CAT(convert_int, VEC)(vload_ucharV(0, counts + t * VEC)) - 1;
            const intV n_extra = more & ~(more >> 31);                    /* max(count - 1, 0) */
            const intV start = row_start[t] + exclusive_prefix(n_extra);
            for (int m = 0; or_lanes((intV)m - n_extra) < 0; ++m) {       /* some lane has an m-th */
                const intV live = (intV)m < n_extra;
                const intV ex = (start + m) & live;                       /* extras[0] exists: masked lanes read it */
                intV ei, ew;
                GATHER_ENTRIES(ei, ew, extras, ex);
#ifdef DETSTATS
                const intV qe = (ew & 0xFFFF) - 1;
                const intV ate = ((ei * CLASSES + ((ew >> 16) & 1)) * SEGMENTS + ((qe >> 12) & (SEGMENTS - 1))) & live;
                intV xe, xk;
                GATHER_NODES_V(xe, xk, nodes, ate);
                sum += NODE_LERP(xe, qe & 4095) & live;
                const intV kn = NODE_LERP(xk, qe & 4095) & live;
                ksum += kn;
                nsum -= kn > 0;                                       /* true is -1 */
#else
                const intV ie = ei & live;
                const floatV p = convert_floatV(GATHER(evidence, ie)) * as_floatV(ew);
                sum += RINT_INTV(p) & live;
#endif
            }
        }
#ifdef DETSTATS
        if (or_lanes(ksum)) {
            __global int *cell = kcells + (ROW_DZ(row) * 8 + ROW_DY(row)) * 8;
            const intV v = vloadV(0, cell) + ksum;
            vstoreV(v > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : v, 0, cell);
            const intV e0 = vloadV(0, cells + (ROW_DZ(row) * 8 + ROW_DY(row)) * 8);   /* before its store */
            __global int *count = looks + (cell - knowledge);
            const intV c = vloadV(0, count) + (nsum & ~STUCK(e0, sum));
            vstoreV(c > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : c, 0, count);
        }
#endif
        if (or_lanes(sum)) {
            /* |sum| < 255 beams x 2^14 (RECORD refuses more) and |cell| <= GRID_LIMIT = 2^30: no
             * int32 overflow to saturate */
            __global int *cell = cells + (ROW_DZ(row) * 8 + ROW_DY(row)) * 8;
            const intV v = vloadV(0, cell) + sum;
            vstoreV(v > (intV)GRID_LIMIT ? (intV)GRID_LIMIT : (v < (intV)-GRID_LIMIT ? (intV)-GRID_LIMIT : v), 0, cell);
        }
    }
}
