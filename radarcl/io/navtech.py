"""Navtech polar scans in the Oxford Radar RobotCar format (Barnes et al., ICRA 2020).

One scan is an 8-bit greyscale PNG of shape (n_azimuths, 11 + n_bins):
  columns 0-7   int64 little-endian UNIX timestamp [us] of the azimuth
  columns 8-9   uint16 little-endian encoder count; angle = count / 5600 x 2 pi
  column 10     valid flag (255: measured, else interpolated)
  columns 11..  range bins of 0.0432 m (CTS350-X), post-FFT power on a log scale, 0-255

Power scaling. The levels are decibels of power, one level per dB: P = 10^(level / 10).
Evidence from the data itself: the lowest levels that occur are 0, 6, 9, 12, 14, 15, 17, 18,
which are 20 log10(k) for amplitudes k = 1 .. 8 to within a unit of rounding, i.e. the
sensor quantises an integer amplitude and writes its power in dB. Level 0 (amplitude <= 1) is
the sensor's floor, so linear power is >= 1. Other scalings can be passed as ``db_per_level``.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError

BIN_SPACING_M = 0.0432        # CTS350-X range bin [m]
ENCODER_COUNTS = 5600         # encoder counts per revolution
DB_PER_LEVEL = 1.0            # see the module docstring
META_COLUMNS = 11


@dataclass(frozen=True)
class NavtechScan:
    """One decoded scan; arrays are indexed by azimuth."""

    path: Path
    timestamps_us: np.ndarray   # int64 (n_az,)
    angles_rad: np.ndarray      # float64 (n_az,) in [0, 2 pi)
    valid: np.ndarray           # bool (n_az,)
    levels: np.ndarray          # uint8 (n_az, n_bins), dB of power

    @property
    def n_bins(self):
        """Range bins per azimuth."""
        return self.levels.shape[1]

    @property
    def bin_spacing_m(self):
        """Range between bins [m]; bin j sits at j x spacing."""
        return BIN_SPACING_M

    def power(self, db_per_level=DB_PER_LEVEL):
        """Linear power (n_az, n_bins) float32: 10^(level x db_per_level / 10)."""
        return levels_to_power(self.levels, db_per_level)


def levels_to_power(levels, db_per_level=DB_PER_LEVEL):
    """Log-scaled levels -> linear power, float32 (level 255 at 1 dB/level is 3.2e25)."""
    if not (np.isfinite(db_per_level) and 0 < db_per_level <= 1.4):
        raise FrameFormatError(f"db_per_level must be in (0, 1.4] so that 255 levels fit float32, "
                               f"got {db_per_level!r}")
    return (10.0 ** (np.asarray(levels, np.float64) * (db_per_level / 10.0))).astype(np.float32)


def load_scan(path):
    """Decode one Oxford-format PNG; raises FrameFormatError naming what is wrong."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    try:
        with Image.open(path) as image:
            raw = np.asarray(image)
    except (OSError, UnidentifiedImageError) as exc:
        raise FrameFormatError(f"{path}: not a readable PNG ({exc})") from exc
    if raw.dtype != np.uint8 or raw.ndim != 2 or raw.shape[1] <= META_COLUMNS or raw.shape[0] < 1:
        raise FrameFormatError(f"{path}: expected an 8-bit greyscale image of shape (azimuths, "
                               f"{META_COLUMNS} + bins), got {raw.shape} {raw.dtype}")
    raw = np.ascontiguousarray(raw)
    timestamps = raw[:, :8].copy().view("<i8")[:, 0]
    counts = raw[:, 8:10].copy().view("<u2")[:, 0]
    if (counts >= ENCODER_COUNTS).any():
        raise FrameFormatError(f"{path}: encoder counts must be below {ENCODER_COUNTS}, found {counts.max()}")
    return NavtechScan(path, timestamps.astype(np.int64), counts / ENCODER_COUNTS * 2 * np.pi,
                       raw[:, 10] == 255, raw[:, META_COLUMNS:].copy())


def scan_paths(directory):
    """The scans (``<unix_us>.png``) of a directory, in time order."""
    paths = sorted(Path(directory).glob("*.png"), key=lambda p: p.stem)
    if not paths:
        raise FrameFormatError(f"no Navtech scans (*.png) in {directory}")
    return paths


def load_odometry(path):
    """Oxford ``radar_odometry.csv``: {(source_radar_us, destination_radar_us): (x, y, yaw)}.

    Each row is the source scan's pose in the destination scan's frame (x forward, y right,
    z down; yaw about z) [m, rad]; rows run from each scan to the one before it."""
    import csv

    path = Path(path)
    out = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                key = (int(row["source_radar_timestamp"]), int(row["destination_radar_timestamp"]))
                out[key] = (float(row["x"]), float(row["y"]), float(row["yaw"]))
    except (OSError, KeyError, ValueError) as exc:
        raise FrameFormatError(f"{path}: not an Oxford radar odometry file ({exc})") from exc
    return out
