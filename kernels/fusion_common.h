/* What the gather (fusion.cl) and the still table's kernel (fusion_cached.cl) share: a work-item's
 * block of a brick, the vectors of its rows, the detection-statistics model's node pairs and the
 * still table's entries (the gather's RECORD passes write the table, fusion_cached reads it).
 * Included with -I <kernels dir>; both kernels are built with the same -D (radarcl.stages.fusion).
 *
 * Blocks: get_global_id(0) = listed brick * SUBS + sub-brick, a VEC x SUB_Y x SUB_Z block of the
 * brick (VEC x 4 x 4 of an 8^3 brick; VEC x 8 x 1 of an 8 x 8 x 1 brick, BRICK_Z 1): BLOCK_ROWS
 * rows of VEC voxels along x, row r at y offset ROW_DY(r), z offset ROW_DZ(r).
 *
 * DETSTATS (the detection-statistics model, radarcl.sensor_model): a bin's update is not
 * e x weight(rho2) but a function of rho2 the interpreter tabulated at NODES rho2 = 0, 1/4, ..., 1
 * (the CFAR's P_d falls non-linearly with the voxel's two-way gain), for each of two classes of
 * target (0 upright, 1 terrain: a voxel whose centre lies below its beam's origin by more than
 * -terrain_dz, i.e. z - origin z < terrain_dz, near the ground plane; a scene without a terrain
 * class keeps the upright class alone, CLASSES 1). nodes[] holds per (beam, bin, class of the
 * CLASSES kept, segment s) the int2 (e_s | e_{s+1} << 16, d_s | d_{s+1} << 16) of the evidence e
 * [logodds units] and the detection opportunity d [KNOWLEDGE_SCALE units] at the segment's two
 * ends, one 8-byte gather per voxel. rho2 is quantised to q = floor(min(rho2 x 2^14, 2^14 - 1))
 * (a float32 multiply by a power of two, then truncation; the cap puts rho2 = 1 at the end of the
 * last segment, and a NaN of an empty beam width there too: every q indexes a node pair), the
 * segment is q >> 12 and the interpolation integer: e_s + ((e_{s+1} - e_s) (q & 4095) + 2048) >> 12
 * (NODE_LERP), so the gather and the still table give the same integers whatever the compiler
 * contracts. The evidence goes to pool[], the opportunity to knowledge[] (the knowledge channel:
 * "never observed" apart from "observed, undecided"), and looks[] counts the updates whose
 * opportunity is not 0 (the reading counts correlated looks once: sensor_model.read_log_odds),
 * except where the evidence sum sat at its limit before the frame and the frame does not pull it
 * back (STUCK).
 *
 * The still table: what each voxel of a plan takes from a frame. Its rows are the gather's: row
 * t = work-item t / BLOCK_ROWS, row t % BLOCK_ROWS of its block (whatever ROWS the recording
 * gather used: a unit's lanes are consecutive voxels of the table). counts[] holds each voxel's
 * number of beams (RECORD 1), first[] each voxel's first entry (beam * N_BINS + bin, as_int(weight)),
 * (0, 0) where no beam reaches, the weight's sign bit set where more entries follow (weights are
 * positive), and extras[] the further entries, per row in blocks of VEC: a voxel's m-th further
 * entry is lane l of block row_start[row] + m - 1, so the row's m-th entries are one vector load
 * (a row has as many blocks as its voxels' largest count beyond the first; a lane with fewer
 * holds (0, 0) there; row_start[] is the host's prefix sums of those block counts) (RECORD 2).
 * With DETSTATS an entry keeps q + 1 (never 0, whose bits mean "no beam") as an integer in place
 * of the weight, and the class in bit 16.
 */
#ifndef FUSION_COMMON_H
#define FUSION_COMMON_H

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
#define as_intV CAT(as_int, VEC)
#define as_floatV CAT(as_float, VEC)
/* round half to even without the builtin (PoCL may call builtins out of line) by the 1.5 x 2^23
 * trick: exact for |x| < 2^22, far beyond any evidence update */
#define RINT_INTV(x) (as_intV((x) + 12582912.0f) - 0x4B400000)
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
/* one int2 per lane (a node pair, a table entry): its first half into pe, its second into pk */
#define G2_(pe, pk, p, at, l) { const int2 q_ = p[at.s##l]; pe.s##l = q_.x; pk.s##l = q_.y; }
#define G2_4(pe, pk, p, at) G2_(pe, pk, p, at, 0) G2_(pe, pk, p, at, 1) G2_(pe, pk, p, at, 2) G2_(pe, pk, p, at, 3)
#define G2_8(pe, pk, p, at) G2_4(pe, pk, p, at) G2_(pe, pk, p, at, 4) G2_(pe, pk, p, at, 5) G2_(pe, pk, p, at, 6) \
    G2_(pe, pk, p, at, 7)
#ifdef DETSTATS
#define SEGMENTS 4                            /* node segments over rho2 in [0, 1] */
#if !defined(CLASSES) || CLASSES < 1 || CLASSES > 2
#error "CLASSES (1 or 2: the node pairs' classes of target) comes from radarcl/stages/fusion.py"
#endif
/* a voxel's node pair: bin j's class cls, segment seg. With CLASSES 1 (a scene without a terrain
 * class) the array holds the upright class alone: a terrain voxel (cls 1) takes nothing, as from
 * that class's all-zero nodes, its lanes masked by TAKES; its index reads an upright pair, in bounds */
#define NODE_AT(j, cls, seg) (((j) * CLASSES + ((cls) & (CLASSES - 1))) * SEGMENTS + (seg))
#if CLASSES == 1
#define TAKES(cls) ((cls) == 0)
#else
#define TAKES(cls) (-1)
#endif
/* lanes (-1) of a voxel whose evidence sum e0 sat at a limit before this frame and whose frame's
 * sum a does not pull it back: its looks are not counted (sensor_model.read_log_odds) */
#define STUCK(e0, a) ((((e0) >= GRID_LIMIT) & ((a) >= 0)) | (((e0) <= -GRID_LIMIT) & ((a) <= 0)))
#define Q_ONE 16384.0f                        /* rho2 = 1 in quantisation steps (2^14; 2^12 per segment) */
#define Q_MAX (Q_ONE - 1.0f)                  /* the last step: q stays in the last segment */
/* the interpolated value between the signed 16-bit halves of x at the fraction f / 4096 */
#define NODE_LERP(x, f) ((((x) << 16) >> 16) + (((((x) >> 16) - (((x) << 16) >> 16)) * (f) + 2048) >> 12))
/* VEC lanes' node pairs at `at`, interpolated at their fractions f: the evidence into le, the
 * opportunity into lk. Gathered as one vector of VEC 64-bit loads and interpolated as 2 VEC words
 * at once, each lane's f twice, then split into even and odd words: half the instructions of a
 * load and two inserts a lane and two interpolations of VEC words. NO_INT64 (a device without
 * 64-bit integers): G2_, then each half. */
#ifdef NO_INT64
#define LERP_NODES(le, lk, p, at, f) { intV e_, k_; const intV f_ = (f); CAT(G2_, VEC)(e_, k_, p, at) \
    le = NODE_LERP(e_, f_); lk = NODE_LERP(k_, f_); }
#else
/* n lanes' 8-byte words of p at the indices of the vector at, as one ulong vector (fusion.cl's
 * gather takes it for its LN lanes) */
#define GL_(p, at, l) p[at.s##l]
#define GL_4(p, at) GL_(p, at, 0), GL_(p, at, 1), GL_(p, at, 2), GL_(p, at, 3)
#define GL_8(p, at) GL_4(p, at), GL_(p, at, 4), GL_(p, at, 5), GL_(p, at, 6), GL_(p, at, 7)
#define GL_16(p, at) GL_8(p, at), GL_(p, at, 8), GL_(p, at, 9), GL_(p, at, a), GL_(p, at, b), GL_(p, at, c), \
    GL_(p, at, d), GL_(p, at, e), GL_(p, at, f)
#define GATHER_U64(n, p, at) (CAT(ulong, n))(CAT(GL_, n)(((const __global ulong *)(p)), at))
#if VEC == 4
#define TWICE(f) ((int8)(f.s0, f.s0, f.s1, f.s1, f.s2, f.s2, f.s3, f.s3))
#else
#define TWICE(f) ((int16)(f.s0, f.s0, f.s1, f.s1, f.s2, f.s2, f.s3, f.s3, f.s4, f.s4, f.s5, f.s5, f.s6, f.s6, f.s7, f.s7))
#endif
#define LERP_NODES(le, lk, p, at, f) { const intV f_ = (f); const CAT(int, VEC2) w_ = CAT(as_int, VEC2)(GATHER_U64(VEC, p, at)); \
    const CAT(int, VEC2) l_ = NODE_LERP(w_, TWICE(f_)); le = l_.even; lk = l_.odd; }
#endif
#if !defined(KNOWLEDGE_SCALE)
#error "KNOWLEDGE_SCALE comes from radarcl.stages.COMMON_DEFINES"
#endif
#endif

#endif
