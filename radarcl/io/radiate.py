"""RADIATE's other sensors, read as the data set writes them (Sheeny et al., ICRA 2021; SDK
github.com/marcelsheeny/radiate_sdk at b1d5de55, "SDK" below): the GPS/IMU as a trajectory,
the Velodyne frames, the vehicle annotations.

GPS/IMU (``GPS_IMU_Twist/NNNNNN.txt``, times in ``GPS_IMU_Twist.txt``), 18 comma-separated lines
(SDK README.md:59-72): 1 latitude, longitude [deg], altitude [m]; 2-4 position covariance;
5 orientation quaternion x, y, z, w; 6 angular velocity; 7 linear acceleration; 8-16 covariances;
17 twist linear; 18 twist angular. What the files hold, measured on ``radiate_fog``:
- every frame is written twice (frames 2k-1 and 2k are byte-identical, times included): the
  duplicates are dropped;
- a run of frames is stamped early (frames 29-50 by 0.41 s: the time steps back while the
  positions go on advancing at 20 Hz): such a run is moved to where the stream's own rate puts
  it (``repair_stamps``), and the note says which frames by how much;
- the quaternion is not a heading (its yaw turns against the gyro's, 54 deg off the track):
  the heading is the track's, from the positions (``gps_trajectory``);
- line 17 is a world velocity (x north, y east): its direction agrees with the track;
- the clock runs about 65.7 s ahead of the radar's, not the 64 s that the sensors' first frames
  suggest: ``estimate_clock_offset`` finds it from the lidar's own motion, or it is given.

The trajectory is planar (x east, y north of the first fix, z 0, a yaw): the radar maps a
plane, the GPS altitude jumps by 0.6 m within a second here, and there is no usable attitude.

Velodyne (``velo_lidar/NNNNNN.csv``): x, y, z, intensity, ring per line, no header (the SDK's
``read_lidar`` reads the first point as a header and drops it); x right, y forward, z up
(measured: the car drives along +y, its right turn is a negative yaw rate about +z), turned
here into REP-103. The points are in the lidar's own frame (SDK README.md:86; its README.md:233
says "relative to the radar", the data says otherwise): the lidar sits at ``LIDAR_IN_RADAR_M``
in the radar's frame, the SDK's lidar-to-radar calibration (README.md:141-144, rotation ~0),
read in the radar's x right, y forward, z up. Measured (``radarcl evaluate-lidar``): without it
every radar map and the raw intensity agree best with the lidar's truth shifted 0.6 m to the
right; with it, unshifted.

Annotations (``annotations/annotations.json``): per object and radar frame a box in pixels of
RADIATE's 1152 x 1152 Cartesian radar image (0.173611 m per pixel, the radar at pixel corner
(576, 576)), the top-left corner and size of the unrotated box, turned about its centre by
-rotation degrees in image axes (SDK radiate.py:845-865, draw_boundingbox_rot).
"""

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.io.polar_layout import read_side_file
from radarcl.io.trajectory import EARTH_RADIUS_M, Trajectory

LIDAR_IN_RADAR_M = (0.6003, -0.120102, 0.250012)   # x right, y forward, z up (see the module)
CARTESIAN_PIXELS, CARTESIAN_M_PER_PIXEL = 1152, 0.173611
TRACK_WINDOW_M = 1.0                # the track's heading from positions at least this far apart
STILL_M_S = 0.5                     # slower than this, the heading is held (a parked car has no track)


def _numbers(path, number, line, count):
    try:
        values = [float(v) for v in line.split(",")]
    except ValueError:
        values = []
    if len(values) != count or not np.isfinite(values).all():
        raise FrameFormatError(f"{path}:{number}: expected {count} comma-separated numbers, got {line.strip()[:80]!r}")
    return values


def gps_directory(path):
    """The ``GPS_IMU_Twist`` folder of a RADIATE sequence given its root, the folder or its
    ``GPS_IMU_Twist.txt``, or None when there is none."""
    path = Path(path)
    for candidate in (path / "GPS_IMU_Twist", path.parent / "GPS_IMU_Twist", path.with_suffix(""), path):
        if candidate.is_dir() and candidate.name == "GPS_IMU_Twist" and candidate.with_suffix(".txt").is_file():
            return candidate
    return None


@dataclass(frozen=True)
class GpsImu:
    """RADIATE's GPS/IMU samples, duplicates dropped and stamps repaired: frame names, times
    [ns] on the GPS/IMU's own clock, latitude, longitude [deg], altitude [m], twist velocity
    (n, 3) (x north, y east), angular velocity (n, 3); ``notes`` say what was repaired."""

    frames: list
    times_ns: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt: np.ndarray
    velocity: np.ndarray
    gyro: np.ndarray
    source: str
    notes: tuple = ()

    def local_xy(self):
        """(n, 2) metres east and north of the first fix (a local plane: equirectangular)."""
        lat0 = math.radians(self.lat[0])
        east = np.radians(self.lon - self.lon[0]) * EARTH_RADIUS_M * math.cos(lat0)
        north = np.radians(self.lat - self.lat[0]) * EARTH_RADIUS_M
        return np.stack([east, north], axis=1)

    def speed(self):
        """Horizontal speed [m/s] from the twist."""
        return np.hypot(self.velocity[:, 0], self.velocity[:, 1])


def read_gps_imu(path):
    """A ``GpsImu`` of a RADIATE sequence (its root, ``GPS_IMU_Twist/`` or its .txt);
    FrameFormatError with the file and line of anything malformed."""
    folder = gps_directory(path)
    if folder is None:
        raise FrameFormatError(f"{path}: no RADIATE GPS/IMU here (GPS_IMU_Twist/ with GPS_IMU_Twist.txt beside it)")
    times = read_side_file(folder.with_suffix(".txt"))
    rows = []
    for frame in sorted(times, key=lambda f: (len(f), f)):
        file = folder / f"{frame}.txt"
        try:
            lines = file.read_text().splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise FrameFormatError(f"{file}: cannot read ({exc})") from exc
        if len(lines) < 18:
            raise FrameFormatError(f"{file}: expected 18 lines (RADIATE GPS_IMU_Twist), got {len(lines)}")
        fix = _numbers(file, 1, lines[0], 3)
        gyro = _numbers(file, 6, lines[5], 3)
        twist = _numbers(file, 17, lines[16], 3)
        rows.append((frame, times[frame], fix, twist, gyro, "\n".join(lines)))
    if len(rows) < 2:
        raise FrameFormatError(f"{folder}: a trajectory needs at least 2 GPS/IMU frames, found {len(rows)}")
    kept = [rows[0]]
    for row in rows[1:]:
        if row[1] == kept[-1][1] and row[5] == kept[-1][5]:
            continue                                    # written twice: the same sample
        kept.append(row)
    notes = []
    if len(kept) < len(rows):
        notes.append(f"{folder}: {len(rows) - len(kept)} of {len(rows)} frames repeat the frame before them "
                     f"(times and values): dropped")
    frames = [r[0] for r in kept]
    stamps, repaired = repair_stamps(np.array([r[1] for r in kept], np.int64), frames, str(folder.with_suffix(".txt")))
    notes += repaired
    fix = np.array([r[2] for r in kept])
    return GpsImu(frames, stamps, fix[:, 0], fix[:, 1], fix[:, 2], np.array([r[3] for r in kept]),
                  np.array([r[4] for r in kept]), str(folder), tuple(notes))


def repair_stamps(times_ns, frames, where):
    """(times, notes): a run of samples stamped early (the time steps back, later steps are the
    stream's own, and the run ends in a gap of the same size) moved later by that amount.
    Anything else that runs backwards is refused with the frames and times named."""
    t = np.array(times_ns, np.int64)
    notes = []
    while True:
        steps = np.diff(t)
        back = np.flatnonzero(steps <= 0)
        if not len(back):
            return t, notes
        nominal = int(np.median(steps[steps > 0])) if (steps > 0).any() else 0
        i = int(back[0])
        early = int(t[i] + nominal - t[i + 1])
        ends = [j for j in range(i + 1, len(steps)) if abs(int(steps[j]) - (nominal + early)) <= nominal // 2]
        run_ok = ends and all(abs(int(s) - nominal) <= nominal // 2 for s in steps[i + 1:ends[0]])
        if nominal <= 0 or not run_ok:
            raise FrameFormatError(f"{where}: the times run backwards at frame {frames[i + 1]} "
                                   f"({t[i + 1] / 1e9:.3f} s after {t[i] / 1e9:.3f} s at frame {frames[i]}) and no "
                                   "run of early stamps explains it")
        j = ends[0]
        t[i + 1:j + 1] += early
        notes.append(f"{where}: frames {frames[i + 1]}-{frames[j]} are stamped {early / 1e9:.3f} s early (the time "
                     f"steps back while the stream goes on every {nominal / 1e9:.3f} s): moved later by that much")


def track_heading(xy, times_ns):
    """Heading [rad, counter-clockwise from x] along a planar track: the direction between the
    positions ``TRACK_WINDOW_M`` behind and ahead (central differences over a distance, not a
    sample count: GPS noise of centimetres moves a 1 m chord's angle by a degree); held where
    the vehicle is slower than ``STILL_M_S``; None when it never moves."""
    n = len(xy)
    step = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]
    heading = np.full(n, np.nan)
    for i in range(n):
        lo = np.searchsorted(step, step[i] - TRACK_WINDOW_M / 2, side="right") - 1
        hi = np.searchsorted(step, step[i] + TRACK_WINDOW_M / 2)
        lo, hi = max(lo, 0), min(hi, n - 1)
        d = xy[hi] - xy[lo]
        dt = (times_ns[hi] - times_ns[lo]) / 1e9
        if dt > 0 and np.hypot(*d) / dt >= STILL_M_S and np.hypot(*d) > 0:
            heading[i] = math.atan2(d[1], d[0])
    good = np.flatnonzero(np.isfinite(heading))
    if not len(good):
        return None
    unwrapped = np.unwrap(heading[good])
    return np.interp(np.arange(n), good, unwrapped)     # held at the ends, interpolated between


def gps_trajectory(gps, clock_offset_s):
    """The ``Trajectory`` of a ``GpsImu`` on the radar's clock (its times less ``clock_offset_s``):
    planar poses at each fix, heading along the track (see the module)."""
    xy = gps.local_xy()
    heading = track_heading(xy, gps.times_ns)
    notes = list(gps.notes)
    if heading is None:
        heading = np.zeros(len(xy))
        notes.append(f"{gps.source}: the vehicle never moves faster than {STILL_M_S} m/s: no track, the heading is 0")
    c, s = np.cos(heading), np.sin(heading)
    poses = np.zeros((len(xy), 4, 4))
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 2, 2] = poses[:, 3, 3] = 1.0
    poses[:, :2, 3] = xy
    notes.append(f"{gps.source}: GPS/IMU clock {clock_offset_s:+.3f} s from the radar's; planar poses (x east, "
                 "y north of the first fix), heading along the track")
    offset = int(round(clock_offset_s * 1e9))
    anchor = dict(latitude_deg=float(gps.lat[0]), longitude_deg=float(gps.lon[0]), altitude_m=float(gps.alt[0]),
                  heading_deg=0.0)                          # x east, y north of the first fix
    return Trajectory(gps.times_ns - offset, poses, f"RADIATE GPS/IMU {gps.source}", tuple(notes), anchor)


# -- the lidar --------------------------------------------------------------------------------------------
def lidar_directory(path):
    """The ``velo_lidar`` folder of a RADIATE sequence (its root or a folder beside), or None."""
    path = Path(path)
    for candidate in (path / "velo_lidar", path.parent / "velo_lidar", path):
        if candidate.is_dir() and candidate.name == "velo_lidar" and candidate.with_suffix(".txt").is_file():
            return candidate
    return None


def read_lidar_frame(path):
    """(n, 5) float64 x, y, z, intensity, ring of one ``velo_lidar`` csv (no header: every line
    is a point), in the file's axes (x right, y forward, z up)."""
    try:
        points = np.loadtxt(path, delimiter=",", ndmin=2)
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"{path}: not a RADIATE lidar frame of 'x,y,z,intensity,ring' lines ({exc})") from exc
    if points.shape[1] != 5 or not np.isfinite(points).all():
        raise FrameFormatError(f"{path}: expected 5 finite numbers per line (x,y,z,intensity,ring), got "
                               f"{points.shape[1]} columns")
    return points


def lidar_to_rep103(points):
    """(n, 3) REP-103 points (x forward, y left, z up) of RADIATE lidar rows (x right, y forward)."""
    return np.stack([points[:, 1], -points[:, 0], points[:, 2]], axis=1)


def lidar_mount():
    """The lidar's pose (4x4) in the radar's REP-103 frame (``LIDAR_IN_RADAR_M``, no rotation)."""
    right, forward, up = LIDAR_IN_RADAR_M
    mount = np.eye(4)
    mount[:3, 3] = (forward, -right, up)
    return mount


def lidar_frames(path):
    """[(frame name, UNIX time [ns], csv path)] of a sequence's lidar in time order."""
    folder = lidar_directory(path)
    if folder is None:
        raise FrameFormatError(f"{path}: no RADIATE lidar here (velo_lidar/ with velo_lidar.txt beside it)")
    times = read_side_file(folder.with_suffix(".txt"))
    out = [(p.stem, times[p.stem], p) for p in sorted(folder.glob("*.csv")) if p.stem in times]
    if not out:
        raise FrameFormatError(f"{folder}: no lidar frame has a time in {folder.with_suffix('.txt')}")
    return sorted(out, key=lambda f: f[1])


# -- the clock offset -------------------------------------------------------------------------------------
OFFSET_STEP_S = 0.01
OFFSET_MARGIN_M_S = 0.05            # offsets whose speed rms is within this of the best: the interval stated


def estimate_clock_offset(gps, root, report=None):
    """(offset [s], interval (lo, hi) [s], rms [m/s]) by which the GPS/IMU clock runs ahead of the
    lidar's (and the radar's: RADIATE's radar and lidar agree within ~0.2 s): the offset at which
    the GPS twist speed best matches the speed of the lidar's own motion (``lidar_odometry``),
    searched over every offset for which the GPS covers the lidar frames. Refused with the
    reason when the lidar is missing or its speed cannot pin the offset (a steady speed)."""
    from radarcl.io import lidar_odometry

    frames = [(t, lidar_to_rep103(read_lidar_frame(p))) for _, t, p in lidar_frames(root)]
    t, speed, _, _ = lidar_odometry.ego_motion(frames, speed_guess_m_s=float(np.median(gps.speed())))
    g = (gps.times_ns - gps.times_ns[0]) / 1e9
    tl = (t - gps.times_ns[0]) / 1e9
    lo, hi = g[0] - tl[0], g[-1] - tl[-1]
    if hi < lo:
        raise FrameFormatError(f"{gps.source}: the GPS/IMU spans {g[-1]:.2f} s, less than the lidar's "
                               f"{tl[-1] - tl[0]:.2f} s: no clock offset can be found; give --clock-offset")
    offsets = np.arange(lo, hi + OFFSET_STEP_S / 2, OFFSET_STEP_S)
    gps_speed = gps.speed()
    rms = np.array([np.sqrt(np.mean((np.interp(tl + o, g, gps_speed) - speed) ** 2)) for o in offsets])
    best = int(np.argmin(rms))
    near = offsets[rms <= rms[best] + OFFSET_MARGIN_M_S]
    if near[0] <= offsets[0] + 1e-9 and near[-1] >= offsets[-1] - 1e-9:
        raise FrameFormatError(f"{gps.source}: the lidar's speed ({speed.min():.1f}-{speed.max():.1f} m/s) matches "
                               f"the GPS at every offset from {lo:.2f} to {hi:.2f} s: too steady to find the clock "
                               "offset; give --clock-offset")
    offset = float(offsets[best])
    if report is not None:
        report(f"clock offset GPS/IMU - lidar {offset:+.2f} s (speed rms {rms[best]:.3f} m/s over {len(t)} lidar "
               f"pairs; within {OFFSET_MARGIN_M_S} m/s of it from {near[0]:+.2f} to {near[-1]:+.2f} s)")
    return offset, (float(near[0]), float(near[-1])), float(rms[best])


# -- annotations ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Box:
    """An annotated object in one radar frame: its corners (4, 2) [m] in the radar's REP-103
    frame at that frame's time."""

    object_id: int
    class_name: str
    frame: int            # the radar frame number (1-based, as the scans' names)
    corners: np.ndarray


def box_corners(position, rotation_deg):
    """(4, 2) REP-103 corners [m] of a RADIATE box ([x, y, width, height] pixels, rotation)."""
    x, y, w, h = (float(v) for v in position)
    theta = math.radians(-float(rotation_deg))
    r = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    pixels = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]])
    centre = np.array([x + w / 2, y + h / 2])
    pixels = (pixels - centre) @ r.T + centre
    right = (pixels[:, 0] - CARTESIAN_PIXELS / 2) * CARTESIAN_M_PER_PIXEL
    ahead = (CARTESIAN_PIXELS / 2 - pixels[:, 1]) * CARTESIAN_M_PER_PIXEL
    return np.stack([ahead, -right], axis=1)


def read_annotations(path):
    """[Box] of a RADIATE ``annotations.json`` (or the sequence root holding ``annotations/``)."""
    path = Path(path)
    if path.is_dir():
        path = path / "annotations" / "annotations.json"
    try:
        objects = json.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise FrameFormatError(f"{path}: not a RADIATE annotations file ({exc})") from exc
    boxes = []
    try:
        for obj in objects:
            for index, box in enumerate(obj["bboxes"]):
                if not box:                             # null, or [] in some files: no box in that frame
                    continue
                boxes.append(Box(int(obj["id"]), str(obj["class_name"]), index + 1,
                                 box_corners(box["position"], box["rotation"])))
    except (TypeError, KeyError, ValueError) as exc:
        raise FrameFormatError(f"{path}: expected objects with id, class_name and bboxes of position [x, y, w, h] "
                               f"and rotation ({type(exc).__name__}: {exc})") from exc
    return boxes
