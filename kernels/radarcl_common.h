/* Shared helpers for radarcl's OpenCL kernels. Included with -I <kernels dir>. */
#ifndef RADARCL_COMMON_H
#define RADARCL_COMMON_H

/* Complex numbers are float2 (re, im). */
inline float2 cmul(float2 a, float2 b)
{
    return (float2)(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

/* Multiply by -i: the forward radix-4 butterfly's quarter turn, exact (no rounding). */
inline float2 cmul_minus_i(float2 a)
{
    return (float2)(a.y, -a.x);
}

inline float2 conj2(float2 a)
{
    return (float2)(a.x, -a.y);
}

/* Per-beam flags, the same values as radarcl.reference.FLAG_*. */
#define FLAG_NONFINITE 1
#define FLAG_CLIPPED 2

#endif
