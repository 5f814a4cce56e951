"""Spinning-radar scans as polar PNG images (the Oxford Radar RobotCar layout, Barnes et al.,
ICRA 2020), for any unit: the layout comes from the sensor profile's [reader] table.

One scan is an 8-bit greyscale PNG of shape (n_azimuths, meta_columns + n_bins). In the Oxford
layout (the built-in ``polar-png`` and ``navtech-cts350x`` profiles):
  columns 0-7   int64 little-endian UNIX timestamp [us] of the azimuth (``timestamp_column``)
  columns 8-9   uint16 little-endian encoder count; angle = count / encoder_counts x 2 pi
  column 10     valid flag (255: measured, else interpolated) (``valid_column``; -1: none)
  columns 11..  range bins of ``bin_spacing_m``, post-FFT power on a log scale, 0-255

Power scaling. The levels are decibels of power, ``db_per_level`` per level (1 for Navtech):
P = 10^(level x db_per_level / 10). Evidence from the Oxford data: the lowest levels that occur
are 0, 6, 9, 12, 14, 15, 17, 18, which are 20 log10(k) for amplitudes k = 1 .. 8 to within a
unit of rounding: the sensor quantises an integer amplitude and writes its power in dB.

Coordinates. radarcl uses x forward, y left, z up (ROS REP-103) everywhere. The Oxford data
uses x forward, y right, z down, and its azimuths turn clockwise seen from above (from x
towards its y). This reader converts, and nothing else in radarcl knows the Oxford frame:
angles are returned counter-clockwise from x towards the left (``clockwise = true`` negates
them and puts the rows in counter-clockwise order) and odometry rows (x, y, yaw) become
(x, -y, -yaw).

Sizes are checked before anything is decoded: a PNG declares its size in a few header bytes,
so a small file that declares 120 Mpixel is refused without allocating them.
"""

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.geometry import interpolate_se2, se2_pose

MAX_PIXELS = 64 * 2 ** 20          # a scan larger than this is refused before decoding


@dataclass(frozen=True)
class PolarLayout:
    """The columns of a polar PNG scan (the sensor profile's [reader] table)."""

    meta_columns: int = 11
    timestamp_column: int = 0
    encoder_column: int = 8
    encoder_counts: int = 5600
    valid_column: int = 10
    db_per_level: float = 1.0
    clockwise: bool = True

    @classmethod
    def of(cls, sensor):
        """The layout a sensor profile's [reader] table gives (defaults: Oxford)."""
        reader = dict(sensor.tables.get("reader", {}))
        if reader.pop("format", "polar-png") != "polar-png":
            raise ConfigError(f"sensor {sensor.name} is not read as polar PNG scans")
        return cls(**reader)

    def __post_init__(self):
        for name, width in (("timestamp_column", 8), ("encoder_column", 2), ("valid_column", 1)):
            col = getattr(self, name)
            if col >= 0 and col + width > self.meta_columns:
                raise ConfigError(f"[reader] {name} = {col} needs {width} columns inside the {self.meta_columns} "
                                  "metadata columns")


@dataclass(frozen=True)
class PolarScan:
    """One decoded scan; arrays are indexed by azimuth. Angles are REP-103 (counter-clockwise)."""

    path: Path
    timestamps_us: np.ndarray   # int64 (n_az,); from the file name when the layout has none
    angles_rad: np.ndarray      # float64 (n_az,) in [0, 2 pi), counter-clockwise from x
    valid: np.ndarray           # bool (n_az,)
    levels: np.ndarray          # uint8 (n_az, n_bins), log power
    db_per_level: float = 1.0
    acquired: np.ndarray = None  # int (n_az,): row i was the acquired[i]-th azimuth of the turn

    @property
    def n_bins(self):
        """Range bins per azimuth."""
        return self.levels.shape[1]

    def power(self):
        """Linear power (n_az, n_bins) float32: 10^(level x db_per_level / 10)."""
        return levels_to_power(self.levels, self.db_per_level)


def levels_to_power(levels, db_per_level=1.0):
    """Log-scaled levels -> linear power, float32 (level 255 at 1 dB/level is 3.2e25)."""
    if not (np.isfinite(db_per_level) and 0 < db_per_level <= 1.4):
        raise FrameFormatError(f"db_per_level must be in (0, 1.4] so that 255 levels fit float32, "
                               f"got {db_per_level!r}")
    return (10.0 ** (np.asarray(levels, np.float64) * (db_per_level / 10.0))).astype(np.float32)


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def verify_png(path):
    """Check a PNG's signature and every chunk's CRC-32 before decoding: PIL stops reading the
    image data once it has its pixels, so a damaged final deflate block (whose Adler-32 it
    never reads) would otherwise decode into wrong pixels without a word (found by the fuzz
    suite). Returns the (width, height) of its IHDR."""
    import struct
    import zlib

    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise FrameFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if not raw.startswith(PNG_SIGNATURE):
        raise FrameFormatError(f"{path}: not a PNG file (no PNG signature)")
    i, size, ended = len(PNG_SIGNATURE), None, False
    while i + 12 <= len(raw) and not ended:
        length, kind = struct.unpack(">I4s", raw[i:i + 8])
        end = i + 12 + length
        if end > len(raw):
            break
        body = raw[i + 4:end - 4]
        if zlib.crc32(body) != struct.unpack(">I", raw[end - 4:end])[0]:
            raise FrameFormatError(f"{path}: PNG chunk {kind!r} at byte {i} fails its CRC: the file is damaged")
        if kind == b"IHDR":
            size = struct.unpack(">II", body[4:12])
        ended = kind == b"IEND"
        i = end
    if not ended or size is None:
        raise FrameFormatError(f"{path}: a truncated PNG (no IHDR or IEND chunk)")
    return size


def load_scan(path, layout=PolarLayout()):
    """Decode one scan; raises FrameFormatError naming what is wrong."""
    from PIL import Image

    path = Path(path)
    width, height = verify_png(path)
    if width * height > MAX_PIXELS:
        raise FrameFormatError(f"{path}: declares {width} x {height} pixels, more than the {MAX_PIXELS} a scan "
                               "may have; refused before decoding")
    try:
        with Image.open(path) as image:
            width, height = image.size
            if width * height > MAX_PIXELS:
                raise FrameFormatError(f"{path}: declares {width} x {height} pixels, more than the "
                                       f"{MAX_PIXELS} a scan may have; refused before decoding")
            if image.mode != "L":
                raise FrameFormatError(f"{path}: expected an 8-bit greyscale image of shape (azimuths, "
                                       f"{layout.meta_columns} + bins), got mode {image.mode} of {height} x {width}")
            raw = np.asarray(image)
    except FrameFormatError:
        raise
    except Exception as exc:            # noqa: BLE001 - PIL raises OSError, SyntaxError, zlib.error...
        raise FrameFormatError(f"{path}: not a readable PNG ({type(exc).__name__}: {exc})") from exc
    if raw.dtype != np.uint8 or raw.ndim != 2 or raw.shape[1] <= layout.meta_columns or raw.shape[0] < 1:
        raise FrameFormatError(f"{path}: expected an 8-bit greyscale image of shape (azimuths, "
                               f"{layout.meta_columns} + bins), got {raw.shape} {raw.dtype}")
    raw = np.ascontiguousarray(raw)
    n_az = raw.shape[0]
    if layout.timestamp_column >= 0:
        c = layout.timestamp_column
        timestamps = raw[:, c:c + 8].copy().view("<i8")[:, 0].astype(np.int64)
    else:
        try:
            start = int(path.stem)
        except ValueError:
            start = 0
        timestamps = np.full(n_az, start, np.int64)
    if layout.encoder_column >= 0:
        c = layout.encoder_column
        counts = raw[:, c:c + 2].copy().view("<u2")[:, 0]
        if (counts >= layout.encoder_counts).any():
            raise FrameFormatError(f"{path}: encoder counts must be below {layout.encoder_counts}, found {counts.max()}")
        angles = counts / layout.encoder_counts * 2 * np.pi
    else:
        angles = np.arange(n_az) * (2 * np.pi / n_az)
    valid = raw[:, layout.valid_column] == 255 if layout.valid_column >= 0 else np.ones(n_az, bool)
    levels = raw[:, layout.meta_columns:]
    order = np.arange(n_az)
    if layout.clockwise:
        # REP-103 angles, and the rows in counter-clockwise order (the first kept), so that row
        # i points near the spinning lattice's azimuth i: the per-azimuth poses then turn each
        # row by a little only.
        angles = np.mod(-angles, 2 * np.pi)
        order = (-order) % n_az
        timestamps, angles, valid, levels = timestamps[order], angles[order], valid[order], levels[order]
    return PolarScan(path, timestamps, angles, valid, np.ascontiguousarray(levels), layout.db_per_level, order)


def scan_paths(directory):
    """The scans (``*.png``) of a directory in time order (by name: ``<unix_us>.png``)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise FrameFormatError(f"{directory} is not a directory of polar PNG scans")
    paths = sorted(directory.glob("*.png"), key=lambda p: (len(p.stem), p.stem))
    if not paths:
        raise FrameFormatError(f"no polar PNG scans (*.png) in {directory}")
    return paths


def load_odometry(path):
    """Oxford ``radar_odometry.csv`` in REP-103: {(source_us, destination_us): (x, y, yaw)}.

    Each row is the source scan's pose in the destination scan's frame; the file's (x forward,
    y right, z down) rows become (x, -y, -yaw) here. Rows run from each scan to the one before."""
    import csv

    path = Path(path)
    out = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                key = (int(row["source_radar_timestamp"]), int(row["destination_radar_timestamp"]))
                x, y, yaw = float(row["x"]), float(row["y"]), float(row["yaw"])
                if not all(math.isfinite(v) for v in (x, y, yaw)):
                    raise ValueError(f"non-finite motion in row {row}")
                out[key] = (x, -y, -yaw)
    except (OSError, KeyError, ValueError, csv.Error, UnicodeDecodeError) as exc:
        raise FrameFormatError(f"{path}: not an Oxford radar odometry file ({exc})") from exc
    return out


def scan_poses(stamps, odometry, invert=False):
    """(n_scans, 4, 4) poses of scans with timestamps ``stamps`` in the first one's frame.
    invert=True reads each odometry row the other way round (a convention check)."""
    poses = [np.eye(4)]
    for prev, cur in zip(stamps[:-1], stamps[1:]):
        try:
            x, y, yaw = odometry[(cur, prev)]
        except KeyError:
            raise ConfigError(f"no odometry row from scan {cur} to scan {prev}") from None
        step = se2_pose(x, y, yaw)
        poses.append(poses[-1] @ (np.linalg.inv(step) if invert else step))
    return np.stack(poses)


@dataclass
class PolarSequence:
    """The scans of one recording in time order with their odometry (``load_odometry`` rows, or
    None) and the file it came from."""

    scans: list
    odometry: dict = None
    odometry_path: Path = None

    @property
    def stamps(self):
        """The scans' UNIX times [us], from their names (``<unix_us>.png``)."""
        try:
            return [int(s.path.stem) for s in self.scans]
        except ValueError:
            raise FrameFormatError("odometry needs scans named by their UNIX time in us (<stamp>.png)") from None

    def poses(self, invert=False):
        """(n_scans, 4, 4) scan poses in the first scan's frame (``scan_poses``); the origin for
        every scan without odometry."""
        if self.odometry is None:
            return np.broadcast_to(np.eye(4), (len(self.scans), 4, 4))
        return scan_poses(self.stamps, self.odometry, invert=invert)


def read_sequence(path, layout, odometry=None):
    """A ``PolarSequence`` of one scan file or a directory of scans read with ``layout``; its
    odometry from ``odometry``, else ``radar_odometry.csv`` beside the scans or in ``../gt``."""
    path = Path(path)
    paths = [path] if path.is_file() else scan_paths(path)
    scans = [load_scan(p, layout) for p in paths]
    if odometry is None and path.is_dir():
        odometry = next((c for c in (path / "radar_odometry.csv", path.parent / "gt" / "radar_odometry.csv")
                         if c.is_file()), None)
    return PolarSequence(scans, None if odometry is None else load_odometry(odometry), odometry)


def beam_poses(scans, poses, n_az, azimuth_sign=1.0, motion=True):
    """(n_scans, n_az, 4, 4) per-azimuth poses for a spinning lattice of ``n_az`` azimuths: the
    scan poses interpolated at each azimuth's time (a line fitted to its bursty timestamps),
    times the rotation of its encoder angle (times ``azimuth_sign``) less the lattice's
    i x 2 pi / n_az. motion=False puts every azimuth at its scan's pose (no motion within a
    scan; a consistency check). One scan alone, or scans without odometry, keep their pose."""
    stamps = np.array([s.timestamps_us[0] for s in scans], np.float64)
    out = []
    for k, scan in enumerate(scans):
        if scan.levels.shape[0] != n_az:
            raise FrameFormatError(f"{scan.path}: expected {n_az} azimuths, got {scan.levels.shape[0]}")
        i = np.arange(n_az)
        ts = scan.timestamps_us.astype(np.float64)
        order = i if scan.acquired is None else scan.acquired.astype(np.float64)   # of acquisition
        t = np.polyval(np.polyfit(order, ts, 1), order) if np.ptp(ts) > 0 else ts
        if not motion or len(scans) == 1 or stamps[-1] == stamps[0]:
            a = b = poses[k]
            frac = np.zeros(n_az)
        elif k + 1 < len(scans):
            a, b, t0, t1 = poses[k], poses[k + 1], stamps[k], stamps[k + 1]
            frac = (t - t0) / (t1 - t0)
        else:                                   # the last scan: extend the motion into it
            a, b, t0, t1 = poses[k - 1], poses[k], stamps[k - 1], stamps[k]
            frac = 1 + (t - stamps[k]) / (t1 - t0)
        moved = interpolate_se2(a, b, frac)
        turn = azimuth_sign * scan.angles_rad - i * (2 * math.pi / n_az)
        out.append(moved @ np.stack([se2_pose(0.0, 0.0, float(r)) for r in turn]))
    return np.stack(out)
