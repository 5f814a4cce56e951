"""The lidar's own motion, for finding a clock offset: planar point-to-point ICP between lidar
frames a few tenths of a second apart gives the vehicle's speed and yaw rate on the lidar's
clock, which another sensor's speed (a GPS/IMU on its own clock) can be slid against
(``radiate.estimate_clock_offset``).

Why by hand: the field's registration libraries (Open3D, KISS-ICP) are large binary installs for
what is here 40 lines of numpy and one scipy k-d tree (the nearest neighbours), on a few
thousand points per frame. Only points above the ground and away from the car take part: the
ground moves with the car and would pull the estimate towards standing still.
"""

import math

import numpy as np

from radarcl.errors import FrameFormatError

GROUND_CLEARANCE_M = 0.5           # points at least this far above the lowest tenth of the frame
RANGE_M = (3.0, 40.0)              # nearer: the car itself; farther: too sparse to match
CELL_M = 0.2                       # one point per cell of this size (even density)
ITERATIONS = 30
TRIM = 70                          # match only the nearest TRIM % of pairs (outliers, moving objects)


def planar_points(points):
    """(n, 2) x, y of REP-103 points (n, 3) above the ground and in ``RANGE_M``, one per
    ``CELL_M`` cell."""
    p = np.asarray(points, np.float64)
    if len(p) == 0:
        return np.zeros((0, 2))
    ground = np.percentile(p[:, 2], 10)
    r = np.hypot(p[:, 0], p[:, 1])
    keep = (p[:, 2] > ground + GROUND_CLEARANCE_M) & (r > RANGE_M[0]) & (r < RANGE_M[1])
    xy = p[keep, :2]
    _, first = np.unique(np.floor(xy / CELL_M).astype(np.int64), axis=0, return_index=True)
    return xy[np.sort(first)]


def icp(source, target, guess=(0.0, 0.0, 0.0)):
    """(x, y, yaw, rms): the planar motion that carries ``source`` points (n, 2) onto
    ``target`` (m, 2), i.e. the source frame's pose in the target's, from ``guess``."""
    from scipy.spatial import cKDTree

    if len(source) < 10 or len(target) < 10:
        raise FrameFormatError(f"ICP needs at least 10 points above the ground per frame, got {len(source)} and "
                               f"{len(target)}")
    tree = cKDTree(target)
    x, y, yaw = guess
    rms = math.inf
    for _ in range(ITERATIONS):
        c, s = math.cos(yaw), math.sin(yaw)
        moved = source @ np.array([[c, s], [-s, c]]) + (x, y)
        d, j = tree.query(moved)
        keep = d <= max(0.3, np.percentile(d, TRIM))
        a, b = moved[keep], target[j[keep]]
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        h = (a - ca).T @ (b - cb)
        turn = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
        ct, st = math.cos(turn), math.sin(turn)
        rot = np.array([[ct, -st], [st, ct]])
        shift = cb - rot @ ca
        yaw += turn
        x, y = rot @ (x, y) + shift
        rms = float(np.sqrt(np.mean(d[keep] ** 2)))
        if abs(turn) < 1e-6 and np.hypot(*shift) < 1e-4:
            break
    return float(x), float(y), float(yaw), rms


def ego_motion(frames, gap=2, speed_guess_m_s=0.0):
    """Speed and yaw rate from lidar frames [(time_ns, REP-103 points (n, 3))] in time order:
    ICP between frame k + ``gap`` and frame k, each pair started from the last answer (the
    first from ``speed_guess_m_s`` straight ahead). Returns (times_ns at the pairs' middles,
    speed [m/s], yaw rate [rad/s], ICP rms [m]) as arrays."""
    clouds = [(t, planar_points(p)) for t, p in frames]
    out = []
    velocity = (speed_guess_m_s, 0.0, 0.0)
    for (t0, a), (t1, b) in zip(clouds[:-gap], clouds[gap:]):
        dt = (t1 - t0) / 1e9
        if dt <= 0:
            raise FrameFormatError("lidar frames must be in time order for ego-motion")
        x, y, yaw, rms = icp(b, a, tuple(v * dt for v in velocity))
        velocity = (x / dt, y / dt, yaw / dt)
        out.append(((t0 + t1) // 2, math.hypot(x, y) / dt, yaw / dt, rms))
    if not out:
        raise FrameFormatError(f"ego-motion needs more than {gap} lidar frames, got {len(frames)}")
    t, v, w, r = (np.array(c) for c in zip(*out))
    return t.astype(np.int64), v, w, r
