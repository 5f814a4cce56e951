"""Spinning-radar scans as polar PNG images, for any unit and any of the published layouts: the
layout comes from the sensor profile's [reader] table (``io.polar_layout.PolarLayout``: azimuths
as rows with metadata columns, as Oxford and Boreas write them, or range bins as rows with no
metadata, as RADIATE and MulRan do; times from the metadata, a side file or the file names).

In the Oxford layout (the built-in ``polar-png`` and ``navtech-cts350x`` profiles) a scan is
(n_azimuths, meta_columns + n_bins):
  columns 0-7   int64 little-endian UNIX timestamp [us] of the azimuth (``timestamp_column``)
  columns 8-9   uint16 little-endian encoder count; angle = count / encoder_counts x 2 pi
  column 10     valid flag (255: measured, else interpolated) (``valid_column``; -1: none)
  columns 11..  range bins of ``bin_spacing_m``, post-FFT power on a log scale, 0-255

Power scaling. The levels are decibels of power, ``db_per_level`` per level (1 for Navtech):
P = 10^(level x db_per_level / 10). Evidence from the Oxford data: the lowest levels that occur
are 0, 6, 9, 12, 14, 15, 17, 18, which are 20 log10(k) for amplitudes k = 1 .. 8 to within a
unit of rounding: the sensor quantises an integer amplitude and writes its power in dB. The
conversion is a 256-entry table: it costs a gather, not an exponential per bin.

Coordinates. radarcl uses x forward, y left, z up (ROS REP-103) everywhere. Navtech azimuths
turn clockwise seen from above (from x towards the right). This reader converts, and nothing
else in radarcl knows the sensor's own sense: angles are returned counter-clockwise from x
towards the left (``clockwise = true`` negates them and puts the rows in counter-clockwise
order) and Oxford odometry rows (x, y, yaw) become (x, -y, -yaw).

Sizes are checked before anything is decoded: a PNG declares its size in a few header bytes,
so a small file that declares 120 Mpixel is refused without allocating them; an image whose
shape does not fit the layout is refused with both shapes and the key to change.
"""

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.geometry import se2_pose
from radarcl.io.png import greyscale_rows, running_sums, verify_png
from radarcl.io.polar_layout import PolarLayout, file_name_time_ns, scan_times_ns
from radarcl.io.trajectory import Trajectory

MAX_PIXELS = 64 * 2 ** 20          # a scan larger than this is refused before decoding


@dataclass(frozen=True)
class PolarScan:
    """One decoded scan; arrays are indexed by azimuth. Angles are REP-103 (counter-clockwise)."""

    path: Path
    timestamps_ns: np.ndarray   # int64 (n_az,): each azimuth's UNIX time [ns]
    angles_rad: np.ndarray      # float64 (n_az,) in [0, 2 pi), counter-clockwise from x
    valid: np.ndarray           # bool (n_az,)
    # uint8 (n_az, n_bins): the levels (log power) or their rows' differences (``coded_levels``),
    # or a ``StoredLevels`` that reads them from the scan's file when they are asked for
    stored_levels: object
    db_per_level: float = 1.0
    acquired: np.ndarray = None  # int (n_az,): row i was the acquired[i]-th azimuth of the turn
    timed: bool = True          # False: the layout gave no time for this scan (a still radar only)
    # True: coded_levels[i, j] = levels[i, j] - levels[i, j - 1] mod 256, [i, 0] the level itself
    # (a PNG's "Sub" rows as the file holds them; the device takes their running sums)
    differenced: bool = False

    @property
    def coded_levels(self):
        """uint8 (n_az, n_bins): the levels as the scan holds them (their rows' differences where
        ``differenced``), read from the file each time where the scan left them there."""
        stored = self.stored_levels
        return stored() if isinstance(stored, StoredLevels) else stored

    @property
    def levels(self):
        """uint8 (n_az, n_bins): each bin's level, log power (the running sums of the
        differences, taken on each access, where the scan holds those)."""
        coded = self.coded_levels
        return running_sums(coded) if self.differenced else coded

    @property
    def shape(self):
        """(n_az, n_bins) of the levels, without reading them."""
        stored = self.stored_levels
        return stored.shape if isinstance(stored, StoredLevels) else tuple(stored.shape)

    @property
    def timestamps_us(self):
        """Each azimuth's UNIX time [us] (int64)."""
        return self.timestamps_ns // 1000

    @property
    def n_bins(self):
        """Range bins per azimuth."""
        return self.shape[1]

    @property
    def start_ns(self):
        """UNIX time [ns] of the scan's first azimuth in acquisition order."""
        first = 0 if self.acquired is None else int(np.argmin(self.acquired))
        return int(self.timestamps_ns[first])

    @property
    def middle_ns(self):
        """UNIX time [ns] of the scan's middle azimuth (the middle row): the time of the pose a
        map keeps for the turn (``Mapping.fuse_source``'s trajectory takes the middle beam's)."""
        return int(self.timestamps_ns[len(self.timestamps_ns) // 2])

    def power(self):
        """Linear power (n_az, n_bins) float32: 10^(level x db_per_level / 10)."""
        return levels_to_power(self.levels, self.db_per_level)


@dataclass(frozen=True)
class StoredLevels:
    """A scan's levels left in its file (``read_sequence(keep_levels=False)``): read again, whole,
    each time they are asked for, so that a recording's scans in memory cost their times and
    angles, not their levels (a drive's scans are read one at a time, beside the fusion)."""

    path: Path
    layout: PolarLayout
    time_ns: int
    period_ns: int
    shape: tuple                # (n_az, n_bins) as first read
    differenced: bool           # as first read

    def __call__(self):
        scan = load_scan(self.path, self.layout, self.time_ns, self.period_ns)
        if scan.shape != self.shape or scan.differenced != self.differenced:
            raise FrameFormatError(f"{self.path}: the scan changed since it was first read (now {scan.shape[0]} x "
                                   f"{scan.shape[1]} levels, first {self.shape[0]} x {self.shape[1]}); read the "
                                   "recording again")
        return scan.stored_levels


_POWER_TABLES = {}


def power_table(db_per_level=1.0):
    """The 256 float32 powers of levels 0 .. 255 at ``db_per_level``: 10^(level x db_per_level /
    10) in float64, rounded once to float32 (level 255 at 1 dB/level is 3.2e25). The one table
    both the host (``levels_to_power``) and the device (``stages.levels``) convert with."""
    if not (np.isfinite(db_per_level) and 0 < db_per_level <= 1.4):
        raise FrameFormatError(f"db_per_level must be in (0, 1.4] so that 255 levels fit float32, "
                               f"got {db_per_level!r}")
    table = _POWER_TABLES.get(db_per_level)
    if table is None:
        table = _POWER_TABLES[db_per_level] = (10.0 ** (np.arange(256) * (db_per_level / 10.0))).astype(np.float32)
        table.flags.writeable = False
    return table


def levels_to_power(levels, db_per_level=1.0):
    """Log-scaled levels -> linear power, float32: uint8 levels through ``power_table``, the same
    floats as 10^(level x db_per_level / 10) in float64 (other integer levels in 0 .. 255 too)."""
    table = power_table(db_per_level)
    levels = np.asarray(levels)
    if levels.dtype != np.uint8:
        if levels.size and (levels.min() < 0 or levels.max() > 255 or not np.all(levels == np.round(levels))):
            return (10.0 ** (np.asarray(levels, np.float64) * (db_per_level / 10.0))).astype(np.float32)
        levels = levels.astype(np.uint8)
    return table.take(levels)                 # take: the same gather as table[levels], in less time


def load_scan(path, layout=PolarLayout(), time_ns=None, period_ns=None):
    """Decode one scan; raises FrameFormatError naming what is wrong (for a shape that does not
    fit the layout: both shapes and the key to change).

    Each azimuth's time comes from the timestamp column; without one, from ``time_ns`` (the
    scan's one time: the azimuth ``layout.timestamp_at`` names; default: the file name's time)
    and the azimuths spread evenly over ``period_ns`` (default: ``layout.scan_period_s``)."""
    import io

    from PIL import Image

    path = Path(path)
    try:
        data = path.read_bytes()          # read once: checked, then decoded from memory
    except OSError as exc:
        raise FrameFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    width, height = verify_png(path, data)
    if width * height > MAX_PIXELS:
        raise FrameFormatError(f"{path}: declares {width} x {height} pixels, more than the {MAX_PIXELS} a scan "
                               "may have; refused before decoding")
    layout.check_shape(path, height, width)
    found = greyscale_rows(path, data, width, height)
    raw, differenced = found if found is not None else (None, False)
    if raw is None:
        try:
            with Image.open(io.BytesIO(data)) as image:
                if image.mode != "L":
                    raise FrameFormatError(f"{path}: expected an 8-bit greyscale image ({layout.orientation}), "
                                           f"got mode {image.mode} of {height} x {width}")
                raw = np.asarray(image)
        except FrameFormatError:
            raise
        except Exception as exc:            # noqa: BLE001 - PIL raises OSError, SyntaxError, zlib.error...
            raise FrameFormatError(f"{path}: not a readable PNG ({type(exc).__name__}: {exc})") from exc
    if raw.dtype != np.uint8 or raw.ndim != 2 or raw.shape != (height, width):
        raise FrameFormatError(f"{path}: expected an 8-bit greyscale image of {height} x {width}, got "
                               f"{raw.shape} {raw.dtype}")
    if time_ns is None and layout.timestamp_column < 0:
        time_ns = file_name_time_ns(path, layout.file_name_unit)
        if time_ns is not None:
            time_ns += int(round(layout.timestamp_offset_s * 1e9))
    return decode_scan(raw, layout, path, time_ns, period_ns, differenced)


def decode_scan(raw, layout, path, time_ns=None, period_ns=None, differenced=False):
    """One scan from its 8-bit image ``raw`` (height, width) as ``layout`` says, named ``path``
    (a file, or a bag's topic and message) in messages; without a timestamp column its azimuths
    are timed from ``time_ns`` (None: untimed) over ``period_ns`` (``load_scan``).
    ``differenced``: ``raw``'s rows are filtered "Sub" (``png.greyscale_rows``); a scan of
    azimuth rows keeps its levels so (``PolarScan.differenced``) and reads its metadata from
    their sums."""
    layout.check_shape(path, *raw.shape)
    if differenced and layout.orientation == "range-rows":
        raw, differenced = running_sums(raw), False     # the filter ran along a bin's azimuths
    if layout.orientation == "range-rows":
        raw = raw.T                     # (azimuths, bins): a view; the row order below copies it
    n_az = raw.shape[0]
    meta, start = raw, None
    if differenced:                     # the metadata columns and the first bin's level, summed
        meta = running_sums(raw[:, :layout.meta_columns + 1])
        start = meta[:, -1]
    timed = True
    if layout.timestamp_column >= 0:
        c = layout.timestamp_column
        timestamps = np.ascontiguousarray(meta[:, c:c + 8]).view("<i8")[:, 0].astype(np.int64) * 1000
    else:
        if time_ns is None:
            time_ns, timed = 0, False
        period = int(period_ns if period_ns is not None else round(layout.scan_period_s * 1e9))
        k = np.arange(n_az, dtype=np.int64) - layout.anchor(n_az)
        timestamps = np.int64(time_ns) + (k * period) // n_az
    if layout.encoder_column >= 0:
        c = layout.encoder_column
        counts = np.ascontiguousarray(meta[:, c:c + 2]).view("<u2")[:, 0]
        if (counts >= layout.encoder_counts).any():
            raise FrameFormatError(f"{path}: encoder counts must be below {layout.encoder_counts}, found "
                                   f"{counts.max()}: check [reader] meta_columns and encoder_column (-1: none)")
        angles = counts / layout.encoder_counts * 2 * np.pi
    else:
        angles = np.arange(n_az) * (2 * np.pi / n_az)
    valid = meta[:, layout.valid_column] == 255 if layout.valid_column >= 0 else np.ones(n_az, bool)
    return assemble_scan(path, timestamps, angles, valid, raw[:, layout.meta_columns:], layout, timed, start)


def assemble_scan(path, timestamps, angles, valid, levels, layout, timed=True, start=None):
    """A ``PolarScan`` of one turn's rows in acquisition order: UNIX times [ns], the sensor's own
    angles [rad] (before ``layout.azimuth_start_deg`` and its sense), valid flags and levels
    (n_az, bins as recorded); the layout's bin shift and sense applied (the one place that
    turns a sensor's rows into REP-103). ``start`` (n_az,) uint8: ``levels`` hold each row's
    differences (``PolarScan.differenced``) and ``start`` each row's first level."""
    n_az = len(levels)
    angles = angles + math.radians(layout.azimuth_start_deg)
    shift = layout.bin_shift()
    if shift >= levels.shape[1]:
        raise FrameFormatError(f"{path}: [reader] range_offset_m = {layout.range_offset_m:g} m drops {shift} bins, every "
                               f"one of the scan's {levels.shape[1]}; check range_offset_m and [range] bin_spacing_m")
    if shift > 0:
        if start is not None:               # the first bin kept: its level, the sum up to it
            start = start + levels[:, 1:shift + 1].sum(axis=1, dtype=np.uint8)
        levels = levels[:, shift:]
    elif shift < 0:
        levels = np.concatenate([np.zeros((n_az, -shift), np.uint8), levels], axis=1)
    order = np.arange(n_az)
    if layout.clockwise:
        # REP-103 angles, and the rows in counter-clockwise order (the first kept), so that row
        # i points near the spinning lattice's azimuth i: the per-azimuth poses then turn each
        # row by a little only.
        angles = -angles
        order = (-order) % n_az
        timestamps, angles, valid, levels = timestamps[order], angles[order], valid[order], levels[order]
        start = None if start is None else start[order]
    angles = np.mod(angles, 2 * np.pi)
    levels = np.ascontiguousarray(levels)
    if start is not None:
        if not levels.flags.owndata:        # still the inflated bytes, or the caller's array
            levels = levels.copy()
        levels[:, max(-shift, 0)] = start   # a zero-padded near end differs by 0 until the first level
    return PolarScan(path, timestamps, angles, valid, levels, layout.db_per_level, order, timed, start is not None)


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
    """The scans of one recording in time order, with their odometry (``load_odometry`` rows)
    or trajectory when one was given or found, and the file it came from."""

    scans: list
    odometry: dict = None
    odometry_path: Path = None
    directory: Path = None

    @property
    def stamps(self):
        """The scans' UNIX times [us] from their names (``<unix_us>.png``): the keys of Oxford
        odometry rows."""
        try:
            return [int(s.path.stem) for s in self.scans]
        except ValueError:
            raise FrameFormatError("odometry needs scans named by their UNIX time in us (<stamp>.png)") from None

    @property
    def timed(self):
        """True when the layout gave every scan a time."""
        return all(s.timed for s in self.scans)

    def poses(self, invert=False):
        """(n_scans, 4, 4) scan poses in the first scan's frame (``scan_poses``); the origin for
        every scan without odometry."""
        if self.odometry is None:
            return np.broadcast_to(np.eye(4), (len(self.scans), 4, 4))
        return scan_poses(self.stamps, self.odometry, invert=invert)

    def trajectory(self, invert=False):
        """The Oxford odometry as a ``Trajectory``: each scan's pose at its first azimuth's time."""
        return Trajectory(np.array([s.start_ns for s in self.scans], np.int64), self.poses(invert),
                          str(self.odometry_path or "odometry"))


def scan_directory(path, layout):
    """The directory that holds the scans: ``path``, or its ``layout.scan_directory`` (a
    recording's root given, e.g. RADIATE's sequence directory holding ``Navtech_Polar/``)."""
    path = Path(path)
    if path.is_dir() and layout.scan_directory and not any(path.glob("*.png")):
        inner = path / layout.scan_directory
        if inner.is_dir():
            return inner
    return path


def read_sequence(path, layout, odometry=None, keep_levels=True, progress=None):
    """A ``PolarSequence`` of one scan file or a directory of scans read with ``layout`` (or a
    recording's directory holding ``layout.scan_directory``), each azimuth timed as the layout
    says; its Oxford odometry from ``odometry``, else ``radar_odometry.csv`` beside the scans or
    in ``../gt`` (``odometry=False``: none; ``io.inputs`` reads every trajectory format).
    ``keep_levels=False``: each scan is read whole once (its checksums, times and angles) and its
    levels left in its file (``StoredLevels``), read again when asked for. ``progress(done,
    total, what)``, if given, hears of the scans read (about a hundred times, and at the last)."""
    path = scan_directory(path, layout)
    paths = [path] if path.is_file() else scan_paths(path)
    directory = path.parent if path.is_file() else path
    times = scan_times_ns(paths, layout, directory)
    period = None
    known = [t for t in times if t is not None]
    if len(known) == len(times) and len(known) > 1:
        steps = np.diff(np.array(known, np.int64))
        if (steps <= 0).any():
            i = int(np.flatnonzero(steps <= 0)[0])
            raise FrameFormatError(f"{directory}: scan {paths[i + 1].name} is timed at or before scan "
                                   f"{paths[i].name} ({known[i + 1] / 1e9:.3f} <= {known[i] / 1e9:.3f} s)")
        period = int(np.median(steps))
    scans, step = [], max(1, -(-len(paths) // 100))
    for p, t in zip(paths, times):
        scan = load_scan(p, layout, t, period)
        if not keep_levels:
            scan = replace(scan, stored_levels=StoredLevels(p, layout, t, period, scan.shape, scan.differenced))
        scans.append(scan)
        if progress is not None and (len(scans) % step == 0 or len(scans) == len(paths)):
            progress(len(scans), len(paths), "scans read (times, angles)")
    if odometry is None and path.is_dir():
        odometry = next((c for c in (path / "radar_odometry.csv", path.parent / "gt" / "radar_odometry.csv")
                         if c.is_file()), None)
    return PolarSequence(scans, load_odometry(odometry) if odometry else None, odometry or None, directory)
