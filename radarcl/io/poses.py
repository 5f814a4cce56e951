"""Trajectories: sensor poses with their times, read from the files that come with the data."""

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.geometry import pose_from_xyz_rpy


def read_pose_file(path):
    """A pose file: CSV or whitespace rows ``t_s x y z roll pitch yaw`` (REP-103, metres and
    radians; # comments) -> (times_ns, poses (n, 4, 4)), sorted and checked."""
    try:
        rows = np.loadtxt(path, delimiter=None if not str(path).endswith(".csv") else ",", ndmin=2, comments="#")
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"{path} is not a pose file of rows 't_s x y z roll pitch yaw' ({exc})") from exc
    if rows.shape[1] != 7 or len(rows) < 1 or not np.isfinite(rows).all():
        raise FrameFormatError(f"{path}: expected finite rows of 7 numbers (t_s x y z roll pitch yaw), got {rows.shape}")
    if np.any(np.diff(rows[:, 0]) <= 0):
        raise FrameFormatError(f"{path}: times must increase row by row")
    poses = np.stack([pose_from_xyz_rpy(*(float(v) for v in r[1:])) for r in rows])
    return np.rint(rows[:, 0] * 1e9).astype(np.int64), poses
