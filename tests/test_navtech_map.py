"""The real-data map: fused with the true odometry, two half maps of the same street agree
better than when the geometry is altered (1 m, 2 deg, azimuth direction, motion in a scan)."""

import math

import numpy as np
import pytest

from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.io import polar_png, scan_poses
from radarcl.jobs import navtech_map as nm

VOXEL, RANGE = 0.5, 40.0


@pytest.fixture(scope="module")
def data(shared_data):
    config = mapconfig.resolve("navtech-cts350x", flags={"grid.voxel_m": VOXEL, "interpret.range_max_m": RANGE,
                                                         "interpret.model": "paper"})   # the geometry check on eq. 12's sums
    scans, poses, stamps, odometry = nm.load(config, shared_data / "navtech_oxford")
    return config, scans, odometry, stamps


def test_scan_poses_chain_the_odometry_in_rep103(data):
    """The Oxford odometry (y right) arrives with y left: the car drives ~19 m forward and its
    rows are (x, -y, -yaw) of the file's."""
    _, scans, odometry, stamps = data
    poses = polar_png.scan_poses(stamps, odometry)
    assert np.array_equal(poses[0], np.eye(4))
    step = odometry[(stamps[1], stamps[0])]
    assert np.allclose(poses[1][:2, 3], step[:2])
    assert 15 < np.linalg.norm(poses[-1][:2, 3]) < 25 and poses[-1][0, 3] > 0     # ~19 m forward
    with pytest.raises(ConfigError, match="no odometry row"):
        polar_png.scan_poses([stamps[0], stamps[2]], odometry)


def test_odometry_is_converted_from_the_oxford_frame(shared_data, tmp_path):
    path = shared_data / "navtech_oxford" / "gt" / "radar_odometry.csv"
    import csv

    with open(path, newline="") as f:
        row = next(csv.DictReader(f))
    key = (int(row["source_radar_timestamp"]), int(row["destination_radar_timestamp"]))
    assert polar_png.load_odometry(path)[key] == (float(row["x"]), -float(row["y"]), -float(row["yaw"]))


def test_true_geometry_is_the_most_self_consistent(runtime, data):
    config, scans, odometry, stamps = data
    poses = polar_png.scan_poses(stamps, odometry)
    true = scan_poses.beam_poses(scans, poses, 400)
    spec = nm.grid_for(true, RANGE, VOXEL)

    def agreement(per_beam, both=False):
        a = nm.build_map(runtime, config, spec, scans[:5], (per_beam if both else true)[:5]).snapshot()
        b = nm.build_map(runtime, config, spec, scans[5:], per_beam[5:]).snapshot()
        return nm.consistency(a, b)["correlation"]

    best = agreement(true)
    assert best > 0.3
    for altered in (nm._moved(true, dx=1.0), nm._moved(true, dyaw=math.radians(2)),
                    nm._moved(true, dyaw=math.radians(-2)), scan_poses.beam_poses(scans, poses, 400, motion=False)):
        assert agreement(altered) < best - 0.05
    assert agreement(scan_poses.beam_poses(scans, poses, 400, azimuth_sign=-1.0), both=True) < best - 0.05


def test_consistency_of_maps_with_knowledge_counts_only_what_both_observed():
    """A map with the knowledge channel reads its prior where it never looked, so "observed" is
    its knowledge, not a non-zero value: the unknown voxels (equal in both, at the prior) must not
    make two maps agree."""
    prior = -3584                                                    # -3.5 nat in logodds units
    a = np.full(100, prior, np.int32)
    b = a.copy()
    a[:10], b[:10] = np.arange(10) * 100, -np.arange(10) * 100       # what both saw: opposite
    seen = np.zeros(100, bool)
    seen[:10] = True
    got = nm.consistency((a, seen), (b, seen))
    assert got["common_voxels"] == 10 and got["correlation"] == pytest.approx(-1.0)
    assert nm.consistency(a, b)["common_voxels"] == 99               # read as eq. 12 maps: every non-zero voxel
