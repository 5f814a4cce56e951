/* What the beam walk (interpret.cl) and the "snr" evidence's nodes (interpret_nodes.cl) share:
 * the node pairs' layout and the logs without builtins (PoCL may call its builtins out of line,
 * each call spilling the vector registers; ARCHITECTURE.md). Included with -I <kernels dir>. */
#ifndef INTERPRET_COMMON_H
#define INTERPRET_COMMON_H

#include "radarcl_common.h"

#ifdef CLASSES
/* int2 per bin: CLASSES x 4 segments (node_pairs.pack_nodes, node_shape); CLASSES 1 where the
 * scene has no terrain class (radarcl.stages.interpret_nodes.classes_needed) */
#define NODE_WORDS (4 * CLASSES)
#endif
#define LN10 2.302585093f

/* log10 of x >= 0 without a builtin call: the exponent, and ln of the mantissa in
 * [sqrt(1/2), sqrt(2)) by the atanh series to t^9 (error < 1e-9); float32 rounding of the sum
 * dominates, ~4e-6 decades at 1e38, 1e-7 near 1. Subnormals are scaled by 2^64 first;
 * log10(0) = -inf as log10's. */
static inline float log10_nb(float x)
{
    int bias = 0;
    if (x < 1.17549435e-38f) {                  /* FLT_MIN */
        if (x <= 0.0f)
            return x == 0.0f ? -INFINITY : NAN;
        x *= 18446744073709551616.0f;          /* 2^64 */
        bias = -64;
    }
    const int i = as_int(x);
    int e = ((i >> 23) & 255) - 127 + bias;
    float m = as_float((i & 0x7FFFFF) | 0x3F800000);
    if (m > 1.41421356f) {
        m *= 0.5f;
        e += 1;
    }
    const float t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
    const float ln_m = 2.0f * t * (1.0f + t2 * (1.0f / 3.0f + t2 * (0.2f + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f)))));
    return (float)e * 0.30102999566f + ln_m * 0.43429448190f;
}

/* log10_nb on N = 8 or 16 values at once (log10_nb8, log10_nb16), lane for lane the same floats
 * (the same operations, the branches as selects) */
#define LOG10_NB_LANES(N) \
static inline float##N log10_nb##N(float##N x) \
{ \
    const int##N sub = x < 1.17549435e-38f;                     /* FLT_MIN; also 0 and below */ \
    const float##N xs = sub ? x * 18446744073709551616.0f : x;   /* 2^64 */ \
    const int##N i = as_int##N(xs); \
    int##N e = ((i >> 23) & 255) - 127 + (sub & -64); \
    float##N m = as_float##N((i & 0x7FFFFF) | 0x3F800000); \
    const int##N big = m > 1.41421356f; \
    m = big ? m * 0.5f : m; \
    e -= big;                                                  /* big is -1 */ \
    const float##N t = (m - 1.0f) / (m + 1.0f), t2 = t * t; \
    const float##N ln_m = 2.0f * t * (1.0f + t2 * (1.0f / 3.0f + t2 * (0.2f + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f))))); \
    const float##N y = convert_float##N(e) * 0.30102999566f + ln_m * 0.43429448190f; \
    return x == 0.0f ? (float##N)(-INFINITY) : (x < 0.0f ? (float##N)(NAN) : y); \
}
LOG10_NB_LANES(8)
LOG10_NB_LANES(16)

#endif
