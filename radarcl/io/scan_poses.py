"""Per-azimuth poses of polar scans: a spinning radar moves during its turn, so each azimuth is
placed by the trajectory at its own time (motion compensation) and turned by its measured angle.
``beam_poses`` stacks them (n_scans, n_az, 4, 4); ``BeamPoses`` gives the same a scan at a time,
as a fusion reads them (a long drive would hold 51 KB a scan).
"""

import math

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.io.trajectory import Trajectory


def azimuth_times(scan):
    """UNIX times [ns] (n_az,) of a scan's azimuths on a line fitted to its (bursty) stamps, in
    acquisition order (float64 ns)."""
    ts = scan.timestamps_ns.astype(np.float64)
    n = len(ts)
    order = np.arange(n, dtype=np.float64) if scan.acquired is None else scan.acquired.astype(np.float64)
    if np.ptp(ts) <= 0:
        return ts
    return np.polyval(np.polyfit(order, ts - ts.min(), 1), order) + ts.min()


def azimuth_turns(angles_rad, n_az, azimuth_sign=1.0):
    """(n_az, 4, 4) rotations about z by each azimuth's measured angle (times ``azimuth_sign``)
    less the lattice's i x 2 pi / n_az: what folds a scan's own angles into one lattice."""
    turn = azimuth_sign * angles_rad - np.arange(n_az) * (2 * math.pi / n_az)
    c, s = np.cos(turn), np.sin(turn)
    rot = np.zeros((n_az, 4, 4))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = c, -s, s, c
    rot[:, 2, 2] = rot[:, 3, 3] = 1.0
    return rot


def _azimuth_ns(scan):
    """Each azimuth's time as the trajectory is read at it: ``azimuth_times`` to whole ns."""
    return np.rint(azimuth_times(scan)).astype(np.int64)


def beam_poses(scans, poses, n_az, azimuth_sign=1.0, motion=True):
    """(n_scans, n_az, 4, 4) per-azimuth poses for a spinning lattice of ``n_az`` azimuths: the
    trajectory at each azimuth's time (motion compensation: the radar moves during its turn),
    times the rotation of its measured angle (times ``azimuth_sign``) less the lattice's
    i x 2 pi / n_az. ``poses`` is a ``Trajectory``, or (n_scans, 4, 4) scan poses at each
    scan's first azimuth (interpolated between scans, extended past the last one).
    motion=False puts every azimuth at its scan's start pose (a consistency check). Without a
    trajectory (None) every scan stays at the origin (a still radar). ``BeamPoses`` gives the
    same a scan at a time."""
    return np.asarray(BeamPoses(scans, poses, n_az, azimuth_sign, motion))


class BeamPoses:
    """``beam_poses`` as a sequence: item k is scan k's (n_az, 4, 4) poses, computed when asked
    (a drive's thousands of scans would hold 51 KB each), a slice the same for those scans;
    ``np.asarray`` stacks them all. Scans of another azimuth count are refused up front."""

    def __init__(self, scans, poses, n_az, azimuth_sign=1.0, motion=True):
        for scan in scans:
            if scan.shape[0] != n_az:
                raise FrameFormatError(f"{scan.path}: expected {n_az} azimuths, got {scan.shape[0]}")
        fixed = None                        # one pose per scan, no motion within it
        if poses is None:
            fixed = np.broadcast_to(np.eye(4), (len(scans), 4, 4))
        elif not isinstance(poses, Trajectory):
            poses = np.asarray(poses)[:len(scans)]
            if len(poses) < len(scans):
                raise FrameFormatError(f"{len(scans)} scans need a pose each, got {len(poses)} poses")
            starts = np.array([s.start_ns for s in scans], np.int64)
            if len(scans) == 1 or not all(s.timed for s in scans) or (np.diff(starts) <= 0).any():
                fixed = poses               # untimed scans stay at their own poses
            else:
                poses = Trajectory(starts, poses, "scan poses")
        if fixed is None and not motion:
            fixed = poses.at([s.start_ns for s in scans])
        elif fixed is None:
            # every azimuth's time checked now: a trajectory that does not cover the scans is
            # refused when they are opened, not midway through a fusion
            ends = [(t.min(), t.max()) for t in map(_azimuth_ns, scans)]
            poses.covers(np.array(ends, np.int64).reshape(-1))
        self.scans, self.n_az, self.azimuth_sign = list(scans), int(n_az), float(azimuth_sign)
        self._fixed, self._track = fixed, poses

    def __len__(self):
        return len(self.scans)

    @property
    def shape(self):
        """(n_scans, n_az, 4, 4), as the stacked array's."""
        return (len(self.scans), self.n_az, 4, 4)

    def __getitem__(self, k):
        if isinstance(k, slice):
            part = object.__new__(BeamPoses)
            part.scans, part.n_az, part.azimuth_sign = self.scans[k], self.n_az, self.azimuth_sign
            part._fixed = None if self._fixed is None else self._fixed[k]
            part._track = self._track
            return part
        scan = self.scans[k]
        if self._fixed is not None:
            moved = np.broadcast_to(self._fixed[k], (self.n_az, 4, 4))
        else:
            moved = self._track.at(_azimuth_ns(scan))
        return moved @ azimuth_turns(scan.angles_rad, self.n_az, self.azimuth_sign)

    def __iter__(self):
        return (self[k] for k in range(len(self)))

    def positions(self, azimuth):
        """(n_scans, 3) [m]: every scan's position at azimuth ``azimuth``, item k's [azimuth, :3, 3]
        (the azimuth's turn leaves the translation as it is), without the other azimuths' poses."""
        if self._fixed is not None:
            return np.array([f[:3, 3] for f in self._fixed], np.float64).reshape(-1, 3)
        times = [_azimuth_ns(s)[azimuth] for s in self.scans]
        return self._track.at(times)[:, :3, 3].copy() if times else np.zeros((0, 3))

    def __array__(self, dtype=None, copy=None):
        out = np.stack(list(self)) if len(self) else np.zeros((0, self.n_az, 4, 4))
        return out if dtype is None else out.astype(dtype)
