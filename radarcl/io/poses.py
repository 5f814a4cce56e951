"""Trajectories from the files that come with the data: one reader (``read_trajectory``) for
every format below, each giving a ``trajectory.Trajectory`` (REP-103 poses, UNIX ns times on the
radar's clock), checked: times that run backwards, rows that do not parse (file and line
named), quaternions that are not unit.

Formats (``FORMATS``; ``detect_format`` tells them apart by name and first line):
  oxford   Oxford Radar RobotCar ``radar_odometry.csv``: each row the source scan's SE(2) pose in
           the destination scan's frame (x forward, y right, yaw clockwise: converted), chained
           from the first destination scan; times the scans' radar timestamps [us]
  tum      ``t tx ty tz qx qy qz qw`` per line (TUM RGB-D benchmark; seconds, a unit quaternion
           with the scalar last; # comments), T_world_sensor
  kitti    12 numbers per line, the 3x4 [R|t] row-major of each pose in the first pose's frame
           (KITTI odometry devkit); its times one per line in ``times.txt`` beside it (seconds)
           or given; the matrices are taken to describe the radar's own frame
  xyzrpy   ``t x y z roll pitch yaw`` (seconds, metres, radians, REP-103; CSV or spaces): radarcl's
           own, what ``radarcl live --poses`` read before
  radiate  RADIATE's GPS/IMU (``io.radiate``): planar poses from the fixes, heading along the
           track, its clock offset to the radar given or found from the lidar's own motion
  boreas   Boreas' ``applanix/<sensor>_poses.csv`` (pyboreas DATA_REFERENCE.md:155-174): a header,
           then t, x, y, z, vx, vy, vz, roll, pitch, heading, wz, wy, wx (note the reversed
           order of the rates); the rotation as pyboreas' get_transform builds it (utils.py:
           66-80: roll(r) @ pitch(p) @ yaw(y) with its principal matrices); times of 16 digits
           (us) or 19 (ns), told apart by their digits as pyboreas does; a sensor frame with z
           down (Boreas' radar: x forward, y right) is turned half a turn about x into REP-103
"""

import csv
import math
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.io import radiate
from radarcl.io.polar_png import load_odometry
from radarcl.io.trajectory import Trajectory, rotations

FORMATS = ("oxford", "tum", "kitti", "xyzrpy", "radiate", "boreas")
_COLUMNS = {8: "tum", 12: "kitti", 7: "xyzrpy"}


def _first_line(path):
    try:
        with open(path, errors="replace") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    return line.strip()
    except OSError as exc:
        raise FrameFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    return ""


def detect_format(path):
    """The format (one of ``FORMATS``) of a pose file or folder, from its name and first line."""
    path = Path(path)
    if radiate.gps_directory(path) is not None:
        return "radiate"
    if path.is_dir():
        raise FrameFormatError(f"{path}: a folder holds no poses radarcl knows (RADIATE's GPS_IMU_Twist/); give a "
                               f"pose file, or --poses-format ({', '.join(FORMATS)})")
    first = _first_line(path)
    if "source_radar_timestamp" in first:
        return "oxford"
    if first.split(",")[0].strip() in ("GPSTime", "ROSTime"):
        return "boreas"
    fields = first.replace(",", " ").split()
    try:
        [float(v) for v in fields]
    except ValueError:
        fields = None
    if fields and len(fields) in _COLUMNS:
        return _COLUMNS[len(fields)]
    raise FrameFormatError(f"{path}: cannot tell its format from its first line {first[:60]!r}; give "
                           f"--poses-format ({', '.join(FORMATS)})")


def read_trajectory(path, fmt=None, clock_offset_s=None, times=None, report=None):
    """The ``Trajectory`` in ``path`` (``fmt``: one of ``FORMATS``, default ``detect_format``);
    ``clock_offset_s``: how far the file's clock runs ahead of the radar's (subtracted from its
    times; RADIATE: found from the lidar when not given); ``times``: KITTI's times file."""
    path = Path(path)
    if not path.exists():
        raise FrameFormatError(f"{path}: no such pose file")
    fmt = fmt or detect_format(path)
    if fmt not in FORMATS:
        raise FrameFormatError(f"unknown pose format {fmt!r}; formats: {', '.join(FORMATS)}")
    if fmt == "radiate":
        gps = radiate.read_gps_imu(path)
        if clock_offset_s is None:
            root = radiate.gps_directory(path).parent
            clock_offset_s, _, _ = radiate.estimate_clock_offset(gps, root, report)
        return radiate.gps_trajectory(gps, clock_offset_s)
    track = {"oxford": _oxford, "tum": _tum, "kitti": lambda p: _kitti(p, times), "xyzrpy": _xyzrpy,
             "boreas": _boreas}[fmt](path)
    if clock_offset_s:
        track = track.shifted(int(round(clock_offset_s * 1e9)))
    return track


def find_beside(scans):
    """(path, format) of the poses that come with polar scans at ``scans`` (a scan folder or a
    recording's root), or None: Oxford's ``radar_odometry.csv`` beside them or in ``../gt``,
    RADIATE's GPS/IMU beside them, Boreas' ``applanix/radar_poses.csv``."""
    scans = Path(scans)
    folder = scans if scans.is_dir() else scans.parent
    for base in (folder, folder.parent):
        for candidate, fmt in ((base / "radar_odometry.csv", "oxford"), (base / "gt" / "radar_odometry.csv", "oxford"),
                               (base / "applanix" / "radar_poses.csv", "boreas")):
            if candidate.is_file():
                return candidate, fmt
        if radiate.gps_directory(base) is not None and (base / "GPS_IMU_Twist").is_dir():
            return base / "GPS_IMU_Twist", "radiate"
    return None


# -- numeric tables ---------------------------------------------------------------------------------------
def _rows(path, columns, what):
    """(rows (n, columns) float64, line numbers, the first column's times [ns], exact) of a
    numeric table; FrameFormatError with the file and line of the first bad row."""
    out, lines, times = [], [], []
    try:
        with open(path, errors="strict") as f:
            for number, line in enumerate(f, 1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                parts = text.replace(",", " ").split()
                try:
                    values = [float(v) for v in parts]
                except ValueError:
                    values = []
                if len(values) != columns or not np.isfinite(values).all():
                    raise FrameFormatError(f"{path}:{number}: expected {columns} finite numbers ({what}), got "
                                           f"{text[:80]!r}")
                out.append(values)
                lines.append(number)
                times.append(seconds_ns(parts[0]))
    except (OSError, UnicodeDecodeError) as exc:
        raise FrameFormatError(f"{path}: cannot read ({exc})") from exc
    if not out:
        raise FrameFormatError(f"{path}: no poses ({what})")
    return np.array(out), np.array(lines), np.array(times, np.int64)


def _increasing(path, times_ns, lines):
    back = np.flatnonzero(np.diff(times_ns) <= 0)
    if len(back):
        i = int(back[0])
        raise FrameFormatError(f"{path}:{lines[i + 1]}: the trajectory runs backwards: t = {times_ns[i + 1] / 1e9:.6f} s "
                               f"follows t = {times_ns[i] / 1e9:.6f} s on line {lines[i]}")


def seconds_ns(text):
    """A time in seconds written in decimal ("1547131014.351772") as exact int ns: a float64 of
    1.5e9 s keeps only ~0.2 us (an exponent falls back to float)."""
    text = text.strip()
    whole, _, fraction = text.partition(".")
    if whole.lstrip("-").isdigit() and (fraction.isdigit() or not fraction) and len(fraction) <= 9:
        sign = -1 if whole.startswith("-") else 1
        return sign * (abs(int(whole)) * 10 ** 9 + int(fraction.ljust(9, "0") or 0))
    return int(round(float(text) * 1e9))


def _tum(path):
    rows, lines, t = _rows(path, 8, "t tx ty tz qx qy qz qw")
    _increasing(path, t, lines)
    q = rows[:, [7, 4, 5, 6]]                              # (w, x, y, z)
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1) > 1e-3)
    if len(bad):
        raise FrameFormatError(f"{path}:{lines[bad[0]]}: the quaternion has norm {norm[bad[0]]:.4f}, not 1")
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = rotations(q)
    poses[:, :3, 3] = rows[:, 1:4]
    return Trajectory(t, poses, f"TUM {path}")


def _xyzrpy(path):
    rows, lines, t = _rows(path, 7, "t_s x y z roll pitch yaw")
    _increasing(path, t, lines)
    poses = np.stack([pose_from_xyz_rpy(*(float(v) for v in r[1:])) for r in rows])
    return Trajectory(t, poses, f"{path}")


def _kitti(path, times):
    rows, lines, _ = _rows(path, 12, "the 3x4 [R|t] of a pose, row-major")
    times = Path(times) if times else path.parent / "times.txt"
    if not times.is_file():
        raise FrameFormatError(f"{path}: KITTI poses carry no times; put times.txt (one time [s] a line) beside it "
                               "or give --poses-times FILE")
    t_rows, t_lines, t = _rows(times, 1, "one time [s] per pose")
    if len(t_rows) != len(rows):
        raise FrameFormatError(f"{times}: {len(t_rows)} times for the {len(rows)} poses of {path}")
    _increasing(times, t, t_lines)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    det = np.linalg.det(poses[:, :3, :3])
    ortho = np.abs(np.einsum("nij,nkj->nik", poses[:, :3, :3], poses[:, :3, :3]) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((np.abs(det - 1) > 1e-3) | (ortho > 1e-3))
    if len(bad):
        raise FrameFormatError(f"{path}:{lines[bad[0]]}: not a rotation (determinant {det[bad[0]]:.4f})")
    return Trajectory(t, poses, f"KITTI {path}")


def _oxford(path):
    rows = load_odometry(path)                          # {(source_us, destination_us): (x, y, yaw)} in REP-103
    if not rows:
        raise FrameFormatError(f"{path}: no odometry rows")
    by_destination = {dst: (src, step) for (src, dst), step in rows.items()}
    sources = {src for src, _ in rows}
    starts = sorted(dst for dst in by_destination if dst not in sources)
    if len(starts) != 1:
        raise FrameFormatError(f"{path}: the odometry rows do not form one chain ({len(starts)} starts; first "
                               f"scans {', '.join(str(s) for s in starts[:3])})")
    stamp, pose = starts[0], np.eye(4)
    times, poses = [stamp], [pose]
    while stamp in by_destination:
        stamp, (x, y, yaw) = by_destination[stamp][0], by_destination[stamp][1]
        pose = pose @ pose_from_xyz_rpy(x, y, 0.0, yaw=yaw)
        times.append(stamp)
        poses.append(pose)
    if len(times) != len(rows) + 1:
        raise FrameFormatError(f"{path}: the odometry rows do not form one chain ({len(rows) + 1 - len(times)} rows "
                               "off it)")
    return Trajectory(np.array(times, np.int64) * 1000, np.stack(poses), f"Oxford odometry {path}")


def _boreas(path):
    try:
        with open(path, newline="") as f:
            table = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FrameFormatError(f"{path}: cannot read ({exc})") from exc
    if not table or table[0][0].strip() not in ("GPSTime", "ROSTime"):
        raise FrameFormatError(f"{path}:1: expected Boreas' header (GPSTime or ROSTime, easting, northing, ...)")
    times, poses, lines = [], [], []
    for number, row in enumerate(table[1:], 2):
        if not row:
            continue
        try:
            values = [float(v) for v in row]
            stamp = row[0].strip()
            if len(values) != 13 or not stamp.isdigit() or not np.isfinite(values).all():
                raise ValueError
        except ValueError:
            raise FrameFormatError(f"{path}:{number}: expected 13 numbers (t, x, y, z, vx, vy, vz, roll, pitch, "
                                   f"heading, wz, wy, wx) with an integer time, got {','.join(row)[:80]!r}") from None
        times.append(int(stamp) * (1 if len(stamp) >= 19 else 1000))       # 19 digits: ns, else us
        poses.append(_boreas_pose(*values[1:4], *values[7:10]))
        lines.append(number)
    if not times:
        raise FrameFormatError(f"{path}: no poses")
    t = np.array(times, np.int64)
    _increasing(path, t, np.array(lines))
    return Trajectory(t, np.stack(poses), f"Boreas applanix {path}")


def _boreas_pose(x, y, z, roll, pitch, heading):
    """pyboreas' get_transform (C = roll(r) @ pitch(p) @ yaw(y), its principal matrices), as
    REP-103: a frame whose z points down is turned half a turn about its x."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(heading), math.sin(heading))
    c = (np.array([[1, 0, 0], [0, cr, sr], [0, -sr, cr]]) @ np.array([[cp, 0, -sp], [0, 1, 0], [sp, 0, cp]])
         @ np.array([[cy, sy, 0], [-sy, cy, 0], [0, 0, 1]]))
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = c, (x, y, z)
    if c[2, 2] < 0:
        pose = pose @ np.diag([1.0, -1.0, -1.0, 1.0])
    return pose
