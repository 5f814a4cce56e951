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
