"""The map store's verification: every array a manifest names is read chunk by chunk and
checked (dtype, shape, CRC-32, range) before a byte reaches the map; what cannot be read is
listed brick by brick (``_Lost``) for ``--salvage``. Used by ``maps.store.read``."""

import zlib

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.gridspec import GRID_LIMIT

CHUNK_BRICKS = 256          # bricks per zarr chunk (and per CRC-32)
_SUMS = dict(segment="segments", knowledge="knowledge", looks="looks")   # array kind -> its checksums entry


class _Arrays:
    """The store's arrays by name, each opened from its own directory (``group[name]`` would need
    the group's zarr.json, which holds nothing the manifest does not)."""

    def __init__(self, zarr, path):
        self.zarr, self.path = zarr, path

    def __getitem__(self, name):
        return self.zarr.open_array(str(self.path / name), mode="r")


class _Lost:
    """Bricks (rows of the index) a damaged store cannot give, each with the reason."""

    def __init__(self, keys):
        self.keys, self.mask, self.entries = keys, np.zeros(len(keys), bool), []

    def add(self, rows, reason):
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, np.int64)
        rows = rows[~self.mask[rows]]
        if len(rows):
            self.mask[rows] = True
            self.entries.append(dict(reason=reason, keys=self.keys[rows].tolist()))

    def summary(self, n):
        lost = int(self.mask.sum())
        reasons = "; ".join(f"{e['reason']} ({len(e['keys'])} bricks)" for e in self.entries[:4])
        more = f"; and {len(self.entries) - 4} more" if len(self.entries) > 4 else ""
        return f"{lost} of {n} bricks cannot be read: {reasons}{more}"


def _read_index(group, path, manifest):
    name = manifest["index"]
    try:
        stored = group[name]
        ok = stored.dtype == np.int32 and stored.ndim == 2 and stored.shape[1] == 5
        index = stored[:] if ok else None
    except Exception as exc:
        raise FrameFormatError(f"{path}: its index {name} cannot be read ({type(exc).__name__}: {exc}); "
                               "the store is damaged") from exc
    if index is None:
        raise FrameFormatError(f"{path}: its index {name} holds {stored.shape} {stored.dtype}, expected (n, 5) int32")
    if len(index) != manifest["bricks"]:
        raise FrameFormatError(f"{path}: its index {name} lists {len(index)} bricks, the manifest {manifest['bricks']}")
    if manifest["format_version"] >= 2 and zlib.crc32(np.ascontiguousarray(index, "<i4")) != manifest["checksums"]["index"]:
        raise FrameFormatError(f"{path}: its index {name} does not match its checksum; the store is damaged "
                               "and which brick is where cannot be known")
    return index


def _check_index(index, spec, manifest, lost):
    keys = index[:, :3].astype(np.int64)
    lost.add(((keys < 0) | (keys >= np.asarray(spec.brick_shape))).any(axis=1), "a key outside the grid")
    ids = (keys[:, 2] << 42) | (keys[:, 1] << 21) | (keys[:, 0] & ((1 << 21) - 1))
    _, inverse, counts = np.unique(ids, return_inverse=True, return_counts=True)
    lost.add(counts[inverse] > 1, "a key listed more than once")
    listed = np.isin(index[:, 3], manifest["segments"])
    lost.add(~listed, "a segment the manifest does not list")
    where = index[:, 3].astype(np.int64) << 32 | (index[:, 4].astype(np.int64) & 0xFFFFFFFF)
    _, inverse, counts = np.unique(where, return_inverse=True, return_counts=True)
    lost.add(counts[inverse] > 1, "a stored brick named by two keys")


def _read_segment(group, path, manifest, segment, index, data, filled, lost, kind="segment"):
    """Copy the ``kind`` bricks of ``segment`` that the index names into ``data``, chunk by
    chunk, each chunk checked (CRC-32 in format 2, range always: sums within the grid's
    saturation, knowledge and looks in [0, saturation]); what cannot be read goes to ``lost``."""
    uses = np.flatnonzero(index[:, 3] == segment)
    if not len(uses):
        return
    rows = index[uses, 4].astype(np.int64)
    entry = manifest["checksums"][_SUMS[kind]][str(segment)] if manifest["format_version"] >= 2 else None
    name = f"{kind}_{segment}"
    lowest = -GRID_LIMIT if kind == "segment" else 0
    try:
        stored = group[name]
        shape, dtype = stored.shape, stored.dtype
    except Exception:
        lost.add(uses, f"{name} is missing")
        return
    brick = manifest["spec"].brick_data_shape
    if dtype != np.int32 or len(shape) != 4 or tuple(shape[1:]) != brick:
        lost.add(uses, f"{name} holds {shape} {dtype}, not (n, {', '.join(map(str, brick))}) int32 bricks")
        return
    n = shape[0] if entry is None else entry["rows"]
    if shape[0] != n:
        lost.add(uses, f"{name} holds {shape[0]} bricks, its checksum entry {n}")
        return
    lost.add(uses[(rows < 0) | (rows >= n)], f"a row beyond the {n} bricks of {name}")
    for c, start in enumerate(range(0, n, CHUNK_BRICKS)):
        stop = min(n, start + CHUNK_BRICKS)
        here = uses[(rows >= start) & (rows < stop)]
        if not len(here):
            continue
        try:
            chunk = np.ascontiguousarray(stored[start:stop], np.int32)
        except Exception as exc:
            lost.add(here, f"{name} chunk {c} cannot be read ({type(exc).__name__})")
            continue
        if entry is not None and zlib.crc32(np.ascontiguousarray(chunk, "<i4")) != entry["crc32"][c]:
            lost.add(here, f"{name} chunk {c} does not match its checksum (zeroed, missing or damaged)")
            continue
        if chunk.size and (chunk.max() > GRID_LIMIT or chunk.min() < lowest):
            lost.add(here, f"{name} chunk {c} holds values beyond the grid's saturation" if kind == "segment"
                     else f"{name} chunk {c} holds values outside [0, {GRID_LIMIT}]")
            continue
        data[here] = chunk[index[here, 4] - start]
        filled[here] = True
