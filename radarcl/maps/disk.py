"""The map on disk, whatever its format: one place that knows the formats (``FORMATS``).

A map is kept as an ``.npz`` file (``maps.npz``: one file, rewritten whole) or as a map store
(``maps.store``: a zarr directory, saved incrementally). Reading asks each format whether it
recognises the path (a store by its directory, an npz by being a file); writing picks the format
by the name (``.npz``, or a store for any other name). Nothing else in radarcl asks "is it a
store?".
"""

import logging
from pathlib import Path


from radarcl.errors import FrameFormatError, ShapeError
from radarcl.grid import EvidenceGrid
from radarcl.io import files
from radarcl.maps import npz, store

log = logging.getLogger(__name__)
FORMATS = {"store": store, "npz": npz}      # asked in this order: a directory first


def format_of(path):
    """The name of the format that reads ``path``, or None."""
    return next((name for name, fmt in FORMATS.items() if fmt.recognises(path)), None)


def output_format(path):
    """The format a map written to ``path`` takes: "npz" for ``*.npz``, else "store"."""
    return "npz" if Path(path).suffix == ".npz" else "store"


def check_output(path, force=False, inputs=(), what="map"):
    """``io.files.check`` for a map output: a store may replace a store (with ``force``)."""
    directory = ("map store", store.recognises) if output_format(path) == "store" else None
    return files.check(path, force, inputs=inputs, what=what, directory=directory)


def read(path):
    """(spec, keys (n, 3) int32, data (n, 8, 8, 8) int32) of a map file or store, without a
    device (numpy only, for the viewer), every structure checked before it is used. What is
    not a radarcl map, or a damaged one, raises ``FrameFormatError`` saying what was wrong."""
    return read_salvaged(path, salvage=False)[:3]


def read_salvaged(path, salvage=True):
    """As ``read``, plus the bricks a damaged map store lost: (spec, keys, data, lost), lost a
    list of {"reason", "keys"} (empty for an intact map). With ``salvage`` a store's damaged
    bricks are left out (and listed) instead of refusing the store; an npz file has no part
    that can be left out (its members are read whole and checked), so it is read or refused."""
    if path is None or not isinstance(path, (str, Path)):
        raise FrameFormatError(f"a map is a path to an .npz file or a map store, got {path!r}")
    if format_of(path) == "store":
        spec, keys, data, manifest = store.read(path, salvage=salvage)
        if manifest["incomplete"]:
            log.warning("%s: a save after version %d did not complete (%s left behind); read version %d",
                        path, manifest["version"], ", ".join(manifest["incomplete"]), manifest["version"])
        return spec, keys, data, manifest["lost"]
    if Path(path).is_dir():
        raise FrameFormatError(f"{path} is a directory that is not a radarcl map store (no radarcl manifest)")
    return (*npz.read(path), [])


def lost_lines(lost):
    """What ``read_salvaged`` lost, one line per reason with every brick key (bx, by, bz)."""
    return [f"lost {len(e['keys'])} brick(s) ({e['reason']}): " + " ".join(f"({x},{y},{z})" for x, y, z in e["keys"])
            if e["keys"] else e["reason"] for e in lost]


def read_poses(path):
    """The sensor poses (n, 4, 4) a map file or store keeps, or None."""
    try:
        return FORMATS["store" if Path(path).is_dir() else "npz"].read_poses(path)
    except FrameFormatError:
        raise
    except (ShapeError, ValueError, TypeError) as exc:
        raise FrameFormatError(f"{path}: bad sensor poses ({exc})") from exc


def read_meta(path, key):
    """The ``key`` entry a map's saver kept (``MapSaver(..., key=value)``: the store's
    manifest, or the npz's ``meta``), or None."""
    return FORMATS["store" if Path(path).is_dir() else "npz"].read_meta(path, key)


def saved_ns(path):
    """When the map at ``path`` was last saved [ns since the epoch]: the time its file (an npz)
    or its manifest (a store, written last by every save) was written."""
    path = Path(path)
    return (path / store.MANIFEST if format_of(path) == "store" else path).stat().st_mtime_ns


class MapSaver:
    """Saves of one map to ``path``: an ``.npz`` file (rewritten whole, through a temporary
    file) or, for any other name, a map store (only changed bricks). ``saver(grid)`` saves."""

    def __init__(self, path, sensor_toml="", config=None, inputs=()):
        self.path = Path(path)
        self.npz = output_format(self.path) == "npz"
        self.meta = dict(sensor_toml=sensor_toml, config=config, inputs=inputs)
        self.writer = None

    def __call__(self, grid, poses=None, **meta):
        """Save ``grid`` (and the sensor ``poses`` (n, 4, 4) so far, when given); ``meta``
        (JSON-able values, e.g. a live stream's counts) goes into the manifest or the npz's
        ``meta`` (``read_meta`` reads either)."""
        if self.npz:
            kept = dict(sensor=self.meta["sensor_toml"] or None, config=self.meta["config"] or None)
            npz.write(self.path, grid.spec, *grid.bricks(), poses=poses,
                      meta={**{k: v for k, v in kept.items() if v}, **meta} or None)
            return
        if self.writer is None:
            self.writer = store.StoreWriter(self.path, grid.spec, overwrite=True, **self.meta)
        self.writer.meta.update(meta)
        self.writer.save(*grid.bricks(), poses=poses)


def convert(source, target, salvage=False):
    """Copy a map between the npz and store formats (by ``target``'s name: ``.npz`` or a
    store directory) with its sensor poses, sensor profile and configuration; returns (spec,
    number of bricks, the bricks lost: see ``read_salvaged``)."""
    spec, keys, data, lost = read_salvaged(source, salvage)
    poses = read_poses(source)
    kept = {key: read_meta(source, key) for key in ("sensor", "config")}
    kept = dict(sensor=kept["sensor"] if isinstance(kept["sensor"], str) else None,
                config=kept["config"] if isinstance(kept["config"], dict) else None)
    if output_format(target) == "npz":
        npz.write(target, spec, keys, data, poses=poses, meta={k: v for k, v in kept.items() if v} or None)
    else:
        writer = store.StoreWriter(target, spec, kept["sensor"] or "", kept["config"], inputs=[source],
                                   overwrite=True, poses=poses)
        writer.save(keys, data)
    return spec, len(keys), lost


def save_grid(grid, path, poses=None):
    """Write an ``EvidenceGrid`` (spec and allocated bricks, not the dense volume) to an npz
    file, with the sensor's ``poses`` (n, 4, 4) when given (the viewer draws them)."""
    npz.write(path, grid.spec, *grid.bricks(), poses=poses)


def load_grid(runtime, path):
    """An ``EvidenceGrid`` on ``runtime``'s device holding the map file or store at ``path``."""
    spec, keys, data = read(path)
    grid = EvidenceGrid(runtime, spec)
    slots = grid.allocate(keys)
    if len(keys):
        grid.write_slots(slots, data)
    return grid
