"""Fusion of whole frames into the evidence grid (paper §3.1 eq. 9, §3.4, Fig. 7c).

``Fusion`` wraps ``kernels/fusion.cl``; it is equivalent to ``radarcl.oracle.fusion(...)``:
each voxel whose centre is inside a beam's volume takes that beam's eq. 12 update for the bin
of its centre, times the two-way weight, rounded half to even; identical to the oracle wherever
no decision (inside or not, which bin) lies within ``FUSION_DECISION_MARGIN`` of its boundary,
and within one unit per update of it (float32 vs float64 weights; tests/test_fusion.py).

A frame is a gather over the bricks its beams can reach. Planning lists those bricks (and
allocates them in the grid) with a conservative bound in the frame's head frame (the middle
beam's pose) that also gives each brick its window of candidate beams (``fusion_plan``:
``candidate_windows``, computed on the device by ``FusionPlanner``, its float32 twin), and
lists them in the pool's order (the kernel's reads and writes then stream; planar bricks by tiles
of columns, ``column_tiles``, so a spinning radar's node pairs are read from cache). The kernel narrows the window per 8x4x4 block
(a bounding-sphere test) and per row of 8 voxels, and takes ``rows`` rows as one vector.

The plans of the last ``PLAN_CACHE`` poses are kept. When a pose comes back (a radar on a
stand, a tilting stand's positions), the plan gets a ``StillTable``: what each voxel takes,
recorded by the kernel's RECORD passes, which ``radarcl.stages.fusion_cached`` then streams
(``kernels/fusion_cached.cl``: the same integers at a fraction of the gather's cost; ``radarcl
bench fusion`` measures both).
"""

import math
from collections import OrderedDict

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import BeamLattice, BeamModel, check_poses
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import BRICK
from radarcl.node_pairs import N_CLASSES, node_shape, unpack_nodes
from radarcl.stages import Port, Stage, build, count, fusion_cached, spacing, work_group_size
from radarcl.stages.fusion_plan import (BLOCK, FramePlan, FusionPlanner, HeadFrame, brick_geometry, candidate_windows,
                                        column_tiles, nonempty, pool_order, take_rows)
from radarcl.stages.node_reach import NodeReach

# A work-item per block of rows of 8 voxels (as float8), its beams' windows planned on the
# host per brick: the shape that measured fastest of those tried (docs/measured-figures.md, "Why the code is
# shaped so"); the local size hardly matters. The per-row filter skips 3/4 of the rows, which
# counts on devices where rows are not the cost.
DEFAULT_LOCAL_SIZE = 64
VECTOR_WIDTHS = (4, 8)             # voxels along x per row of a work-item's block
# Rows of 8 taken two at a time, 16 lanes (AVX-512's width; the two rows are contiguous in the
# brick), the same integers: the default on CPUs; elsewhere one row (a GPU's lanes are its
# work-items: unmeasured).
CPU_ROWS = 2
PLAN_CACHE = 16                    # plans kept for poses that come back (the paper's stand has 15 tilts)
PACKED_LOOKS = 21                  # detstats gather: looks counted above bit 21 of the knowledge sum (n_beams < 512)


class Fusion(Stage):
    """A compiled fusion plan for frames of one lattice into one grid.

    runtime: a ``radarcl.cl.Runtime``; grid: the ``EvidenceGrid`` to update; lattice: the
    frame's ``BeamLattice`` (beam b = i * n_el + k); model: a ``BeamModel`` (near-field
    cylinder and Gaussian weight as -D switches); n_bins, bin_spacing_m: the evidence rows
    (bin j at j x spacing); first_bin, last_bin: bins that carry evidence (others are skipped);
    per_beam_poses: accept one pose per beam (a radar scanning while it moves); vector_width:
    voxels along x per row of a work-item's block (4 or 8); rows: rows of the block taken
    together as one vector (1, or 2 with vector_width 8; None: 2 on a CPU, else 1); still: "auto"
    records a ``StillTable`` when a plan's pose comes back (a radar on a stand, a parked
    vehicle) and the table fits ``fusion_cached.STILL_TABLE_SHARE`` of the device's memory, then fuses that
    pose's frames from it (``fusion_cached``, the same integers); True records on the first
    repeat whatever its size, False never. detstats: the detection-statistics model
    (``radarcl.sensor_model``): a frame is not one update per bin but node pairs per bin
    (``node_pairs.node_shape(classes)``, from ``node_pairs.pack_nodes``), interpolated in the
    voxel's rho2, and the grid must hold a knowledge pool (``EvidenceGrid(..., knowledge=True)``);
    a voxel whose centre lies more than -``terrain_dz`` [m] below its beam's origin takes the
    terrain class's nodes (-inf: none does); equivalent to ``oracle.fusion_at_points(...,
    nodes=..., terrain_dz=...)``. classes: the node pairs' classes of target, the interpreter's
    (``Interpreter.classes``): 2, or 1 for a scene without a terrain class, whose nodes hold the
    upright class alone (half the bytes to read) and a terrain voxel takes nothing, as it would
    from that class's all-zero nodes. live_segments: with detstats, ``node_pairs.live_segments``
    of the interpreter's bin model (n_bins, classes) uint8: a still table leaves out the entries
    in a segment whose nodes never carry anything, and the gather skips the voxels that lie only
    in such segments (None: every segment may carry something). It must be the bin model's: a
    segment marked dead whose nodes are not 0 would lose their updates.
    """

    def __init__(self, runtime, grid, lattice, model, n_bins, bin_spacing_m, first_bin=0, last_bin=None,
                 *, per_beam_poses=False, still="auto", vector_width=8, rows=None, local_size=None, detstats=False,
                 terrain_dz=-math.inf, classes=N_CLASSES, live_segments=None):
        if not isinstance(grid, EvidenceGrid):
            raise ConfigError(f"grid must be an EvidenceGrid, got {type(grid).__name__}")
        if not isinstance(lattice, BeamLattice) or not isinstance(model, BeamModel):
            raise ConfigError("lattice must be a BeamLattice and model a BeamModel")
        self.runtime, self.grid, self.lattice, self.model = runtime, grid, lattice, model
        self.n_bins = count(n_bins, "n_bins")
        self.bin_spacing_m = spacing(bin_spacing_m)
        self.first_bin = max(0, count(first_bin, "first_bin", lo=-(1 << 30)))
        self.last_bin = self.n_bins - 1 if last_bin is None else min(count(last_bin, "last_bin", lo=-(1 << 30)),
                                                                      self.n_bins - 1)
        if self.first_bin > self.last_bin:
            raise ConfigError(f"no bin carries evidence: first_bin {first_bin} > last_bin {last_bin}")
        self.per_beam_poses = bool(per_beam_poses)
        if lattice.n_beams * logodds.EVIDENCE_LIMIT > (1 << 30) - 1:
            raise ConfigError(f"{lattice.n_beams} beams per frame: a voxel's sum of one frame's updates could overflow "
                              f"int32 beside the grid's +-2^30 (at most {((1 << 30) - 1) // logodds.EVIDENCE_LIMIT} beams)")
        if vector_width not in VECTOR_WIDTHS:
            raise ConfigError(f"vector_width must be one of {VECTOR_WIDTHS}, got {vector_width!r}")
        self.vector_width = int(vector_width)
        if rows is None:
            rows = CPU_ROWS if runtime.is_cpu and self.vector_width == 8 else 1
        if rows not in (1, 2) or (rows == 2 and self.vector_width != 8):
            raise ConfigError(f"rows must be 1, or 2 with vector_width 8; got rows={rows!r}, "
                              f"vector_width={self.vector_width}")
        self.rows = int(rows)
        self.detstats = bool(detstats)
        self.terrain_dz = float(terrain_dz)
        if math.isnan(self.terrain_dz) or self.terrain_dz == math.inf:
            raise ConfigError(f"terrain_dz must be a number of metres or -inf, got {terrain_dz!r}")
        if classes not in (1, N_CLASSES):
            raise ConfigError(f"classes must be 1 (upright targets only) or {N_CLASSES} (and terrain), got {classes!r}")
        self.classes = int(classes)
        if self.detstats and not grid.has_knowledge:
            raise ConfigError("the detection-statistics model writes the knowledge channel: give Fusion an "
                              "EvidenceGrid(..., knowledge=True)")
        self.brick_z = grid.spec.brick_z
        # a work-item's block: VEC x 4 x 4 voxels of an 8^3 brick (16 rows), VEC x 8 x 1 of a planar one (8)
        self._block_rows = 16 if self.brick_z == 8 else 8
        self._subs = (8 // self.vector_width) * (4 if self.brick_z == 8 else 1)
        defines = dict(VEC=self.vector_width, ROWS=self.rows, BRICK_Z=self.brick_z, N_AZ=lattice.n_az, N_EL=lattice.n_el,
                       N_BINS=self.n_bins,
                       NEAR_FIELD=model.near_field, GAUSSIAN=model.gaussian,
                       PER_BEAM_POSES=self.per_beam_poses, AZ_WRAP=lattice.wraps, DETSTATS=self.detstats,
                       NO_INT64=not runtime.limits.int64)
        if self.detstats:
            defines["CLASSES"] = self.classes
        if self.detstats and lattice.n_beams * logodds.KNOWLEDGE_SCALE < 1 << PACKED_LOOKS:
            defines["PACKED_LOOKS"] = PACKED_LOOKS         # knowledge and looks in one accumulator
        live = self._live_segments(live_segments)
        # some segment of the window never carries anything: the gather skips the units lying there
        defines["DEAD_SEGMENTS"] = self.detstats and bool((live[self.first_bin:self.last_bin + 1] & 0xF != 0xF).any())
        self._defines = {k: v for k, v in defines.items() if v is not False}
        if still not in ("auto", True, False):
            raise ConfigError(f"still must be 'auto', True or False, got {still!r}")
        self.still = still
        self._kernel = build(runtime, "fusion", self._defines)["fusion"]
        self._cached_kernel = fusion_cached.cached_kernel(runtime, self._defines)
        self._record_kernels = None
        self.local_size = work_group_size(runtime, [self._kernel, self._cached_kernel], local_size, DEFAULT_LOCAL_SIZE)
        self._local_size_requested = local_size is not None
        self._rotations = lattice.beam_rotations()
        self.r_lo = (self.first_bin - 0.5) * self.bin_spacing_m
        self.r_hi = (self.last_bin + 0.5) * self.bin_spacing_m
        self._plans = OrderedDict()      # (grid generation, poses) -> FramePlan, least recent first
        self._plan_arrays, self._uploaded = None, None
        self._planner = None             # a FusionPlanner, built on the first plan
        self._supers = None              # the planner's coarse level: blocks of BLOCK^3 blocks of bricks
        # Evidence from a raw radar's detection comes as (n_az, n_el, n_bins) even for one
        # elevation; (n_beams, n_bins) is the same rows.
        tail = node_shape(self.classes) if self.detstats else ()
        aliases = ((lattice.n_az, lattice.n_el, self.n_bins, *tail), (lattice.n_beams, self.n_bins, *tail))
        self._allocate([Port("evidence", (*lattice.batch, self.n_bins, *tail), np.dtype(np.int32),
                             "evidence nodes" if self.detstats else "evidence", aliases)], [])
        import pyopencl.array as cla

        q = runtime.queue               # the RECORD buffers the plain gather ignores, and the other model's
        self._no_table = (cla.zeros(q, (1,), np.uint8), cla.zeros(q, (1,), np.int32), cla.zeros(q, (1, 2), np.int32))
        self.live_segments = live                     # (n_bins, classes) int32, as the kernels read it
        self._live = cla.to_device(q, live)           # the RECORD passes' and DEAD_SEGMENTS' (fusion.cl)
        self._reach = None                            # a NodeReach, built on a moving frame's first node_reach

    def node_reach(self, plan):
        """(node_use, event): the node pairs ``plan``'s voxels may read, bounded from its beams'
        geometry on the device (``node_reach``; a still plan's table knows them exactly) and, for a
        part of a frame (``restrict``), to its azimuths' beams, for the interpreter of a
        detection-statistics Fusion. ``node_use`` is one device array, which the next call
        overwrites. None without a terrain class, where the bound would split no classes and only
        trim the range past the grid, which a rolling window has none of."""
        if self.detstats and self.classes == 1:
            return None
        if self._reach is None:
            self._reach = NodeReach(self)            # ConfigError without detstats
        return self._reach.node_use, self._reach.enqueue(self._plan_device(plan)["beams"], plan.azimuths)

    def _live_segments(self, live_segments):
        """``live_segments`` checked, as the kernels read it: int32 (n_bins, classes), every segment
        live where None."""
        if live_segments is None:
            return np.full((self.n_bins, self.classes), 0xF, np.int32)
        live = live_segments
        if not self.detstats:
            raise ConfigError("live_segments are the detection-statistics model's (detstats=True)")
        if not isinstance(live, np.ndarray) or live.dtype != np.uint8 or live.shape != (self.n_bins, self.classes):
            raise ShapeError(f"live_segments must be a uint8 array ({self.n_bins}, {self.classes}) (bins, classes), "
                             f"got {getattr(live, 'dtype', type(live).__name__)} {getattr(live, 'shape', '')}")
        if (live > 0xF).any():
            raise ConfigError(f"live_segments holds one bit per segment (0..15), got {int(live.max())}")
        return live.astype(np.int32)

    @property
    def evidence_shape(self):
        """Shape of one frame's evidence: (n_beams, n_bins) int32, or with detstats
        (n_beams, n_bins, *node_pairs.node_shape(classes)) int32 node pairs."""
        return (self.lattice.n_beams, self.n_bins, *(node_shape(self.classes) if self.detstats else ()))

    # -- host side: beams, head frame, bricks ---------------------------------------------------
    def plan(self, poses, cache=True, record=True):
        """Prepare a frame taken at ``poses``: one 4x4 pose, or (n_beams, 4, 4) with
        per_beam_poses. Allocates the bricks the beams may reach. The last plan is reused for
        a repeated pose unless ``cache`` is False; a reused plan gets its ``StillTable`` (see
        ``still``) unless ``record`` is False: a frame fused in parts (``restrict``, a live
        stream) plans the same pose once per part, and a part never reads the whole plan's
        table, so recording it there would only stall the stream."""
        P = check_poses(poses, self.lattice.n_beams)
        if len(P) > 1 and not self.per_beam_poses:
            raise ConfigError("this Fusion takes one pose per frame; build it with per_beam_poses=True "
                              "to give one pose per beam")
        key = (self.grid.generation, P.tobytes())
        if self._plans and next(iter(self._plans))[0] != self.grid.generation:
            self._plans = OrderedDict((k, p) for k, p in self._plans.items() if k[0] == self.grid.generation)
        if cache and key in self._plans:
            plan = self._plans.pop(key)
            self._plans[key] = plan                              # the most recent last
            if self.still and record and not plan._table:
                self.record(plan)
            return plan
        spec = self.grid.spec
        ref = P[len(P) // 2]
        rots = (P[:, :3, :3] if len(P) > 1 else ref[:3, :3]) @ self._rotations
        origins = np.broadcast_to(P[:, :3, 3], (self.lattice.n_beams, 3)) - np.asarray(spec.origin_m)
        beams = np.concatenate([np.swapaxes(rots, 1, 2), origins[:, :, None]], axis=2)
        index, windows, keep = self._reached_bricks(self.head_frame(P))
        slots = self.grid.allocate_index(index)
        # listed in pool order: the kernel's reads and writes of the pool then stream, and the
        # CPU's prefetchers follow
        order = pool_order(slots, self.grid.n_slots)
        listed = np.empty((len(slots), 4), np.int32)
        self.grid.brick_coords(index[order], out=listed)
        listed[:, 3] = slots[order]
        if self.brick_z == 1:
            # planar bricks by tiles of columns (column_tiles): the same integers, the node
            # pairs' reads mostly cached
            tiles = column_tiles(listed, self.grid.chunk_bricks)
            listed, order = listed[tiles], order[tiles]
        plan = FramePlan(np.ascontiguousarray(beams, np.float32), listed, take_rows(windows, keep[order]),
                         self, self.grid.generation)
        if cache:
            self._plans[key] = plan
            while len(self._plans) > PLAN_CACHE:
                self._plans.popitem(last=False)                  # the oldest, and its table
        return plan

    def warm_up(self):
        """Build the planner (its kernel compiles) before the first frame, so a stream's first
        frame does not wait for it, and, when the pool has a chunk, the gather's kernel (launched
        over a brick that no beam reaches: nothing changes). Returns the number of bricks a frame
        at the grid's centre reaches (what to ``reserve`` for a first frame)."""
        spec = self.grid.spec
        centre = 0.5 * np.asarray(spec.shape, np.float64) * spec.voxel_m         # [m, grid coordinates]
        index, _, _ = self._reached_bricks(HeadFrame(np.eye(3), centre, 0.0, 0.0))     # nothing allocated
        if self.grid.capacity:
            # the gather too (the device compiles a kernel's work-group function on its first
            # launch): over one brick with no candidate beam, which leaves it as it is
            n = self.lattice.n_beams
            plan = FramePlan(np.zeros((n, 3, 4), np.float32), np.zeros((1, 4), np.int32),
                             np.array([[0, -1, 0, -1]], np.int32), self, self.grid.generation)
            self._launch(self._kernel, plan, self.arrays["evidence"])
            self.runtime.queue.finish()
            self._uploaded = self._plan_arrays = None
        return len(index)

    def record(self, plan):
        """Record ``plan``'s ``StillTable`` (``radarcl.stages.fusion_cached.record``); returns it,
        or None (and remembers so) where ``still`` is "auto" and the table would take more than
        ``fusion_cached.STILL_TABLE_SHARE`` of the device's memory, or a voxel lies in 255 beams or more."""
        return fusion_cached.record(self, plan)

    def head_frame(self, P):
        """The ``HeadFrame`` the windows of a frame at poses ``P`` ((n, 4, 4), checked) are
        computed in: the middle beam's pose, and how far the others stray from it."""
        ref = P[len(P) // 2]
        cos_rot = (np.trace(ref[:3, :3].T @ P[:, :3, :3], axis1=1, axis2=2) - 1) / 2
        return HeadFrame(ref[:3, :3] @ self.lattice.head_rotation(), ref[:3, 3] - np.asarray(self.grid.spec.origin_m),
                         float(np.linalg.norm(P[:, :3, 3] - ref[:3, 3], axis=1).max()),
                         float(np.arccos(np.clip(cos_rot, -1, 1)).max()))

    def restrict(self, plan, az_lo, az_hi):
        """The part of ``plan`` that the beams of azimuths ``az_lo``..``az_hi`` (every elevation)
        can reach: the bricks whose candidate window meets them, each window clipped to them.
        Fusing the sub-plans of disjoint azimuth ranges, each with its beams' evidence, gives
        the whole plan's map: each beam's update is rounded on its own and the sums are exact
        integers (the grid clamps at +-2^30 after each fuse, so the two agree below that).
        A radar streaming beam by beam fuses what has arrived this way (``radarcl live``)."""
        if self.lattice.wraps:
            raise ConfigError("a spinning radar's turn wraps around in azimuth: fuse whole turns, not azimuth ranges")
        if not all(isinstance(a, (int, np.integer)) and not isinstance(a, (bool, np.bool_)) for a in (az_lo, az_hi)):
            raise ConfigError(f"azimuths {az_lo!r}..{az_hi!r} must be integer beam indices")
        lo, hi = int(az_lo), int(az_hi)
        if not 0 <= lo <= hi < self.lattice.n_az:
            raise ConfigError(f"azimuths {az_lo}..{az_hi} are not a range of this lattice's 0..{self.lattice.n_az - 1}")
        if not isinstance(plan, FramePlan) or plan.owner is not self:
            raise ConfigError("plan must be a FramePlan made by this Fusion's plan()")
        w = plan.windows
        i_lo, i_hi = np.maximum(w[:, 0], lo), np.minimum(w[:, 1], hi)
        keep = i_lo <= i_hi
        windows = w[keep].copy()
        windows[:, 0], windows[:, 1] = i_lo[keep], i_hi[keep]
        return FramePlan(plan.beams, plan.bricks[keep], windows, self, plan.generation, [plan.beams_outside],
                         azimuths=(lo, hi))

    def _windows(self, brick_index, edge, frame):
        centres, radius = brick_geometry(brick_index, edge * self.grid.spec.voxel_m, self.brick_z)
        return candidate_windows(centres, radius, frame, self.r_lo, self.r_hi, self.lattice, self.model)

    def _reached_bricks(self, frame):
        """The bricks some beam may reach, as flat indices of the grid's brick table, and their
        windows as ``windows[keep]``, both levels on the device (``FusionPlanner``): the blocks
        of BLOCK^3 bricks some beam may reach (evaluated as bricks of a coarser grid), then the
        bricks of those blocks."""
        shape = np.asarray(self.grid.spec.brick_shape)
        coarse = -(-shape // BLOCK)
        edge = BRICK * self.grid.spec.voxel_m
        if self._planner is None:
            self._planner = FusionPlanner(self.runtime, self.lattice, self.model, self.r_lo, self.r_hi,
                                          brick_z=self.brick_z)
            supers = [np.arange(0, n, BLOCK) for n in coarse]       # blocks of BLOCK^3 blocks
            self._supers = np.stack(np.meshgrid(*supers, indexing="ij"), -1).reshape(-1, 3)
            # each one's centre and bounding radius [m, grid coordinates]: a grid much larger than
            # the sensor's reach (a drive) plans only those the reach can meet
            self._super_centres, self._super_radius = brick_geometry(self._supers / BLOCK, edge * BLOCK * BLOCK,
                                                                     self.brick_z)
        reach = self.r_hi + frame.trans_margin + self._super_radius + 0.01      # 1 cm over the device reach
        near = ((self._super_centres - frame.origin) ** 2).sum(axis=1) <= reach * reach
        supers = self._supers if near.all() else self._supers[near]
        coarse_windows = self._planner.windows(supers, coarse, edge * BLOCK, frame)
        kept = FusionPlanner.bricks_of(supers, np.flatnonzero(nonempty(coarse_windows))) * BLOCK
        windows = self._planner.windows(kept, shape, edge, frame)
        keep = np.flatnonzero(nonempty(windows))
        return FusionPlanner.brick_index(kept, keep, shape), windows, keep

    def _beams_outside(self, w):
        """Beams in no reached brick's window ``w``: they certainly miss the grid (a lower bound)."""
        lat = self.lattice
        if not len(w):
            return lat.n_beams
        size = (lat.n_az + 1) * (lat.n_el + 1)
        covered = np.zeros(size, np.int64)
        w = w.astype(np.int64)
        for lo, hi in ((w[:, 0], w[:, 1]), (w[:, 0] + lat.n_az, w[:, 1] + lat.n_az), (w[:, 0] - lat.n_az, w[:, 1] - lat.n_az)):
            lo_c, hi_c = np.clip(lo, 0, lat.n_az), np.clip(hi + 1, 0, lat.n_az)
            ok = hi_c > lo_c
            for a, sign in ((lo_c, 1), (hi_c, -1)):        # 2-D difference array of the windows' rectangles
                for k, s in ((w[ok, 2], sign), (w[ok, 3] + 1, -sign)):
                    covered += s * np.bincount(a[ok] * (lat.n_el + 1) + k, minlength=size)
        covered = covered.reshape(lat.n_az + 1, lat.n_el + 1)
        reached = np.cumsum(np.cumsum(covered, axis=0), axis=1)[:lat.n_az, :lat.n_el] > 0
        return int(np.count_nonzero(~reached))

    # -- device side ------------------------------------------------------------------------------
    def check(self, evidence, name="evidence"):
        """One frame of evidence, (n_beams, n_bins) or (*batch, n_bins) int32, as the
        (*batch, n_bins) array the kernel reads; ShapeError otherwise."""
        ev = np.asarray(evidence)
        if ev.shape == self.evidence_shape:
            ev = ev.reshape(*self.lattice.batch, *self.evidence_shape[1:])
        ev = self.check_input(name, ev)
        if self.detstats:
            e, d = unpack_nodes(ev)
            if e.size and (np.abs(e).max() > logodds.EVIDENCE_LIMIT or d.min() < 0 or d.max() > logodds.KNOWLEDGE_SCALE):
                raise ConfigError(f"evidence nodes must lie within +-{logodds.EVIDENCE_LIMIT} units and their detection "
                                  f"opportunity within [0, {logodds.KNOWLEDGE_SCALE}], got evidence up to "
                                  f"{np.abs(e).max()} and opportunity in [{d.min()}, {d.max()}]")
            return ev
        if ev.size and np.abs(ev.astype(np.int64)).max() > logodds.EVIDENCE_LIMIT:
            raise ConfigError(f"evidence must lie within +-{logodds.EVIDENCE_LIMIT} units (+-{logodds.EVIDENCE_LIMIT_NATS:g} "
                              f"nat per update, eq. 12 clamps there), got up to {np.abs(ev.astype(np.int64)).max()}: "
                              "larger updates could wrap the kernel's int32 sums")
        return ev

    def upload(self, evidence):
        """Copy a checked frame of evidence into the plan's input array; returns the copy event."""
        return super().upload(evidence=self.check(evidence))[0]

    def enqueue(self, evidence=None, plan=None, wait_for=None, gather=False):
        """Fuse one frame of evidence (a device array (*batch, n_bins) int32 within
        +-``logodds.EVIDENCE_LIMIT``, e.g. an ``Interpreter``'s ``arrays["evidence"]``, whose
        values are clamped there; None: this plan's own, as ``upload`` checked it) taken as ``plan``
        (from this Fusion's ``plan``, for the grid as it is now) says: from its ``StillTable``
        where one is recorded (the same integers), unless ``gather``. Returns the kernel event
        (None when no brick is reached)."""
        if not isinstance(plan, FramePlan) or plan.owner is not self:
            raise ConfigError("plan must be a FramePlan made by this Fusion's plan() (a plan of another "
                              "Fusion lists bricks of another grid)")
        if plan.generation != self.grid.generation:
            raise ConfigError("the plan was made before grid.clear(): its bricks are gone; call plan() again")
        evidence = self.device("evidence", evidence)
        if not len(plan.bricks):
            return None
        if plan.table is not None and not gather:
            return fusion_cached.enqueue(self, plan, evidence, wait_for)
        return self._launch(self._kernel, plan, evidence, wait_for=wait_for)

    def _inputs(self, evidence, c, cached=False):
        """The kernels' evidence arguments for pool chunk ``c``: eq. 12's updates, or the node
        pairs and the chunk of the knowledge and looks pools (the other model's get a
        placeholder); the still table keeps each entry's class."""
        none = self._no_table[1]
        if self.detstats:
            out = dict(evidence=none, nodes=evidence, knowledge=self.grid.chunk(c, "knowledge"),
                       looks=self.grid.chunk(c, "looks"), terrain_dz=self.terrain_dz)
        else:
            out = dict(evidence=evidence, nodes=self._no_table[2], knowledge=none, looks=none, terrain_dz=-math.inf)
        if cached:
            del out["terrain_dz"]
        return out

    def _chunk_launches(self, plan):
        """(global offset, global size, n_items, chunk) of each launch over ``plan``: one per
        pool chunk its bricks lie in (they are listed chunk by chunk: in slot order, or by
        ``fusion_plan.column_tiles`` within each chunk, so each chunk's are a run),
        as work-items offset to the run's first brick (``get_global_id`` keeps counting the
        plan's work-items, so table rows and brick rows stay where one launch puts them)."""
        ls, per = self.local_size, self._subs
        if not len(plan.bricks):
            return []
        chunk = plan.bricks[:, 3] // self.grid.chunk_bricks
        cut = np.flatnonzero(np.diff(chunk)) + 1
        starts, ends = np.concatenate([[0], cut]), np.concatenate([cut, [len(chunk)]])
        out = []
        for a, b in zip(starts, ends):
            first, n = int(a) * per, (int(b) - int(a)) * per
            out.append(((first,) if first else None, (-(-n // ls) * ls,), int(b) * per, int(chunk[a])))
        return out

    def _plan_device(self, plan):
        """The plan's arrays on the device (uploaded once per plan)."""
        if self._uploaded is not plan:
            import pyopencl.array as cla

            q = self.runtime.queue
            bricks = plan.bricks.copy()
            bricks[:, 3] %= self.grid.chunk_bricks          # the kernel reads a slot within its chunk
            self._plan_arrays = dict(beams=cla.to_device(q, plan.beams), bricks=cla.to_device(q, bricks),
                                     windows=cla.to_device(q, plan.windows))
            self._uploaded = plan
        return self._plan_arrays

    def _n_items(self, plan):
        """The gather's work-items for ``plan``: one per block of its bricks (VEC x 4 x 4 voxels
        of an 8^3 brick, VEC x 8 x 1 of a planar one)."""
        return len(plan.bricks) * self._subs

    def _launch(self, kernel, plan, evidence, wait_for=None, **record):
        """One gather launch over ``plan`` (the fusion, or a RECORD pass with its buffers; those
        it is not given get a placeholder)."""
        none = self._no_table
        record = {**dict(counts=none[0], row_start=none[1], first=none[2], extras=none[2], node_use=none[1],
                         live=self._live), **record}
        rt = self.runtime
        nx, ny, nz = self.grid.spec.shape
        event = None
        for offset, gsize, n_items, c in self._chunk_launches(plan):
            event = kernel(rt.queue, gsize, (self.local_size,), wait_for=wait_for, global_offset=offset,
                           **self._inputs(evidence, c), **self._plan_device(plan),
                           voxel=self.grid.spec.voxel_m, inv_spacing=1.0 / self.bin_spacing_m,
                           first_bin=self.first_bin, last_bin=self.last_bin, nx=nx, ny=ny, nz=nz,
                           **self.beam_volume(), n_items=n_items, pool=self.grid.chunk(c), **record)
        return event

    def beam_volume(self):
        """The beam volume as the kernels take it: tan_half_az, tan_half_el (the half-power
        half-widths' tangents) and a_az, a_el (the half apertures, 0 without the near-field cylinder)."""
        m = self.model
        a_az, a_el = m.apertures
        return dict(tan_half_az=math.tan(m.beamwidth_az_rad / 2), tan_half_el=math.tan(m.beamwidth_el_rad / 2),
                    a_az=a_az, a_el=a_el)

    def download(self, wait_for=None):
        """Fusion writes the grid, not arrays of its own: read the map with ``grid.snapshot()``."""
        raise ConfigError("Fusion has no outputs to download; read the map with grid.snapshot() or grid.bricks()")

    def __call__(self, evidence, poses):
        """Fuse one frame given on the host: evidence (n_beams, n_bins) or (*batch, n_bins)
        int32 in logodds units, taken at ``poses``. Blocks; returns the FramePlan used."""
        self.check(evidence)
        plan = self.plan(poses)
        event = self.enqueue(plan=plan, wait_for=[self.upload(evidence)])
        if event is not None:
            event.wait()
        else:
            self.runtime.queue.finish()
        return plan
