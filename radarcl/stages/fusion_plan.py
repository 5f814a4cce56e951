"""Planning a frame on the device: each brick's window of candidate beams.

``FusionPlanner`` wraps ``kernels/fusion_plan.cl``, the float32 device twin of
``radarcl.stages.fusion.candidate_windows`` (its float64 oracle, tests/test_fusion_plan.py),
evaluated for every brick of a list of blocks (the blocks a coarse host pass keeps). A moving
radar plans every frame: numpy windows over the paper frustum's bricks at 0.1 m took 30-45 ms
per frame. The kernel computes its angles without builtin calls (``atan2_nb``: PoCL may call
its builtins out of line), which made it 3x faster here.
"""

import math

import numpy as np

from radarcl.errors import ConfigError
from radarcl.stages import build

# [rad] added to every angle bound, as the float64 oracle's WINDOW_SLACK: it covers float32's
# rounding of angles up to 2 pi (~1e-6 rad) a hundred times over.
WINDOW_SLACK = 1e-4
BLOCK = 4                   # bricks per block edge: the coarse pass's unit
PVEC_CPU = 8                # bricks per work-item on a CPU, one per SIMD lane


class FusionPlanner:
    """Windows (i_lo, i_hi, k_lo, k_hi) of every brick of a list of blocks of BLOCK^3 bricks,
    for one lattice and beam model and the range interval [r_lo, r_hi] that carries evidence;
    vector_width: bricks per work-item (default 8 on a CPU, 1 elsewhere)."""

    def __init__(self, runtime, lattice, model, r_lo, r_hi, vector_width=None):
        import pyopencl.array as cla

        self.runtime, self.lattice, self.model = runtime, lattice, model
        self.r_lo, self.r_hi = float(r_lo), float(r_hi)
        if vector_width is None:
            vector_width = PVEC_CPU if runtime.is_cpu else 1
        if vector_width not in (1, PVEC_CPU):
            raise ConfigError(f"vector_width must be 1 or {PVEC_CPU}, got {vector_width!r}")
        self.vector_width = vector_width
        defines = dict(N_AZ=lattice.n_az, N_EL=lattice.n_el, WINDOW_SLACK=WINDOW_SLACK, BLOCK=BLOCK,
                       PVEC=self.vector_width)
        if lattice.wraps:
            defines["AZ_WRAP"] = True
        self._kernel = build(runtime, "fusion_plan", defines)["fusion_plan"]
        self._head = cla.empty(runtime.queue, (12,), np.float32)
        self._blocks, self._out = None, None

    def windows(self, blocks, grid_bricks, brick_m, frame):
        """(n_blocks * BLOCK^3, 4) int32 windows of the bricks of ``blocks`` ((n, 3) first
        brick of each block; bricks x fastest within a block), seen from ``frame`` (a
        ``fusion.HeadFrame``); (0, -1, 0, -1) where no beam can reach or past ``grid_bricks``."""
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
        local = 64
        event = self._kernel(q, (-(-n // local) * local,), (local,), blocks=self._blocks, n_blocks=len(blocks),
                             grid_bx=int(grid_bricks[0]), grid_by=int(grid_bricks[1]), grid_bz=int(grid_bricks[2]),
                             brick_m=float(brick_m), head=self._head, trans_margin=float(frame.trans_margin),
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
        nbx + bx. The same bricks as ``bricks_of``, in 1-D arithmetic (0.45 -> 0.05 ms for the
        paper frame's 55k bricks here)."""
        nbx, nby = int(grid_bricks[0]), int(grid_bricks[1])
        blocks = np.asarray(blocks, np.int64).reshape(-1, 3)
        first = (blocks[:, 2] * nby + blocks[:, 1]) * nbx + blocks[:, 0]
        local = np.arange(BLOCK ** 3)
        offset = ((local // (BLOCK * BLOCK)) * nby + (local // BLOCK) % BLOCK) * nbx + local % BLOCK
        which = np.asarray(which, np.int64)
        return first[which // BLOCK ** 3] + offset[which % BLOCK ** 3]
