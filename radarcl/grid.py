"""The evidence grid (paper §3.1, eq. 9): fixed-point log-odds in sparse bricks on the device.

Convention (one place, used everywhere): index (ix, iy, iz) covers world points p with
``origin + i * voxel <= p < origin + (i + 1) * voxel``; its coordinates are those of its CENTRE,
``origin + (i + 0.5) * voxel``. Index tuples and ``shape`` are (x, y, z). Dense numpy
snapshots are (nz, ny, nx), x fastest: the layout of a GL 3D texture of size (nx, ny, nz).

Values are int32 in ``radarcl.logodds`` units (1/1024 nat). The grid stores exact integer sums
of eq. 9 updates (each update already clamped to +-16 nat), so a map does not depend on the
order of frames or beams. Sums saturate at +-``GRID_LIMIT`` (2^30 units, about 1e6 nat, where
p = 1 in float64 anyway); only there would the order matter. Views (``log_odds``,
``probability``) are computed from the sums on read.

Storage: bricks of 8 x 8 x 8 voxels (2 KiB), allocated the first time some beam reaches them
("leave out what the scene does not need"). A host table maps brick -> slot in one device pool.
A grid made with ``knowledge=True`` (the detection-statistics model, ``radarcl.sensor_model``)
holds two more pools with the same slots: per voxel the summed detection opportunity of its looks
(``knowledge``: int32, ``logodds.KNOWLEDGE_SCALE`` units per look, non-negative, saturating at
``GRID_LIMIT``), so that "never observed" (0) differs from "observed, undecided" (evidence near
0), and the number of those looks (``looks``: the reading counts correlated looks once).
This module holds the grid on the device only; ``radarcl.maps`` reads and writes it as files.
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError, DeviceCapabilityError, ShapeError

BRICK = 8                           # voxels per brick edge
BRICK_VOXELS = BRICK ** 3
BRICK_BYTES = 4 * BRICK_VOXELS
GRID_LIMIT = 2 ** 30                # stored sums saturate here [units]
MAX_TABLE_BRICKS = 2 ** 28          # the host brick table (int32) stays below 1 GiB
MAX_EXTENT_M = 1e7                  # as far as a pose may lie (geometry.MAX_TRANSLATION_M)
MIN_VOXEL_M, MAX_VOXEL_M = 1e-4, 1e4


@dataclass(frozen=True)
class GridSpec:
    """Where the grid lies: ``origin_m`` (x, y, z) of its low corner [m], cubic voxels of
    ``voxel_m`` [m], ``shape`` (nx, ny, nz) voxels."""

    origin_m: tuple
    voxel_m: float
    shape: tuple

    def __post_init__(self):
        try:
            raw = np.asarray(self.origin_m)
            origin = tuple(float(v) for v in raw.reshape(-1)) if raw.dtype.kind in "iuf" else ()
        except (TypeError, ValueError):
            origin = ()
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ConfigError(f"origin_m must be 3 finite numbers, got {self.origin_m!r}")
        if isinstance(self.voxel_m, (bool, np.bool_)) or not (
                isinstance(self.voxel_m, (int, float, np.integer, np.floating)) and math.isfinite(self.voxel_m)
                and MIN_VOXEL_M <= self.voxel_m <= MAX_VOXEL_M):
            raise ConfigError(f"voxel_m must be a number in [{MIN_VOXEL_M:g}, {MAX_VOXEL_M:g}] m, got {self.voxel_m!r}")
        try:
            shape = tuple(self.shape)
        except TypeError:
            shape = ()
        if len(shape) != 3 or not all(isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_))
                                      and n >= 1 for n in shape):
            raise ConfigError(f"shape must be 3 positive integers (nx, ny, nz), got {self.shape!r}")
        if max(shape) > 2 ** 20:
            raise ConfigError(f"shape {shape} exceeds 2^20 voxels along an axis")
        far = np.abs(np.asarray(origin)) + np.asarray(shape, np.float64) * float(self.voxel_m)
        if (far > MAX_EXTENT_M).any():
            raise ConfigError(f"the grid from {list(origin)} m, {shape} voxels of {float(self.voxel_m):g} m, reaches "
                              f"beyond +-{MAX_EXTENT_M:g} m; express it in a local frame near the sensor (as poses)")
        object.__setattr__(self, "origin_m", origin)
        object.__setattr__(self, "voxel_m", float(self.voxel_m))
        object.__setattr__(self, "shape", tuple(int(n) for n in shape))

    @classmethod
    def around(cls, centre_m, size_m, voxel_m):
        """A grid of at least ``size_m`` (x, y, z) [m] centred on ``centre_m``."""
        try:
            size, centre, voxel = np.asarray(size_m, dtype=float), np.asarray(centre_m, dtype=float), float(voxel_m)
        except (TypeError, ValueError):
            raise ConfigError(f"GridSpec.around takes numbers: centre_m {centre_m!r}, size_m {size_m!r}, "
                              f"voxel_m {voxel_m!r}") from None
        if size.shape != (3,) or centre.shape != (3,) or not (np.isfinite(size).all() and np.isfinite(centre).all()
                                                              and math.isfinite(voxel) and voxel > 0):
            raise ConfigError(f"GridSpec.around needs finite (x, y, z) centre_m and size_m and a positive voxel_m, got "
                              f"{centre_m!r}, {size_m!r}, {voxel_m!r}")
        shape = tuple(int(n) for n in np.clip(np.ceil(size / voxel - 1e-9), 1, 2 ** 21))
        origin = centre - 0.5 * np.asarray(shape) * voxel
        return cls(tuple(origin), voxel, shape)

    @property
    def array_shape(self):
        """Shape of a dense snapshot: (nz, ny, nx)."""
        nx, ny, nz = self.shape
        return nz, ny, nx

    @property
    def n_voxels(self):
        """Voxels in the grid."""
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def brick_shape(self):
        """Bricks along (x, y, z); partial bricks at the high ends hold voxels outside the grid."""
        return tuple(-(-n // BRICK) for n in self.shape)

    def check_brick_table(self):
        """The number of bricks, or ConfigError when the host's brick table cannot hold them."""
        n_total = int(np.prod(self.brick_shape, dtype=np.int64))
        if n_total > MAX_TABLE_BRICKS:
            raise ConfigError(f"a grid of {self.shape} voxels of {self.voxel_m:g} m has {n_total} bricks, more "
                              f"than the {MAX_TABLE_BRICKS} a brick table holds; use voxels of at least "
                              f"{self.voxel_m * (n_total / MAX_TABLE_BRICKS) ** (1 / 3):.3g} m or a smaller grid")
        return n_total

    @property
    def dense_bytes(self):
        """Bytes of the grid stored densely as int32."""
        return 4 * self.n_voxels

    def world_to_index(self, points):
        """(..., 3) world points [m] -> (..., 3) int64 voxel indices floor((p - origin) / voxel),
        possibly outside the grid (see ``contains``, ``world_to_index_checked``)."""
        p = np.asarray(points, dtype=np.float64)
        return np.floor((p - np.asarray(self.origin_m)) / self.voxel_m).astype(np.int64)

    def index_to_world(self, index):
        """(..., 3) voxel indices -> (..., 3) world coordinates [m] of the voxel centres."""
        return np.asarray(self.origin_m) + (np.asarray(index, dtype=np.float64) + 0.5) * self.voxel_m

    def brick_voxels(self, bricks):
        """(n, 3) int64 indices (x, y, z) of the voxels of ``bricks`` (m, >= 3) (bx, by, bz, ...)
        that lie inside the grid (partial bricks at the high ends hold voxels outside it)."""
        b = np.asarray(bricks)[:, :3].astype(np.int64)
        offsets = np.stack(np.meshgrid(*[np.arange(BRICK)] * 3, indexing="ij"), -1).reshape(-1, 3)
        index = (b[:, None, :] * BRICK + offsets[None]).reshape(-1, 3)
        return index[self.contains(index)]

    def contains(self, index):
        """(...,) bool: index inside the grid."""
        i = np.asarray(index)
        return ((i >= 0) & (i < np.asarray(self.shape))).all(axis=-1)

    def world_to_index_checked(self, points):
        """As ``world_to_index``, but ConfigError names the first point outside the grid."""
        p = np.asarray(points, dtype=np.float64)
        if not np.isfinite(p).all():
            raise ConfigError("points must be finite")
        index = self.world_to_index(p)
        inside = self.contains(index)
        if not inside.all():
            bad = p.reshape(-1, 3)[np.flatnonzero(~inside.reshape(-1))[0]]
            upper = np.asarray(self.origin_m) + np.asarray(self.shape) * self.voxel_m
            raise ConfigError(f"point {bad.tolist()} lies outside the grid [{list(self.origin_m)}, "
                              f"{upper.tolist()}) m")
        return index


class EvidenceGrid:
    """A fixed-point log-odds grid on one device, stored in sparse bricks.

    runtime: a ``radarcl.cl.Runtime``; spec: a ``GridSpec``. ``dense=True`` allocates every
    brick at once (to compare memory, or when the whole grid will be seen anyway);
    ``knowledge=True`` adds the knowledge pool (see the module docstring).
    """

    def __init__(self, runtime, spec, *, dense=False, knowledge=False):
        if not isinstance(spec, GridSpec):
            raise ConfigError(f"spec must be a GridSpec, got {type(spec).__name__}")
        self.runtime = runtime
        self.spec = spec
        nbx, nby, nbz = spec.brick_shape
        n_total = spec.check_brick_table()
        self.table = np.full((nbz, nby, nbx), -1, np.int32)     # brick (z, y, x) -> slot
        self.keys = np.empty((0, 3), np.int32)                  # slot -> brick (bx, by, bz)
        self.pool = None
        self.has_knowledge = bool(knowledge)
        self.knowledge = None                                   # the knowledge pool (same slots)
        self.looks = None                                       # the looks' count pool (same slots)
        self.capacity = 0
        self.generation = 0                                     # bumped by clear(): slots change
        if dense:
            self._check_fits(n_total)
            bz, by, bx = np.indices(self.table.shape).reshape(3, -1)
            self.allocate(np.stack([bx, by, bz], axis=1))

    @property
    def n_bricks(self):
        """Bricks allocated so far."""
        return len(self.keys)

    def memory(self):
        """Bytes of the grid stored densely and as allocated here, and the brick counts."""
        table = self.table.nbytes
        channels = 3 if self.has_knowledge else 1
        return {"dense_bytes": self.spec.dense_bytes, "sparse_bytes": channels * self.n_bricks * BRICK_BYTES + table,
                "bricks": self.n_bricks, "bricks_total": int(self.table.size)}

    def _check_fits(self, needed):
        limit = int(self.runtime.device.max_mem_alloc_size)
        if needed * BRICK_BYTES > limit:
            factor = (needed * BRICK_BYTES / limit) ** (1 / 3)
            raise DeviceCapabilityError(
                f"the grid needs {needed} bricks = {needed * BRICK_BYTES / 2**20:.0f} MiB but "
                f"{self.runtime.name} allows buffers of {limit / 2**20:.0f} MiB; use voxels of at least "
                f"{self.spec.voxel_m * factor:.3g} m, or a smaller grid (sparse bricks already leave out "
                "space no beam reaches)")
        return limit

    def _grow(self, needed):
        import pyopencl as cl

        limit = self._check_fits(needed)
        capacity = max(needed, min(int(self.capacity * 1.5) + 64, limit // BRICK_BYTES))
        q = self.runtime.queue
        pools = []
        for old in (self.pool, self.knowledge, self.looks) if self.has_knowledge else (self.pool,):
            pool = self.runtime.empty(capacity * BRICK_BYTES)
            cl.enqueue_fill_buffer(q, pool, np.int32(0), 0, capacity * BRICK_BYTES)
            if old is not None and self.capacity:
                cl.enqueue_copy(q, pool, old, byte_count=self.n_bricks * BRICK_BYTES)
            pools.append(pool)
        self.pool, self.capacity = pools[0], capacity
        if self.has_knowledge:
            self.knowledge, self.looks = pools[1], pools[2]

    def allocate(self, bricks):
        """Slots of bricks (n, 3) (bx, by, bz), allocating the missing ones in the order of their
        index in the brick table (``allocate_index``). Returns (n,) int32 slots."""
        b = np.asarray(bricks, dtype=np.int64).reshape(-1, 3)
        if len(b) and ((b < 0).any() or (b >= np.asarray(self.spec.brick_shape)).any()):
            raise ConfigError(f"brick indices must lie in [0, {self.spec.brick_shape}), got {b.min(0)}..{b.max(0)}")
        nbx, nby, _ = self.spec.brick_shape
        return self.allocate_index((b[:, 2] * nby + b[:, 1]) * nbx + b[:, 0])

    def allocate_index(self, index):
        """Slots of the bricks at flat positions ``index`` of the brick table
        ((bz * nby + by) * nbx + bx, integers; Fusion's planner makes them), allocating the
        missing ones in increasing index order, so a grid's layout depends only on the bricks
        seen. Returns (n,) int32 slots."""
        flat = self.table.reshape(-1)
        index = np.asarray(index)
        if index.dtype.kind not in "iu":
            raise ConfigError(f"brick indices must be integers, got {index.dtype}")
        if len(index) and (index.min() < 0 or index.max() >= flat.size):   # a negative one would wrap
            raise ConfigError(f"flat brick indices must lie in [0, {flat.size}), got {index.min()}..{index.max()}")
        slots = flat[index]
        missing = slots < 0
        if missing.any():
            new_index = np.unique(index[missing])
            needed = self.n_bricks + len(new_index)
            if needed > self.capacity:
                self._grow(needed)
            flat[new_index] = np.arange(self.n_bricks, needed, dtype=np.int32)
            self.keys = np.concatenate([self.keys, self.brick_coords(new_index)])
            slots = flat[index]
        return slots

    def brick_coords(self, index, out=None):
        """(n, 3) int32 bricks (bx, by, bz) at flat positions ``index`` of the brick table, or
        written into the first three columns of ``out`` (n, >= 3) int32 and returned. int32
        division by a constant, column by column (np.divmod on int64 and a stack took 3x as
        long)."""
        nbx, nby, _ = self.spec.brick_shape
        i = np.asarray(index).astype(np.int32)          # MAX_TABLE_BRICKS < 2^31
        if out is None:
            out = np.empty((len(i), 3), np.int32)
        zy = i // nbx
        out[:, 0] = i - zy * nbx
        bz = zy // nby
        out[:, 1] = zy - bz * nby
        out[:, 2] = bz
        return out

    def bricks(self):
        """Sparse snapshot: (keys (n, 3) int32 (bx, by, bz), data (n, 8, 8, 8) int32 [z, y, x])."""
        import pyopencl as cl

        data = np.zeros((self.n_bricks, BRICK, BRICK, BRICK), np.int32)
        if self.n_bricks:
            cl.enqueue_copy(self.runtime.queue, data, self.pool, is_blocking=True)
        return self.keys.copy(), data

    def knowledge_bricks(self, channel="knowledge"):
        """The knowledge pool's bricks (or ``channel="looks"``: the looks' counts) in the order of
        ``bricks()``'s keys: (n, 8, 8, 8) int32 [z, y, x] in ``logodds.KNOWLEDGE_SCALE`` units
        (counts), or None for a grid without knowledge."""
        import pyopencl as cl

        if not self.has_knowledge:
            return None
        data = np.zeros((self.n_bricks, BRICK, BRICK, BRICK), np.int32)
        if self.n_bricks:
            cl.enqueue_copy(self.runtime.queue, data, {"knowledge": self.knowledge, "looks": self.looks}[channel],
                            is_blocking=True)
        return data

    def knowledge_snapshot(self, channel="knowledge"):
        """Dense int32 (nz, ny, nx) copy of the knowledge channel (0 where never observed) or the
        looks' counts (``channel="looks"``), or None for a grid without knowledge."""
        data = self.knowledge_bricks(channel)
        return None if data is None else assemble(self.spec, self.keys.copy(), data)

    def read_slots(self, slots):
        """(keys (n, 3), data (n, 8, 8, 8)) of the bricks in pool ``slots`` (e.g. a plan's
        bricks[:, 3]), read in contiguous runs: what changed, without the whole pool."""
        import pyopencl as cl

        slots = np.unique(np.asarray(slots, np.int64))
        if len(slots) and (slots[0] < 0 or slots[-1] >= self.n_bricks):
            raise ConfigError(f"brick slots must lie in [0, {self.n_bricks}), got {slots[0]}..{slots[-1]}")
        data = np.empty((len(slots), BRICK, BRICK, BRICK), np.int32)
        if len(slots):
            starts = np.concatenate([[0], np.flatnonzero(np.diff(slots) != 1) + 1, [len(slots)]])
            for a, b in zip(starts[:-1], starts[1:]):
                cl.enqueue_copy(self.runtime.queue, data[a:b], self.pool, src_offset=int(slots[a]) * BRICK_BYTES,
                                is_blocking=False)
            self.runtime.queue.finish()
        return self.keys[slots].copy(), data

    def snapshot(self):
        """Dense int32 (nz, ny, nx) copy of the grid in logodds units; unseen voxels are 0."""
        keys, data = self.bricks()
        return assemble(self.spec, keys, data)

    def log_odds(self):
        """Dense float64 (nz, ny, nx) log-odds [nat]."""
        return logodds.to_nats(self.snapshot())

    def probability(self):
        """Dense float64 (nz, ny, nx) occupancy probabilities."""
        return logodds.probability(self.snapshot())

    def clear(self):
        """Forget all evidence and free the bricks."""
        self.table.fill(-1)
        self.keys = np.empty((0, 3), np.int32)
        self.pool, self.knowledge, self.looks, self.capacity = None, None, None, 0
        self.generation += 1


def assemble(spec, keys, data):
    """Dense int32 (nz, ny, nx) array from bricks (keys (n, 3) (bx, by, bz), data (n, 8, 8, 8))."""
    if data.shape != (len(keys), BRICK, BRICK, BRICK):
        raise ShapeError(f"expected bricks of shape ({len(keys)}, 8, 8, 8), got {data.shape}")
    nbx, nby, nbz = spec.brick_shape
    full = np.zeros((nbz * BRICK, nby * BRICK, nbx * BRICK), np.int32)
    view = full.reshape(nbz, BRICK, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)
    if len(keys):
        view[keys[:, 2], keys[:, 1], keys[:, 0]] = data
    nz, ny, nx = spec.array_shape
    return np.ascontiguousarray(full[:nz, :ny, :nx])
