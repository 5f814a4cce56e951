/* A polar scan's 8-bit levels (decibels of power) -> float32 linear power, on the device.
 *
 * Equivalent to radarcl.io.polar_png.levels_to_power(levels, db_per_level): the same 256-entry
 * float32 table, indexed by each level, so the power is bit-identical to the host's and the CFAR
 * after it sees the same floats. A scan travels to the device as its levels (a quarter of the
 * bytes of its power) and becomes power here, right before the CFAR.
 *
 * Work mapping: get_global_id(0) = g converts the VEC levels g*VEC .. g*VEC+VEC-1 of the frame
 * taken as one flat array of n levels (one vector load and store per work-item; the lookups
 * themselves are scalar gathers); the tail past n goes level by level. Any local size works.
 *
 * levels_differenced takes a frame whose rows hold their levels' differences (a PNG's "Sub"
 * filter: d[j] = level[j] - level[j - 1] mod 256, d[0] = level[0]; radarcl.io.png): the levels
 * are their running sums mod 256, the same levels the host's radarcl.io.png.running_sums gives,
 * then the same table. get_global_id(0) = one row, 16 differences at a time whatever VEC (their
 * running sums by shifted adds in the vector, then the row's sum so far added), the row's tail
 * one by one; any local size works.
 *
 * -D constants (set by radarcl/stages/levels.py):
 *   VEC           levels per work-item: 1, 4, 8 or 16
 */
#include "radarcl_common.h"

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)

__kernel void levels(
    const __global uchar *levels,     // (n,) levels, one byte per range bin
    const __global float *table,      // (256,) power of each level [linear]
    const int n,                      // levels in the frame
    __global float *power)            // (n,) out: table[levels[i]]
{
    const int i0 = get_global_id(0) * VEC;
    if (i0 >= n)
        return;
#if VEC > 1
    if (i0 + VEC <= n) {
        const CAT(uchar, VEC) l = CAT(vload, VEC)(0, levels + i0);
        CAT(float, VEC) p;
#if VEC == 4
        p = (float4)(table[l.s0], table[l.s1], table[l.s2], table[l.s3]);
#elif VEC == 8
        p = (float8)(table[l.s0], table[l.s1], table[l.s2], table[l.s3],
                     table[l.s4], table[l.s5], table[l.s6], table[l.s7]);
#elif VEC == 16
        p = (float16)(table[l.s0], table[l.s1], table[l.s2], table[l.s3],
                      table[l.s4], table[l.s5], table[l.s6], table[l.s7],
                      table[l.s8], table[l.s9], table[l.sa], table[l.sb],
                      table[l.sc], table[l.sd], table[l.se], table[l.sf]);
#endif
        CAT(vstore, VEC)(p, 0, power + i0);
        return;
    }
#endif
    for (int i = i0; i < n && i < i0 + VEC; i++)
        power[i] = table[levels[i]];
}

/* One row per work-item (the header's levels_differenced). */
__kernel void levels_differenced(
    const __global uchar *coded,      // (n_rows, row_len) each row's differences, the first its level
    const __global float *table,      // (256,) power of each level [linear]
    const int n_rows,                 // rows in the frame (azimuths)
    const int row_len,                // levels per row (range bins)
    __global float *power)            // (n_rows, row_len) out: table[running sum] [linear]
{
    const int r = get_global_id(0);
    if (r >= n_rows)
        return;
    const __global uchar *d = coded + (size_t)r * row_len;
    __global float *p = power + (size_t)r * row_len;
    uchar level = 0;                  /* the row's sum so far, mod 256 as uchar arithmetic is */
    int j = 0;
    for (; j + 16 <= row_len; j += 16) {
        uchar16 s = vload16(0, d + j);
        s += (uchar16)(0, s.s0, s.s1, s.s2, s.s3, s.s4, s.s5, s.s6, s.s7, s.s8, s.s9, s.sa, s.sb, s.sc, s.sd, s.se);
        s += (uchar16)(0, 0, s.s0, s.s1, s.s2, s.s3, s.s4, s.s5, s.s6, s.s7, s.s8, s.s9, s.sa, s.sb, s.sc, s.sd);
        s += (uchar16)(0, 0, 0, 0, s.s0, s.s1, s.s2, s.s3, s.s4, s.s5, s.s6, s.s7, s.s8, s.s9, s.sa, s.sb);
        s += (uchar16)(0, 0, 0, 0, 0, 0, 0, 0, s.s0, s.s1, s.s2, s.s3, s.s4, s.s5, s.s6, s.s7);
        s += (uchar16)(level);
        level = s.sf;
        vstore16((float16)(table[s.s0], table[s.s1], table[s.s2], table[s.s3],
                           table[s.s4], table[s.s5], table[s.s6], table[s.s7],
                           table[s.s8], table[s.s9], table[s.sa], table[s.sb],
                           table[s.sc], table[s.sd], table[s.se], table[s.sf]), 0, p + j);
    }
    for (; j < row_len; ++j) {
        level += d[j];
        p[j] = table[level];
    }
}
