"""kernels/fusion_plan.cl <-> radarcl/stages/fusion_plan.py against its float64 oracle,
radarcl.stages.fusion_plan.candidate_windows: every brick's window of candidate beams.

float32 may move a bound across a beam only where the oracle's bound lies within WINDOW_SLACK of
it; so windows must agree exactly on almost every brick and differ by at most one beam index
elsewhere, and a plan made on the device lists the bricks the host's numpy windows list."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import RadarConfig
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import BRICK, GridSpec
from radarcl.stages.fusion_plan import BLOCK, FusionPlanner, HeadFrame, candidate_windows

RADAR = RadarConfig()
WINDOWS_DIFFERING_MAX = 1e-3        # share of bricks whose window may differ (by one index) from float64's

CASES = {
    "paper, tilt -7 deg": (BeamLattice.from_radar(RADAR, tilt_deg=-7.0), pose_from_xyz_rpy(1.0, -2.0, 0.3, yaw=0.4),
                           0.0, 0.0),
    "spinning, 400 azimuths": (BeamLattice.spinning(400, az0_rad=0.01), pose_from_xyz_rpy(0.5, 0.5, 0.0, yaw=-1.0),
                               0.0, 0.0),
    "paper, moving while it scans": (BeamLattice.from_radar(RADAR, tilt_deg=-3.0), pose_from_xyz_rpy(0.0, 0.0, 0.5),
                                     0.8, 0.05),
}


@pytest.mark.parametrize("vector_width", [1, 8])
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
@pytest.mark.parametrize("near_field", [True, False])
def test_windows_match_the_float64_oracle(runtime, case, near_field, vector_width):
    lattice, pose, trans_margin, rot_margin = case
    model = BeamModel.from_radar(RADAR, near_field=near_field)
    spec = GridSpec((-30.0, -30.0, -6.0), 0.1, (600, 600, 120))
    origin = pose[:3, 3] - np.asarray(spec.origin_m)
    frame = HeadFrame(pose[:3, :3] @ lattice.head_rotation(), origin, trans_margin, rot_margin)
    r_lo, r_hi = 1.0, 28.0
    shape = np.asarray(spec.brick_shape)
    blocks = np.stack(np.meshgrid(*[np.arange(0, n, BLOCK) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    got = FusionPlanner(runtime, lattice, model, r_lo, r_hi, vector_width).windows(blocks, shape, BRICK * spec.voxel_m,
                                                                                frame)
    bricks = FusionPlanner.bricks_of(blocks)
    inside = (bricks < shape).all(axis=1)
    assert (got[~inside] == (0, -1, 0, -1)).all(), "bricks past the grid get empty windows"
    index = FusionPlanner.brick_index(blocks, np.flatnonzero(inside), shape)
    assert np.array_equal(index, (bricks[inside, 2] * shape[1] + bricks[inside, 1]) * shape[0] + bricks[inside, 0])
    got, bricks = got[inside], bricks[inside]
    centres = (bricks + 0.5) * BRICK * spec.voxel_m
    want = candidate_windows(centres, 0.5 * math.sqrt(3) * BRICK * spec.voxel_m, frame, r_lo, r_hi, lattice, model)
    empty = lambda w: (w[:, 0] > w[:, 1]) | (w[:, 2] > w[:, 3])          # noqa: E731
    both_empty = empty(got) & empty(want)
    same = both_empty | (got == want).all(axis=1)
    reached = ~empty(want)
    assert reached.sum() > 1000, "the case reaches too few bricks to test anything"
    assert (~same).mean() <= WINDOWS_DIFFERING_MAX
    differing = ~same
    assert (np.abs(got[differing].astype(np.int64) - want[differing]) <= 1).all()


def test_a_device_plan_lists_the_hosts_bricks(runtime):
    """Fusion.plan (device windows) against the numpy windows of the same blocks."""
    from radarcl.grid import EvidenceGrid
    from radarcl.stages.fusion import Fusion

    lattice, model = BeamLattice.from_radar(RADAR, tilt_deg=-7.0), BeamModel.from_radar(RADAR)
    spec = GridSpec((-8.0, -35.0, -10.0), 0.2, (400, 350, 100))
    f = Fusion(runtime, EvidenceGrid(runtime, spec), lattice, model, 512, 0.125, 8, 511)
    pose = pose_from_xyz_rpy(2.0, 1.0, 0.2, yaw=0.3)
    plan = f.plan(pose)
    head = HeadFrame(pose[:3, :3] @ lattice.head_rotation(), pose[:3, 3] - np.asarray(spec.origin_m), 0.0, 0.0)
    shape = np.asarray(spec.brick_shape)
    bz, by, bx = np.indices(shape[::-1]).reshape(3, -1)
    bricks = np.stack([bx, by, bz], axis=1)
    want = f._windows(bricks, BRICK, head)
    listed = (want[:, 0] <= want[:, 1]) & (want[:, 2] <= want[:, 3])
    got = {tuple(b) for b in plan.bricks[:, :3]}
    host = {tuple(b) for b in bricks[listed]}
    assert len(got) == len(plan.bricks), "each brick listed once"
    assert len(got ^ host) <= WINDOWS_DIFFERING_MAX * len(host)
    # listed in pool order, each with its own slot and window
    slots = plan.bricks[:, 3]
    assert (np.diff(slots) > 0).all()
    assert np.array_equal(f.grid.table[plan.bricks[:, 2], plan.bricks[:, 1], plan.bricks[:, 0]], slots)
    index = {tuple(b): i for i, b in enumerate(bricks.tolist())}
    mine = want[[index[tuple(b)] for b in plan.bricks[:, :3].tolist()]]
    assert (np.abs(plan.windows.astype(np.int64) - mine) <= 1).all()
