"""A still radar's frames from a recorded table (the still table of ``radarcl.stages.fusion``).

Wraps ``kernels/fusion_cached.cl``. When a plan's pose comes back (a radar on a stand, a tilting
stand's positions, a parked vehicle), ``record`` runs the gather (``kernels/fusion.cl``) twice in
its RECORD modes to write what each voxel of the plan takes from a frame: its count of beams, its
first entry and its further entries (``StillTable``; the layout is in ``kernels/fusion_common.h``).
``enqueue`` then fuses that pose's frames by streaming the table instead of testing beams: the
same integers as the gather (the weights are the gather's own float32 values; with the
detection-statistics model, its quantised rho2 and class), at a fraction of its cost
(``radarcl bench fusion`` measures it). ``Fusion`` calls both; tests/test_fusion_cached.py checks the table against the
gather, integer for integer, and against the float64 oracle.
"""

from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError
from radarcl.stages import build
from radarcl.stages.fusion_plan import FramePlan

STILL_TABLE_SHARE = 0.25           # the still tables held may take this share of the device's memory


@dataclass
class StillTable:
    """What every voxel of a plan takes from a frame, recorded once for a still radar (the
    kernel's RECORD passes), on the device: per voxel its count of beams and its first entry
    (beam * n_bins + bin, the weight's float32 bits, whose sign bit says that more entries
    follow), the further entries row by row, each row's m-th ones together (the layout:
    kernels/fusion_common.h)."""

    counts: object           # pyopencl Array uint8 (n_rows * VEC,): beams per voxel
    row_start: object        # pyopencl Array int32 (n_rows,): first block of further entries of each row
    first: object            # pyopencl Array int32 (n_rows * VEC, 2): each voxel's first entry
    extras: object           # pyopencl Array int32 (n_blocks * VEC, 2): the further entries, a block of VEC at a time
    n_rows: int
    n_entries: int
    node_use: object = None  # detstats: pyopencl Array uint32 (n_beams, n_bins): bit c where an entry reads class c's
                             #   node pairs of that bin (the interpreter's node kernel computes those alone)

    @property
    def nbytes(self):
        """Device memory the table takes."""
        return sum(a.nbytes for a in (self.counts, self.row_start, self.first, self.extras, self.node_use)
                   if a is not None)


def cached_kernel(runtime, defines):
    """The ``fusion_cached`` kernel, built with the gather's -D ``defines`` (it reads VEC,
    BRICK_Z, DETSTATS, CLASSES and NO_INT64 of them)."""
    return build(runtime, "fusion_cached", defines)["fusion_cached"]


def record(fusion, plan):
    """Record ``plan``'s ``StillTable`` for ``fusion`` (a ``radarcl.stages.fusion.Fusion``; two
    passes of its gather that write instead of fuse) and return it, or None (and remember so on
    the plan) where ``fusion.still`` is "auto" and the table would take more than
    ``STILL_TABLE_SHARE`` of the device's memory, or a voxel lies in 255 beams or more."""
    import pyopencl as cl
    import pyopencl.array as cla

    if not isinstance(plan, FramePlan) or plan.owner is not fusion:
        raise ConfigError("plan must be a FramePlan made by this Fusion's plan()")
    if plan.table is not None:
        return plan.table
    runtime = fusion.runtime
    q = runtime.queue
    vec = fusion.vector_width
    n_rows = fusion._n_items(plan) * fusion._block_rows
    limits = runtime.limits
    held = sum(p.table.nbytes for p in fusion._plans.values() if p.table is not None)
    budget = STILL_TABLE_SHARE * limits.global_mem_size - held if fusion.still == "auto" else float("inf")
    # beside everything else radarcl holds on the device (the tables are held too, below)
    limit = min(budget, limits.max_mem_alloc_size, limits.global_mem_size - runtime.held_bytes)
    dense_bytes = n_rows * (9 * vec + 4)   # counts, first entries, row starts
    if not n_rows or dense_bytes > limit:
        plan._table.append(None)
        return None
    if fusion._record_kernels is None:
        fusion._record_kernels = [build(runtime, "fusion", {**fusion._defines, "RECORD": r})["fusion"] for r in (1, 2)]
        # launches use one size; the work-item index, not the group, places a table row
        fits = min(runtime.max_local_size(k) for k in fusion._record_kernels)
        if fusion.local_size > fits and fusion._local_size_requested:
            raise ConfigError(f"local_size {fusion.local_size} is more than the {fits} work-items {runtime.name} "
                              "runs the still table's recording kernels with (CL_KERNEL_WORK_GROUP_SIZE); use "
                              f"local_size <= {fits}, or leave it out")
        fusion.local_size = min(fusion.local_size, fits)
    counts = cla.zeros(q, (n_rows * vec,), np.uint8)
    row_start = cla.zeros(q, (n_rows,), np.int32)
    dummy = cla.zeros(q, (1, 2), np.int32)
    fusion._launch(fusion._record_kernels[0], plan, fusion.arrays["evidence"], counts=counts, row_start=row_start,
                   first=dummy, extras=dummy).wait()
    host = counts.get(q).reshape(n_rows, vec)
    total = int(host.sum(dtype=np.int64))
    # a row's further entries in blocks of VEC, one per further entry of its most-reached voxel
    blocks_per_row = np.maximum(host.max(axis=1).astype(np.int64) - 1, 0)
    n_blocks = int(blocks_per_row.sum())
    use_bytes = 4 * fusion.lattice.n_beams * fusion.n_bins if fusion.detstats else 0
    if host.max(initial=0) == 255 or n_blocks >= 2**31 or dense_bytes + 8 * vec * n_blocks + use_bytes > limit:
        plan._table.append(None)
        return None
    starts = np.concatenate([[0], np.cumsum(blocks_per_row)[:-1]]).astype(np.int32)
    cl.enqueue_copy(q, row_start.data, starts, is_blocking=True)
    first = cla.zeros(q, (n_rows * vec, 2), np.int32)     # (0, 0): evidence[0] x 0.0
    extras = cla.zeros(q, (max(n_blocks * vec, 1), 2), np.int32)      # (0, 0) where a lane has fewer
    node_use = cla.zeros(q, (fusion.lattice.n_beams, fusion.n_bins), np.uint32) if fusion.detstats else None
    use = {} if node_use is None else dict(node_use=node_use)
    fusion._launch(fusion._record_kernels[1], plan, fusion.arrays["evidence"], counts=counts, row_start=row_start,
                   first=first, extras=extras, **use).wait()
    table = StillTable(counts, row_start, first, extras, n_rows, total, node_use)
    runtime.hold(table, table.nbytes, "the still radar's table")
    plan._table.append(table)
    return table


def enqueue(fusion, plan, evidence, wait_for=None):
    """Fuse one frame of ``evidence`` (the device array ``fusion.enqueue`` checked) from
    ``plan``'s recorded ``StillTable``, one launch per pool chunk; returns the last kernel event."""
    t = plan.table
    event = None
    for offset, gsize, n_items, c in fusion._chunk_launches(plan):
        event = fusion._cached_kernel(fusion.runtime.queue, gsize, (fusion.local_size,), wait_for=wait_for,
                                      global_offset=offset, bricks=fusion._plan_device(plan)["bricks"],
                                      counts=t.counts, row_start=t.row_start, first=t.first, extras=t.extras,
                                      n_items=n_items, pool=fusion.grid.chunk(c),
                                      **fusion._inputs(evidence, c, cached=True))
    return event
