"""The node pairs a moving frame's voxels may read (the detection-statistics model).

A still plan's table records exactly which (beam, bin, class) node pairs its voxels read
(``StillTable.node_use``), and the node kernel computes those alone. A moving frame has no
table; ``NodeReach`` wraps ``kernels/node_reach.cl``, which bounds the same set from the beams'
geometry: a beam tilted down sees only terrain past where its upper edge meets the ground, and
only upright targets before its lower edge does; a bin past the grid's far corner is read by no
voxel. ``node_reach`` is its float64 oracle in numpy (tests/test_node_reach.py): the device's
bits are the oracle's but where a bound lies within float32's rounding of a class's height or the
grid's edge, and both hold every pair the gather reads.
"""

import numpy as np

from radarcl.errors import ConfigError
from radarcl.stages import build, work_group_size

# [m] and [m per m of range]: every bound is widened by REACH_M + REACH_REL x range, beyond
# float32's rounding of the gather's ranges, heights and rho2 (~1e-6 relative) and beyond what a
# pose's rotation may lack of orthonormality (geometry.ROTATION_TOLERANCE, 1e-5 an element: the
# gather projects onto the beam's axes, the bound maps back through them, ~3e-5 of the range).
REACH_M = 1e-3
REACH_REL = 1e-4
# Bins bounded together by one work-item (their ranges' union): one bound per bin cost more than
# the node kernel saved, and the node kernel decides per 8 or 16 bins anyway.
REACH_BINS = 8
LOCAL_SIZE = 64             # work-items per group where the kernel allows it (any size works)


def live_classes(live):
    """(n_bins,) uint32, bit c where some segment of class c may carry something: ``live``,
    (n_bins, classes) ``node_pairs.live_segments``. A class without one is read as zeros."""
    live = np.asarray(live) & 0xF
    return ((live != 0) << np.arange(live.shape[1])).sum(axis=1).astype(np.uint32)


def node_reach(beams, box_lo, box_hi, spacing, first_bin, last_bin, n_bins, tan_half_az, tan_half_el, a_az, a_el,
               terrain_dz, live, n_el=1, azimuths=None):
    """Float64 bound of the node pairs a frame's voxels may read: (n_beams, n_bins) uint32, bit c
    where class c (0 upright, 1 terrain; ``live``'s columns) of a bin in [first_bin, last_bin] may
    be read, bounded over groups of REACH_BINS bins from first_bin. ``beams``: (n_beams, 3, 4)
    the plan's axes u, v, w in grid coordinates, column 3 the origin; ``box_lo``, ``box_hi``: the
    grid's first and last voxel centres [m, grid coordinates]; the beam volume as
    ``Fusion.beam_volume`` gives it; ``live``: (n_bins, classes) ``node_pairs.live_segments``;
    ``azimuths``: (lo, hi), the azimuths whose beams a part of a frame fuses (beam b is azimuth
    b // ``n_el``'s), None for all. The bound is the kernel's (kernels/node_reach.cl), widened by
    REACH_M + REACH_REL x range."""
    beams = np.asarray(beams, np.float64)
    classes = np.shape(live)[1]
    o = beams[:, :, 3]
    U, V, W = beams[:, 0, :3], beams[:, 1, :3], beams[:, 2, :3]
    lo, hi = np.asarray(box_lo, np.float64) - o, np.asarray(box_hi, np.float64) - o
    near = np.linalg.norm(np.maximum(np.maximum(lo, -hi), 0.0), axis=1)[:, None]
    far = np.linalg.norm(np.maximum(np.abs(lo), np.abs(hi)), axis=1)[:, None]
    j0 = np.arange(first_bin, last_bin + 1, REACH_BINS, dtype=np.float64)[None, :]      # each group's bins: [j0, j1)
    j1 = np.minimum(j0 + REACH_BINS, last_bin + 1)
    reach = (j1 - 0.5) * spacing
    m = REACH_M + REACH_REL * reach
    r_lo, r_hi = np.maximum((j0 - 0.5) * spacing - m, 0.0), reach + m
    d_lo = np.sqrt(np.maximum(r_lo ** 2 - (a_az ** 2 + a_el ** 2), 0.0) / (1.0 + tan_half_az ** 2 + tan_half_el ** 2))

    def half_height(d):
        return np.hypot(np.maximum(d * tan_half_az, a_az) * V[:, 2:], np.maximum(d * tan_half_el, a_el) * W[:, 2:])

    uz = U[:, 2:]
    top = np.minimum(np.maximum(d_lo * uz + half_height(d_lo), r_hi * uz + half_height(r_hi)), hi[:, 2:]) + m
    bottom = np.maximum(np.minimum(d_lo * uz - half_height(d_lo), r_hi * uz - half_height(r_hi)), lo[:, 2:]) - m
    ok = (r_lo <= far + m) & (r_hi >= near - m) & (bottom <= top)
    if azimuths is not None:
        az = np.arange(len(beams))[:, None] // n_el
        ok &= (az >= azimuths[0]) & (az <= azimuths[1])
    bits = (ok & (top >= terrain_dz)) * 1 | (ok & (bottom < terrain_dz)) * 2
    bits = np.repeat(bits, REACH_BINS, axis=1)[:, :last_bin + 1 - first_bin] & ((1 << classes) - 1)
    out = np.zeros((len(beams), n_bins), np.uint32)
    out[:, first_bin:last_bin + 1] = bits & live_classes(live)[first_bin:last_bin + 1]
    return out


class NodeReach:
    """The node-reach kernel of a ``Fusion`` with the detection-statistics model: ``enqueue(beams)``
    writes, on the device, the node pairs that the voxels of a plan with those beams may read
    (``node_reach``) into one array it keeps, ``node_use`` (n_beams, n_bins) uint32, which the
    interpreter takes as it takes a still table's. ``local_size``: work-items per work-group
    (None: LOCAL_SIZE where the kernel allows it)."""

    def __init__(self, fusion, local_size=None):
        import pyopencl.array as cla

        if not fusion.detstats:
            raise ConfigError("node reach is the detection-statistics model's (Fusion(..., detstats=True))")
        self.fusion, rt = fusion, fusion.runtime
        self._kernel = build(rt, "node_reach", dict(N_BINS=fusion.n_bins, CLASSES=fusion.classes,
                                                    REACH_BINS=REACH_BINS, REACH_M=REACH_M,
                                                    REACH_REL=REACH_REL))["node_reach"]
        self.local_size = work_group_size(rt, self._kernel, local_size, LOCAL_SIZE)
        self._live = cla.to_device(rt.queue, live_classes(fusion.live_segments))
        self.node_use = cla.zeros(rt.queue, (fusion.lattice.n_beams, fusion.n_bins), np.uint32)   # 0 past the window

    def arguments(self):
        """``node_reach``'s arguments but the beams: the fusion's geometry and live segments."""
        f, spec = self.fusion, self.fusion.grid.spec
        v = spec.voxel_m
        return dict(box_lo=np.full(3, 0.5 * v), box_hi=(np.asarray(spec.shape, np.float64) - 0.5) * v,
                    spacing=f.bin_spacing_m, first_bin=f.first_bin, last_bin=f.last_bin, n_bins=f.n_bins,
                    **f.beam_volume(), terrain_dz=f.terrain_dz, live=f.live_segments, n_el=f.lattice.n_el)

    def enqueue(self, beams, azimuths=None, wait_for=None):
        """Launch over the plan's ``beams`` (a device array (n_beams, 3) float4); ``azimuths``:
        (lo, hi), the azimuths whose beams the plan fuses (a part of a frame: the others' pairs are
        read by no voxel of it), None for all. Returns the event."""
        f = self.fusion
        az_lo, az_hi = (0, f.lattice.n_az - 1) if azimuths is None else azimuths
        n_groups = -(-(f.last_bin - f.first_bin + 1) // REACH_BINS)
        n, ls = f.lattice.n_beams * n_groups, self.local_size
        nx, ny, nz = f.grid.spec.shape
        return self._kernel(f.runtime.queue, (-(-n // ls) * ls,), (ls,), wait_for=wait_for, beams=beams,
                            live=self._live, spacing=f.bin_spacing_m, **f.beam_volume(), terrain_dz=f.terrain_dz,
                            voxel=f.grid.spec.voxel_m, nx=nx, ny=ny, nz=nz, first_bin=f.first_bin,
                            last_bin=f.last_bin, n_groups=n_groups, n_beams=f.lattice.n_beams, n_el=f.lattice.n_el,
                            az_lo=int(az_lo), az_hi=int(az_hi), node_use=self.node_use)
