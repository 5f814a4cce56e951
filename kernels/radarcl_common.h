/* Shared definitions for radarcl's OpenCL kernels. Included with -I <kernels dir>. */
#ifndef RADARCL_COMMON_H
#define RADARCL_COMMON_H

/* Per-beam flags, the same values as radarcl.reference.FLAG_*. */
#define FLAG_NONFINITE 1
#define FLAG_CLIPPED 2

#endif
