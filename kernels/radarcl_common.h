/* Shared definitions for radarcl's OpenCL kernels. Included with -I <kernels dir>.
 *
 * The constants the kernels share with Python have one source, Python: radarcl.stages.
 * COMMON_DEFINES passes them to every build as -D (beam flags, the pair ratio and the profile
 * limit from radarcl.oracle, the fixed-point log-odds unit from radarcl.logodds, the grid's
 * saturation from radarcl.gridspec.GRID_LIMIT).
 * A build without them stops here instead of compiling with values that may have drifted.
 */
#ifndef RADARCL_COMMON_H
#define RADARCL_COMMON_H

#if !defined(FLAG_NONFINITE) || !defined(FLAG_CLIPPED) || !defined(FLAG_BAD_PROFILE) \
    || !defined(FLAG_SILENT) || !defined(FLAG_OVERRANGE) || !defined(FLAG_CROSSTALK) \
    || !defined(NO_EVIDENCE_FLAGS) || !defined(PAIR_RATIO) || !defined(PROFILE_LIMIT)
#error "beam flags come from radarcl.stages.COMMON_DEFINES (-D FLAG_...)"
#endif
#if !defined(LOGODDS_SCALE) || !defined(EVIDENCE_LIMIT_NATS) || !defined(GRID_LIMIT)
#error "LOGODDS_SCALE, EVIDENCE_LIMIT_NATS and GRID_LIMIT come from radarcl.stages.COMMON_DEFINES"
#endif

#endif
