"""A trajectory: a sensor's poses with their times, whatever file they came from
(``io.poses.read_trajectory``), interpolated at any time (one pose per azimuth of a spinning
radar) and checked before anything is fused.

Poses are 4x4 rigid transforms T_world_sensor in REP-103 (x forward, y left, z up; a point of
the sensor's frame times T is the point in the world). Times are int64 UNIX nanoseconds on the
radar's clock (a reader shifts a sensor's own clock by its offset). Between samples, positions
are interpolated linearly and rotations by slerp; within one sample interval past either end
the motion is extended at constant velocity, up to 1.5 sample intervals (an Oxford odometry
file ends at the last scan's first azimuth, and the scan goes on for a turn of 247-253 ms
while its scans come every ~250 ms); farther is refused with the times named.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from radarcl.errors import FrameFormatError

DEFAULT_MAX_SPEED_M_S = 70.0      # faster than a road vehicle: a pose file that jumps, not a car
EXTEND_STEPS = 1.5                # how far past its ends a trajectory is extended, in sample intervals


def unix_text(t_ns):
    """A UNIX time [ns] as seconds with 3 decimals, for messages."""
    return f"{int(t_ns) / 1e9:.3f}"


@dataclass(frozen=True)
class Trajectory:
    """``poses[i]`` (4x4, T_world_sensor, REP-103) at ``times_ns[i]`` (strictly increasing
    int64 UNIX ns); ``source`` says where it came from, ``notes`` what the reader repaired or
    assumed."""

    times_ns: np.ndarray
    poses: np.ndarray
    source: str = "poses"
    notes: tuple = ()
    anchor: dict = None             # where the world frame lies on the Earth, when known (``GeoAnchor``)

    def __post_init__(self):
        t = np.asarray(self.times_ns, np.int64).reshape(-1)
        p = np.asarray(self.poses, np.float64)
        if p.shape != (len(t), 4, 4) or len(t) < 1:
            raise FrameFormatError(f"{self.source}: expected n >= 1 poses (n, 4, 4) with n times, got {p.shape} "
                                   f"and {len(t)} times")
        if not np.isfinite(p).all():
            raise FrameFormatError(f"{self.source}: a pose is not finite")
        back = np.flatnonzero(np.diff(t) <= 0)
        if len(back):
            i = int(back[0])
            raise FrameFormatError(f"{self.source}: the trajectory runs backwards: pose {i + 1} at t = "
                                   f"{unix_text(t[i + 1])} s follows pose {i} at {unix_text(t[i])} s "
                                   f"({len(back)} such step(s))")
        object.__setattr__(self, "times_ns", t)
        object.__setattr__(self, "poses", p)

    def __len__(self):
        return len(self.times_ns)

    @property
    def step_ns(self):
        """The median interval between samples [ns] (0 for one sample)."""
        return int(np.median(np.diff(self.times_ns))) if len(self) > 1 else 0

    # -- poses at any time -----------------------------------------------------------------------------------
    def covers(self, t_ns, what="the scans"):
        """FrameFormatError naming both intervals unless every time of ``t_ns`` lies within the
        trajectory, or within ``EXTEND_STEPS`` sample intervals past its ends (one sample: any
        time)."""
        t = np.asarray(t_ns, np.int64)
        if len(self) == 1 or t.size == 0:
            return
        slack = int(EXTEND_STEPS * self.step_ns)
        lo, hi = self.times_ns[0] - slack, self.times_ns[-1] + slack
        if t.min() < lo or t.max() > hi:
            early = max(0, int(lo - t.min())) / 1e9
            late = max(0, int(t.max() - hi)) / 1e9
            gap = " and ".join(s for s in (f"{early:.3f} s before its start" if early else "",
                                           f"{late:.3f} s after its end" if late else "") if s)
            raise FrameFormatError(
                f"{self.source}: the trajectory covers t = {unix_text(self.times_ns[0])} .. "
                f"{unix_text(self.times_ns[-1])} s but {what} run {unix_text(t.min())} .. {unix_text(t.max())} s "
                f"({gap}); a clock offset between the two (--clock-offset) or the wrong pose file?")

    def at(self, t_ns):
        """Poses (m, 4, 4) at the times ``t_ns`` (m,) [ns]; checked by ``covers`` first."""
        t = np.asarray(t_ns, np.int64).reshape(-1)
        self.covers(t)
        if len(self) == 1:
            return np.broadcast_to(self.poses[0], (len(t), 4, 4)).copy()
        i = np.clip(np.searchsorted(self.times_ns, t, side="right"), 1, len(self) - 1)
        t0, t1 = self.times_ns[i - 1], self.times_ns[i]
        a = ((t - t0).astype(np.float64) / (t1 - t0).astype(np.float64))[:, None]
        p0, p1 = self.poses[i - 1], self.poses[i]
        q = self._quaternions
        out = np.zeros((len(t), 4, 4))
        out[:, 3, 3] = 1.0
        out[:, :3, 3] = (1 - a) * p0[:, :3, 3] + a * p1[:, :3, 3]
        out[:, :3, :3] = rotations(slerp(q[i - 1], q[i], a[:, 0]))
        return out

    @cached_property
    def _quaternions(self):
        """Every pose's rotation as a quaternion (``quaternions``, row by row), taken once: a
        drive asks ``at`` for each azimuth of each scan, and they fall between a few poses."""
        return quaternions(self.poses[:, :3, :3])

    # -- checks and summaries ----------------------------------------------------------------------------------
    def check_motion(self, max_speed_m_s=DEFAULT_MAX_SPEED_M_S):
        """FrameFormatError naming the times and the jump when the sensor moves faster than
        ``max_speed_m_s`` between two samples."""
        if len(self) < 2:
            return
        step = np.linalg.norm(np.diff(self.poses[:, :3, 3], axis=0), axis=1)
        dt = np.diff(self.times_ns) / 1e9
        speed = step / dt
        bad = np.flatnonzero(speed > max_speed_m_s)
        if len(bad):
            i = int(bad[np.argmax(speed[bad])])
            raise FrameFormatError(
                f"{self.source}: the trajectory jumps {step[i]:.2f} m in {dt[i]:.3f} s between t = "
                f"{unix_text(self.times_ns[i])} and {unix_text(self.times_ns[i + 1])} s ({speed[i]:.1f} m/s, over "
                f"the bound of {max_speed_m_s:g} m/s; --max-speed sets it); {len(bad)} such step(s)")

    def summary(self):
        """{poses, start_s, end_s, duration_s, length_m, speed_mean_m_s, speed_max_m_s,
        turn_deg}: what a trajectory is, at a glance."""
        step = np.linalg.norm(np.diff(self.poses[:, :3, 3], axis=0), axis=1)
        dt = np.diff(self.times_ns) / 1e9
        duration = float((self.times_ns[-1] - self.times_ns[0]) / 1e9)
        length = float(step.sum())
        yaw = np.unwrap(np.arctan2(self.poses[:, 1, 0], self.poses[:, 0, 0]))
        return dict(poses=len(self), start_s=float(self.times_ns[0] / 1e9), end_s=float(self.times_ns[-1] / 1e9),
                    duration_s=duration, length_m=length,
                    speed_mean_m_s=length / duration if duration > 0 else 0.0,
                    speed_max_m_s=float((step / dt).max()) if len(dt) else 0.0,
                    turn_deg=float(np.degrees(yaw[-1] - yaw[0])))

    def relative_to(self, t_ns):
        """The same motion in the frame of the pose at ``t_ns`` (that pose becomes the identity)."""
        pose = self.at([t_ns])[0]
        anchor = None if self.anchor is None else geo_anchor(self.anchor, pose)
        return Trajectory(self.times_ns, np.linalg.inv(pose) @ self.poses, self.source, self.notes, anchor)

    def shifted(self, offset_ns):
        """The same poses with ``offset_ns`` subtracted from every time (a sensor clock running
        ``offset_ns`` ahead of the radar's)."""
        return Trajectory(self.times_ns - np.int64(offset_ns), self.poses, self.source, self.notes, self.anchor)

    def tum_text(self):
        """The trajectory in TUM form: ``t tx ty tz qx qy qz qw`` per line (seconds, metres, a unit
        quaternion with the scalar last), the format of the TUM RGB-D benchmark and evo."""
        q = quaternions(self.poses[:, :3, :3])
        lines = [f"# radarcl trajectory from {self.source}: t[s] tx ty tz qx qy qz qw (T_world_sensor, REP-103)"]
        if self.anchor is not None:
            lines.append("# geo_anchor " + " ".join(f"{k} {v!r}" for k, v in self.anchor.items()))
        for t, p, (w, x, y, z) in zip(self.times_ns, self.poses, q):
            lines.append(f"{t // 10 ** 9}.{t % 10 ** 9:09d} {p[0, 3]:.6f} {p[1, 3]:.6f} {p[2, 3]:.6f} "
                         f"{x:.9f} {y:.9f} {z:.9f} {w:.9f}")
        return "\n".join(lines) + "\n"


# -- where a frame lies on the Earth ------------------------------------------------------------------------
EARTH_RADIUS_M = 6378137.0          # WGS-84 equatorial radius: a local plane around a fix (equirectangular)


def geo_anchor(anchor, pose):
    """The anchor of the frame at ``pose`` (4x4 in the frame ``anchor`` places): a dict of the
    frame origin's ``latitude_deg``, ``longitude_deg``, ``altitude_m`` (WGS-84) and the
    direction of its x axis, ``heading_deg`` counter-clockwise from east (ENU yaw). ``anchor`` is
    such a dict for a frame whose x, y, z are east, north, up (heading 0) or turned by its
    heading; positions go through the local plane of its origin (equirectangular: a map's
    extent, not a continent's)."""
    yaw = np.radians(anchor["heading_deg"])
    c, s = np.cos(yaw), np.sin(yaw)
    x, y, z = np.asarray(pose, np.float64)[:3, 3]
    east, north = c * x - s * y, s * x + c * y
    lat0 = np.radians(anchor["latitude_deg"])
    heading = anchor["heading_deg"] + np.degrees(np.arctan2(pose[1][0], pose[0][0]))
    return dict(latitude_deg=float(anchor["latitude_deg"] + np.degrees(north / EARTH_RADIUS_M)),
                longitude_deg=float(anchor["longitude_deg"] + np.degrees(east / (EARTH_RADIUS_M * np.cos(lat0)))),
                altitude_m=float(anchor["altitude_m"] + z), heading_deg=float((heading + 180.0) % 360.0 - 180.0))


# -- rotations as quaternions (w, x, y, z), vectorised -----------------------------------------------------
def quaternions(r):
    """Unit quaternions (n, 4) as (w, x, y, z) of rotation matrices (n, 3, 3), w >= 0
    (Shepperd's method: each from its largest diagonal term, so none divides by a small one)."""
    r = np.asarray(r, np.float64).reshape(-1, 3, 3)
    tr = np.trace(r, axis1=1, axis2=2)
    cands = np.stack([tr, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    k = np.argmax(cands, axis=1)
    q = np.zeros((len(r), 4))
    for case in range(4):
        m = k == case
        if not m.any():
            continue
        s = r[m]
        if case == 0:
            w = np.sqrt(1 + tr[m]) / 2
            q[m] = np.stack([w, (s[:, 2, 1] - s[:, 1, 2]) / (4 * w), (s[:, 0, 2] - s[:, 2, 0]) / (4 * w),
                             (s[:, 1, 0] - s[:, 0, 1]) / (4 * w)], axis=1)
        else:
            i = case - 1
            j, l = (i + 1) % 3, (i + 2) % 3
            v = np.sqrt(np.maximum(0.0, 1 + s[:, i, i] - s[:, j, j] - s[:, l, l])) / 2
            out = np.zeros((m.sum(), 4))
            out[:, 1 + i] = v
            out[:, 1 + j] = (s[:, j, i] + s[:, i, j]) / (4 * v)
            out[:, 1 + l] = (s[:, l, i] + s[:, i, l]) / (4 * v)
            out[:, 0] = (s[:, l, j] - s[:, j, l]) / (4 * v)
            q[m] = out
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotations(q):
    """Rotation matrices (n, 3, 3) of quaternions (n, 4) as (w, x, y, z) (normalised here)."""
    q = np.asarray(q, np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], axis=1)


def slerp(q0, q1, a):
    """Spherical interpolation of quaternions (n, 4) at fractions ``a`` (n,) (outside [0, 1]:
    the same rotation rate continued)."""
    q0, q1, a = np.asarray(q0, float), np.asarray(q1, float).copy(), np.asarray(a, float)
    dot = np.sum(q0 * q1, axis=1)
    q1[dot < 0] *= -1
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-9
    s = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / s)
    w1 = np.where(small, a, np.sin(a * theta) / s)
    return w0[:, None] * q0 + w1[:, None] * q1
