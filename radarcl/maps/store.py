"""The map store: a chunked, versioned directory of zarr v3 arrays, saved incrementally and
atomically for readers.

Why zarr: it saved the paper's 0.1 m map fastest of the formats tried, and rewrote changed
bricks fastest (``radarcl bench store``; docs/guide/maps.md has the figures). Beyond speed, a directory of
immutable chunk files makes a save atomic for readers without locks, where an HDF5 file
modified in place is torn by a killed writer.

Layout of ``map.rcmap/`` (any directory name):
  zarr.json               the zarr group, its attribute "radarcl" marking it as a store
  segment_<k>/            (n, *brick) int32 bricks written by one save (brick (8, 8, 8), or (1, 8, 8)
                          for a planar grid: format 3); never modified again
  index_<v>/              (n_bricks, 5) int32: bx, by, bz, segment, row of every brick in version v
  knowledge_<k>/          only in a map of the detection-statistics model (store format 3): the
  looks_<k>/              knowledge and looks bricks of segment k, row for row (``maps.npz`` says
                          what they are), checksummed like the segments; its manifest adds
                          "reading" (``sensor_model.READING``: how the sums are read)
  manifest.json           written last (temporary file + rename): the version, its index, its
                          segments, the grid spec, a CRC-32 of the index and of each chunk of
                          ``CHUNK_BRICKS`` bricks of every segment (format 2), the sensor profile,
                          poses and configuration that made the map, and its provenance (radarcl
                          version, inputs and their SHA-256)

A save writes the changed bricks as a new segment, a new index, then the manifest; a reader
reads the manifest first and only what it names, so it sees the previous version or the new one,
never a mix. A killed writer leaves unnamed segments and indexes: readers ignore them (and say
so), the next save removes them. When more than ``COMPACT_SEGMENTS`` segments accumulate or half
the stored bricks are dead, a save writes everything into one new segment.

Nothing is believed on trust (``read``): every entry of the manifest, the index and each chunk
are checked before a byte reaches the map, so a deleted, zeroed, swapped or damaged chunk, a
key repeated or outside the grid, a segment of another dtype or a manifest that lies are refused
with what is wrong, or, asked to ``salvage``, left out and listed brick by brick. Only a
directory radarcl marked is a store (``recognises``): ``--force`` never replaces another
program's zarr group. Format 1 (no checksums) is still read, with every structural check.
"""

import hashlib
import json
import logging
import os
import re
import shutil
import time
import zlib
from pathlib import Path

import numpy as np

from radarcl import __version__
from radarcl.errors import ConfigError, FrameFormatError, RadarclError
from radarcl.gridspec import BRICK, GridSpec
from radarcl.maps.npz import check_reading, check_trajectory
from radarcl.maps.store_verify import _SUMS, CHUNK_BRICKS, _Arrays, _check_index, _Lost, _read_index, _read_segment

log = logging.getLogger(__name__)
FORMAT = "radarcl-map-store"
FORMAT_VERSION = 3          # 2: a CRC-32 per chunk of every segment and of the index; 1 is still read
PLAIN_FORMAT = 2            # what a cubic map without knowledge is written as (an older radarcl reads it)
KNOWLEDGE_FORMAT = 3        # may hold knowledge_<k> and looks_<k> arrays, then with a "reading"
PLANAR_FORMAT = 3           # the grid may name its brick depth (planar bricks)
KINDS = ("segment", "knowledge", "looks")
COMPACT_SEGMENTS = 32
MANIFEST = "manifest.json"
_NAME = re.compile(r"^index_[0-9]{1,9}$")


def recognises(path):
    """True when ``path`` is a map store directory: one that radarcl's own manifest, or the mark
    radarcl puts on the zarr group it creates (before the first save lands), says is a store.
    A zarr group another program wrote is not one, so ``--force`` never removes it."""
    path = Path(path)
    if not path.is_dir():
        return False
    for name, check in ((MANIFEST, lambda d: d.get("format")),
                        ("zarr.json", lambda d: d.get("attributes", {}).get("radarcl"))):
        try:
            found = json.loads((path / name).read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            continue
        if isinstance(found, dict) and isinstance(found.get("attributes", {}), dict) and check(found) == FORMAT:
            return True
    return False


def zarr_modules():
    """(zarr, its ZstdCodec), or ConfigError naming what to install."""
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


def chunk_crcs(data):
    """CRC-32 of each ``CHUNK_BRICKS`` bricks of ``data`` (n, 8, 8, 8) int32, as stored (little-endian)."""
    data = np.ascontiguousarray(data, "<i4")
    return [zlib.crc32(data[i:i + CHUNK_BRICKS]) for i in range(0, len(data), CHUNK_BRICKS)]


def read_manifest(path):
    """The store's manifest (a dict), checked (``check_manifest``); FrameFormatError says what is wrong."""
    path = Path(path)
    try:
        manifest = json.loads((path / MANIFEST).read_text())
    except FileNotFoundError:
        raise FrameFormatError(f"{path} has no complete save yet (no {MANIFEST})") from None
    except (OSError, ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise FrameFormatError(f"{path}/{MANIFEST} is not readable ({exc})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise FrameFormatError(f"{path} is not a radarcl map store")
    version = manifest.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise FrameFormatError(f"{path}: its manifest names no store format (format_version {version!r})")
    if version > FORMAT_VERSION:
        raise FrameFormatError(f"{path} was written in store format {version}; this radarcl reads formats 1 to "
                               f"{FORMAT_VERSION}: update radarcl")
    manifest["sealed"] = version < 2 or manifest.get("crc32") == seal(manifest)
    check_manifest(path, manifest)
    if version >= KNOWLEDGE_FORMAT and "reading" in manifest:
        manifest["reading"] = check_reading(manifest["reading"], path)
    return manifest


UNSEALED = "the manifest does not match its checksum: its grid and array names were believed as they read"


def seal(manifest):
    """The CRC-32 of a manifest's entries (all but ``crc32`` itself and what a reader adds),
    kept in format 2 so that an edited or damaged manifest (a grid moved, a segment dropped) is
    found, not believed."""
    kept = {k: v for k, v in manifest.items() if k not in ("crc32", "sealed", "spec", "incomplete", "lost")}
    return zlib.crc32(json.dumps(kept, sort_keys=True, separators=(",", ":")).encode())


def check_manifest(path, m):
    """FrameFormatError unless every entry a reader relies on has its type and range."""
    def bad(what):
        raise FrameFormatError(f"{path}/{MANIFEST}: {what}; the store is damaged")

    if not isinstance(m.get("version"), int) or isinstance(m["version"], bool) or m["version"] < 1:
        bad(f"version {m.get('version')!r} is not a save number")
    if not isinstance(m.get("index"), str) or not _NAME.match(m["index"]):
        bad(f"index {m.get('index')!r} is not the name of an index array (index_<n>)")
    segments = m.get("segments")
    if not isinstance(segments, list) or not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 1 << 30
                                                 for s in segments) or len(set(segments)) != len(segments):
        bad(f"segments {str(segments)[:80]} is not a list of distinct segment numbers")
    grid = m.get("grid")
    try:
        m["spec"] = GridSpec(tuple(grid["origin_m"]), grid["voxel_m"], tuple(grid["shape"]),
                             grid.get("brick_z", 8) if m["format_version"] >= PLANAR_FORMAT else 8)
    except (TypeError, KeyError, ValueError, RadarclError) as exc:
        bad(f"grid {str(grid)[:120]} does not describe a grid ({exc})")
    if not isinstance(m.get("bricks"), int) or isinstance(m["bricks"], bool) or m["bricks"] < 0:
        bad(f"bricks {m.get('bricks')!r} is not a count")
    if m["format_version"] >= 2:
        crcs = m.get("checksums")
        if not isinstance(crcs, dict) or not isinstance(crcs.get("index"), int) or not isinstance(crcs.get("segments"), dict):
            bad("it has no checksums (format 2 keeps a CRC-32 of the index and of every chunk)")
        for kind in kinds_of(m):
            entries = crcs.get(_SUMS[kind])
            for s in segments:
                entry = entries.get(str(s)) if isinstance(entries, dict) else None
                if not (isinstance(entry, dict) and isinstance(entry.get("rows"), int) and entry["rows"] >= 1
                        and isinstance(entry.get("crc32"), list)
                        and len(entry["crc32"]) == -(-entry["rows"] // CHUNK_BRICKS)
                        and all(isinstance(c, int) for c in entry["crc32"])):
                    bad(f"{kind} {s} has no checksum entry")


def kinds_of(manifest):
    """The arrays each segment of the store has: ``segment`` (the sums), and ``knowledge`` and
    ``looks`` in a map of the detection-statistics model (format 3)."""
    return KINDS if manifest["format_version"] >= KNOWLEDGE_FORMAT and "reading" in manifest else KINDS[:1]


def _check_channels(path, manifest, kinds):
    """FrameFormatError naming both when the manifest gives no reading (a map of sums) while the
    store lists or holds knowledge channels for its segments: a store edited or damaged so, read
    as its manifest says, would show unread sums as log-odds."""
    if "knowledge" in kinds:
        return
    sums = manifest.get("checksums")
    listed = sorted(_SUMS[k] for k in KINDS[1:] if isinstance(sums, dict) and _SUMS[k] in sums)
    held = sorted(f"{k}_{s}" for k in KINDS[1:] for s in manifest["segments"] if (Path(path) / f"{k}_{s}").exists())
    if listed or held:
        raise FrameFormatError(f"{path}: its manifest (store format {manifest['format_version']}) gives no reading, "
                               f"yet the store {'lists checksums of ' + ', '.join(listed) if listed else 'holds '}"
                               f"{' and holds ' if listed and held else ''}{', '.join(held)}: a map of the "
                               "knowledge channel that lost its reading; refused rather than read as plain sums")
    if manifest["format_version"] >= KNOWLEDGE_FORMAT and manifest["spec"].brick_z == BRICK:
        raise FrameFormatError(f"{path}: store format {manifest['format_version']} is written for planar bricks or "
                               "the knowledge channel, but this store is cubic and its manifest gives no reading; "
                               "refused rather than read as plain sums")


def read(path, salvage=False):
    """(spec, keys (n, 3) int32, data (n, *brick) int32, manifest) of the last complete save
    (a map of the detection-statistics model: ``manifest["knowledge"]`` and ``["looks"]`` its
    bricks of those channels, else None),
    verified before any byte reaches the map: the manifest's entries, the index (dtype, shape,
    CRC-32, keys unique and inside the grid, each naming a listed segment and a row it holds),
    every listed segment (present, int32 bricks, each chunk's CRC-32, values within the grid's
    saturation). A damaged store raises ``FrameFormatError`` saying what is wrong; with
    ``salvage`` the damaged bricks are left out instead and ``manifest["lost"]`` lists them
    (reason and keys). ``manifest["incomplete"]`` names anything a killed writer left (ignored)."""
    zarr, _ = zarr_modules()
    path = Path(path)
    manifest = read_manifest(path)
    if not manifest["sealed"]:
        if not salvage:
            raise FrameFormatError(f"{path}/{MANIFEST} does not match its checksum: edited or damaged, it may name "
                                   "another grid or other bricks; radarcl refuses it (--salvage reads it as it says, "
                                   "every brick still checked)")
        log.warning("%s/%s does not match its checksum; read as it says (--salvage)", path, MANIFEST)
    spec = manifest["spec"]
    group = _Arrays(zarr, path)                     # each array by its own path: the group's metadata is not needed
    index = _read_index(group, path, manifest)
    lost = _Lost(index[:, :3])
    _check_index(index, spec, manifest, lost)
    kinds = kinds_of(manifest)
    _check_channels(path, manifest, kinds)
    planes = {kind: np.zeros((len(index), *spec.brick_data_shape), np.int32) for kind in kinds}  # never uninitialised
    for kind in kinds:
        filled = np.zeros(len(index), bool)
        for segment in manifest["segments"]:
            _read_segment(group, path, manifest, segment, index, planes[kind], filled, lost, kind)
        lost.add(~filled & ~lost.mask, f"no stored {'data' if kind == 'segment' else kind}")
    if lost.mask.any() and not salvage:
        raise FrameFormatError(f"{path}: a damaged map store: {lost.summary(len(index))}; radarcl refuses it "
                               "(--salvage reads the rest and lists the lost bricks)")
    keep = ~lost.mask
    previous = manifest.get("previous")                 # only guides the next writer's clean-up
    named = {manifest["index"]} | {f"{kind}_{s}" for s in manifest["segments"] for kind in kinds} | \
        {p for p in (previous if isinstance(previous, list) else []) if isinstance(p, str)}
    stray = sorted(p.name for p in path.iterdir() if p.is_dir() and p.name not in named
                   and p.name.startswith(("segment_", "index_", "knowledge_", "looks_")))
    unsealed = [] if manifest["sealed"] else [dict(reason=UNSEALED, keys=[])]
    manifest["incomplete"], manifest["lost"] = stray, unsealed + lost.entries
    manifest["knowledge"], manifest["looks"] = ((planes["knowledge"][keep], planes["looks"][keep])
                                                if "knowledge" in planes else (None, None))
    return spec, np.ascontiguousarray(index[keep, :3], dtype=np.int32), planes["segment"][keep], manifest


class StoreWriter:
    """Saves of one map into a store, each writing only the bricks that changed since the last.

    path: the store directory (created; an existing store is continued, anything else refused by
    the caller's ``maps.disk.check_output``); spec: the grid's ``GridSpec``; sensor_toml, config: what
    made the map (kept in the manifest); inputs: paths whose SHA-256 goes into the provenance.
    """

    def __init__(self, path, spec, sensor_toml="", config=None, inputs=(), overwrite=False, poses=None, reading=None):
        zarr, self._codec = zarr_modules()
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
        if self.group.attrs.get("radarcl") != FORMAT:
            self.group.attrs["radarcl"] = FORMAT          # marks the directory ours before any save lands
        self.meta = manifest_meta(sensor_toml, config, inputs, poses)
        self.version, self.segments, self.keys, self.data = 0, [], None, None
        self.reading = reading                              # a map with the knowledge channel: its reading
        self.kinds = KINDS if reading is not None else KINDS[:1]
        self.index = np.zeros((0, 5), np.int32)
        self.segment_rows = {}                              # segment -> bricks stored in it
        self.crcs = {}                                      # (kind, segment) -> CRC-32 of each of its chunks
        self._legacy = False
        if (self.path / MANIFEST).is_file():                # continue an existing store (verified)
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
            if manifest["format_version"] >= 2:
                self.crcs = {(kind, s): manifest["checksums"][_SUMS[kind]][str(s)]["crc32"]
                             for s in self.segments for kind in self.kinds}
            else:
                self._legacy = True                         # no checksums: the next save rewrites it whole
            if poses is None:
                self.meta["poses"] = manifest.get("poses", [])

    @property
    def dead(self):
        """Stored bricks no longer in the map (superseded by later saves)."""
        return sum(self.segment_rows[s] for s in self.segments) - len(self.index)

    def save(self, keys, data, poses=None, knowledge=None, looks=None):
        """Write the bricks (keys (n, 3), data (n, *brick) int32, and their ``knowledge`` and
        ``looks`` bricks for a writer made with a ``reading``) that differ from the last save, and
        the sensor ``poses`` (n, 4, 4) so far when given; returns the number of bricks written.
        Atomic for readers."""
        if (knowledge is None) != (self.reading is None):
            raise ConfigError("a store made with a reading saves knowledge bricks with its data, and only it")
        if poses is not None:
            self.meta["poses"] = check_trajectory(poses).reshape(-1, 16).tolist()
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
        compact = (self._legacy or len(self.segments) + 1 > COMPACT_SEGMENTS
                   or self.dead + len(changed) > len(keys))
        rows = np.arange(len(keys)) if compact else changed
        segment = (max(self.segments) + 1) if self.segments else 0
        if len(rows):
            self.segment_rows[segment] = len(rows)
            parts = (data,) if knowledge is None else (data[:, 0], data[:, 1], data[:, 2])
            for kind, values in zip(self.kinds, parts):
                self.crcs[kind, segment] = write_segment(self.group, segment, values[rows], self._codec, kind)
        index = self._next_index(keys, rows, segment, compact)
        version = self.version + 1
        name = f"index_{version}"
        write_index(self.group, name, index, self._codec)
        segments = sorted(set(index[:, 3].tolist()))
        previous = sorted(({f"index_{self.version}"} if self.version else set()) |
                          {f"{kind}_{s}" for s in self.segments for kind in self.kinds})
        write_manifest(self.path, self.spec, version, name, index, self.segment_rows, self.crcs, previous, self.meta,
                       self.reading if knowledge is not None else None)
        self.version, self.index, self.keys, self.data = version, index, keys.copy(), data.copy()
        self.segments, self._legacy = segments, False
        self.segment_rows = {s: self.segment_rows[s] for s in segments}
        self.crcs = {(kind, s): self.crcs[kind, s] for s in segments for kind in self.kinds}
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
        named = {f"index_{self.version}"} | {f"{kind}_{s}" for s in self.segments for kind in KINDS} | set(keep)
        for p in self.path.iterdir():
            if p.is_dir() and p.name.startswith(("segment_", "index_", "knowledge_", "looks_")) and p.name not in named:
                shutil.rmtree(p, ignore_errors=True)
        for p in self.path.glob(f".{MANIFEST}.*.tmp"):
            p.unlink(missing_ok=True)


def manifest_meta(sensor_toml="", config=None, inputs=(), poses=None):
    """What a store's manifest keeps beside its bricks: the sensor profile, configuration and
    poses that made the map, and its provenance (radarcl version, inputs and their SHA-256)."""
    return dict(sensor=sensor_toml, config=config or {},
                poses=[] if poses is None else check_trajectory(poses).reshape(-1, 16).tolist(),
                provenance=dict(radarcl=__version__, created=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                                inputs=[dict(path=str(p), sha256=file_digest(p)) for p in inputs]))


def create_segment(group, segment, shape, codec, kind="segment"):
    """Create array ``<kind>_<segment>`` of ``shape`` (n, *brick) int32 in the zarr ``group``
    (zstd-1, ``CHUNK_BRICKS`` bricks per chunk: each chunk its own file, so writers of distinct
    chunks, e.g. the workers of ``radarcl.jobs.merge_maps``, never touch one file)."""
    return group.create_array(f"{kind}_{segment}", shape=tuple(shape), dtype="int32",
                              chunks=(CHUNK_BRICKS, *shape[1:]), compressors=codec(level=1))


def write_segment(group, segment, data, codec, kind="segment"):
    """Write ``data`` (n, *brick) int32 as array ``<kind>_<segment>`` of the zarr ``group``
    (``create_segment``); returns the CRC-32 of each chunk."""
    create_segment(group, segment, data.shape, codec, kind)[:] = data
    return chunk_crcs(data)


def write_index(group, name, index, codec):
    """Write the index ``index`` (n, 5) int32 (bx, by, bz, segment, row) as array ``name``."""
    arr = group.create_array(name, shape=index.shape, dtype="int32", chunks=(max(1, min(len(index), 1 << 16)), 5),
                             compressors=codec(level=1))
    if len(index):
        arr[:] = index


def write_manifest(path, spec, version, index_name, index, segment_rows, crcs, previous, meta, reading=None):
    """Write the manifest of save ``version`` (its index array ``index_name`` holding ``index``,
    the segments it names with their rows and chunk CRCs, ``crcs[kind, segment]``) through a
    temporary file renamed into place: the save happens at the rename. Format 2, or 3 for planar
    bricks or a map with the knowledge channel (``reading`` given; an older reader then refuses
    the store naming both formats)."""
    segments = sorted(set(index[:, 3].tolist()))
    grid = dict(origin_m=list(spec.origin_m), voxel_m=spec.voxel_m, shape=list(spec.shape))
    if spec.brick_z != BRICK:
        grid["brick_z"] = spec.brick_z
    kinds = KINDS if reading is not None else KINDS[:1]
    sums = {_SUMS[kind]: {str(s): dict(rows=segment_rows[s], crc32=crcs[kind, s]) for s in segments} for kind in kinds}
    extra = {} if reading is None else dict(reading=check_reading(dict(reading), path))
    newer = spec.brick_z != BRICK or reading is not None
    manifest = dict(format=FORMAT, format_version=FORMAT_VERSION if newer else PLAIN_FORMAT, version=version,
                    index=index_name, segments=segments, previous=previous, **extra, grid=grid, bricks=len(index),
                    saved=time.strftime("%Y-%m-%dT%H:%M:%S"),
                    checksums=dict(index=zlib.crc32(np.ascontiguousarray(index, "<i4")), **sums), **meta)
    manifest["crc32"] = seal(manifest)
    tmp = Path(path) / f".{MANIFEST}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(manifest, indent=1))
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.replace(tmp, Path(path) / MANIFEST)


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


def read_poses(path):
    """The sensor poses (n, 4, 4) the store's manifest keeps, or None."""
    poses = read_manifest(path).get("poses")
    return None if not poses else check_trajectory(np.asarray(poses, float).reshape(-1, 4, 4))


def read_meta(path, key):
    """The ``key`` entry of the store's manifest (what its saver kept), or None."""
    return read_manifest(path).get(key)
