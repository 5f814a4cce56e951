"""The fleet's merge: partial maps summed brick by brick as a Dask reduction partitioned by brick
key, the merged map store's chunks written by the workers.

Why: one process adding every input's bricks costs O(bricks x inputs) on one core, exactly where
a fleet has many inputs. Here each partition is a range of brick keys, in the order the
one-process ``merge`` gives them ((bz, by, bx)), holding a whole number of the store's chunks
(``CHUNK_BRICKS`` bricks). A worker reads the partition's bricks from every input store (only
the chunks that hold them, each checked against its CRC-32 as ``maps.store.read`` checks it),
adds them in int64, clamps at the grid's saturation and writes its chunks of the merged store's
one segment: no two workers write one chunk file. The coordinator reads only the inputs'
manifests and indexes (20 bytes a brick against a brick's 2 KiB), plans the partitions, and
writes the index and the manifest last, in a temporary directory renamed over the output when
every worker has finished. So the store is, file for file, the one ``StoreWriter`` writes of the
one-process merge (the manifest's time stamps aside), and a failed worker leaves nothing at the
output.

A map of the detection-statistics model carries its knowledge channel (``knowledge`` and
``looks`` arrays beside each segment, ``maps.store``): those are sums too, merged the same way
(clamped at [0, saturation]) and written with the inputs' reading, which must be one.

Inputs are map stores on a filesystem every worker sees under the same path (``fuse-many``
writes its partial maps beside the output). A store whose bricks lie in key order (fuse-many's
partials, a merged map) gives each partition a contiguous run of chunks; any other store merges
the same, reading more chunks.
"""

import contextlib
import time
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError, RadarclError
from radarcl.gridspec import BRICK, GRID_LIMIT
from radarcl.io import files
from radarcl.maps import npz, store
from radarcl.maps.disk import output_format
from radarcl.maps.store_verify import CHUNK_BRICKS, _Arrays, _check_index, _Lost, _read_index, _read_segment

PARTITIONS_PER_WORKER = 3       # more partitions than workers: a slow worker delays less


def key_ids(keys):
    """One int64 per brick key (bx, by, bz), ordered as (bz, by, bx)."""
    k = np.asarray(keys).astype(np.int64)
    return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]


def merge(parts, channels=False):
    """Sum sparse maps [(keys, data), ...] brick by brick (int64), clamped at +-GRID_LIMIT:
    (keys sorted by (bz, by, bx), data int32). The one-process merge, and each partition's.
    ``channels``: data is (n, 3, *brick), the sums, knowledge and looks of a map with the
    knowledge channel (those two clamped at [0, GRID_LIMIT])."""
    keys = np.concatenate([k for k, _ in parts]) if parts else np.zeros((0, 3), np.int32)
    if not len(keys):
        return keys.astype(np.int32), np.zeros((0, *(parts[0][1].shape[1:] if parts else (8, 8, 8))), np.int32)
    unique, inverse = np.unique(key_ids(keys), return_inverse=True)
    total = np.zeros((len(unique), *parts[0][1].shape[1:]), np.int64)
    start = 0
    for _, d in parts:                  # a part's keys are unique: a plain indexed add is exact
        rows = inverse[start:start + len(d)]
        if len(np.unique(rows)) != len(rows):
            raise ConfigError("a map to merge lists a brick twice")
        total[rows] += d
        start += len(d)
    mask = (1 << 21) - 1
    out_keys = np.stack([unique & mask, (unique >> 21) & mask, unique >> 42], axis=1).astype(np.int32)
    out = np.clip(total, -GRID_LIMIT, GRID_LIMIT)
    if channels:
        out[:, 1:] = np.maximum(out[:, 1:], 0)
    return out_keys, out.astype(np.int32)


def describe(spec):
    """A grid in words: voxel, shape, origin and brick shape (x by y by z)."""
    return (f"{spec.voxel_m:g} m voxels, {' x '.join(map(str, spec.shape))} from {list(spec.origin_m)} m, "
            f"{BRICK} x {BRICK} x {spec.brick_z} bricks")


class _Input:
    """One input store as the coordinator knows it: its grid, its index (checked) and the part of
    its manifest a worker needs to check the chunks it reads."""

    def __init__(self, path):
        self.path = Path(path)
        if not store.recognises(self.path):
            raise ConfigError(f"{path} is not a map store; the merge reads map stores "
                              "(radarcl convert writes one from an .npz)")
        manifest = store.read_manifest(self.path)
        if not manifest["sealed"]:
            raise FrameFormatError(f"{path}/{store.MANIFEST} does not match its checksum: edited or damaged; "
                                   "the merge refuses it")
        self.kinds = store.kinds_of(manifest)
        self.reading = manifest.get("reading") if len(self.kinds) > 1 else None
        zarr, _ = store.zarr_modules()
        self.spec = manifest["spec"]
        self.index = _read_index(_Arrays(zarr, self.path), self.path, manifest)
        lost = _Lost(self.index[:, :3])
        _check_index(self.index, self.spec, manifest, lost)
        if lost.mask.any():
            raise FrameFormatError(f"{path}: a damaged map store: {lost.summary(len(self.index))}; the merge refuses it")
        self.manifest = dict(spec=self.spec, format_version=manifest["format_version"],
                             checksums=manifest.get("checksums"), kinds=list(self.kinds))
        ids = key_ids(self.index[:, :3])
        self.order = np.argsort(ids, kind="stable")
        self.sorted_ids = ids[self.order]

    def rows(self, lo, hi):
        """The index rows of the bricks with key ids in [lo, hi), in stored order."""
        a, b = np.searchsorted(self.sorted_ids, [lo, hi])
        return self.index[np.sort(self.order[a:b])]


def open_inputs(paths):
    """Every input's manifest and index, checked, before any work; a map on another lattice
    (origin, voxel, shape or brick shape) is refused naming both."""
    if not paths:
        raise ConfigError("no maps to merge")
    if len(set(map(str, paths))) != len(paths):
        raise ConfigError("a map appears twice among the inputs; each is merged once")
    inputs = []
    for p in paths:
        one = _Input(p)
        if inputs and one.spec != inputs[0].spec:
            raise ConfigError(f"{p} holds a map on another lattice than {inputs[0].path}: {describe(one.spec)}, "
                              f"against {describe(inputs[0].spec)}; maps merge only on one lattice")
        if inputs and one.reading != inputs[0].reading:
            said = {i: "no knowledge channel (eq. 12)" if i.reading is None else f"the reading {i.reading}"
                    for i in (one, inputs[0])}
            raise ConfigError(f"{p} holds a map with {said[one]}, {inputs[0].path} one with {said[inputs[0]]}; maps "
                              "merge only with one sensor model and one reading (a map written before radarcl kept "
                              "known_looks reads with it 0: fuse it again)")
        inputs.append(one)
    return inputs


def plan(inputs, partitions):
    """The merged keys (sorted ids) and the partitions: [(first row, key ids of its bricks)],
    each a whole number of ``CHUNK_BRICKS`` chunks but the last."""
    ids = np.unique(np.concatenate([i.sorted_ids for i in inputs]))
    chunks = -(-len(ids) // CHUNK_BRICKS)
    edges = np.unique(np.linspace(0, chunks, max(1, min(partitions, chunks)) + 1).round().astype(np.int64))
    rows = np.minimum(edges * CHUNK_BRICKS, len(ids))
    return ids, [(int(r0), ids[r0:r1]) for r0, r1 in zip(rows[:-1], rows[1:]) if r1 > r0]


def merge_partition(pieces, expect, target, row0):
    """On a worker: read one partition's bricks from every input (``pieces``: [(path, the
    manifest's checks, index rows)]), sum them (``merge``), check they are the planned keys
    ``expect``; write them at rows ``row0``... of ``target``'s segment_0 (and its knowledge_0
    and looks_0; returns (worker, {kind: the chunks' CRC-32})), or return (worker, keys, data)
    when ``target`` is None."""
    zarr, _ = store.zarr_modules()
    parts = []
    for path, manifest, index in pieces:
        kinds = manifest["kinds"]
        data = np.zeros((len(index), len(kinds), *manifest["spec"].brick_data_shape), np.int32)
        lost = _Lost(index[:, :3])
        group = _Arrays(zarr, Path(path))
        for c, kind in enumerate(kinds):
            filled, channel = np.zeros(len(index), bool), np.zeros(data.shape[:1] + data.shape[2:], np.int32)
            for segment in np.unique(index[:, 3]).tolist():
                _read_segment(group, path, manifest, segment, index, channel, filled, lost, kind)
            lost.add(~filled & ~lost.mask, f"no stored {kind} data")
            data[:, c] = channel
        if lost.mask.any():
            raise FrameFormatError(f"{path}: a damaged map store: {lost.summary(len(index))}; the merge stops")
        parts.append((index[:, :3], data if len(kinds) > 1 else data[:, 0]))
    keys, data = merge(parts, channels=len(pieces[0][1]["kinds"]) > 1)
    if not np.array_equal(key_ids(keys), expect):
        raise FrameFormatError(f"the inputs changed while they were merged ({', '.join(p for p, _, _ in pieces)}); "
                               "merge them again")
    worker = _worker_name()
    if target is None:
        return worker, keys, data
    return worker, write_rows(target, row0, data)


def write_rows(target, row0, data):
    """Write ``data`` at rows ``row0``... of segment_0 of the store being written at ``target``
    (with the knowledge channel, data (n, 3, *brick): its three kinds' arrays); returns the
    chunks' CRC-32 per kind."""
    zarr, _ = store.zarr_modules()
    parts = [data] if data.ndim == 4 else [data[:, c] for c in range(data.shape[1])]
    crcs = {}
    for kind, values in zip(store.KINDS, parts):
        zarr.open_array(str(Path(target) / f"{kind}_0"), mode="r+")[row0:row0 + len(values)] = values
        crcs[kind] = store.chunk_crcs(values)
    return crcs


def _worker_name():
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"


def merge_stores(client, paths, out, sensor_toml="", config=None, provenance=(), partitions=None):
    """Merge the map stores ``paths`` into ``out`` (a map store, or an ``.npz`` file) on the Dask
    ``client``'s workers, partitioned by brick key (see the module docstring); the manifest keeps
    ``sensor_toml``, ``config`` and the paths and SHA-256 of ``provenance`` (fuse-many's
    recordings; none by default: hashing the inputs would be a pass over all their bytes in the
    coordinator alone). Every input is checked before any work. Returns dict(bricks, partitions,
    workers used, seconds)."""
    start = time.perf_counter()
    inputs = open_inputs(paths)
    spec, kinds, reading = inputs[0].spec, inputs[0].kinds, inputs[0].reading
    workers = sorted(client.nthreads())
    ids, parts = plan(inputs, partitions or PARTITIONS_PER_WORKER * max(1, len(workers)))
    meta = store.manifest_meta(sensor_toml, config, provenance)
    npz_out = output_format(out) == "npz"
    with files.atomic(out) as tmp:
        if not npz_out:
            zarr, codec = store.zarr_modules()
            group = zarr.open_group(str(tmp), mode="a")
            group.attrs["radarcl"] = store.FORMAT
            if len(ids):
                for kind in kinds:
                    store.create_segment(group, 0, (len(ids), *spec.brick_data_shape), codec, kind)
        futures = [client.submit(merge_partition, [(str(i.path), i.manifest, i.rows(expect[0], expect[-1] + 1))
                                                   for i in inputs], expect, None if npz_out else str(tmp), row0,
                                 pure=False, workers=[workers[p % len(workers)]], allow_other_workers=True)
                   for p, (row0, expect) in enumerate(parts)]
        results = _gather(client, futures, out)
        if npz_out:
            keys = np.concatenate([r[1] for r in results]) if results else np.zeros((0, 3), np.int32)
            data = np.concatenate([r[2] for r in results]) if results else np.zeros((0, *spec.brick_data_shape), np.int32)
            kept = {k: v for k, v in dict(sensor=sensor_toml or None, config=config or None).items() if v}
            if reading is None:
                npz.write(tmp, spec, keys, data, meta=kept or None)
            else:
                data = data if len(data) else np.zeros((0, 3, *spec.brick_data_shape), np.int32)
                npz.write(tmp, spec, keys, data[:, 0], meta=kept or None,
                          channels=npz.Channels(data[:, 1], data[:, 2], reading))
        else:
            index = np.zeros((len(ids), 5), np.int32)
            mask = (1 << 21) - 1
            index[:, 0], index[:, 1], index[:, 2] = ids & mask, (ids >> 21) & mask, ids >> 42
            index[:, 4] = np.arange(len(ids))
            store.write_index(group, "index_1", index, codec)
            crcs = {(kind, 0): [c for r in results for c in r[1][kind]] for kind in kinds} if len(ids) else {}
            store.write_manifest(tmp, spec, 1, "index_1", index, {0: len(ids)} if len(ids) else {}, crcs, [], meta,
                                 reading)
    return dict(bricks=len(ids), partitions=len(parts), workers_used=sorted({r[0] for r in results}),
                seconds=time.perf_counter() - start)


def _gather(client, futures, out):
    """The workers' results; a worker's failure as one sentence (its own, when it is radarcl's)."""
    try:
        return client.gather(futures)
    except RadarclError:
        raise
    except Exception as exc:            # a worker died, a disk filled: whatever it raised, said once
        raise ConfigError(f"the merge failed on a worker ({type(exc).__name__}: {exc}); nothing was written "
                          f"to {out}") from None
    finally:
        with contextlib.suppress(Exception):
            client.cancel(futures)
