"""Planning a frame: each brick's window of candidate beams.

``candidate_windows`` is the float64 oracle, in numpy, of the bound. ``FusionPlanner`` wraps
``kernels/fusion_plan.cl``, its float32 device twin (tests/test_fusion_plan.py),
evaluated for every brick of a list of blocks (the blocks a coarse host pass keeps). A moving
radar plans every frame, so planning runs on the device. The kernel computes its angles without
builtin calls (``atan2_nb``: PoCL may call its builtins out of line and spill its registers).
"""

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from radarcl.errors import ConfigError
from radarcl.stages import build, work_group_size

# [rad] added to every angle bound, by the oracle and the kernel alike: it covers float32's
# rounding of angles up to 2 pi (~1e-6 rad) a hundred times over.
WINDOW_SLACK = 1e-4
# [m] added on the device to every brick's bounding radius (its trans_margin): float32 puts a
# brick's range and angles within ~1e-5 m and ~1e-6 rad of float64's, so with this the device's
# windows hold the float64 oracle's (1e-3 m subtends >= 5e-6 rad out to 200 m) and its plan
# lists every brick the oracle lists; it may list a few more, never fewer (tests/test_fusion_plan.py).
DEVICE_REACH_M = 1e-3
BLOCK_BITS = 2
BLOCK = 1 << BLOCK_BITS     # bricks per block edge: the coarse pass's unit
PVEC_CPU = 8                # bricks per work-item on a CPU, one per SIMD lane
COLUMN_TILE = 4             # brick columns per tile edge of a planar grid's listing (column_tiles)
LOCAL_SIZE = 64             # work-items per group where the compiled kernel allows it (any size works:
                            # the kernel returns past the last brick)


class HeadFrame(NamedTuple):
    """The head frame the windows are computed in, and how far any beam's own frame strays."""

    rotation: np.ndarray     # (3, 3) head -> world
    origin: np.ndarray       # (3,) [m, grid coordinates]
    trans_margin: float      # max |beam origin - origin| [m]
    rot_margin: float        # max rotation angle between a beam's frame and this one [rad]


def candidate_windows(centres, radius, ref, r_lo, r_hi, lattice, model):
    """Beams that may reach balls of ``radius`` around ``centres`` (n, 3) [m, grid coords],
    seen from ``ref`` (a ``HeadFrame``), for ranges in [r_lo, r_hi]: (n, 4) int64 windows
    (i_lo, i_hi, k_lo, k_hi), empty where i_lo > i_hi or k_lo > k_hi.

    The bounds, for a point at range r >= r_min, elevation el and azimuth offset daz from beam
    (i, k) in the head frame (a ball of radius rs = radius + trans_margin around the centre,
    whose direction is known within delta = asin(rs / r_c) + rot_margin):
    - inside needs |y| = r cos(el) |sin daz| <= max(a_az, r tan(theta_az / 2)), so
      |sin daz| <= s_az = max(tan(theta_az / 2), a_az / r_min) / cos(el); this bounds daz
      below 90 deg only when tan|el| tan|el_k| < sqrt(1 - s_az^2) (else d > 0 allows daz past
      90 deg, and every azimuth is a candidate);
    - z = r [sin(el - el_k) + sin(el_k) cos(el) (1 - cos daz)], so |sin(el - el_k)| <=
      max(tan(theta_el / 2), a_el / r_min) + (1 - cos daz), and |el - el_k| < 90 deg since d > 0;
    - a cap of radius delta at elevation el spans asin(sin delta / cos el) in azimuth.
    """
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    n = len(c)
    q = (c - ref.origin) @ ref.rotation
    rs = radius + ref.trans_margin
    tan_el_max = math.tan(float(np.abs(lattice.elevations).max()))
    r = np.linalg.norm(q, axis=1)
    out = np.empty((n, 4), np.int64)
    out[:] = (0, lattice.n_az - 1, 0, lattice.n_el - 1)
    none = (r + rs < r_lo) | (r - rs > r_hi)
    r_min = r - rs
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.arcsin(np.minimum(1.0, rs / r)) + ref.rot_margin + WINDOW_SLACK
        el = np.arctan2(q[:, 2], np.hypot(q[:, 0], q[:, 1]))
        el_abs = np.abs(el) + delta
        a_az, a_el = model.apertures
        s_az = np.maximum(math.tan(model.beamwidth_az_rad / 2), a_az / r_min) / np.cos(el_abs)
        full = (r_min <= 0) | (el_abs >= 0.5 * math.pi - 1e-3) | (s_az >= 1)
        full |= np.tan(el_abs) * tan_el_max >= np.sqrt(np.maximum(0.0, 1 - s_az ** 2))
        haz = np.arcsin(np.clip(s_az, 0, 1))
        daz = np.arcsin(np.minimum(1.0, np.sin(delta) / np.cos(np.abs(el))))
        s_el = np.maximum(math.tan(model.beamwidth_el_rad / 2), a_el / r_min) + (1 - np.cos(haz))
        hel = np.where(s_el >= 1, 0.5 * math.pi, np.arcsin(np.clip(s_el, 0, 1))) + delta
        az = np.arctan2(q[:, 1], q[:, 0])
        inv_az = 1.0 / lattice.az_step_rad if lattice.n_az > 1 else 0.0
        inv_el = 1.0 / lattice.el_step_rad if lattice.n_el > 1 else 0.0
        i_lo = np.ceil((az - haz - daz - lattice.az0_rad) * inv_az)
        i_hi = np.floor((az + haz + daz - lattice.az0_rad) * inv_az)
        k_lo = np.maximum(0, np.ceil((el - hel - lattice.el0_rad) * inv_el))
        k_hi = np.minimum(lattice.n_el - 1, np.floor((el + hel - lattice.el0_rad) * inv_el))
    part = ~full & ~none
    if lattice.wraps:
        wide = i_hi - i_lo + 1 >= lattice.n_az
        i_lo, i_hi = np.where(wide, 0, i_lo), np.where(wide, lattice.n_az - 1, i_hi)
    else:
        i_lo, i_hi = np.maximum(i_lo, 0), np.minimum(i_hi, lattice.n_az - 1)
    out[part] = np.stack([i_lo, i_hi, k_lo, k_hi], axis=1)[part].astype(np.int64)
    out[none] = (0, -1, 0, -1)
    return out


def nonempty(windows):
    """Which windows (n, 4) hold a beam."""
    return (windows[:, 0] <= windows[:, 1]) & (windows[:, 2] <= windows[:, 3])


class FusionPlanner:
    """Windows (i_lo, i_hi, k_lo, k_hi) of every brick of a list of blocks of BLOCK^3 bricks,
    for one lattice and beam model and the range interval [r_lo, r_hi] that carries evidence;
    vector_width: bricks per work-item (default 8 on a CPU, 1 elsewhere); brick_z: voxels per
    brick along z (8, or 1: bricks of brick_m x brick_m x brick_m / 8)."""

    def __init__(self, runtime, lattice, model, r_lo, r_hi, vector_width=None, brick_z=8):
        import pyopencl.array as cla

        self.runtime, self.lattice, self.model = runtime, lattice, model
        self.r_lo, self.r_hi = float(r_lo), float(r_hi)
        if vector_width is None:
            vector_width = PVEC_CPU if runtime.is_cpu else 1
        if vector_width not in (1, PVEC_CPU):
            raise ConfigError(f"vector_width must be 1 or {PVEC_CPU}, got {vector_width!r}")
        self.vector_width = vector_width
        if brick_z not in (8, 1):
            raise ConfigError(f"brick_z must be 8 or 1, got {brick_z!r}")
        self.brick_z = int(brick_z)
        defines = dict(N_AZ=lattice.n_az, N_EL=lattice.n_el, WINDOW_SLACK=WINDOW_SLACK, BLOCK=BLOCK,
                       PVEC=self.vector_width, BRICK_Z=self.brick_z)
        if lattice.wraps:
            defines["AZ_WRAP"] = True
        self._kernel = build(runtime, "fusion_plan", defines)["fusion_plan"]
        self._local = work_group_size(runtime, self._kernel, None, LOCAL_SIZE)
        self._head = cla.empty(runtime.queue, (12,), np.float32)
        self._blocks, self._out = None, None

    def windows(self, blocks, grid_bricks, brick_m, frame):
        """(n_blocks * BLOCK^3, 4) int32 windows of the bricks of ``blocks`` ((n, 3) first
        brick of each block; bricks x fastest within a block) of edge ``brick_m`` along x and y
        (``brick_m * brick_z / 8`` along z), seen from ``frame`` (a ``HeadFrame``); (0, -1, 0,
        -1) where no beam can reach or past ``grid_bricks``. Equivalent to ``candidate_windows``
        at the bricks' centres with ``brick_radius``."""
        import pyopencl as cl
        import pyopencl.array as cla

        blocks = np.asarray(blocks, np.int64).reshape(-1, 3)
        n = len(blocks) * BLOCK ** 3
        if n == 0:
            return np.zeros((0, 4), np.int32)
        q = self.runtime.queue
        if self._out is None or self._out.shape[0] < n:
            self._out = cla.empty(q, (n, 4), np.int32)
            self._blocks = cla.empty(q, (len(blocks), 4), np.int32)
        lat, m = self.lattice, self.model
        a_az, a_el = m.apertures
        head = np.concatenate([np.asarray(frame.rotation, np.float64).reshape(9), np.asarray(frame.origin, np.float64)])
        packed = np.zeros((len(blocks), 4), np.int32)
        packed[:, :3] = blocks
        cl.enqueue_copy(q, self._head.data, head.astype(np.float32), is_blocking=False)
        cl.enqueue_copy(q, self._blocks.data, packed, is_blocking=False)
        margin = float(frame.rot_margin) + WINDOW_SLACK
        local = self._local
        event = self._kernel(q, (-(-n // local) * local,), (local,), blocks=self._blocks, n_blocks=len(blocks),
                             grid_bx=int(grid_bricks[0]), grid_by=int(grid_bricks[1]), grid_bz=int(grid_bricks[2]),
                             brick_m=float(brick_m), head=self._head,
                             trans_margin=float(frame.trans_margin) + DEVICE_REACH_M,
                             margin=margin, cos_margin=math.cos(margin), sin_margin=math.sin(margin),
                             r_lo=self.r_lo, r_hi=self.r_hi,
                             az0=float(lat.az0_rad), az_step=float(lat.az_step_rad), el0=float(lat.el0_rad),
                             el_step=float(lat.el_step_rad),
                             tan_el_max=math.tan(float(np.abs(lat.elevations).max())),
                             tan_half_az=math.tan(m.beamwidth_az_rad / 2), tan_half_el=math.tan(m.beamwidth_el_rad / 2),
                             a_az=float(a_az), a_el=float(a_el), windows=self._out)
        host = np.empty((n, 4), np.int32)
        cl.enqueue_copy(q, host, self._out.data, wait_for=[event], is_blocking=True)
        return host

    @staticmethod
    def bricks_of(blocks, which=None):
        """(n, 3) the bricks ``windows`` evaluates for ``blocks``, in its order; or only those at
        positions ``which`` of that order."""
        o = np.arange(BLOCK ** 3) if which is None else np.asarray(which, np.int64)
        blocks = np.asarray(blocks, np.int64).reshape(-1, 3)
        local = o % BLOCK ** 3
        offsets = np.stack([local % BLOCK, (local // BLOCK) % BLOCK, local // (BLOCK * BLOCK)], axis=1)
        if which is None:
            return (blocks[:, None, :] + offsets[None]).reshape(-1, 3)
        return blocks[o // BLOCK ** 3] + offsets

    @staticmethod
    def brick_index(blocks, which, grid_bricks):
        """The bricks at positions ``which`` of ``windows``' order for ``blocks``, as flat
        indices of a brick table of shape ``grid_bricks`` (nbx, nby, nbz): (bz * nby + by) *
        nbx + bx. The same bricks as ``bricks_of``, in 1-D arithmetic (no (n, 3) temporaries)."""
        nbx, nby = int(grid_bricks[0]), int(grid_bricks[1])
        blocks = np.asarray(blocks, np.int64).reshape(-1, 3)
        first = (blocks[:, 2] * nby + blocks[:, 1]) * nbx + blocks[:, 0]
        local = np.arange(BLOCK ** 3)
        offset = ((local // (BLOCK * BLOCK)) * nby + (local // BLOCK) % BLOCK) * nbx + local % BLOCK
        which = np.asarray(which, np.int64)
        return first[which >> (3 * BLOCK_BITS)] + offset[which & (BLOCK ** 3 - 1)]


def brick_geometry(bricks, brick_m, brick_z=8):
    """(centres (n, 3) [m, grid coordinates], bounding radius [m]) of bricks (n, 3) of edge
    ``brick_m`` along x and y and ``brick_m * brick_z / 8`` along z: what ``FusionPlanner``
    evaluates, for ``candidate_windows``."""
    edge = np.array([brick_m, brick_m, brick_m * brick_z / 8.0])
    centres = (np.asarray(bricks, np.float64) + 0.5) * edge
    return centres, 0.5 * float(np.linalg.norm(edge))


@dataclass(frozen=True)
class FramePlan:
    """What the kernel needs for one frame's pose(s), prepared on the host."""

    beams: np.ndarray        # (n_beams, 3, 4) float32: u, v, w axes; [.., 3] = origin [m, grid coords]
    bricks: np.ndarray       # (n, 4) int32: bx, by, bz, slot of every brick the beams may reach
    windows: np.ndarray      # (n, 4) int32: candidate beams of each brick, i_lo, i_hi, k_lo, k_hi
    owner: object = field(default=None, compare=False, repr=False)   # the Fusion that made it
    generation: int = -1     # the grid's generation it was made for (slots die with grid.clear())
    _outside: list = field(default_factory=list, compare=False, repr=False)
    _table: list = field(default_factory=list, compare=False, repr=False)    # a StillTable, once recorded
    azimuths: tuple | None = None   # (lo, hi): the azimuths a part of a frame fuses (Fusion.restrict); None: all

    @property
    def table(self):
        """The ``StillTable`` recorded for this plan (a still radar), or None."""
        return self._table[0] if self._table else None       # [None]: recording was declined

    @property
    def beams_outside(self):
        """Beams that reach no brick of the grid (they give nothing); counted when first asked
        (a moving radar plans every frame, and few callers ask)."""
        if not self._outside:
            self._outside.append(self.owner._beams_outside(self.windows))
        return self._outside[0]


def pool_order(slots, n_slots):
    """The order that sorts ``slots`` (distinct, in [0, n_slots)): a scatter where the pool is
    not much larger than the list (linear in the pool), else argsort."""
    if n_slots > 4 * len(slots):
        return np.argsort(slots)
    position = np.full(n_slots, -1, np.int32)
    position[slots] = np.arange(len(slots), dtype=np.int32)
    return position[position >= 0]


def column_tiles(listed, chunk_bricks, tile=COLUMN_TILE):
    """An order of ``listed`` ((n, 4) int32 bx, by, bz, slot, in pool order) that keeps each pool
    chunk's bricks a run and, within a chunk, takes tiles of ``tile`` x ``tile`` brick columns
    one after the other, each tile's bricks in their listed (pool) order. Pool order visits a
    whole layer of planar bricks before the next, so a spinning radar's tall beams read every
    bin's node pairs once per layer, out of cache each time; by tiles, the layers of a tile
    read the same few node pairs while they are cached, and each layer's bricks of a tile stay
    a few pages of the pool."""
    listed = np.asarray(listed)
    if not len(listed):
        return np.arange(0, dtype=np.intp)
    tx = listed[:, 0].astype(np.int64) // tile
    ty = listed[:, 1].astype(np.int64) // tile
    chunk = listed[:, 3].astype(np.int64) // chunk_bricks
    key = (chunk * (int(ty.max()) + 1) + ty) * (int(tx.max()) + 1) + tx
    return np.argsort(key, kind="stable")


def take_rows(a, order):
    """Rows ``order`` of an (n, 4) int32 array, each moved as one 16-byte item (numpy's
    fancy indexing of 2-D rows moves them element by element)."""
    a = np.ascontiguousarray(a, np.int32)
    return a.view(np.complex128)[:, 0][order].view(np.int32).reshape(-1, 4)
