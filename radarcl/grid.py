"""The evidence grid (paper §3.1, eq. 9): fixed-point log-odds in sparse bricks on the device
(its spec, the voxel convention and the brick shapes: ``radarcl.gridspec``). It stores exact
int32 sums of eq. 9 updates in ``radarcl.logodds`` units, saturating at +-``GRID_LIMIT``.

Storage: bricks of 8 x 8 x ``brick_z`` voxels, allocated the first time some beam reaches them
("leave out what the scene does not need"): 8^3 (2 KiB) in general, 8 x 8 x 1 (256 bytes) for a
planar sensor (a spinning radar with one elevation maps a plane one voxel thick, so 7/8 of an
8^3 brick would never be written; ``GridSpec.brick_z``, chosen by ``config.sensors.brick_depth``).
A brick's data is (brick_z, 8, 8) [z, y, x]. A host table maps brick -> slot; the slots live in
the device pools (``EvidenceGrid.pools``: one per channel, the same slots in each), each a list
of fixed-size chunks, so growing the grid allocates a chunk and never copies what is there.
A grid made with ``knowledge=True`` (the detection-statistics model, ``radarcl.sensor_model``)
has two more channels with the same slots: per voxel the summed detection opportunity of its
looks (``knowledge``: int32, ``logodds.KNOWLEDGE_SCALE`` units per look, non-negative, saturating
at ``GRID_LIMIT``), so that "never observed" (0) differs from "observed, undecided" (evidence near
0), and the number of those looks (``looks``: the reading counts correlated looks once).
This module holds the grid on the device only; ``radarcl.maps`` reads and writes it as files.
"""


import numpy as np

from radarcl import logodds
from radarcl.cl.limits import size_text
from radarcl.errors import ConfigError, DeviceCapabilityError
from radarcl.gridspec import GridSpec, assemble

CHUNK_BYTES = 32 * 2 ** 20          # a pool chunk: growing the grid adds one, copying nothing
PAGE_BYTES = 4096                   # a CPU device's chunk starts on a page (PoCL uses it in place)
SPAN_GAP_BYTES = 64 * 2 ** 10       # reading bricks, slots this close are read in one copy, gap included


class EvidenceGrid:
    """A fixed-point log-odds grid on one device, stored in sparse bricks.

    runtime: a ``radarcl.cl.Runtime``; spec: a ``GridSpec``. ``dense=True`` allocates every
    brick at once (to compare memory, or when the whole grid will be seen anyway);
    ``knowledge=True`` adds the knowledge and looks channels (see the module docstring);
    ``chunk_bricks``: slots per pool chunk (default: ``CHUNK_BYTES`` worth, within the
    device's largest buffer); ``backing``: where bricks that left the device live (``evict``),
    an object whose ``restore(keys)`` gives (rows of ``keys`` it holds, their data per channel),
    asked whenever a brick is allocated again (``radarcl.maps.rolling``).

    Slots: ``keys[slot]`` is the brick in that slot, (-1, -1, -1) for a freed one; a slot lives
    in chunk ``slot // chunk_bricks`` of every channel's pool at ``slot % chunk_bricks``.
    """

    KNOWLEDGE_CHANNELS = ("evidence", "knowledge", "looks")

    def __init__(self, runtime, spec, *, dense=False, knowledge=False, chunk_bricks=None, backing=None):
        if not isinstance(spec, GridSpec):
            raise ConfigError(f"spec must be a GridSpec, got {type(spec).__name__}")
        self.runtime = runtime
        self.spec = spec
        nbx, nby, nbz = spec.brick_shape
        n_total = spec.check_brick_table()
        self.table = np.full((nbz, nby, nbx), -1, np.int32)     # brick (z, y, x) -> slot
        self.keys = np.empty((0, 3), np.int32)                  # slot -> brick (bx, by, bz); -1 when free
        self.free = np.empty(0, np.int32)                       # freed slots, reused lowest first
        limit = int(runtime.limits.max_mem_alloc_size)
        if limit < spec.brick_bytes:
            raise DeviceCapabilityError(f"one brick of the grid takes {size_text(spec.brick_bytes)}, more than the largest "
                                        f"buffer of {runtime.name}, {size_text(limit)} (radarcl info)")
        self.chunk_bricks = int(chunk_bricks) if chunk_bricks else max(1, min(CHUNK_BYTES, limit) // spec.brick_bytes)
        if self.chunk_bricks < 1 or self.chunk_bricks * spec.brick_bytes > limit:
            raise ConfigError(f"chunk_bricks must be in [1, {limit // spec.brick_bytes}], got {chunk_bricks!r}")
        self.has_knowledge = bool(knowledge)
        self.reading = None             # how a grid with knowledge reads (set by ``Mapping.from_config``)
        # pools with the same slots, grown and evicted together
        self.channels = self.KNOWLEDGE_CHANNELS if self.has_knowledge else ("evidence",)
        self.pools = {name: [] for name in self.channels}       # channel -> its chunks (device buffers)
        self.backing = backing
        self.generation = 0                                     # bumped when slots change (clear, evict)
        self.stats = dict(chunks=0, evicted=0, restored=0, chunks_ahead=0, chunks_waited=0)
        self._ahead, self._pending, self._ahead_pool, self._ahead_queue, self._ahead_bricks = 0, None, None, None, 0
        self._largest = 0                                       # the most bricks one allocation added
        if dense:
            self._check_fits(n_total)
            bz, by, bx = np.indices(self.table.shape).reshape(3, -1)
            self.allocate(np.stack([bx, by, bz], axis=1))

    @property
    def n_slots(self):
        """Slots handed out so far (live and freed): slot numbers lie below this."""
        return len(self.keys)

    @property
    def n_bricks(self):
        """Bricks on the device now."""
        return len(self.keys) - len(self.free)

    @property
    def capacity(self):
        """Slots the pools hold."""
        return len(self.pools[self.channels[0]]) * self.chunk_bricks

    @property
    def pool(self):
        """The evidence pool's buffer while it is one chunk (a single-chunk grid's kernels take
        it whole); with several chunks, use ``chunk``."""
        chunks = self.pools["evidence"]
        if len(chunks) > 1:
            raise ConfigError(f"the grid's pool is {len(chunks)} chunks; launch per chunk (EvidenceGrid.chunk)")
        return chunks[0] if chunks else None

    def chunk(self, c, channel="evidence"):
        """Chunk ``c`` of a channel's pool: slots c * chunk_bricks ... (c + 1) * chunk_bricks - 1."""
        return self.pools[channel][c]

    def memory(self):
        """Bytes of the grid stored densely and as allocated here, and the brick counts."""
        table = self.table.nbytes
        spare = self._ahead_bricks if self._pending is not None else 0       # chunks grown ahead count
        return {"dense_bytes": self.spec.dense_bytes,
                "sparse_bytes": len(self.channels) * self.n_bricks * self.spec.brick_bytes + table,
                "device_bytes": len(self.channels) * (self.capacity + spare) * self.spec.brick_bytes,
                "bricks": self.n_bricks, "bricks_total": int(self.table.size)}

    def _check_fits(self, needed):
        limit = int(self.runtime.limits.max_mem_alloc_size)
        total = int(self.runtime.limits.global_mem_size) - self.runtime.held_bytes    # beside the stages' buffers
        if needed * self.spec.brick_bytes * len(self.channels) > total:
            factor = (needed * self.spec.brick_bytes * len(self.channels) / max(total, 1)) ** (1 / 3)
            raise DeviceCapabilityError(
                f"the grid needs {needed} bricks = {size_text(needed * self.spec.brick_bytes * len(self.channels))} "
                f"but {self.runtime.name} has {size_text(max(total, 0))} beside the pipeline's buffers; use voxels of at least "
                f"{self.spec.voxel_m * factor:.3g} m, a smaller grid, or a rolling window (sparse bricks already "
                "leave out space no beam reaches)")
        return limit

    def _grow(self, needed):
        """Add chunks until ``needed`` slots fit, in every channel's pool: a new chunk is
        allocated and zeroed, and nothing already stored is copied (a whole-pool copy stalled
        the stream when the map reached new ground)."""
        self._check_fits(needed)
        q = self.runtime.queue
        size = self.chunk_bricks * self.spec.brick_bytes
        ready = []
        while self.capacity < needed:
            if not ready and self._pending is not None:     # grown ahead: ready, or nearly
                ready, self._pending = self._pending.result(), None
            if ready:
                bufs = ready.pop(0)
            else:                                           # grown here: the caller waits for it
                self.stats["chunks_waited"] += 1
                bufs = {name: self._zeroed_buffer(size, q) for name in self.pools}
            for name, chunks in self.pools.items():
                chunks.append(bufs[name])
            self.stats["chunks"] += 1
        for bufs in ready:                                  # grown ahead beyond the need: kept
            for name, chunks in self.pools.items():
                chunks.append(bufs[name])
            self.stats["chunks"] += 1

    def grow_ahead(self, spare_slots=None):
        """Keep free slots ready: whenever fewer than ``spare_slots`` (default: a chunk's), or
        than the most bricks one allocation has added so far, remain, the chunks that make them up are allocated and zeroed on a thread and a queue
        of their own, so a frame that reaches new ground takes ready chunks instead of waiting
        for them (a stream's latency; ``radarcl live`` asks for a frame's worth). 0 turns it off."""
        self._ahead = self.chunk_bricks if spare_slots is None else max(0, int(spare_slots))
        if self._ahead and self._ahead_pool is None:          # made now: the first frame should not wait for them
            from concurrent.futures import ThreadPoolExecutor

            import pyopencl as cl

            self._ahead_pool = ThreadPoolExecutor(1, thread_name_prefix="radarcl-grow")
            self._ahead_queue = cl.CommandQueue(self.runtime.context)
            self._ahead_pool.submit(lambda: None).result()    # the thread started
        self._kick()

    def _kick(self):
        """Start growing the next chunk ahead when the free slots run low (``grow_ahead``)."""
        want = max(self._ahead, self._largest) if self._ahead else 0        # what the greediest frame took
        if not want or self._pending is not None or self.capacity - self.n_slots >= want:
            return
        n = -(-(want - (self.capacity - self.n_slots)) // self.chunk_bricks)
        self._check_fits(self.capacity + n * self.chunk_bricks)
        self._pending = self._ahead_pool.submit(self._zeroed_chunks, n)
        self._ahead_bricks = n * self.chunk_bricks
        self.stats["chunks_ahead"] += n

    def _zeroed_chunks(self, n):
        """On the grow-ahead thread: ``n`` chunks, each a buffer per channel, zeroed, finished."""
        size = self.chunk_bricks * self.spec.brick_bytes
        out = [{name: self._zeroed_buffer(size, self._ahead_queue) for name in self.pools} for _ in range(n)]
        self._ahead_queue.finish()
        return out

    def _zeroed_buffer(self, size, queue):
        """A new device buffer of ``size`` bytes, all zero. On a CPU device it is the memory of
        a fresh host array (the OS hands out zeroed pages when they are first touched: nothing
        to fill, so growing the pool costs no device time that a frame would wait behind);
        elsewhere a buffer filled with zeros on ``queue``."""
        import pyopencl as cl

        if self.runtime.is_cpu:
            raw = np.zeros(size + PAGE_BYTES, np.uint8)            # calloc: pages untouched until used
            start = (-raw.ctypes.data) % PAGE_BYTES
            return cl.Buffer(self.runtime.context, cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR,
                             hostbuf=raw[start:start + size])      # the buffer keeps the array alive
        buf = self.runtime.empty(size)
        cl.enqueue_fill_buffer(queue, buf, np.int32(0), 0, size)
        return buf

    def reserve(self, slots):
        """Grow the pools now (a chunk at a time) so that ``slots`` slots fit: before a stream,
        so its first frame does not wait for the allocation."""
        if slots > self.capacity:
            self._grow(int(slots))
        self.runtime.queue.finish()

    def allocate(self, bricks):
        """Slots of bricks (n, 3) (bx, by, bz), allocating the missing ones in the order of their
        index in the brick table (``allocate_index``). Returns (n,) int32 slots."""
        try:
            b = np.asarray(bricks, dtype=np.float64).reshape(-1, 3)
        except (TypeError, ValueError):
            raise ConfigError(f"bricks must be integer brick indices (n, 3) (bx, by, bz), got {bricks!r}") from None
        if not (np.isfinite(b).all() and (b == np.round(b)).all()):
            raise ConfigError("bricks must be whole finite brick indices (bx, by, bz), got non-integer or NaN values")
        b = b.astype(np.int64)
        if len(b) and ((b < 0).any() or (b >= np.asarray(self.spec.brick_shape)).any()):
            raise ConfigError(f"brick indices must lie in [0, {self.spec.brick_shape}), got {b.min(0)}..{b.max(0)}")
        nbx, nby, _ = self.spec.brick_shape
        return self.allocate_index((b[:, 2] * nby + b[:, 1]) * nbx + b[:, 0])

    def allocate_index(self, index):
        """Slots of the bricks at flat positions ``index`` of the brick table
        ((bz * nby + by) * nbx + bx, integers; Fusion's planner makes them), allocating the
        missing ones in increasing index order (freed slots first, lowest first), so a grid's
        layout depends only on the bricks seen and left. A brick the ``backing`` holds comes
        back with its data. Returns (n,) int32 slots."""
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
            self._largest = max(self._largest, len(new_index))
            reuse = min(len(new_index), len(self.free))
            fresh = len(new_index) - reuse
            needed = self.n_slots + fresh
            if needed > self.capacity:
                self._grow(needed)
            new_slots = np.concatenate([self.free[:reuse], np.arange(self.n_slots, needed, dtype=np.int32)])
            self.free = self.free[reuse:]
            flat[new_index] = new_slots
            keys = self.brick_coords(new_index)
            self.keys = np.concatenate([self.keys, np.empty((fresh, 3), np.int32)])
            self.keys[new_slots] = keys
            if self.backing is not None:
                rows, data = self.backing.restore(keys)
                if len(rows):
                    self.write_slots(new_slots[rows], data)
                    self.stats["restored"] += len(rows)
            slots = flat[index]
            self._kick()
        return slots

    def _runs(self, slots):
        """Sorted ``slots`` as runs (chunk, first slot in it, first row, end row) of consecutive
        slots within one chunk."""
        cut = np.flatnonzero((np.diff(slots) != 1) | (np.diff(slots // self.chunk_bricks) != 0)) + 1
        starts = np.concatenate([[0], cut])
        ends = np.concatenate([cut, [len(slots)]])
        return [(int(slots[a]) // self.chunk_bricks, int(slots[a]) % self.chunk_bricks, int(a), int(b))
                for a, b in zip(starts, ends)]

    def write_slots(self, slots, data):
        """Write bricks into pool ``slots`` (distinct): ``data`` a dict channel -> (n, *brick) int32
        (an array alone is the evidence). Blocks until written."""
        import pyopencl as cl

        if not isinstance(data, dict):
            data = {"evidence": data}
        slots = np.asarray(slots, np.int64)
        order = np.argsort(slots)
        slots = slots[order]
        size = self.spec.brick_bytes
        for name, values in data.items():
            values = np.ascontiguousarray(np.asarray(values, np.int32)[order])
            for c, first, a, b in self._runs(slots):
                cl.enqueue_copy(self.runtime.queue, self.pools[name][c], values[a:b], dst_offset=first * size,
                                is_blocking=False)
        self.runtime.queue.finish()

    def evict(self, index):
        """Take the bricks at flat positions ``index`` (allocated ones) off the device: returns
        (keys (n, 3) int32, data: channel -> (n, *brick) int32) and frees their slots (zeroed
        for their next bricks). Plans made before no longer hold (``generation``)."""
        import pyopencl as cl

        flat = self.table.reshape(-1)
        index = np.unique(np.asarray(index, np.int64))
        slots = flat[index]
        if (slots < 0).any():
            raise ConfigError("only allocated bricks can be evicted")
        keys, data = self.read_slots(slots, channels=self.channels)
        slots = np.sort(slots)
        size = self.spec.brick_bytes
        for chunks in self.pools.values():
            for c, first, a, b in self._runs(slots):
                cl.enqueue_fill_buffer(self.runtime.queue, chunks[c], np.int32(0), first * size, (b - a) * size)
        flat[index] = -1
        self.keys[slots] = -1
        self.free = np.sort(np.concatenate([self.free, slots.astype(np.int32)]))
        self.generation += 1
        self.stats["evicted"] += len(slots)
        return keys, data

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

    def live_slots(self):
        """The slots that hold a brick, ascending."""
        return np.flatnonzero(self.keys[:, 0] >= 0) if len(self.free) else np.arange(self.n_slots)

    def bricks(self, channel="evidence"):
        """Sparse snapshot: (keys (n, 3) int32 (bx, by, bz), data (n, *brick) int32 [z, y, x]) of
        the bricks on the device, in slot order."""
        keys, data = self.read_slots(self.live_slots(), channels=(channel,))
        return keys, data[channel]

    def knowledge_bricks(self, channel="knowledge"):
        """The knowledge channel's bricks (or ``channel="looks"``: the looks' counts) in the order
        of ``bricks()``'s keys: (n, *brick) int32 [z, y, x] in ``logodds.KNOWLEDGE_SCALE`` units
        (counts), or None for a grid without knowledge."""
        return self.bricks(channel)[1] if self.has_knowledge else None

    def knowledge_snapshot(self, channel="knowledge"):
        """Dense int32 (nz, ny, nx) copy of the knowledge channel (0 where never observed) or the
        looks' counts (``channel="looks"``), or None for a grid without knowledge."""
        if not self.has_knowledge:
            return None
        keys, data = self.bricks(channel)
        return assemble(self.spec, keys, data)

    def read_slots(self, slots, channels=None):
        """(keys (n, 3), data (n, *brick)) of the bricks in pool ``slots`` (e.g. a plan's
        slots), read in contiguous runs: what changed, without the whole pool. With
        ``channels`` (names), data is a dict channel -> (n, *brick)."""
        import pyopencl as cl

        slots = np.unique(np.asarray(slots, np.int64))
        if len(slots) and (slots[0] < 0 or slots[-1] >= self.n_slots):
            raise ConfigError(f"brick slots must lie in [0, {self.n_slots}), got {slots[0]}..{slots[-1]}")
        out = {}
        spans = self._spans(slots) if len(slots) else []
        for name in channels or ("evidence",):
            data = np.empty((len(slots), *self.spec.brick_data_shape), np.int32)
            read = []
            for c, first, a, b, n in spans:
                # one copy per span of nearby slots (the bricks a window evicts are scattered;
                # a copy per brick costs more than the few unwanted ones between them)
                tmp = data[a:b] if n == b - a else np.empty((n, *self.spec.brick_data_shape), np.int32)
                cl.enqueue_copy(self.runtime.queue, tmp, self.pools[name][c],
                                src_offset=first * self.spec.brick_bytes, is_blocking=False)
                if tmp.base is not data:
                    read.append((tmp, a, b, first))
            self.runtime.queue.finish()
            for tmp, a, b, first in read:
                data[a:b] = tmp[slots[a:b] % self.chunk_bricks - first]
            out[name] = data
        return self.keys[slots].copy(), (out if channels else out["evidence"])

    def _spans(self, slots):
        """Sorted distinct ``slots`` as spans (chunk, first slot in it, first row, end row, slots
        spanned) of slots within one chunk no more than ``SPAN_GAP_BYTES`` of bricks apart."""
        gap = max(1, SPAN_GAP_BYTES // self.spec.brick_bytes)
        cut = np.flatnonzero((np.diff(slots) > gap) | (np.diff(slots // self.chunk_bricks) != 0)) + 1
        starts, ends = np.concatenate([[0], cut]), np.concatenate([cut, [len(slots)]])
        return [(int(slots[a]) // self.chunk_bricks, int(slots[a]) % self.chunk_bricks, int(a), int(b),
                 int(slots[b - 1] - slots[a]) + 1) for a, b in zip(starts, ends)]

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
        self.free = np.empty(0, np.int32)
        self.pools = {name: [] for name in self.channels}
        self.generation += 1
        self._kick()
