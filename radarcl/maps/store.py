"""The map store: a chunked, versioned directory of zarr v3 arrays, saved incrementally and
atomically for readers.

Why zarr: it saved the paper's 0.1 m map fastest of the formats tried, and rewrote changed
bricks fastest (``radarcl bench store``; the README's figures). Beyond speed, a directory of
immutable chunk files makes a save atomic for readers without locks, where an HDF5 file
modified in place is torn by a killed writer.

Layout of ``map.rcmap/`` (any directory name):
  zarr.json               the zarr group
  segment_<k>/            (n, 8, 8, 8) int32 bricks written by one save; never modified again
  index_<v>/              (n_bricks, 5) int32: bx, by, bz, segment, row of every brick in version v
  manifest.json           written last (temporary file + rename): the version, its index, its
                          segments, the grid spec, the sensor profile and configuration that made
                          the map, and its provenance (radarcl version, inputs and their SHA-256)
  knowledge_<k>/          only in a map of the detection-statistics model (store format 2): the
  looks_<k>/              knowledge and looks bricks of segment k, row for row (``maps.npz`` says
                          what they are); its manifest adds "reading" (``sensor_model.READING``:
                          how the sums are read). Without them a store is format 1, as before.

A save writes the changed bricks as a new segment, a new index, then the manifest; a reader
reads the manifest first and only what it names, so it sees the previous version or the new one,
never a mix. A killed writer leaves unnamed segments and indexes: readers ignore them (and say
so), the next save removes them. When more than ``COMPACT_SEGMENTS`` segments accumulate or half
the stored bricks are dead, a save writes everything into one new segment.
"""

import hashlib
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from radarcl import __version__
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.grid import BRICK, GridSpec
from radarcl.maps.npz import check_reading, check_trajectory

FORMAT = "radarcl-map-store"
FORMAT_VERSION = 1
KNOWLEDGE_FORMAT = 2        # a store with knowledge_<k> and looks_<k> arrays and a reading
KINDS = ("segment", "knowledge", "looks")
CHUNK_BRICKS = 256
COMPACT_SEGMENTS = 32
MANIFEST = "manifest.json"


def recognises(path):
    """True when ``path`` is a map store directory."""
    return Path(path, MANIFEST).is_file() or (Path(path).is_dir() and Path(path, "zarr.json").is_file())


def _zarr():
    try:
        import zarr
        from zarr.codecs import ZstdCodec
    except ImportError as exc:
        raise ConfigError(f"the map store needs zarr >= 3 (pip install 'zarr>=3'): {exc}") from None
    return zarr, ZstdCodec


def file_digest(path, limit=1 << 30):
    """SHA-256 of a file (or of a directory's files, sorted by name); None beyond ``limit`` bytes."""
    path = Path(path)
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    if sum(p.stat().st_size for p in files) > limit:
        return None
    h = hashlib.sha256()
    for p in files:
        h.update(p.name.encode())
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def read_manifest(path):
    """The store's manifest (a dict), checked; FrameFormatError says what is wrong."""
    path = Path(path)
    try:
        manifest = json.loads((path / MANIFEST).read_text())
    except FileNotFoundError:
        raise FrameFormatError(f"{path} has no complete save yet (no {MANIFEST})") from None
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise FrameFormatError(f"{path}/{MANIFEST} is not readable ({exc})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise FrameFormatError(f"{path} is not a radarcl map store")
    version = manifest.get("format_version")
    if not isinstance(version, int) or version > KNOWLEDGE_FORMAT:
        raise FrameFormatError(f"{path} was written in store format {version!r}; this radarcl reads format "
                               f"{KNOWLEDGE_FORMAT} and older: update radarcl")
    if version == KNOWLEDGE_FORMAT:
        manifest["reading"] = check_reading(manifest.get("reading"), path)
    return manifest


def read(path):
    """(spec, keys (n, 3) int32, data (n, 8, 8, 8) int32, manifest) of the last complete save.
    ``manifest["incomplete"]`` names anything a killed writer left (ignored here)."""
    zarr, _ = _zarr()
    path = Path(path)
    manifest = read_manifest(path)
    try:
        g = zarr.open_group(str(path), mode="r")
        spec = GridSpec(tuple(manifest["grid"]["origin_m"]), float(manifest["grid"]["voxel_m"]),
                        tuple(int(n) for n in manifest["grid"]["shape"]))
        index = g[manifest["index"]][:]
        if index.ndim != 2 or index.shape[1] != 5:
            raise FrameFormatError(f"{path}: index {manifest['index']} has shape {index.shape}, expected (n, 5)")
        data = np.empty((len(index), BRICK, BRICK, BRICK), np.int32)
        has_knowledge = manifest["format_version"] == KNOWLEDGE_FORMAT
        knowledge = np.empty_like(data) if has_knowledge else None
        looks = np.empty_like(data) if has_knowledge else None
        for segment in manifest["segments"]:
            rows = index[:, 3] == segment
            if rows.any():
                for name, out in (("segment", data), ("knowledge", knowledge), ("looks", looks)):
                    if out is None:
                        continue
                    stored = g[f"{name}_{segment}"]
                    if stored.shape[1:] != (BRICK, BRICK, BRICK) or index[rows, 4].max() >= stored.shape[0]:
                        raise FrameFormatError(f"{path}: {name} {segment} does not hold the rows its index names")
                    out[rows] = stored[:][index[rows, 4]]
    except FrameFormatError:
        raise
    except Exception as exc:                        # zarr raises its own types for damaged stores
        raise FrameFormatError(f"{path}: a damaged map store ({type(exc).__name__}: {exc})") from exc
    named = ({manifest["index"]} | {f"{kind}_{s}" for s in manifest["segments"] for kind in KINDS}
             | set(manifest.get("previous", [])))
    stray = sorted(p.name for p in path.iterdir() if p.is_dir() and p.name not in named
                   and p.name.startswith(("segment_", "index_", "knowledge_", "looks_")))
    manifest["incomplete"] = stray
    manifest["knowledge"], manifest["looks"] = knowledge, looks
    return spec, np.ascontiguousarray(index[:, :3], dtype=np.int32), data, manifest


class StoreWriter:
    """Saves of one map into a store, each writing only the bricks that changed since the last.

    path: the store directory (created; an existing store is continued, anything else refused by
    the caller's ``maps.disk.check_output``); spec: the grid's ``GridSpec``; sensor_toml, config: what
    made the map (kept in the manifest); inputs: paths whose SHA-256 goes into the provenance.
    """

    def __init__(self, path, spec, sensor_toml="", config=None, inputs=(), overwrite=False, poses=None, reading=None):
        zarr, self._codec = _zarr()
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise ConfigError(f"{self.path} exists and is not a map store directory")
        if self.path.exists() and any(self.path.iterdir()):
            if not recognises(self.path):
                raise ConfigError(f"{self.path} is a directory that is not a map store; choose another name")
            if overwrite:
                shutil.rmtree(self.path)
        self.spec = spec
        self.group = zarr.open_group(str(self.path), mode="a")
        self.meta = dict(sensor=sensor_toml, config=config or {},
                         poses=[] if poses is None else check_trajectory(poses).reshape(-1, 16).tolist(),
                         provenance=dict(radarcl=_version(), created=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                                         inputs=[dict(path=str(p), sha256=file_digest(p)) for p in inputs]))
        self.version, self.segments, self.keys, self.data = 0, [], None, None
        self.reading = reading                              # a map with the knowledge channel: its reading
        self.index = np.zeros((0, 5), np.int32)
        self.segment_rows = {}                              # segment -> bricks stored in it
        if (self.path / MANIFEST).is_file():                # continue an existing store
            spec0, keys, data, manifest = read(self.path)
            if spec0 != spec:
                raise ConfigError(f"{self.path} holds a map of grid {spec0}, not {spec}; choose another name")
            self.version, self.segments = manifest["version"], list(manifest["segments"])
            self.index = self.group[manifest["index"]][:]
            if (manifest["knowledge"] is None) != (reading is None):
                raise ConfigError(f"{self.path} holds a map {'with' if reading is None else 'without'} the knowledge "
                                  "channel; this map is the other kind: choose another name")
            self.keys = keys
            self.data = data if reading is None else np.stack([data, manifest["knowledge"], manifest["looks"]], 1)
            self.segment_rows = {s: self.group[f"segment_{s}"].shape[0] for s in self.segments}
            if poses is None:
                self.meta["poses"] = manifest.get("poses", [])

    @property
    def dead(self):
        """Stored bricks no longer in the map (superseded by later saves)."""
        return sum(self.segment_rows[s] for s in self.segments) - len(self.index)

    def save(self, keys, data, poses=None, knowledge=None, looks=None):
        """Write the bricks (keys (n, 3), data (n, 8, 8, 8) int32, and their ``knowledge`` and
        ``looks`` bricks for a writer made with a ``reading``) that differ from the last save, and the sensor
        ``poses`` (n, 4, 4) so far when given; returns the number of bricks written. Atomic for
        readers."""
        if poses is not None:
            self.meta["poses"] = check_trajectory(poses).reshape(-1, 16).tolist()
        if (knowledge is None) != (self.reading is None):
            raise ConfigError("a store made with a reading saves knowledge bricks with its data, and only it")
        keys = np.ascontiguousarray(keys, np.int32)
        data = np.ascontiguousarray(data, np.int32)
        if knowledge is not None:                           # compared and kept as one (n, 3, 8, 8, 8) array
            data = np.ascontiguousarray(np.stack([data, np.asarray(knowledge, np.int32), np.asarray(looks, np.int32)],
                                                 axis=1))
        self._clean()
        if self.keys is None:
            changed = np.arange(len(keys))
        else:
            changed = _changed_rows(self.keys, self.data, keys, data)
        compact = len(self.segments) + 1 > COMPACT_SEGMENTS or self.dead + len(changed) > len(keys)
        rows = np.arange(len(keys)) if compact else changed
        segment = (max(self.segments) + 1) if self.segments else 0
        if len(rows):
            self.segment_rows[segment] = len(rows)
            parts = (("segment", data),) if knowledge is None else tuple(zip(KINDS, (data[:, 0], data[:, 1], data[:, 2])))
            for name, values in parts:
                arr = self.group.create_array(f"{name}_{segment}", shape=(len(rows), 8, 8, 8), dtype="int32",
                                              chunks=(CHUNK_BRICKS, 8, 8, 8), compressors=self._codec(level=1))
                arr[:] = values[rows]
        index = self._next_index(keys, rows, segment, compact)
        version = self.version + 1
        name = f"index_{version}"
        arr = self.group.create_array(name, shape=index.shape, dtype="int32", chunks=(max(1, min(len(index), 1 << 16)), 5),
                                      compressors=self._codec(level=1))
        if len(index):
            arr[:] = index
        segments = sorted(set(index[:, 3].tolist()))
        kinds = ("segment",) if knowledge is None else KINDS
        previous = sorted(({f"index_{self.version}"} if self.version else set()) |
                          {f"{kind}_{s}" for s in self.segments for kind in kinds})
        extra = {} if knowledge is None else dict(reading=check_reading(dict(self.reading), self.path))
        manifest = dict(format=FORMAT, format_version=FORMAT_VERSION if knowledge is None else KNOWLEDGE_FORMAT,
                        version=version, index=name, segments=segments, previous=previous, **extra,
                        grid=dict(origin_m=list(self.spec.origin_m), voxel_m=self.spec.voxel_m,
                                  shape=list(self.spec.shape)), bricks=len(keys), saved=time.strftime("%Y-%m-%dT%H:%M:%S"),
                        **self.meta)
        tmp = self.path / f".{MANIFEST}.{os.getpid()}.tmp"
        tmp.write_text(json.dumps(manifest, indent=1))
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, self.path / MANIFEST)             # the save happens here
        self.version, self.index, self.keys, self.data = version, index, keys.copy(), data.copy()
        self.segments = segments
        self.segment_rows = {s: self.segment_rows[s] for s in segments}
        self._clean(keep=set(previous))                  # a reader may still be reading those
        return len(rows)

    def _next_index(self, keys, rows, segment, compact):
        index = np.empty((len(keys), 5), np.int32)
        index[:, :3] = keys
        if compact:
            index[:, 3], index[:, 4] = segment, np.arange(len(keys))
            return index
        index[:, 3:] = -1
        if len(self.index):
            match = _match(self.index[:, :3], keys)
            index[:, 3:] = np.where(match[:, None] >= 0, self.index[np.maximum(match, 0), 3:], -1)
        index[rows, 3], index[rows, 4] = segment, np.arange(len(rows))
        if (index[:, 3] < 0).any():
            raise ConfigError("a brick without stored data: it must be among the changed ones")
        return index

    def _clean(self, keep=()):
        """Remove segments and indexes no manifest names (a killed writer's, or superseded ones
        beyond the previous version, which a reader may still be reading)."""
        named = ({f"index_{self.version}"} | {f"{kind}_{s}" for s in self.segments for kind in KINDS} | set(keep))
        for p in self.path.iterdir():
            if p.is_dir() and p.name.startswith(("segment_", "index_", "knowledge_", "looks_")) and p.name not in named:
                shutil.rmtree(p, ignore_errors=True)
        for p in self.path.glob(f".{MANIFEST}.*.tmp"):
            p.unlink(missing_ok=True)


def _ids(keys):
    k = keys.astype(np.int64)
    return (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]


def _match(old_keys, keys):
    """For each of ``keys``, the row of the same key in ``old_keys``, or -1."""
    n = len(old_keys)
    if not n:
        return np.full(len(keys), -1, np.int64)
    if len(keys) >= n and np.array_equal(old_keys, keys[:n]):    # a grid's keys grow at the end
        return np.concatenate([np.arange(n), np.full(len(keys) - n, -1)])
    return _match_sorted(old_keys, keys)


def _match_sorted(old_keys, keys):
    old_ids, new_ids = _ids(old_keys), _ids(keys)
    order = np.argsort(old_ids)
    pos = np.minimum(np.searchsorted(old_ids[order], new_ids), len(order) - 1)
    hit = old_ids[order][pos] == new_ids
    return np.where(hit, order[pos], -1)


def _changed_rows(old_keys, old_data, keys, data):
    """Rows of (keys, data) that are new or differ from the old snapshot."""
    a = data.reshape(len(data), -1).view(np.int64)              # 256 words per brick, not 512
    b = old_data.reshape(len(old_data), -1).view(np.int64)
    n = len(old_keys)
    if len(keys) >= n and np.array_equal(old_keys, keys[:n]):  # the grid's keys grow at the end
        changed = np.ones(len(keys), bool)
        changed[:n] = (a[:n] != b).any(axis=1)
        return np.flatnonzero(changed)
    match = _match_sorted(old_keys, keys) if n else np.full(len(keys), -1)
    changed = match < 0
    idx = np.flatnonzero(~changed)
    if len(idx):
        changed[idx[(a[idx] != b[match[idx]]).any(axis=1)]] = True
    return np.flatnonzero(changed)


def _version():
    return __version__


def read_poses(path):
    """The sensor poses (n, 4, 4) the store's manifest keeps, or None."""
    poses = read_manifest(path).get("poses")
    return None if not poses else check_trajectory(np.asarray(poses, float).reshape(-1, 4, 4))


def read_meta(path, key):
    """The ``key`` entry of the store's manifest (what its saver kept), or None."""
    return read_manifest(path).get(key)
