"""The map on disk, whatever its format: one table of the formats (``FORMATS``).

A map is kept as an ``.npz`` file (``maps.npz``: one file, rewritten whole) or as a map store
(``maps.store``: a zarr directory, saved incrementally). Each is a ``MapFormat``: how it knows
a map of its own, reads one, writes one and tells when it was saved. Reading asks each format
whether it recognises the path (a store by its directory, an npz by being a file); writing
picks the format by the name's extension (``.npz``), any other name ``DEFAULT`` (a store).
Nothing else in radarcl asks "is it a store?"; a new format is one ``register`` here and its
test.
"""

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from radarcl import sensor_model
from radarcl.errors import ConfigError, FrameFormatError, ShapeError
from radarcl.grid import EvidenceGrid
from radarcl.io import files
from radarcl.maps import npz, store

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MapFormat:
    """One way of keeping a map on disk.

    name: the format's name; suffixes: the extensions that make an output this format (none:
    the ``DEFAULT``'s, any other name); recognises(path): True when the existing ``path`` is
    this format's to read (or to refuse with the reason); read(path, salvage): (spec, keys,
    data, lost, channels), as ``read_map`` says; read_poses(path), read_meta(path, key): as the
    functions of those names below; saved(path): the file whose time is the last save's;
    writer(path, spec, sensor_toml, config, inputs, reading): a function that saves a map's
    bricks to ``path``, ``save(keys, data, poses=None, channels=None, meta=None)``, each call
    a new version of the map (``MapSaver`` says what each keeps); directory: (what, is_ours)
    for a format kept as a directory, which ``--force`` replaces only where ``is_ours``."""

    name: str
    suffixes: tuple
    recognises: Callable
    read: Callable
    read_poses: Callable
    read_meta: Callable
    saved: Callable
    writer: Callable
    directory: tuple = None


def register(fmt, first=False):
    """Add the ``MapFormat`` ``fmt`` to ``FORMATS``. Reading asks the formats in order and the
    npz format takes any file (to refuse what is no map with the reason): a format that knows
    its files by something narrower is asked ``first``."""
    if fmt.name in FORMATS:
        raise ConfigError(f"map format {fmt.name!r} is registered already")
    others = dict(FORMATS)
    FORMATS.clear()
    FORMATS.update({fmt.name: fmt, **others} if first else {**others, fmt.name: fmt})
    return fmt

def _read_store(path, salvage):
    """A map store's (spec, keys, data, lost, channels), warning of a save that did not complete."""
    spec, keys, data, manifest = store.read(path, salvage=salvage)
    if manifest["incomplete"]:
        log.warning("%s: a save after version %d did not complete (%s left behind); read version %d",
                    path, manifest["version"], ", ".join(manifest["incomplete"]), manifest["version"])
    knowledge = manifest["knowledge"]
    channels = None if knowledge is None else npz.Channels(knowledge, manifest["looks"], manifest["reading"])
    return spec, keys, data, manifest["lost"], channels


def _read_npz(path, salvage):
    """An npz map's (spec, keys, data, [], channels)."""
    spec, keys, data, channels = npz.read_channels(path)     # read whole or refused: nothing to salvage
    return spec, keys, data, [], channels


def _store_writer(path, spec, sensor_toml="", config=None, inputs=(), reading=None):
    """Saves into a map store (replaced on the first save): each writes only the changed bricks,
    and ``meta`` adds to the manifest's."""
    writer = store.StoreWriter(path, spec, sensor_toml, config, inputs, overwrite=True, reading=reading)

    def save(keys, data, poses=None, channels=None, meta=None):
        writer.meta.update(meta or {})
        writer.save(keys, data, poses=poses, knowledge=None if channels is None else channels.knowledge,
                    looks=None if channels is None else channels.looks)
    return save


def _npz_writer(path, spec, sensor_toml="", config=None, inputs=(), reading=None):
    """Saves as an npz file, rewritten whole each time; its ``meta`` keeps the sensor profile and
    configuration with each save's ``meta``."""
    kept = {k: v for k, v in dict(sensor=sensor_toml or None, config=config or None).items() if v}

    def save(keys, data, poses=None, channels=None, meta=None):
        npz.write(path, spec, keys, data, poses=poses, meta={**kept, **(meta or {})} or None, channels=channels)
    return save


FORMATS = {}                                # asked in this order: a store (a directory) first
register(MapFormat("store", (), store.recognises, _read_store, store.read_poses, store.read_meta,
                   lambda path: Path(path) / store.MANIFEST, _store_writer, directory=("map store", store.recognises)))
register(MapFormat("npz", (".npz",), npz.recognises, _read_npz, npz.read_poses, npz.read_meta, Path, _npz_writer))
DEFAULT = "store"                           # what a map written to a name no format's suffixes claim takes


def format_of(path):
    """The name of the format that reads ``path``, or None."""
    return next((name for name, fmt in FORMATS.items() if fmt.recognises(path)), None)


def _reader(path):
    """The format that reads ``path``: the one that recognises it; else, to say why it is no map,
    the first of its kind (a directory's or a file's)."""
    name = format_of(path)
    if name is not None:
        return FORMATS[name]
    return next(f for f in FORMATS.values() if (f.directory is not None) == Path(path).is_dir())


def output_format(path):
    """The name of the format a map written to ``path`` takes: the one whose suffixes hold its
    extension ("npz" for ``*.npz``), else ``DEFAULT`` ("store")."""
    return next((name for name, fmt in FORMATS.items() if Path(path).suffix in fmt.suffixes), DEFAULT)


def check_output(path, force=False, inputs=(), what="map"):
    """``io.files.check`` for a map output: a store may replace a store (with ``force``)."""
    return files.check(path, force, inputs=inputs, what=what, directory=FORMATS[output_format(path)].directory)


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
    if format_of(path) is None and Path(path).is_dir():
        raise FrameFormatError(f"{path} is a directory that is not a radarcl map store (no radarcl manifest)")
    return _reader(path).read(path, salvage)


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
        reading = getattr(grid, "reading", None)       # a pipeline's grid knows it (Mapping.from_config)
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
        return _reader(path).read_poses(path)
    except FrameFormatError:
        raise
    except (ShapeError, ValueError, TypeError) as exc:
        raise FrameFormatError(f"{path}: bad sensor poses ({exc})") from exc


def read_meta(path, key):
    """The ``key`` entry a map's saver kept (``MapSaver(..., key=value)``: the store's
    manifest, or the npz's ``meta``), or None."""
    return _reader(path).read_meta(path, key)


def saved_ns(path):
    """When the map at ``path`` was last saved [ns since the epoch]: the time its file (an npz)
    or its manifest (a store, written last by every save) was written."""
    name = format_of(path)
    return (FORMATS[name].saved(path) if name is not None else Path(path)).stat().st_mtime_ns


class MapSaver:
    """Saves of one map to ``path`` in the format its name takes (``output_format``): an
    ``.npz`` file (rewritten whole, through a temporary file) or, for any other name, a map
    store (only changed bricks). ``saver(grid)`` saves."""

    def __init__(self, path, sensor_toml="", config=None, inputs=()):
        self.path = Path(path)
        self.format = FORMATS[output_format(self.path)]
        self.meta = dict(sensor_toml=sensor_toml, config=config, inputs=inputs)
        self.save = None

    def __call__(self, grid, poses=None, **meta):
        """Save ``grid`` (and the sensor ``poses`` (n, 4, 4) so far, when given); ``meta``
        (JSON-able values, e.g. a live stream's counts) goes into the manifest or the npz's
        ``meta`` (``read_meta`` reads either)."""
        keys, data = grid.bricks()
        channels = _channels(grid, reading_of(self.meta["config"]))
        if self.save is None:
            self.save = self.format.writer(self.path, grid.spec, **self.meta,
                                           reading=None if channels is None else channels.reading)
        self.save(keys, data, poses=poses, channels=channels, meta=meta)


def convert(source, target, salvage=False):
    """Copy a map between formats (``target``'s by its name: ``.npz`` or a store directory)
    with its sensor poses, sensor profile and configuration; returns (spec, number of bricks,
    the bricks lost: see ``read_salvaged``)."""
    spec, keys, data, lost, channels = read_map(source, salvage)
    poses = read_poses(source)
    sensor, config = read_meta(source, "sensor"), read_meta(source, "config")
    save = FORMATS[output_format(target)].writer(target, spec, sensor if isinstance(sensor, str) else "",
                                                 config if isinstance(config, dict) else None, [source],
                                                 None if channels is None else channels.reading)
    save(keys, data, poses=poses, channels=channels)
    return spec, len(keys), lost

def save_grid(grid, path, poses=None, reading=None):
    """Write an ``EvidenceGrid`` (spec and allocated bricks, not the dense volume) to an npz
    file, with the sensor's ``poses`` (n, 4, 4) when given (the viewer draws them); a grid with
    the knowledge channel with it and its reading: the grid's own (a pipeline's grid,
    ``Mapping.from_config``, knows it), or ``reading``: a dict (``reading_of``) or the
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
