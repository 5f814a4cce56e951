"""The map as one ``.npz`` file: the grid spec, the allocated bricks, the sensor's poses.

Members: ``version`` (1; 2 for planar bricks, which adds ``brick_z``; 3 for the knowledge channel), ``origin_m``, ``voxel_m``,
``shape`` (the ``GridSpec``), ``keys`` (n, 3) int32 bricks (bx, by, bz), ``data`` (n, *brick) int32
[z, y, x] (brick (8, 8, 8), or (1, 8, 8) planar) in
``radarcl.logodds`` units, optional ``poses`` (m, 4, 4) float64 and ``meta`` (a JSON object).
A map of the detection-statistics model (``radarcl.sensor_model``) adds three members and is
version ``KNOWLEDGE_VERSION`` (3; radarcl wrote such maps as version 2 before, which still
read): ``knowledge`` (n, *brick) int32 [z, y, x], the summed
detection opportunity in ``logodds.KNOWLEDGE_SCALE`` units per look (same bricks, same order as
``data``; 0 where never observed), ``looks`` (n, *brick) int32, the number of those looks, and
``reading`` (a JSON object of ``sensor_model.READING``: look_limit, prior_nats, prior_looks, known_looks): a
voxel's log-odds is ``sensor_model.read_log_odds(data, knowledge, looks, reading)``, not
``data`` itself. A map without
them is written as version 1 (2 when planar), byte for byte as before. A file whose version
and members disagree (a version 3 file without its knowledge members, a version 1 file with
them, a version 2 file with neither ``brick_z`` nor the knowledge channel) is refused naming
both, never read as a map of sums; a radarcl that reads only version 1 refuses version 2
instead of showing unread sums as log-odds.
Written through a temporary file renamed over the target, so a reader (``radarcl view --live``)
sees the old map or the new one, never half of one. Read member by member with every size
checked against its header and the memory budget (``io.files.safe_npz``), never unpickled.
"""

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError, ShapeError
from radarcl.gridspec import BRICK, GRID_LIMIT, GridSpec
from radarcl.io.files import atomic, safe_npz
from radarcl.sensor_model import READING

FILE_VERSION = 3            # the newest this radarcl reads; a cubic map without knowledge is still written as 1
PLANAR_VERSION = 2          # adds brick_z: an older reader refuses such a file naming both versions
KNOWLEDGE_VERSION = 3       # the knowledge channel, which this version requires (see the module docstring)
LEGACY_KNOWLEDGE_VERSION = 2   # knowledge maps written before version 3: the channel was optional in them
MAX_POSES = 10000          # a map keeps at most this many sensor poses (evenly subsampled)


def recognises(path):
    """True when ``path`` is a file (an npz map, or something to refuse with a reason)."""
    return Path(path).is_file()


@dataclass(frozen=True)
class Channels:
    """What a map of the detection-statistics model keeps beside its sums: ``knowledge``
    (n, 8, 8, 8) int32 in ``logodds.KNOWLEDGE_SCALE`` units and ``looks`` (n, 8, 8, 8) int32
    counts (the bricks of ``data``, in order), and ``reading`` (a dict of
    ``sensor_model.READING``, checked by ``check_reading``)."""

    knowledge: np.ndarray
    looks: np.ndarray
    reading: dict


READING_SIGNS = {"prior_nats": ("number <= 0", lambda v: v <= 0),         # the rest: positive
                 "prior_looks": ("number >= 0", lambda v: v >= 0),     # 0: the prior applies everywhere
                 "known_looks": ("number >= 0", lambda v: v >= 0)}     # 0: every voxel read by its sums
LEGACY_READING = {"known_looks": 0.0}   # what a reading written before these keys reads with


def check_reading(reading, where):
    """A map's reading as a dict of floats (a reading written before ``LEGACY_READING``'s keys
    were kept gets their old values), or FrameFormatError naming what is wrong."""
    if isinstance(reading, dict) and set(reading) == set(READING) - set(LEGACY_READING):
        reading = {**reading, **LEGACY_READING}
    if not isinstance(reading, dict) or set(reading) != set(READING):
        raise FrameFormatError(f"{where}: its reading must give exactly {', '.join(READING)}, got {reading!r}")
    out = {}
    for key, value in reading.items():
        ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
        wanted, test = READING_SIGNS.get(key, ("positive number", lambda v: v > 0))
        if not ok or not test(value):
            raise FrameFormatError(f"{where}: reading {key} = {value!r} is not a {wanted}")
        out[key] = float(value)
    return out


def write(path, spec, keys, data, poses=None, meta=None, channels=None):
    """A map file: ``spec``, the bricks (``keys`` (n, 3) int32, ``data`` (n, *brick) int32),
    the sensor's ``poses`` and ``meta`` (a JSON-able dict) when given, and the knowledge
    ``channels`` (``Channels``, version 2) when given, written atomically."""
    extra = {} if poses is None else dict(poses=check_trajectory(poses))
    planar = spec.brick_z != BRICK
    if planar:
        extra["brick_z"] = spec.brick_z
    if meta:
        extra["meta"] = np.str_(json.dumps(meta))
    version = PLANAR_VERSION if planar else 1
    if channels is not None:
        for name in ("knowledge", "looks"):
            if np.shape(getattr(channels, name)) != np.shape(data):
                raise ShapeError(f"{name} bricks {np.shape(getattr(channels, name))} must match the data's {np.shape(data)}")
            extra[name] = np.ascontiguousarray(getattr(channels, name), np.int32)
        extra["reading"] = np.str_(json.dumps(check_reading(channels.reading, path)))
        version = KNOWLEDGE_VERSION
    with atomic(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, version=version, origin_m=np.asarray(spec.origin_m), voxel_m=spec.voxel_m,
                            shape=np.asarray(spec.shape), keys=keys, data=data, **extra)


def read(path):
    """(spec, keys (n, 3) int32, data (n, *brick) int32) of a map file. A file that is not a
    radarcl map raises ``FrameFormatError`` saying what was wrong; array sizes are checked
    against their headers and the memory budget before they are read."""
    return read_channels(path)[:3]


def read_channels(path):
    """``read``'s (spec, keys, data) and the map's ``Channels`` (None for a version 1 file)."""
    if not Path(path).is_file():
        raise FrameFormatError(f"{path} does not exist (yet)" if not Path(path).exists()
                               else f"{path} is not a map file or store")
    with safe_npz(path, what="radarcl grid file (an npz radarcl wrote)") as f:
        missing = {"version", "origin_m", "voxel_m", "shape", "keys", "data"} - set(f.files)
        if missing:
            raise FrameFormatError(f"{path} is not a radarcl grid file: it lacks {sorted(missing)} "
                                   f"(expected an npz radarcl wrote, e.g. radarcl demo's map.npz)")
        try:
            version = int(f["version"])
            if not 1 <= version <= FILE_VERSION:
                raise FrameFormatError(f"{path} has grid file version {version}, this radarcl reads versions 1 to "
                                       f"{FILE_VERSION}" + (": update radarcl" if version > FILE_VERSION else ""))
            brick_z = int(f["brick_z"]) if version >= PLANAR_VERSION and "brick_z" in f.files else BRICK
            spec = GridSpec(tuple(f["origin_m"]), float(f["voxel_m"]), tuple(int(n) for n in f["shape"]), brick_z)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, FrameFormatError):
                raise
            raise FrameFormatError(f"{path}: a bad grid description ({exc})") from exc
        n_keys = f.header("keys")[0]
        n_data = f.header("data")[0]
        if len(n_keys) != 2 or n_keys[1:] != (3,) or n_data != (n_keys[0], *spec.brick_data_shape):
            raise FrameFormatError(f"{path}: expected brick keys (n, 3) and bricks (n, "
                                   f"{', '.join(map(str, spec.brick_data_shape))}), got {n_keys} and {n_data}")
        if n_keys[0] > int(np.prod(spec.brick_shape, dtype=np.int64)):
            raise FrameFormatError(f"{path}: {n_keys[0]} bricks in a grid of only {spec.brick_shape} bricks")
        keys, data = f["keys"], f["data"]
        channels = None
        _check_members(path, version, set(f.files))
        if version >= LEGACY_KNOWLEDGE_VERSION and {"knowledge", "looks", "reading"} & set(f.files):
            planes = {}
            for name in ("knowledge", "looks"):
                if f.header(name)[0] != n_data:
                    raise FrameFormatError(f"{path}: {name} bricks {f.header(name)[0]} do not match the data's {n_data}")
                plane = planes[name] = f[name]
                if plane.dtype != np.int32 or (plane.size and (plane.min() < 0 or plane.max() > GRID_LIMIT)):
                    raise FrameFormatError(f"{path}: {name} must be int32 in [0, {GRID_LIMIT}] (radarcl writes nothing else)")
            try:
                reading = json.loads(str(f["reading"]))
            except (ValueError, TypeError) as exc:
                raise FrameFormatError(f"{path}: its reading is not JSON ({exc})") from exc
            channels = Channels(planes["knowledge"], planes["looks"], check_reading(reading, path))
    if data.dtype != np.int32:
        raise FrameFormatError(f"{path}: expected bricks ({len(keys)}, {', '.join(map(str, spec.brick_data_shape))}) "
                               f"int32, got {data.shape} {data.dtype}")
    if keys.dtype != np.int32:
        raise FrameFormatError(f"{path}: expected brick keys (n, 3) int32, got {keys.shape} {keys.dtype}")
    if len(keys) and ((keys < 0).any() or (keys >= np.asarray(spec.brick_shape)).any()):
        raise FrameFormatError(f"{path}: brick keys outside the grid's {spec.brick_shape} bricks")
    if len(np.unique(keys, axis=0)) != len(keys):
        raise FrameFormatError(f"{path}: a brick key appears more than once")
    if data.size and (data.max() > GRID_LIMIT or data.min() < -GRID_LIMIT):
        raise FrameFormatError(f"{path}: values beyond the grid's saturation +-{GRID_LIMIT} units; "
                               "radarcl never writes them")
    return spec, keys, data, channels


def _check_members(path, version, members):
    """FrameFormatError naming the version and the members when they disagree (see the module
    docstring): a file edited or damaged would otherwise read its sums as log-odds."""
    channel = {"knowledge", "looks", "reading"}
    present, missing = sorted(channel & members), sorted(channel - members)
    if version >= KNOWLEDGE_VERSION and missing:
        raise FrameFormatError(f"{path} is a version {version} map (the knowledge channel) but lacks its "
                               f"{', '.join(missing)}; refused rather than read as a map of plain sums")
    if version < LEGACY_KNOWLEDGE_VERSION and present:
        raise FrameFormatError(f"{path} is a version {version} map but holds knowledge-channel members "
                               f"({', '.join(present)}), which only versions {LEGACY_KNOWLEDGE_VERSION} and "
                               f"{KNOWLEDGE_VERSION} have; refused")
    if version == LEGACY_KNOWLEDGE_VERSION and present and missing:
        raise FrameFormatError(f"{path}: a version {version} map with {', '.join(present)} lacks its "
                               f"{', '.join(missing)}; refused rather than read as a map of plain sums")
    if version == PLANAR_VERSION and "brick_z" not in members and not present:
        raise FrameFormatError(f"{path} is a version {version} map, which is planar (brick_z) or has the knowledge "
                               "channel (knowledge, looks, reading), but holds neither; refused rather than read "
                               "as a map of plain sums")


def check_trajectory(poses):
    """Sensor poses (n, 4, 4) float64 to keep with a map: finite, at most MAX_POSES (evenly
    subsampled, the last kept)."""
    P = np.asarray(poses)
    if P.dtype.kind not in "iuf":
        raise ShapeError(f"poses must be real numbers (n, 4, 4), got {P.shape} {P.dtype}")
    P = P.astype(np.float64)
    if P.ndim != 3 or P.shape[1:] != (4, 4) or not np.isfinite(P).all():
        raise ShapeError(f"poses must be finite (n, 4, 4), got {P.shape}")
    if len(P) > MAX_POSES:
        P = P[np.unique(np.r_[np.linspace(0, len(P) - 1, MAX_POSES).astype(int), len(P) - 1])]
    return P


def read_poses(path):
    """The sensor poses (n, 4, 4) a map file keeps, or None."""
    with safe_npz(path) as f:
        return check_trajectory(f["poses"]) if "poses" in f.files else None


def read_meta(path, key):
    """The ``key`` entry of the map file's ``meta``, or None."""
    with safe_npz(path) as f:
        if "meta" not in f.files:
            return None
        try:
            return json.loads(str(f["meta"])).get(key)
        except (ValueError, AttributeError) as exc:
            raise FrameFormatError(f"{path}: its meta is not a JSON object ({exc})") from exc
