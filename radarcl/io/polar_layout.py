"""How a spinning radar's polar PNG scans are laid out: the sensor profile's [reader] table as a
``PolarLayout``, and the scans' times (metadata columns, a side file, or file names).

Layouts met in the published data sets (each built-in profile cites its sources):

  Oxford, Boreas   400 rows of azimuths x (11 metadata + bins) columns: int64 UNIX time [us] of
                   the azimuth (columns 0-7), uint16 encoder count (8-9), a valid byte (10)
  RADIATE, MulRan  range bins as rows x 400 azimuth columns, no metadata at all: the times come
                   from a side file (RADIATE's ``Navtech_Polar.txt``) or from the file names
                   (MulRan: nanoseconds), the angles from a start angle and a direction

Keys (all optional; the defaults are Oxford's):
  orientation        "azimuth-rows" (one row per azimuth) or "range-rows" (one row per range bin)
  meta_columns       columns (azimuth-rows) before the first range bin; 0: none
  timestamp_column   int64 little-endian UNIX time [us] (8 columns); -1: none
  encoder_column     uint16 little-endian encoder count (2 columns); -1: none (angles from
                     azimuth_start_deg, evenly spaced)
  encoder_counts     counts per turn
  valid_column       255 = measured; -1: none
  timestamps         "metadata" (the timestamp column), "side-file" (timestamp_file), or
                     "file-name" (<time>.png); default: metadata when there is a timestamp column
  timestamp_file     the side file, relative to the scans' directory ("../Navtech_Polar.txt")
  file_name_unit     unit of a time in a file name: "auto" (by its digits: 10 s, 13 ms, 16 us,
                     19 ns, as pyboreas' get_time_from_filename), "s", "ms", "us", "ns"
  timestamp_at       which azimuth a scan's one time names: "start" (the first), "middle"
                     (azimuth n/2 - 1: Boreas), "end" (the last)
  timestamp_offset_s added to a scan's one time (from a side file or its name) to get that
                     azimuth's: a time of arrival comes after the scan (RADIATE: -0.25 s)
  scan_period_s      one turn [s] when the scans' own times cannot tell (a single scan)
  azimuth_start_deg  bearing of the first azimuth from straight ahead, turning as ``clockwise``
                     says; with an encoder column, added to every encoder angle
  clockwise          the azimuths turn clockwise seen from above (Navtech)
  range_offset_m     range of bin 0 (Boreas: -0.31 m): whole bins are dropped (or padded) so
                     that bin j lies at j x bin_spacing_m, to within half a bin
  db_per_level       decibels of power per 8-bit level (1 for Navtech)
  scan_directory     where the scans are below a recording's directory ("Navtech_Polar")

A layout that does not match the files is refused with both shapes and the key to change
(``PolarLayout.check_shape``), before anything is decoded further or fused.
"""

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from radarcl.errors import ConfigError, FrameFormatError

ORIENTATIONS = ("azimuth-rows", "range-rows")
TIMESTAMPS = ("metadata", "side-file", "file-name")
FILE_NAME_UNITS = {"s": 10 ** 9, "ms": 10 ** 6, "us": 10 ** 3, "ns": 1}
DIGITS_UNIT = {10: "s", 13: "ms", 16: "us", 19: "ns"}
TIMESTAMP_AT = ("start", "middle", "end")


@dataclass(frozen=True)
class PolarLayout:
    """The layout of a polar PNG scan (the sensor profile's [reader] table; see the module)."""

    orientation: str = "azimuth-rows"
    meta_columns: int = 11
    timestamp_column: int = 0
    encoder_column: int = 8
    encoder_counts: int = 5600
    valid_column: int = 10
    timestamps: str = None
    timestamp_file: str = None
    file_name_unit: str = "auto"
    timestamp_at: str = "start"
    timestamp_offset_s: float = 0.0
    scan_period_s: float = 0.25
    azimuth_start_deg: float = 0.0
    clockwise: bool = True
    range_offset_m: float = 0.0
    db_per_level: float = 1.0
    scan_directory: str = None
    n_azimuth: int = None          # from the profile's [beams]: checked against the images
    bin_spacing_m: float = None    # from the profile's [range]: for range_offset_m

    @classmethod
    def of(cls, sensor):
        """The layout a sensor profile's [reader] table gives (defaults: Oxford)."""
        reader = dict(sensor.tables.get("reader", {}))
        if reader.pop("format", "polar-png") not in ("polar-png", "rosbag"):   # a bag of polar images too
            raise ConfigError(f"sensor {sensor.name} is not read as polar PNG scans")
        beams, rng = sensor.tables.get("beams", {}), sensor.tables.get("range", {})
        return cls(**reader, n_azimuth=beams.get("n_azimuth"), bin_spacing_m=rng.get("bin_spacing_m"))

    def __post_init__(self):
        if self.timestamps is None:
            object.__setattr__(self, "timestamps", "metadata" if self.timestamp_column >= 0 else "file-name")
        for key, allowed in (("orientation", ORIENTATIONS), ("timestamps", TIMESTAMPS),
                             ("file_name_unit", ("auto", *FILE_NAME_UNITS)), ("timestamp_at", TIMESTAMP_AT)):
            if getattr(self, key) not in allowed:
                raise ConfigError(f"[reader] {key} = {getattr(self, key)!r}: allowed {', '.join(map(repr, allowed))}")
        if self.orientation == "range-rows" and self.meta_columns:
            raise ConfigError(f"[reader] orientation = 'range-rows' reads images without metadata columns; set "
                              f"meta_columns = 0 (got {self.meta_columns})")
        for name, width in (("timestamp_column", 8), ("encoder_column", 2), ("valid_column", 1)):
            col = getattr(self, name)
            if col >= 0 and col + width > self.meta_columns:
                raise ConfigError(f"[reader] {name} = {col} needs {width} columns inside the {self.meta_columns} "
                                  f"metadata columns (-1: none)")
        if self.timestamps == "metadata" and self.timestamp_column < 0:
            raise ConfigError("[reader] timestamps = 'metadata' needs a timestamp_column (>= 0); without one, "
                              "set timestamps = 'side-file' or 'file-name'")
        if self.timestamps == "side-file" and not self.timestamp_file:
            raise ConfigError("[reader] timestamps = 'side-file' needs timestamp_file = \"...\" (relative to the "
                              "scans' directory)")
        if not math.isfinite(self.timestamp_offset_s):
            raise ConfigError("[reader] timestamp_offset_s must be a finite number of seconds")
        if not (math.isfinite(self.scan_period_s) and self.scan_period_s > 0):
            raise ConfigError(f"[reader] scan_period_s must be a positive number of seconds, got {self.scan_period_s}")

    # -- the shape of an image ------------------------------------------------------------------------------
    def check_shape(self, path, rows, columns):
        """Raise FrameFormatError with both shapes and the key to change when an image of ``rows``
        x ``columns`` cannot be a scan of this layout; returns (n_azimuths, n_bins)."""
        n_az = self.n_azimuth
        if self.orientation == "azimuth-rows":
            az, bins = rows, columns - self.meta_columns
            expected = f"{n_az or 'n'} azimuth rows x ({self.meta_columns} metadata + bins) columns"
        else:
            az, bins = columns, rows
            expected = f"bins as rows x {n_az or 'n'} azimuth columns"
        said = f"{path}: the image is {rows} x {columns} (rows x columns); the layout reads {expected}"
        if n_az is not None and az != n_az:
            other_az = rows if self.orientation == "range-rows" else columns
            if other_az == n_az:
                flip = "range-rows" if self.orientation == "azimuth-rows" else "azimuth-rows"
                hint = (f"; its {'columns' if flip == 'range-rows' else 'rows'} look like the {n_az} azimuths: set "
                        f"[reader] orientation = \"{flip}\""
                        + (" and meta_columns = 0" if flip == "range-rows" and self.meta_columns else ""))
            else:
                hint = "; set [beams] n_azimuth to the scans' azimuth count, or check [reader] orientation"
            raise FrameFormatError(said + f" ({az} azimuths where the sensor has {n_az})" + hint)
        if az < 1:
            raise FrameFormatError(said + ": no azimuths")
        if bins < 1:
            raise FrameFormatError(said + f": no range bins after {self.meta_columns} metadata columns; check "
                                          "[reader] meta_columns")
        return az, bins

    def bin_shift(self):
        """Whole bins to drop (> 0) or pad (< 0) at the near end for ``range_offset_m``."""
        if not self.range_offset_m:
            return 0
        if not self.bin_spacing_m:
            raise ConfigError("[reader] range_offset_m needs the profile's [range] bin_spacing_m")
        return -int(round(self.range_offset_m / self.bin_spacing_m))

    def anchor(self, n_az):
        """The azimuth (in acquisition order) a scan's one time names (``timestamp_at``)."""
        return {"start": 0, "middle": n_az // 2 - 1, "end": n_az - 1}[self.timestamp_at]


# -- times ----------------------------------------------------------------------------------------------
def file_name_time_ns(path, unit="auto"):
    """UNIX time [ns] a scan's file name gives (``<time>.png``), or None when the name is not a
    time in that unit (``auto``: 10, 13, 16 or 19 digits)."""
    stem = Path(path).stem
    if not stem.isdigit():
        return None
    if unit == "auto":
        unit = DIGITS_UNIT.get(len(stem))
        if unit is None:
            return None
    return int(stem) * FILE_NAME_UNITS[unit]


_RADIATE_LINE = re.compile(r"^\s*Frame:\s*(\S+)\s+Time:\s*(\d+)(?:\.(\d+))?\s*$")


def seconds_text_to_ns(whole, fraction):
    """UNIX seconds written as "whole.fraction" -> int ns. The fraction is left-padded with zeros
    to 9 digits, as RADIATE's SDK does (``__timestamp_format``): some of its files print the
    nanoseconds without their leading zeros, so "12.5" there means 12.000000005 s."""
    fraction = fraction or ""
    if len(fraction) > 9:
        fraction = fraction[:9]
    return int(whole) * 10 ** 9 + int(fraction.rjust(9, "0") or 0)


def read_side_file(path):
    """{frame name: UNIX time [ns]} of a RADIATE-style side file (``Frame: 000007 Time:
    1574859773.185142137`` per line); FrameFormatError with the file and line of a bad line."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise FrameFormatError(f"{path}: cannot read the scans' times ({exc})") from exc
    out = {}
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        m = _RADIATE_LINE.match(line)
        if m is None:
            raise FrameFormatError(f"{path}:{number}: expected 'Frame: NNNNNN Time: <unix seconds>', got {line[:80]!r}")
        out[m.group(1)] = seconds_text_to_ns(m.group(2), m.group(3))
    if not out:
        raise FrameFormatError(f"{path}: no 'Frame: ... Time: ...' lines")
    return out


def scan_times_ns(paths, layout, directory):
    """Each scan's one UNIX time [ns] (the azimuth ``timestamp_at`` names, ``timestamp_offset_s``
    applied) from the side file or the file names, or None for a scan whose time the layout
    cannot give (metadata layouts: the times are in the images)."""
    offset = int(round(layout.timestamp_offset_s * 1e9))
    if layout.timestamps == "metadata":
        return [None] * len(paths)
    if layout.timestamps == "file-name":
        times = [file_name_time_ns(p, layout.file_name_unit) for p in paths]
        return [None if t is None else t + offset for t in times]
    side = Path(os.path.normpath(Path(directory) / layout.timestamp_file))     # lexical: ".." of the path given
    if not side.is_file():
        raise FrameFormatError(f"{side}: no such side file of scan times ([reader] timestamp_file = "
                               f"{layout.timestamp_file!r}, relative to {directory})")
    times = read_side_file(side)
    out = []
    for p in paths:
        t = times.get(Path(p).stem)
        if t is None:
            raise FrameFormatError(f"{side}: no time for scan {Path(p).name} (frame {Path(p).stem!r})")
        out.append(t + offset)
    return out


# -- which published recording a directory is ------------------------------------------------------------
# (built-in profile, what marks it, the test): a recording's own files, narrowest first (Boreas and
# Oxford both keep their scans in radar/; Boreas alone has applanix/).
RECORDINGS = (
    ("radiate-cts350x", "RADIATE (Navtech_Polar/)", lambda d: (d / "Navtech_Polar").is_dir() or d.name == "Navtech_Polar"),
    ("mulran", "MulRan (sensor_data/radar/polar/)",
     lambda d: (d / "sensor_data" / "radar" / "polar").is_dir() or d.parts[-3:] == ("sensor_data", "radar", "polar")),
    ("boreas-cir204", "Boreas (radar/ beside applanix/)",
     lambda d: (d / "applanix").is_dir() or (d.name == "radar" and (d.parent / "applanix").is_dir())),
    ("navtech-cts350x", "Oxford Radar RobotCar (radar/ with radar.timestamps or gt/radar_odometry.csv)",
     lambda d: any((b / "radar.timestamps").is_file() or (b / "gt" / "radar_odometry.csv").is_file()
                   for b in (d, d.parent)) and ((d / "radar").is_dir() or d.name == "radar")),
)


def recognise(path):
    """(built-in sensor profile name, the layout's name) of a directory laid out as one of the
    published recordings (``RECORDINGS``: RADIATE, MulRan, Boreas, Oxford), or None."""
    d = Path(path)
    if not d.is_dir():
        return None
    return next(((name, what) for name, what, test in RECORDINGS if test(d.resolve())), None)
