/* Shared definitions for radarcl's OpenCL kernels. Included with -I <kernels dir>. */
#ifndef RADARCL_COMMON_H
#define RADARCL_COMMON_H

/* Per-beam flags, the same values as radarcl.reference.FLAG_*. */
#define FLAG_NONFINITE 1     /* a NaN/Inf sample (range_fft) */
#define FLAG_CLIPPED 2       /* a sample at the clip level (range_fft) */
#define FLAG_BAD_PROFILE 4   /* a NaN, Inf or negative power bin (interpret) */
#define FLAG_SILENT 8        /* all bins exactly 0 (interpret) */
#define NO_EVIDENCE_FLAGS (FLAG_NONFINITE | FLAG_BAD_PROFILE | FLAG_SILENT)

/* Fixed-point log-odds, the same values as radarcl.logodds. */
#define LOGODDS_SCALE 1024.0f
#define EVIDENCE_LIMIT_NATS 16.0f
/* Grid sums saturate here [units], the same value as radarcl.grid.GRID_LIMIT. */
#define GRID_LIMIT (1 << 30)

#endif
