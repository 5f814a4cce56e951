/* Planning a frame on the device: which bricks the beams may reach, and each one's window of
 * candidate beams (i_lo, i_hi, k_lo, k_hi), for every brick of a list of blocks of bricks.
 *
 * The same bounds as radarcl.stages.fusion_plan.candidate_windows (its docstring derives them; it is
 * this kernel's float64 oracle), in float32: every angle bound carries WINDOW_SLACK, far more
 * than float32's rounding of angles up to 2 pi (~1e-6 rad), so no beam that can reach a brick
 * is left out of its window. The wrapper adds DEVICE_REACH_M to trans_margin, which widens
 * every bound beyond float32's rounding of ranges and angles: a window holds the oracle's, and
 * is wider by one beam only where the oracle's bound lies within that of a beam. An empty
 * window is (0, -1, 0, -1).
 *
 * Work mapping: work-item g handles bricks g * PVEC .. g * PVEC + PVEC - 1 of the list (brick
 * n = block * BLOCK^3 + its place in the block, x fastest, then y, then z), one per SIMD lane
 * (PVEC = 8 on CPUs, where PoCL does not vectorise across work-items; 1 on GPUs). Every lane
 * computes every bound and the masks pick the result, so the code has no branch per brick.
 * Bricks beyond the grid get an empty window.
 *
 * -D N_AZ, N_EL (the lattice), AZ_WRAP (the azimuths span a full turn), WINDOW_SLACK [rad],
 *    BLOCK (bricks per block edge; BLOCK^3 a multiple of PVEC), PVEC (1 or 8), BRICK_Z (voxels per
 *    brick along z, 8 or 1: a brick is brick_m x brick_m x brick_m BRICK_Z / 8; default 8).
 */
#ifndef BRICK_Z
#define BRICK_Z 8
#endif
#define Z_EDGE (BRICK_Z / 8.0f)               /* a brick's z edge over its x edge */

#if PVEC == 1
typedef float realv;
typedef int intv;
#define LANE_IDS 0
#define TO_INT(x) ((int)(x))
#define TO_REAL(x) ((float)(x))
#define TRUE_MASK 1
#elif PVEC == 8
typedef float8 realv;
typedef int8 intv;
#define LANE_IDS ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#define TO_INT(x) convert_int8(x)
#define TO_REAL(x) convert_float8(x)
#define TRUE_MASK (-1)
#else
#error "PVEC must be 1 or 8"
#endif

/* Builtin-free arithmetic (PoCL may call its builtins out of line); the ternary is
 * component-wise on vectors, so each works on scalars and vectors alike. */
#define ABS(x) ((x) < 0.0f ? -(x) : (x))
#define MIN(a, b) ((a) < (b) ? (a) : (b))
#define MAX(a, b) ((a) > (b) ? (a) : (b))

/* floor of x clamped to +-2^20 (beam indices) */
static inline realv floor_nb(realv x)
{
    x = MAX((realv)-1048576.0f, MIN(x, (realv)1048576.0f));
    const realv t = TO_REAL(TO_INT(x));                   /* toward zero */
    return t > x ? t - 1.0f : t;
}

static inline realv ceil_nb(realv x)
{
    return -floor_nb(-x);
}

/* atan2: Cephes' atanf, |error| ~1e-7 rad, far inside WINDOW_SLACK */
static inline realv atan2_nb(realv y, realv x)
{
    const realv ay = ABS(y), ax = ABS(x);
    const realv big_y = ay > ax ? (realv)1.0f : (realv)0.0f;
    const realv num = big_y > 0.0f ? ax : ay, den = big_y > 0.0f ? ay : ax;
    const realv t = den > 0.0f ? num / den : (realv)0.0f;                  /* in [0, 1] */
    const realv u = t > 0.41421356f ? (t - 1.0f) / (t + 1.0f) : t;         /* tan(pi / 8) */
    const realv z = u * u;
    realv a = ((((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z
               - 3.33329491539e-1f) * z) * u + u;
    a = t > 0.41421356f ? a + 0.78539816f : a;
    a = big_y > 0.0f ? 1.57079633f - a : a;
    a = x < 0.0f ? 3.14159265f - a : a;
    return y < 0.0f ? -a : a;
}

__kernel void fusion_plan(
    const __global int4 *blocks,      // (n_blocks,) first brick of each block (bx, by, bz, -)
    const int n_blocks,
    const int grid_bx,                // the grid's bricks along x, y, z
    const int grid_by,
    const int grid_bz,
    const float brick_m,              // brick edge along x and y [m]
    const __global float *head,       // 12: the head frame's rotation R (head -> grid axes) row-major,
                                      //   then its origin [m, grid coordinates]; q = R^T (c - origin)
    const float trans_margin,         // max |beam origin - origin| [m]
    const float margin,               // rot_margin + WINDOW_SLACK [rad], rot_margin the largest
                                      //   rotation between a beam's frame and the head's
    const float cos_margin,           // its cosine and sine
    const float sin_margin,
    const float r_lo,                 // ranges that carry evidence [m]
    const float r_hi,
    const float az0,                  // the lattice [rad]
    const float az_step,
    const float el0,
    const float el_step,
    const float tan_el_max,           // tan of the largest |beam elevation|
    const float tan_half_az,          // tan(half-power beamwidth / 2)
    const float tan_half_el,
    const float a_az,                 // half apertures [m] (0 without the near field)
    const float a_el,
    __global int4 *windows)           // (n_blocks * BLOCK^3,) out
{
    const int g = get_global_id(0);
    const int first = g * PVEC;
    if (first >= n_blocks * BLOCK * BLOCK * BLOCK)
        return;
    const int4 block = blocks[first / (BLOCK * BLOCK * BLOCK)];          /* PVEC divides BLOCK^3 */
    const intv o = first % (BLOCK * BLOCK * BLOCK) + LANE_IDS;
    const intv bx = block.x + o % BLOCK, by = block.y + (o / BLOCK) % BLOCK, bz = block.z + o / (BLOCK * BLOCK);
    const intv outside = (bx >= grid_bx) | (by >= grid_by) | (bz >= grid_bz);
    const realv cx = (TO_REAL(bx) + 0.5f) * brick_m - head[9];
    const realv cy = (TO_REAL(by) + 0.5f) * brick_m - head[10];
    const realv cz = (TO_REAL(bz) + 0.5f) * (brick_m * Z_EDGE) - head[11];
    /* q = R^T c: column j of R dotted with c */
    const realv qx = head[0] * cx + head[3] * cy + head[6] * cz;
    const realv qy = head[1] * cx + head[4] * cy + head[7] * cz;
    const realv qz = head[2] * cx + head[5] * cy + head[8] * cz;
    const float rs = 0.5f * sqrt(2.0f + Z_EDGE * Z_EDGE) * brick_m + trans_margin;
    const realv r = sqrt(qx * qx + qy * qy + qz * qz);
    const float half_pi = 0.5f * M_PI_F;
    const intv none = outside | (r + rs < r_lo) | (r - rs > r_hi);
    const realv r_min = r - rs;
    const realv rho = sqrt(qx * qx + qy * qy);
    /* delta = asin(rs / r) + rot_margin + WINDOW_SLACK, with its sine and cosine by the angle sum */
    const realv s0 = MIN((realv)1.0f, rs / r), c0 = sqrt(MAX((realv)0.0f, 1.0f - s0 * s0));
    const realv delta = atan2_nb(s0, c0) + margin;
    const realv sd = s0 * cos_margin + c0 * sin_margin, cd = c0 * cos_margin - s0 * sin_margin;
    const realv ce = rho / r, se = ABS(qz) / r;                  /* cos and sin of |el| */
    const realv el = atan2_nb(qz, rho);
    const realv el_abs = ABS(el) + delta;
    /* cos and sin of el_abs = |el| + delta; past 90 deg the window is full anyway */
    const realv c_abs = ce * cd - se * sd, s_abs = se * cd + ce * sd;
    const realv s_az = MAX((realv)tan_half_az, a_az / r_min) / c_abs;
    intv full = (r_min <= 0.0f) | (el_abs >= half_pi - 1e-3f) | (c_abs <= 0.0f) | (s_az >= 1.0f);
    full |= s_abs * tan_el_max >= c_abs * sqrt(MAX((realv)0.0f, 1.0f - s_az * s_az));
    /* the bounds (meaningless where full or none: masked below) */
    const realv s_az1 = MIN(MAX(s_az, (realv)0.0f), (realv)1.0f);
    const realv c_haz = sqrt(MAX((realv)0.0f, 1.0f - s_az1 * s_az1));
    const realv haz = atan2_nb(s_az1, c_haz);
    const realv s_daz = MIN((realv)1.0f, sd / ce);
    const realv daz = atan2_nb(s_daz, sqrt(MAX((realv)0.0f, 1.0f - s_daz * s_daz)));
    const realv s_el = MAX((realv)tan_half_el, a_el / r_min) + (1.0f - c_haz);
    const realv s_el1 = MIN(s_el, (realv)1.0f);
    const realv hel = (s_el >= 1.0f ? (realv)half_pi : atan2_nb(s_el1, sqrt(MAX((realv)0.0f, 1.0f - s_el1 * s_el1)))) + delta;
    const realv az = atan2_nb(qy, qx);
    const float inv_az = N_AZ > 1 ? 1.0f / az_step : 0.0f;
    const float inv_el = N_EL > 1 ? 1.0f / el_step : 0.0f;
    realv i_lo = ceil_nb((az - haz - daz - az0) * inv_az), i_hi = floor_nb((az + haz + daz - az0) * inv_az);
    const realv k_lo = MAX((realv)0.0f, ceil_nb((el - hel - el0) * inv_el));
    const realv k_hi = MIN((realv)(N_EL - 1), floor_nb((el + hel - el0) * inv_el));
#ifdef AZ_WRAP
    const intv wide = i_hi - i_lo + 1.0f >= (realv)N_AZ;
    i_lo = wide ? (realv)0.0f : i_lo;
    i_hi = wide ? (realv)(N_AZ - 1) : i_hi;
#else
    i_lo = MAX(i_lo, (realv)0.0f);
    i_hi = MIN(i_hi, (realv)(N_AZ - 1));
#endif
    intv w0 = TO_INT(i_lo), w1 = TO_INT(i_hi), w2 = TO_INT(k_lo), w3 = TO_INT(k_hi);
    w0 = full ? (intv)0 : w0;
    w1 = full ? (intv)(N_AZ - 1) : w1;
    w2 = full ? (intv)0 : w2;
    w3 = full ? (intv)(N_EL - 1) : w3;
    w0 = none ? (intv)0 : w0;
    w1 = none ? (intv)-1 : w1;
    w2 = none ? (intv)0 : w2;
    w3 = none ? (intv)-1 : w3;
#if PVEC == 1
    windows[first] = (int4)(w0, w1, w2, w3);
#else
    for (int l = 0; l < PVEC; ++l)
        windows[first + l] = (int4)(((const int *)&w0)[l], ((const int *)&w1)[l], ((const int *)&w2)[l],
                                    ((const int *)&w3)[l]);
#endif
}
