/* Planning a frame on the device: which bricks the beams may reach, and each one's window of
 * candidate beams (i_lo, i_hi, k_lo, k_hi), for every brick of a list of blocks of bricks.
 *
 * The same bounds as radarcl.stages.fusion.candidate_windows (its docstring derives them; it is
 * this kernel's float64 oracle), in float32: every angle bound carries WINDOW_SLACK, far more
 * than float32's rounding of angles up to 2 pi (~1e-6 rad), so a window may differ from the
 * oracle's by one beam only where the oracle's own bound lies within the slack of a beam: never
 * a beam that can reach the brick. An empty window is (0, -1, 0, -1).
 *
 * Work mapping: get_global_id(0) = block * BLOCK^3 + brick of the block, x fastest, then y,
 * then z. Bricks beyond the grid get an empty window.
 *
 * -D N_AZ, N_EL (the lattice), AZ_WRAP (the azimuths span a full turn), WINDOW_SLACK [rad],
 *    BLOCK (bricks per block edge).
 */

#define ABS(x) ((x) < 0.0f ? -(x) : (x))
#define MIN(a, b) ((a) < (b) ? (a) : (b))
#define MAX(a, b) ((a) > (b) ? (a) : (b))

/* floor and ceil of x clamped to +-2^20 (beam indices), without a builtin */
static inline float floor_nb(float x)
{
    x = MAX(-1048576.0f, MIN(x, 1048576.0f));
    const int t = (int)x;                  /* toward zero */
    return (float)(t - ((float)t > x));
}

static inline float ceil_nb(float x)
{
    return -floor_nb(-x);
}

/* atan2 without a builtin call (PoCL may call its builtins out of line, each one spilling the
 * vector registers): Cephes' atanf, |error| ~1e-7 rad, far inside WINDOW_SLACK. */
static inline float atan2_nb(float y, float x)
{
    const float ay = ABS(y), ax = ABS(x);
    const int swap = ay > ax;
    const float t = swap ? ax / ay : (ax > 0.0f ? ay / ax : 0.0f);       /* in [0, 1] */
    const int big = t > 0.41421356f;                                      /* tan(pi / 8) */
    const float u = big ? (t - 1.0f) / (t + 1.0f) : t;
    const float z = u * u;
    float a = ((((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z
                - 3.33329491539e-1f) * z) * u + u;
    a = big ? a + 0.78539816f : a;
    a = swap ? 1.57079633f - a : a;
    a = x < 0.0f ? 3.14159265f - a : a;
    return y < 0.0f ? -a : a;
}

__kernel void fusion_plan(
    const __global int4 *blocks,      // (n_blocks,) first brick of each block (bx, by, bz, -)
    const int n_blocks,
    const int grid_bx,                // the grid's bricks along x, y, z
    const int grid_by,
    const int grid_bz,
    const float brick_m,              // brick edge [m]
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
    const int id = get_global_id(0);
    if (id >= n_blocks * BLOCK * BLOCK * BLOCK)
        return;
    const int o = id % (BLOCK * BLOCK * BLOCK);
    const int3 b = blocks[id / (BLOCK * BLOCK * BLOCK)].xyz + (int3)(o % BLOCK, (o / BLOCK) % BLOCK, o / (BLOCK * BLOCK));
    if (b.x >= grid_bx || b.y >= grid_by || b.z >= grid_bz) {
        windows[id] = (int4)(0, -1, 0, -1);
        return;
    }
    const float3 c = (convert_float3(b) + 0.5f) * brick_m - (float3)(head[9], head[10], head[11]);
    /* q = R^T c: column j of R dotted with c */
    const float3 q = (float3)(head[0] * c.x + head[3] * c.y + head[6] * c.z,
                              head[1] * c.x + head[4] * c.y + head[7] * c.z,
                              head[2] * c.x + head[5] * c.y + head[8] * c.z);
    const float rs = 0.5f * sqrt(3.0f) * brick_m + trans_margin;
    const float r = sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    const float half_pi = 0.5f * M_PI_F;
    int4 w = (int4)(0, N_AZ - 1, 0, N_EL - 1);
    if (r + rs < r_lo || r - rs > r_hi) {
        windows[id] = (int4)(0, -1, 0, -1);
        return;
    }
    const float r_min = r - rs;
    const float rho = sqrt(q.x * q.x + q.y * q.y);
    /* delta = asin(rs / r) + rot_margin + WINDOW_SLACK, with its sine and cosine by the angle sum */
    const float s0 = MIN(1.0f, rs / r), c0 = sqrt(MAX(0.0f, 1.0f - s0 * s0));
    const float delta = atan2_nb(s0, c0) + margin;
    const float sd = s0 * cos_margin + c0 * sin_margin, cd = c0 * cos_margin - s0 * sin_margin;
    const float ce = rho / r, se = ABS(q.z) / r;                 /* cos and sin of |el| */
    const float el = atan2_nb(q.z, rho);
    const float el_abs = ABS(el) + delta;
    /* cos and sin of el_abs = |el| + delta; past 90 deg the window is full anyway */
    const float c_abs = ce * cd - se * sd, s_abs = se * cd + ce * sd;
    const float s_az = MAX(tan_half_az, a_az / r_min) / c_abs;
    int full = r_min <= 0.0f || el_abs >= half_pi - 1e-3f || c_abs <= 0.0f || s_az >= 1.0f;
    full = full || s_abs * tan_el_max >= c_abs * sqrt(MAX(0.0f, 1.0f - s_az * s_az));
    if (!full) {
        const float c_haz = sqrt(1.0f - s_az * s_az);
        const float haz = atan2_nb(s_az, c_haz);
        const float s_daz = MIN(1.0f, sd / ce);
        const float daz = atan2_nb(s_daz, sqrt(MAX(0.0f, 1.0f - s_daz * s_daz)));
        const float s_el = MAX(tan_half_el, a_el / r_min) + (1.0f - c_haz);
        const float hel = (s_el >= 1.0f ? half_pi : atan2_nb(s_el, sqrt(MAX(0.0f, 1.0f - s_el * s_el)))) + delta;
        const float az = atan2_nb(q.y, q.x);
        const float inv_az = N_AZ > 1 ? 1.0f / az_step : 0.0f;
        const float inv_el = N_EL > 1 ? 1.0f / el_step : 0.0f;
        /* float bounds before the int conversion: a bound far outside the lattice must not overflow */
        float i_lo = ceil_nb((az - haz - daz - az0) * inv_az), i_hi = floor_nb((az + haz + daz - az0) * inv_az);
        const float k_lo = MAX(0.0f, ceil_nb((el - hel - el0) * inv_el));
        const float k_hi = MIN((float)(N_EL - 1), floor_nb((el + hel - el0) * inv_el));
#ifdef AZ_WRAP
        if (i_hi - i_lo + 1.0f >= (float)N_AZ) {
            i_lo = 0.0f;
            i_hi = (float)(N_AZ - 1);
        }
#else
        i_lo = MAX(i_lo, 0.0f);
        i_hi = MIN(i_hi, (float)(N_AZ - 1));
#endif
        w = (int4)((int)i_lo, (int)i_hi,
                   (int)k_lo, (int)k_hi);
    }
    windows[id] = w;
}
