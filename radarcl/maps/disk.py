"""The map on disk, whatever its format: one place that knows the formats (``FORMATS``).

A map is kept as an ``.npz`` file (``maps.npz``: one file, rewritten whole) or as a map store
(``maps.store``: a zarr directory, saved incrementally). Reading asks each format whether it
recognises the path (a store by its directory, an npz by being a file); writing picks the format
by the name (``.npz``, or a store for any other name). Nothing else in radarcl asks "is it a
store?".
"""

import logging
from pathlib import Path

from radarcl import sensor_model
from radarcl.errors import ConfigError, FrameFormatError, ShapeError
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
    not a radarcl map, or a damaged one, raises ``FrameFormatError`` saying what was wrong.
    ``data`` are the stored sums: a map with the knowledge channel is read through its reading
    (``read_map``; ``maps.Map`` does)."""
    return read_map(path, salvage=False)[:3]


def read_salvaged(path, salvage=True):
    """As ``read``, plus the bricks a damaged map store lost: (spec, keys, data, lost) (see ``read_map``)."""
    return read_map(path, salvage)[:4]


def read_channels(path):
    """``read``'s (spec, keys, data) and the map's ``npz.Channels`` (knowledge, looks and
    reading), or None for a map without the knowledge channel."""
    spec, keys, data, _, channels = read_map(path)
    return spec, keys, data, channels


def read_map(path, salvage=False):
    """(spec, keys, data, lost, channels) of a map file or store: ``lost`` a list of {"reason",
    "keys"} (empty for an intact map), ``channels`` the knowledge channel (``npz.Channels``) or
    None. With ``salvage`` a store's damaged bricks are left out (and listed) instead of refusing
    the store; an npz file has no part that can be left out (its members are read whole and
    checked), so it is read or refused."""
    if path is None or not isinstance(path, (str, Path)):
        raise FrameFormatError(f"a map is a path to an .npz file or a map store, got {path!r}")
    if format_of(path) == "store":
        spec, keys, data, manifest = store.read(path, salvage=salvage)
        if manifest["incomplete"]:
            log.warning("%s: a save after version %d did not complete (%s left behind); read version %d",
                        path, manifest["version"], ", ".join(manifest["incomplete"]), manifest["version"])
        knowledge = manifest["knowledge"]
        channels = None if knowledge is None else npz.Channels(knowledge, manifest["looks"], manifest["reading"])
        return spec, keys, data, manifest["lost"], channels
    if Path(path).is_dir():
        raise FrameFormatError(f"{path} is a directory that is not a radarcl map store (no radarcl manifest)")
    spec, keys, data, channels = npz.read_channels(path)
    return spec, keys, data, [], channels


def reading_of(config):
    """The reading a map of ``config`` (a ``Resolved`` or its ``as_dict()``) keeps: its
    [sensor_model] keys' (``sensor_model.READING``)."""
    values = dict(config or {}) if config is None or isinstance(config, dict) else config.values
    return sensor_model.ModelParams.of(values).reading


def _channels(grid, reading):
    """The grid's knowledge channel and reading (``npz.Channels``), or None for a grid without."""
    if not getattr(grid, "has_knowledge", False):
        return None
    if reading is None:
        raise ConfigError("a map with the knowledge channel is saved with its reading (the [sensor_model] keys "
                          "look_limit, prior_nats, prior_looks): pass reading= the configuration it was made with")
    if not isinstance(reading, dict):
        reading = reading_of(reading)
    return npz.Channels(grid.knowledge_bricks(), grid.knowledge_bricks("looks"), reading)


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
        keys, data = grid.bricks()
        channels = _channels(grid, reading_of(self.meta["config"]))
        if self.npz:
            kept = dict(sensor=self.meta["sensor_toml"] or None, config=self.meta["config"] or None)
            npz.write(self.path, grid.spec, keys, data, poses=poses,
                      meta={**{k: v for k, v in kept.items() if v}, **meta} or None, channels=channels)
            return
        if self.writer is None:
            self.writer = store.StoreWriter(self.path, grid.spec, overwrite=True, **self.meta,
                                            reading=None if channels is None else channels.reading)
        self.writer.meta.update(meta)
        self.writer.save(keys, data, poses=poses, knowledge=None if channels is None else channels.knowledge,
                         looks=None if channels is None else channels.looks)


def convert(source, target, salvage=False):
    """Copy a map between the npz and store formats (by ``target``'s name: ``.npz`` or a
    store directory) with its sensor poses, sensor profile and configuration; returns (spec,
    number of bricks, the bricks lost: see ``read_salvaged``)."""
    spec, keys, data, lost, channels = read_map(source, salvage)
    poses = read_poses(source)
    kept = {key: read_meta(source, key) for key in ("sensor", "config")}
    kept = dict(sensor=kept["sensor"] if isinstance(kept["sensor"], str) else None,
                config=kept["config"] if isinstance(kept["config"], dict) else None)
    if output_format(target) == "npz":
        npz.write(target, spec, keys, data, poses=poses, meta={k: v for k, v in kept.items() if v} or None,
                  channels=channels)
    else:
        writer = store.StoreWriter(target, spec, kept["sensor"] or "", kept["config"], inputs=[source],
                                   overwrite=True, poses=poses, reading=None if channels is None else channels.reading)
        writer.save(keys, data, knowledge=None if channels is None else channels.knowledge,
                    looks=None if channels is None else channels.looks)
    return spec, len(keys), lost


def save_grid(grid, path, poses=None, reading=None):
    """Write an ``EvidenceGrid`` (spec and allocated bricks, not the dense volume) to an npz
    file, with the sensor's ``poses`` (n, 4, 4) when given (the viewer draws them); a grid with
    the knowledge channel with it and its ``reading``: a dict (``reading_of``) or the
    ``mapconfig.Resolved`` the map was made with."""
    npz.write(path, grid.spec, *grid.bricks(), poses=poses, channels=_channels(grid, reading))


def load_grid(runtime, path):
    """An ``EvidenceGrid`` on ``runtime``'s device holding the map file or store at ``path``."""
    spec, keys, data, channels = read_channels(path)
    grid = EvidenceGrid(runtime, spec, knowledge=channels is not None)
    slots = grid.allocate(keys)
    if len(keys):
        grid.write_slots(slots, data if channels is None else
                         dict(evidence=data, knowledge=channels.knowledge, looks=channels.looks))
    return grid
