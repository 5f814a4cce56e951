"""The real-data map: fused with the true odometry, two half maps of the same street agree
better than when the geometry is altered (1 m, 2 deg, azimuth direction, motion in a scan)."""

import math

import numpy as np
import pytest

from radarcl.jobs import navtech_map as nm
from radarcl.errors import ConfigError
from radarcl.io import navtech

VOXEL, RANGE = 0.5, 40.0


@pytest.fixture(scope="module")
def data(shared_data):
    root = shared_data / "navtech_oxford"
    scans = [navtech.load_scan(p) for p in navtech.scan_paths(root / "radar")]
    odometry = navtech.load_odometry(root / "gt" / "radar_odometry.csv")
    return scans, odometry, [int(s.path.stem) for s in scans]


def test_scan_poses_chain_the_odometry(data):
    scans, odometry, stamps = data
    poses = nm.scan_poses(stamps, odometry)
    assert np.array_equal(poses[0], np.eye(4))
    step = odometry[(stamps[1], stamps[0])]
    assert np.allclose(poses[1][:2, 3], step[:2])
    assert 15 < np.linalg.norm(poses[-1][:2, 3]) < 25 and poses[-1][0, 3] > 0     # ~19 m forward
    with pytest.raises(ConfigError, match="no odometry row"):
        nm.scan_poses([stamps[0], stamps[2]], odometry)


def test_true_geometry_is_the_most_self_consistent(runtime, data):
    scans, odometry, stamps = data
    poses = nm.scan_poses(stamps, odometry)
    true = nm.beam_poses(scans, poses)
    spec = nm.grid_for(true, RANGE, VOXEL)

    def agreement(per_beam, both=False):
        a = nm.build_map(runtime, spec, scans[:5], (per_beam if both else true)[:5], RANGE).snapshot()
        b = nm.build_map(runtime, spec, scans[5:], per_beam[5:], RANGE).snapshot()
        return nm.consistency(a, b)["correlation"]

    best = agreement(true)
    assert best > 0.3
    for altered in (nm._moved(true, dx=1.0), nm._moved(true, dyaw=math.radians(2)),
                    nm._moved(true, dyaw=math.radians(-2)), nm.beam_poses(scans, poses, motion=False)):
        assert agreement(altered) < best - 0.05
    assert agreement(nm.beam_poses(scans, poses, azimuth_sign=-1.0), both=True) < best - 0.05
