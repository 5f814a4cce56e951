/* The node pairs a moving frame's voxels may read (the detection-statistics model): for each beam
 * and bin of the window, bit c of node_use where a voxel centre of the grid inside the beam, at a
 * range that rounds to the bin, may be of class c (0 upright, 1 terrain: fusion.cl's
 * z - origin z < terrain_dz) and some segment of that bin and class may carry something (live[],
 * from node_pairs.live_segments).
 * The node kernel (interpret_nodes.cl) then computes only those classes: a still plan's table
 * knows the exact set (fusion.cl's RECORD 2), a moving frame has no table and takes this bound.
 *
 * Equivalent to radarcl.stages.node_reach.node_reach, its float64 oracle: the bound, for a point
 * c = d u + y v + z w from the beam's origin (d > 0, (y / W_az(d))^2 + (z / W_el(d))^2 <= 1,
 * W(d) = max(d tan(theta / 2), a)) at range D in a group of bins' [(j0 - 1/2) s, (j1 - 1/2) s]:
 * - its height above the origin, d u_z + y v_z + z w_z, lies within d u_z +- h(d), h(d) =
 *   hypot(W_az(d) v_z, W_el(d) w_z) (Cauchy-Schwarz over the ellipse); d u_z + h(d) is convex
 *   in d (and d u_z - h(d) concave), so over d in [d_lo, D] both take their extremes at the ends;
 * - D^2 = d^2 + y^2 + z^2 <= d^2 (1 + tan_az^2 + tan_el^2) + a_az^2 + a_el^2 gives d_lo;
 * - the point is a voxel centre: within the box of the grid's voxel centres, in height
 *   and in range (the box's nearest and farthest points from the origin);
 * - a part of a frame (radarcl live: Fusion.restrict) fuses the beams of its azimuths alone.
 * Every bound is widened by REACH_M + REACH_REL x range [m], far beyond float32's rounding in the
 * gather (its ranges, bins, heights and rho2) and what a pose's rotation may lack of orthonormality
 * (radarcl.stages.node_reach), so a voxel the gather finds in a beam and bin is always within it
 * (tests/test_node_reach.py against the still table's exact set).
 *
 * Work mapping: get_global_id(0) = beam x n_groups + group, a group being REACH_BINS bins from
 * first_bin, bounded together (their ranges' union); any local size works.
 * -D: N_BINS (bins per profile), CLASSES (1: upright alone, as the node array; 2: and terrain),
 *     REACH_BINS, REACH_M, REACH_REL (the widening).
 */

/* Builtin-free forms (PoCL may call builtins out of line, a call per work-item): sqrt alone */
#define MAXF(a, b) ((a) > (b) ? (a) : (b))
#define MINF(a, b) ((a) < (b) ? (a) : (b))

/* hypot(W_az(d) v_z, W_el(d) w_z) */
static inline float half_height(float d, float vz, float wz, float tan_az, float tan_el, float a_az, float a_el)
{
    const float wa = MAXF(d * tan_az, a_az) * vz, we = MAXF(d * tan_el, a_el) * wz;
    return sqrt(wa * wa + we * we);
}

__kernel void node_reach(
    const __global float4 *beams,     // (n_beams, 3): u, v, w axes in grid coordinates; .w of the
                                      //   three = the beam's origin x, y, z [m, from the grid origin]
    const __global uint *live,        // (N_BINS,) bit c: some segment of class c may carry an update
    const float spacing,              // range bin spacing [m]
    const float tan_half_az,          // tan(half-power beamwidth / 2), azimuth
    const float tan_half_el,          //   and elevation
    const float a_az,                 // half apertures [m] (0 without the near-field cylinder)
    const float a_el,
    const float terrain_dz,           // voxels with z - beam origin z below this are terrain [m] (-inf: none)
    const float voxel,                // voxel edge [m]
    const int nx,                     // grid shape [voxels]: its voxel centres lie in [voxel / 2, (n - 1/2) voxel]
    const int ny,
    const int nz,
    const int first_bin,              // the window [first_bin, last_bin]
    const int last_bin,
    const int n_groups,               // groups of REACH_BINS bins from first_bin that meet the window
    const int n_beams,
    const int n_el,                   // beams per azimuth: beam b is azimuth b / n_el's
    const int az_lo,                  // the azimuths whose beams the frame fuses (a part of a frame: the
    const int az_hi,                  //   others' pairs are read by none of its voxels)
    __global uint *node_use)          // (n_beams, N_BINS) out: bit c where class c's pairs may be read
{
    const int id = get_global_id(0);
    if (id >= n_beams * n_groups)
        return;
    const int b = id / n_groups, j0 = first_bin + (id % n_groups) * REACH_BINS;
    const int j1 = MINF(j0 + REACH_BINS, last_bin + 1);                /* the group's bins: [j0, j1) */
    const float4 U = beams[3 * b], V4 = beams[3 * b + 1], W4 = beams[3 * b + 2];
    /* the beam's own origin: the gather's bins take beam 0's where a frame has one pose, which
     * its beams share */
    const float3 o = (float3)(U.w, V4.w, W4.w);
    /* the box of the grid's voxel centres, from the origin, and its nearest and farthest points */
    const float3 lo = 0.5f * voxel - o, hi = (convert_float3((int3)(nx, ny, nz)) - 0.5f) * voxel - o;
    const float gx = MAXF(MAXF(lo.x, -hi.x), 0.0f), gy = MAXF(MAXF(lo.y, -hi.y), 0.0f);
    const float gz = MAXF(MAXF(lo.z, -hi.z), 0.0f);
    const float sx = MAXF(-lo.x, hi.x), sy = MAXF(-lo.y, hi.y), sz = MAXF(-lo.z, hi.z);
    const float near = sqrt(gx * gx + gy * gy + gz * gz), far = sqrt(sx * sx + sy * sy + sz * sz);
    const float reach = (j1 - 0.5f) * spacing;
    const float m = REACH_M + REACH_REL * reach;
    const float r_lo = MAXF((j0 - 0.5f) * spacing - m, 0.0f), r_hi = reach + m;
    uint bits = 0;
    if (b / n_el >= az_lo && b / n_el <= az_hi && r_lo <= far + m && r_hi >= near - m) {
        const float d_lo = sqrt(MAXF(r_lo * r_lo - (a_az * a_az + a_el * a_el), 0.0f)
                                / (1.0f + tan_half_az * tan_half_az + tan_half_el * tan_half_el));
        const float h_lo = half_height(d_lo, V4.z, W4.z, tan_half_az, tan_half_el, a_az, a_el);
        const float h_hi = half_height(r_hi, V4.z, W4.z, tan_half_az, tan_half_el, a_az, a_el);
        const float top = MINF(MAXF(d_lo * U.z + h_lo, r_hi * U.z + h_hi), hi.z) + m;
        const float bottom = MAXF(MINF(d_lo * U.z - h_lo, r_hi * U.z - h_hi), lo.z) - m;
        if (bottom <= top)
            bits = (top >= terrain_dz ? 1u : 0u) | (bottom < terrain_dz ? 2u : 0u);
    }
    bits &= (1u << CLASSES) - 1u;            /* CLASSES 1: a terrain voxel takes nothing */
    __global uint *out = node_use + (size_t)b * N_BINS;
    for (int j = j0; j < j1; ++j)
        out[j] = bits & live[j];
}
