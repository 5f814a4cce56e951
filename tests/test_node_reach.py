"""kernels/node_reach.cl <-> radarcl/stages/node_reach.py against its float64 oracle,
radarcl.stages.node_reach.node_reach: the node pairs a moving frame's voxels may read.

The bound must hold every pair the gather reads. A still table records exactly those
(``StillTable.node_use``, tests/test_fusion_cached.py), so at each pose here the device's bound
and the oracle's each contain the table's set, with the class boundary (terrain_dz) put just above
and just below every height of the grid's voxel centres, where a bound too tight by any amount
first loses a pair. A moving radar's map made with the bound is the one made with every pair
(tests/test_pipeline.py)."""

import numpy as np
import pytest
from test_fusion import FIRST, LAST, LATTICES, MODELS, N_BINS, POSE, SMALL, SPACING, random_nodes

from radarcl.errors import ConfigError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec
from radarcl.stages.fusion import Fusion
from radarcl.stages.node_reach import NodeReach, node_reach

# share of the window's (beam, bin, class) where float32's bound and float64's differ: only where
# one lies within rounding of a class's height or the grid's edge
DIFFERING_MAX = 0.002
PLANAR = GridSpec((-1.0, -6.0, -3.0), 0.25, (48, 48, 8), brick_z=1)
ABOVE = pose_from_xyz_rpy(2.0, 0.0, 4.0, pitch=0.2)          # over the grid's top, looking down into it
PAPER = LATTICES["paper, tilt -10 deg"]
# a radar moving while it scans: one pose per beam, rising, turning and rolling
SCANNING = np.stack([pose_from_xyz_rpy(0.6 * f, 0.1, 0.2 * f, roll=0.05 * f, yaw=0.1 * f)
                     for f in np.linspace(0, 1, PAPER.n_beams)])

CASES = {   # lattice, beam model, pose (or one per beam), grid, terrain_dz [m] splitting what the beams reach
    "paper, near field, pitched and rolled": (PAPER, MODELS["near_field=True, gaussian=True"], POSE, SMALL, -0.8),
    "paper, cone without near field": (PAPER, MODELS["near_field=False, gaussian=False"],
                                       pose_from_xyz_rpy(0.0, 1.0, 0.5, yaw=-0.3), SMALL, -0.5),
    "paper, planar grid": (PAPER, MODELS["near_field=True, gaussian=True"], POSE, PLANAR, -2.0),
    "paper, over the grid": (PAPER, MODELS["near_field=True, gaussian=True"], ABOVE, SMALL, -3.0),
    "paper, moving while it scans": (PAPER, MODELS["near_field=True, gaussian=True"], SCANNING, SMALL, -0.8),
    "spinning, tall beams": (LATTICES["spinning, 90 azimuths"], MODELS["near_field=True, gaussian=True"],
                             pose_from_xyz_rpy(0.5, 0.5, 0.2, roll=0.05), SMALL, -0.3),
}


def detstats_fusion(runtime, case, classes=2, live=None, terrain_dz=None):
    lattice, model, pose, spec, dz = case
    return Fusion(runtime, EvidenceGrid(runtime, spec, knowledge=True), lattice, model, N_BINS, SPACING, FIRST, LAST,
                  per_beam_poses=np.ndim(pose) == 3, still=True, detstats=True,
                  terrain_dz=dz if terrain_dz is None else terrain_dz, classes=classes, live_segments=live)


def bound(fusion, plan, local_size=None):
    """(the device's bound, the float64 oracle's) of ``plan``."""
    import pyopencl.array as cla

    reach = NodeReach(fusion, local_size=local_size)
    reach.enqueue(cla.to_device(fusion.runtime.queue, plan.beams)).wait()
    return reach.node_use.get(), node_reach(plan.beams, **reach.arguments())


def live_segments(seed):
    """Random segments that never carry anything, a third of the bins live in every segment."""
    live = np.random.default_rng(seed).integers(0, 16, (N_BINS, 2)).astype(np.uint8)
    live[: N_BINS // 3] = 0xF
    live[N_BINS // 2: N_BINS // 2 + 8, 1] = 0                      # no live segment of the terrain class
    return live


def voxel_heights(case):
    """Every height of the grid's voxel centres above the (first) beam's origin [m]."""
    _, _, pose, spec, _ = case
    origin_z = np.reshape(pose, (-1, 4, 4))[0, 2, 3] - spec.origin_m[2]
    return (np.arange(spec.shape[2]) + 0.5) * spec.voxel_m - origin_z


@pytest.mark.parametrize("classes", [2, 1])
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_the_device_bound_matches_the_float64_oracle(runtime, case, classes):
    """The device's bits are the oracle's but within float32's rounding of a boundary, the window's
    bins alone, the classes the pipeline keeps; any local size gives the same bits."""
    f = detstats_fusion(runtime, case, classes, live_segments(3)[:, :classes])
    plan = f.plan(case[2])
    got, want = bound(f, plan)
    window = np.zeros(N_BINS, bool)
    window[FIRST:LAST + 1] = True
    assert (got[:, ~window] == 0).all() and (want[:, ~window] == 0).all()
    assert got.max() < 1 << classes
    differ = sum(((got >> c) & 1) != ((want >> c) & 1) for c in range(classes))
    assert differ.sum() <= DIFFERING_MAX * got[:, window].size * classes
    assert ((want & 1) != 0).any()
    for local_size in (1, 7):
        assert np.array_equal(bound(f, plan, local_size)[0], got)


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_the_bound_holds_every_node_pair_the_voxels_read(runtime, case):
    """The still table's exact set (its entries' bins and classes) lies inside the bound, on the
    device and in float64, with the class boundary just above and below every voxel-centre height
    (and at the case's own, where the bound also leaves out some of each class's pairs)."""
    lattice, _, pose, _, own = case
    frame = random_nodes(lattice, seed=4)[2]
    heights = [own] + [h + e for h in voxel_heights(case) for e in (-1e-4, 1e-4)]
    for terrain_dz in heights:
        f = detstats_fusion(runtime, case, terrain_dz=terrain_dz)
        f(frame, pose)
        plan = f(frame, pose)
        read = plan.table.node_use.get()
        got, want = bound(f, plan)
        assert read.any()
        assert not (read & ~got).any(), f"a pair the voxels read is outside the device's bound, terrain_dz {terrain_dz}"
        assert not (read & ~want).any(), f"a pair the voxels read is outside the float64 bound, terrain_dz {terrain_dz}"
        if terrain_dz == own and lattice.n_el > 1:           # a tilted radar's beams: both classes, not everywhere
            window = got[:, FIRST:LAST + 1]
            for c in (0, 1):
                assert ((read >> c) & 1).any() and not ((window >> c) & 1).all()


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_the_bound_leaves_out_only_segments_that_never_carry_anything(runtime, case):
    """With segments that never carry anything (``live_segments``), the table leaves out their
    entries and the bound a (bin, class) with no live segment; the table's set stays inside it."""
    lattice, _, pose, _, _ = case
    live = live_segments(5)
    f = detstats_fusion(runtime, case, live=live)
    frame = random_nodes(lattice, seed=6)[2]
    f(frame, pose)
    read = f(frame, pose).table.node_use.get()
    got, want = bound(f, f.plan(pose))
    assert read.any() and not (read & ~got).any() and not (read & ~want).any()
    dead = (live & 0xF) == 0                                    # (bins, classes)
    for c in (0, 1):
        assert not ((got[:, dead[:, c]] >> c) & 1).any()


@pytest.mark.parametrize("case", [c for c in CASES.values() if not c[0].wraps], ids=[k for k, c in CASES.items()
                                                                                    if not c[0].wraps])
def test_a_part_of_a_frame_bounds_its_own_beams(runtime, case):
    """A part of a frame (``Fusion.restrict``: the beams of some azimuths, as ``radarcl live``
    fuses what has arrived) bounds the pairs of its beams alone: the whole frame's bound there, 0
    elsewhere, on the device as in float64."""
    lattice, _, pose, _, _ = case
    f = detstats_fusion(runtime, case)
    plan = f.plan(pose)
    whole, _ = bound(f, plan)
    part = f.restrict(plan, 20, 37)
    assert part.azimuths == (20, 37) and plan.azimuths is None
    use, event = f.node_reach(part)
    event.wait()
    got = use.get()
    want = node_reach(plan.beams, **NodeReach(f).arguments(), azimuths=part.azimuths)
    mine = (np.arange(lattice.n_beams) // lattice.n_el >= 20) & (np.arange(lattice.n_beams) // lattice.n_el <= 37)
    assert np.array_equal(got[mine], whole[mine]) and not got[~mine].any() and got[mine].any()
    assert not want[~mine].any()
    assert (got != want).mean() <= DIFFERING_MAX


def test_the_bound_is_the_detection_statistics_models(runtime):
    """Eq. 12's Fusion has no node pairs to bound; a Fusion without a terrain class takes none
    (the bound would split no class)."""
    case = CASES["paper, near field, pitched and rolled"]
    lattice, model, pose, spec, _ = case
    eq12 = Fusion(runtime, EvidenceGrid(runtime, spec), lattice, model, N_BINS, SPACING, FIRST, LAST)
    with pytest.raises(ConfigError, match="detection-statistics"):
        eq12.node_reach(eq12.plan(pose))
    with pytest.raises(ConfigError, match="detection-statistics"):
        NodeReach(eq12)
    one = detstats_fusion(runtime, case, classes=1)
    assert one.node_reach(one.plan(pose)) is None
    two = detstats_fusion(runtime, case)
    use, event = two.node_reach(two.plan(pose))
    event.wait()
    assert use.shape == (lattice.n_beams, N_BINS) and use.get().any()
