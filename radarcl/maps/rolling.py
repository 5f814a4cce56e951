"""A rolling map: the bricks near the sensor on the device, the rest in the map store.

A drive maps far more ground than a device holds (the Oxford sequence: 37 minutes, about 9 km).
``RollingWindow`` keeps on the device only the bricks whose centre lies within ``window_m`` of
the sensor; before each frame it takes the others off (``EvidenceGrid.evict``) and hands them to
a ``RollingStore``, which writes them into a map store as they leave, a segment at a time, and
gives them back when the sensor returns (the grid asks its ``backing`` whenever it allocates a
brick). Integer sums do not care when a brick was away, so the map on disk after ``finish`` is
the one an unbounded grid gives, bit for bit (tests/test_rolling.py drives out and back).

Bounded host memory: what waits to be written (at most two segments of ``SEGMENT_BRICKS``),
and the index of the stored bricks (20 bytes each, about 8 % of a planar brick), never the map.
Segments are written on a thread of their own (``zarr`` compresses outside the GIL), so the
stream does not wait for the disk; the manifest after each segment names everything stored so
far, so a drive that stops (or a disk that fills) leaves the map saved up to its last segment.

A grid with the knowledge channel (the detection-statistics model) rolls the same way: its
knowledge and looks bricks leave and come back with its sums, stored beside them (the store's
``knowledge_<k>`` and ``looks_<k>`` arrays) with the map's reading.
"""

import math
import shutil
import threading
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.grid import EvidenceGrid
from radarcl.maps import store
from radarcl.maps.store_verify import CHUNK_BRICKS

SEGMENT_BRICKS = 32768          # bricks per segment written (8 MiB of planar bricks, 64 MiB of 8^3)
WINDOW_RANGE_FACTOR = 1.5       # the default window: this times the sensor's range (bricks just out
                                # of reach stay, so a sensor turning on the spot does not churn them)


def _ids(keys):
    k = np.asarray(keys, np.int64).reshape(-1, 3)
    return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]


class RollingStore:
    """A map store that receives bricks as they leave the device and gives them back.

    path: the store directory (a new one; an existing store only with ``overwrite``); spec:
    the grid's ``GridSpec``; meta: what the manifest keeps (sensor, config, provenance: as
    ``store.StoreWriter`` makes it); ``reading``: a grid with the knowledge channel's reading
    (its bricks are then dicts channel -> bricks, ``EvidenceGrid.KNOWLEDGE_CHANNELS``).
    ``put(keys, data)`` takes bricks, ``restore(keys)`` returns those it holds,
    ``finish(keys, data)`` writes the last ones and closes. A failed write (disk full,
    read-only) is raised, as ``ConfigError``, by the next call."""

    def __init__(self, path, spec, sensor_toml="", config=None, inputs=(), overwrite=False,
                 segment_bricks=SEGMENT_BRICKS, reading=None):
        self.path = Path(path)
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            if not store.recognises(self.path) or not overwrite:
                raise ConfigError(f"{self.path} exists; a rolling map starts a new store (choose another name, or "
                                  "--force to replace a map store)")
            shutil.rmtree(self.path)
        try:
            self._writer = store.StoreWriter(self.path, spec, sensor_toml, config, inputs, reading=reading)
        except OSError as exc:
            raise ConfigError(f"{self.path}: the map store cannot be written ({exc.strerror or exc})") from None
        self.spec, self.segment_bricks, self.reading = spec, int(segment_bricks), reading
        # bricks are kept as (n, kinds, *brick): the sums, and with knowledge its two channels
        self.kinds = store.KINDS if reading is not None else store.KINDS[:1]
        self._lock = threading.Lock()
        self._pending_keys, self._pending_data = [], []          # taken, not yet handed to the writer
        self._flushing = []                                      # (ids, keys, data) handed to the writer
        self._ids = np.zeros(0, np.int64)                        # stored bricks, sorted by id
        self._where = np.zeros((0, 2), np.int32)                 # their (segment, row)
        self._keys = np.zeros((0, 3), np.int32)
        self._segment_rows, self._crcs = {}, {}
        self._version, self._error = 0, None
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="rolling-store")
        self._future = None
        self.stats = dict(written=0, segments=0, restored=0, restored_from_disk=0)

    # -- what the grid calls ------------------------------------------------------------------------
    def restore(self, keys):
        """(rows of ``keys`` this store holds, their data (n, *brick) int32): the bricks come back
        to the device, so they leave what waits to be written (their stored copy is superseded
        when they leave again)."""
        self._raise()
        ids = _ids(keys)
        found = np.zeros(len(ids), bool)
        data = np.zeros((len(ids), len(self.kinds), *self.spec.brick_data_shape), np.int32)
        with self._lock:
            if self._pending_keys:
                pk, pd = np.concatenate(self._pending_keys), np.concatenate(self._pending_data)
                pos, hit = _lookup(_ids(pk), ids)
                if hit.any():
                    data[hit] = pd[pos[hit]]
                    found |= hit
                    keep = np.ones(len(pk), bool)
                    keep[pos[hit]] = False
                    self._pending_keys, self._pending_data = [pk[keep]], [pd[keep]]
            for f_ids, _, f_data in reversed(self._flushing):        # newest first
                pos, hit = _lookup(f_ids, ids)
                hit &= ~found
                data[hit] = f_data[pos[hit]]
                found |= hit
            pos, hit = _lookup_sorted(self._ids, ids)
            hit &= ~found
            where = self._where[pos[hit]]
        if hit.any():
            data[hit] = self._read(where)
            self.stats["restored_from_disk"] += int(hit.sum())
            found |= hit
        rows = np.flatnonzero(found)
        self.stats["restored"] += len(rows)
        return rows, self._channels(data[rows])

    def put(self, keys, data):
        """Take bricks (keys (n, 3), data (n, *brick) int32, or with knowledge a dict channel ->
        bricks) that left the device; a full segment goes to the writer's thread."""
        self._raise()
        if not len(keys):
            return
        with self._lock:
            self._pending_keys.append(np.asarray(keys, np.int32))
            self._pending_data.append(self._stacked(data))
            waiting = sum(len(k) for k in self._pending_keys)
        if waiting >= self.segment_bricks:
            self._flush()

    def finish(self, keys=None, data=None, meta=None):
        """Write the bricks still waiting and ``keys``/``data`` (the device's, at the end of the
        drive), then the final manifest (with ``meta``). Returns the bricks stored."""
        if keys is not None and len(keys):
            with self._lock:
                self._pending_keys.append(np.asarray(keys, np.int32))
                self._pending_data.append(self._stacked(data))
        if meta:
            self._writer.meta.update(meta)
        self._flush(final=True)
        self._wait()
        self._pool.shutdown()
        self._raise()
        return len(self._ids)

    def close(self):
        """Stop the writer's thread (what it was writing finishes; nothing more is written)."""
        self._wait(raise_error=False)
        self._pool.shutdown()

    def _stacked(self, data):
        """Bricks as kept here, (n, kinds, *brick) int32, from an array (the sums alone) or a dict
        channel -> bricks (a grid with the knowledge channel)."""
        if isinstance(data, dict):
            if self.reading is None:
                raise ConfigError("a rolling store without a reading keeps eq. 12 maps; give the grid's reading")
            return np.stack([np.asarray(data[c], np.int32) for c in EvidenceGrid.KNOWLEDGE_CHANNELS], axis=1)
        if self.reading is not None:
            raise ConfigError("a rolling store with a reading keeps the knowledge channel with the sums")
        return np.asarray(data, np.int32)[:, None]

    def _channels(self, data):
        """What the grid writes back (``EvidenceGrid.write_slots``): the sums alone, or a dict."""
        if self.reading is None:
            return data[:, 0]
        return {c: data[:, i] for i, c in enumerate(EvidenceGrid.KNOWLEDGE_CHANNELS)}

    @property
    def bricks_stored(self):
        """Bricks the last manifest names."""
        return len(self._ids)

    # -- the writer's side ----------------------------------------------------------------------------
    def _flush(self, final=False):
        with self._lock:
            if self._pending_keys:
                keys, data = np.concatenate(self._pending_keys), np.concatenate(self._pending_data)
                self._pending_keys, self._pending_data = [], []
            else:
                keys = data = None
            if keys is not None:
                self._flushing.append((_ids(keys), keys, data))
        if keys is None and not final:
            return
        self._wait()                                    # one segment at a time, in order
        self._future = self._pool.submit(self._write, keys, data)

    def _wait(self, raise_error=True):
        if self._future is not None:
            self._future.result()
            self._future = None
        if raise_error:
            self._raise()

    def _raise(self):
        if self._error is not None:
            raise ConfigError(self._error)

    def _write(self, keys, data):
        """On the writer's thread: one segment, the index, the manifest."""
        try:
            w = self._writer
            segment = len(self._segment_rows)
            if keys is not None:
                for i, kind in enumerate(self.kinds):
                    self._crcs[kind, segment] = store.write_segment(w.group, segment, data[:, i], w._codec, kind)
                self._segment_rows[segment] = len(keys)
            with self._lock:
                if keys is not None:
                    self._merge(keys, segment)
                index = np.concatenate([self._keys, self._where], axis=1).astype(np.int32)
            self._version += 1
            name = f"index_{self._version}"
            arr = w.group.create_array(name, shape=index.shape, dtype="int32",
                                       chunks=(max(1, min(len(index), 1 << 16)), 5), compressors=w._codec(level=1))
            if len(index):
                arr[:] = index
            previous = [f"index_{self._version - 1}"] if self._version > 1 else []
            store.write_manifest(self.path, self.spec, self._version, name, index, self._segment_rows, self._crcs,
                                 previous, w.meta, self.reading)
            old = self.path / f"index_{self._version - 2}"
            if self._version > 2 and old.is_dir():
                shutil.rmtree(old, ignore_errors=True)           # two back: no reader can still be on it
            self.stats["written"] += 0 if keys is None else len(keys)
            self.stats["segments"] = len(self._segment_rows)
        except OSError as exc:
            self._error = (f"{self.path}: the map store cannot be written ({exc.strerror or exc}); the map is saved up "
                           f"to its last complete segment ({len(self._ids)} bricks, manifest version {self._version})")
        finally:
            with self._lock:
                if keys is not None and self._flushing:
                    self._flushing.pop(0)

    def _merge(self, keys, segment):
        """Point the index at ``segment`` for ``keys`` (new keys inserted in id order)."""
        ids = _ids(keys)
        rows = np.arange(len(keys), dtype=np.int32)
        pos, hit = _lookup_sorted(self._ids, ids)
        self._where[pos[hit]] = np.stack([np.full(int(hit.sum()), segment, np.int32), rows[hit]], axis=1)
        new = ~hit
        if new.any():
            order = np.argsort(ids[new])
            new_ids = ids[new][order]
            at = np.searchsorted(self._ids, new_ids)
            self._ids = np.insert(self._ids, at, new_ids)
            self._keys = np.insert(self._keys, at, keys[new][order], axis=0)
            where = np.stack([np.full(len(new_ids), segment, np.int32), rows[new][order]], axis=1)
            self._where = np.insert(self._where, at, where, axis=0)

    def _read(self, where):
        """Bricks (n, kinds, *brick) at (segment, row) pairs, read chunk by chunk, each chunk's
        CRC-32 checked."""
        out = np.zeros((len(where), len(self.kinds), *self.spec.brick_data_shape), np.int32)
        chunk = where[:, 1] // CHUNK_BRICKS
        for seg in np.unique(where[:, 0]):
            for i, kind in enumerate(self.kinds):
                array = self._writer.group[f"{kind}_{int(seg)}"]
                for c in np.unique(chunk[where[:, 0] == seg]):
                    here = np.flatnonzero((where[:, 0] == seg) & (chunk == c))
                    start = int(c) * CHUNK_BRICKS
                    block = np.ascontiguousarray(array[start:start + CHUNK_BRICKS], np.int32)
                    if zlib.crc32(np.ascontiguousarray(block, "<i4")) != self._crcs[kind, int(seg)][int(c)]:
                        raise FrameFormatError(f"{self.path}: {kind}_{int(seg)} chunk {int(c)} does not match its "
                                               "checksum: the store was changed under the drive")
                    out[here, i] = block[where[here, 1] - start]
        return out


def _lookup(haystack, needles):
    """(positions, found) of ``needles`` in the unsorted ids ``haystack``."""
    if not len(haystack):
        return np.zeros(len(needles), np.int64), np.zeros(len(needles), bool)
    order = np.argsort(haystack)
    pos, hit = _lookup_sorted(haystack[order], needles)
    return order[pos], hit


def _lookup_sorted(haystack, needles):
    """(positions, found) of ``needles`` in the sorted ids ``haystack``."""
    if not len(haystack):
        return np.zeros(len(needles), np.int64), np.zeros(len(needles), bool)
    pos = np.minimum(np.searchsorted(haystack, needles), len(haystack) - 1)
    return pos, haystack[pos] == needles


class RollingWindow:
    """Keeps ``grid``'s device bricks within ``window_m`` of the sensor, the rest in ``backing``
    (a ``RollingStore``, which becomes the grid's backing). ``check_reach(reach_m)`` refuses a
    window smaller than one frame's reach; ``update(position_m)`` before each frame evicts the
    bricks whose centre lies farther than ``window_m`` from ``position_m`` (world, [m])."""

    def __init__(self, grid, backing, window_m):
        try:
            window = float(window_m)
        except (TypeError, ValueError):
            raise ConfigError(f"the window must be a distance [m], got {window_m!r}") from None
        if not (math.isfinite(window) and window > 0):
            raise ConfigError(f"the window must be a positive distance [m], got {window_m!r}")
        self.grid, self.backing, self.window_m = grid, backing, window
        grid.backing = backing
        spec = grid.spec
        self._edge = np.asarray(spec.brick, np.float64) * spec.voxel_m
        self._origin = np.asarray(spec.origin_m, np.float64) + 0.5 * self._edge
        self.evicted = 0

    @property
    def brick_diagonal_m(self):
        """The diagonal of one brick [m]."""
        return float(np.linalg.norm(self._edge))

    def check_reach(self, reach_m):
        """ConfigError unless a frame reaching ``reach_m`` from the sensor fits the window with a
        brick to spare (bricks a frame needs would otherwise leave and come back every frame)."""
        need = float(reach_m) + self.brick_diagonal_m
        if self.window_m < need:
            raise ConfigError(f"a window of {self.window_m:g} m is smaller than one frame's reach: the sensor reaches "
                              f"{float(reach_m):g} m and a brick spans {self.brick_diagonal_m:.3g} m; use --window of "
                              f"at least {math.ceil(need)} m")

    def update(self, position_m):
        """Evict the bricks beyond the window around ``position_m`` (3,) [m]; returns how many."""
        grid = self.grid
        if not grid.n_bricks:
            return 0
        slots = grid.live_slots()
        keys = grid.keys[slots]
        d2 = (((keys * self._edge + self._origin) - np.asarray(position_m, np.float64)) ** 2).sum(axis=1)
        far = d2 > self.window_m ** 2
        if not far.any():
            return 0
        nbx, nby, _ = grid.spec.brick_shape
        k = keys[far].astype(np.int64)
        out_keys, data = grid.evict((k[:, 2] * nby + k[:, 1]) * nbx + k[:, 0])
        self.backing.put(out_keys, data if grid.has_knowledge else data["evidence"])
        self.evicted += len(out_keys)
        return len(out_keys)

    def finish(self, meta=None):
        """Write every brick still on the device and close the store; returns the bricks stored."""
        grid = self.grid
        if grid.has_knowledge:
            keys, data = grid.read_slots(grid.live_slots(), channels=grid.channels)
        else:
            keys, data = grid.bricks()
        return self.backing.finish(keys, data, meta)
