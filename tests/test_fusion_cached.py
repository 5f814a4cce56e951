"""kernels/fusion_cached.cl <-> radarcl/stages/fusion_cached.py: a still radar's frames from the
recorded table give the gather's integers (kernels/fusion.cl, compared exactly), within the float64
oracle's tolerance (radarcl.oracle.fusion); the table is recorded when a pose comes back, and only
where it fits its budget.

The table's frames of the detection-statistics model and of planar bricks are checked beside the
gather's in tests/test_fusion.py (its DETSTATS and BRICK_Z cases run both paths).
"""

import math

import numpy as np
import pytest
from test_fusion import (FIRST, LAST, LATTICES, MODELS, N_BINS, POSE, SMALL, SPACING, check_against_oracle, evidence,
                         one_class_nodes, random_nodes)

from radarcl import node_pairs
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.stages import fusion_cached
from radarcl.stages.fusion import Fusion

STILL_CASES = {
    "paper, gaussian, near field": (LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"], False, 8, 2),
    "paper, one row per vector": (LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"], False, 8, 1),
    "paper, uniform cone, vec 4": (LATTICES["paper, tilt -10 deg"], MODELS["near_field=False, gaussian=False"], False, 4, 1),
    "spinning, per-beam poses": (LATTICES["spinning, 90 azimuths"], MODELS["near_field=True, gaussian=True"], True, 8, 2),
}


@pytest.mark.parametrize("case", STILL_CASES.values(), ids=STILL_CASES.keys())
def test_a_still_radars_table_gives_the_gathers_integers(runtime, case):
    """Record once, then every frame at that pose from the table: the same integers as the
    gather (integer results compared exactly), and within the oracle's tolerance."""
    lattice, model, per_beam, vec, rows = case
    poses = POSE if not per_beam else np.stack(
        [pose_from_xyz_rpy(0.5 * f, 0.1, 0.0, yaw=0.05 * f) for f in np.linspace(0, 1, lattice.n_beams)])
    frames = [evidence(lattice, seed=s) for s in (11, 12, 13)]
    maps = {}
    for still in (False, True):
        grid = EvidenceGrid(runtime, SMALL)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, per_beam_poses=per_beam, still=still,
                   vector_width=vec, rows=rows)
        steps = []
        for ev in frames:
            plan = f(ev, poses)
            steps.append(grid.snapshot())
        maps[still] = steps
        assert (plan.table is not None) == still
    for a, b in zip(maps[False], maps[True]):
        assert np.array_equal(a, b)
    # the last frame alone, from the table, against the float64 oracle
    check_against_oracle(maps[True][2] - maps[True][1], SMALL, lattice, model, frames[2], poses)


@pytest.mark.parametrize("case", STILL_CASES.values(), ids=STILL_CASES.keys())
def test_a_table_of_one_class_masks_the_terrain_entries(runtime, case):
    """The detection-statistics model with the upright class alone (classes 1) and a finite
    terrain_dz: the table keeps each entry's class and takes nothing from a terrain entry, the
    gather's integers (evidence, knowledge, looks) frame after frame, and those of both classes
    with all-zero terrain nodes."""
    lattice, model, per_beam, vec, rows = case
    poses = POSE if not per_beam else np.stack(
        [pose_from_xyz_rpy(0.5 * f, 0.1, 0.0, yaw=0.05 * f) for f in np.linspace(0, 1, lattice.n_beams)])
    frames = [one_class_nodes(lattice, s) for s in (14, 15)]
    terrain_dz = 0.0 if lattice.wraps else -0.8       # a height that splits the voxels the beams reach
    maps = {}
    for classes, still in ((1, False), (1, True), (2, True)):
        grid = EvidenceGrid(runtime, SMALL, knowledge=True)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, per_beam_poses=per_beam, still=still,
                   vector_width=vec, rows=rows, detstats=True, terrain_dz=terrain_dz, classes=classes)
        steps = []
        for frame in frames * 2:
            plan = f(frame[3] if classes == 1 else frame[2], poses)
            steps.append((grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")))
        assert (plan.table is not None) == still
        maps[classes, still] = steps
    entries = plan.table.first.get()[:, 1]                  # the last table's first entries: both classes
    terrain = (entries & (1 << 16)) != 0
    assert terrain.any() and ((entries != 0) & ~terrain).any()
    assert maps[1, False][-1][0].any() and maps[1, False][-1][2].sum() > 100
    for other in ((1, True), (2, True)):
        for a, b in zip(maps[1, False], maps[other]):
            assert all(np.array_equal(x, y) for x, y in zip(a, b))



@pytest.mark.parametrize("case", STILL_CASES.values(), ids=STILL_CASES.keys())
def test_the_table_marks_the_node_pairs_its_entries_read(runtime, case):
    """The detection-statistics table's ``node_use``: bit c of (beam, bin) set exactly where one of
    its entries (first or further) reads class c's node pairs there (the interpreter makes those
    alone), compared as integers with the set the entries make on the host; eq. 12's table has none."""
    lattice, model, per_beam, vec, rows = case
    poses = POSE if not per_beam else np.stack(
        [pose_from_xyz_rpy(0.5 * f, 0.1, 0.0, yaw=0.05 * f) for f in np.linspace(0, 1, lattice.n_beams)])
    frame = one_class_nodes(lattice, 16)[2]
    terrain_dz = 0.0 if lattice.wraps else -0.8       # a height that splits the voxels the beams reach
    f = Fusion(runtime, EvidenceGrid(runtime, SMALL, knowledge=True), lattice, model, N_BINS, SPACING, FIRST, LAST,
               per_beam_poses=per_beam, still=True, vector_width=vec, rows=rows, detstats=True, terrain_dz=terrain_dz)
    f(frame, poses)
    table = f(frame, poses).table
    entries = np.concatenate([table.first.get(), table.extras.get()])
    entries = entries[entries[:, 1] != 0]                   # (0, 0): no entry
    want = np.zeros(lattice.n_beams * N_BINS, np.uint32)
    for c in (0, 1):
        want[entries[(entries[:, 1] >> 16 & 1) == c, 0]] |= 1 << c
    got = table.node_use.get().ravel()
    assert np.array_equal(got, want)
    assert (got & 1).any() and (got & 2).any() and (got == 0).any()
    eq12 = Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST,
                  per_beam_poses=per_beam, still=True, vector_width=vec, rows=rows)
    eq12(evidence(lattice, seed=3), poses)
    assert eq12(evidence(lattice, seed=3), poses).table.node_use is None



@pytest.mark.parametrize("case", STILL_CASES.values(), ids=STILL_CASES.keys())
def test_the_table_leaves_out_entries_in_segments_that_never_carry_anything(runtime, case):
    """``live_segments`` (node_pairs.live_segments: which segments of a bin and class may carry
    an update) takes out of the table every entry in another segment, and nothing else; with those
    segments' node pairs 0 (what the interpreter writes there, every frame) the table's frames give
    the gather's integers (evidence, knowledge, looks), frame after frame, and so does the gather
    that skips the units lying in them (DEAD_SEGMENTS)."""
    lattice, model, per_beam, vec, rows = case
    poses = POSE if not per_beam else np.stack(
        [pose_from_xyz_rpy(0.5 * f, 0.1, 0.0, yaw=0.05 * f) for f in np.linspace(0, 1, lattice.n_beams)])
    rng = np.random.default_rng(21)
    live = rng.integers(0, 16, (N_BINS, 2)).astype(np.uint8)
    live[: N_BINS // 3] = 0xF                                # some bins live in every segment
    frames = []
    for s in (22, 23, 24):
        e, d, _ = random_nodes(lattice, seed=s)
        for k in range(node_pairs.SEGMENTS):                  # a dead segment's two nodes are 0
            dead = ((live >> k) & 1) == 0
            for node in (k, k + 1):
                e[:, dead, node], d[:, dead, node] = 0, 0
        frames.append(node_pairs.pack_nodes(e, d))
    terrain_dz = 0.0 if lattice.wraps else -0.8
    maps, tables = {}, {}
    for name, still, segments in (("gather", False, None), ("all", True, None), ("live", True, live),
                                  ("gather, live", False, live)):
        grid = EvidenceGrid(runtime, SMALL, knowledge=True)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, per_beam_poses=per_beam, still=still,
                   vector_width=vec, rows=rows, detstats=True, terrain_dz=terrain_dz, live_segments=segments)
        steps = []
        for frame in frames:
            plan = f(frame, poses)
            steps.append((grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")))
        maps[name], tables[name] = steps, plan.table
    for other in ("all", "live", "gather, live"):         # the last skips the units of dead segments
        for a, b in zip(maps["gather"], maps[other]):
            assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert maps["gather"][-1][2].sum() > 100
    def entries(table):
        got = np.concatenate([table.first.get(), table.extras.get()])
        got = got[got[:, 1] != 0]
        return got[:, 0] % N_BINS, (got[:, 1] >> 16) & 1, ((got[:, 1] & 0xFFFF) - 1) >> 12
    every, kept = entries(tables["all"]), entries(tables["live"])
    alive = lambda b, c, s: (live[b, c] >> s) & 1 == 1
    assert alive(*kept).all() and len(kept[0]) == alive(*every).sum() < len(every[0])


def test_the_table_is_recorded_when_a_pose_comes_back_and_only_if_it_fits(runtime, monkeypatch):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    ev = evidence(lattice, seed=4)
    f = Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST)
    first = f(ev, POSE)
    assert first.table is None                                   # a pose seen once: the gather
    second = f(ev, POSE)
    assert second is first and first.table is not None          # the pose came back: recorded
    assert first.table.n_entries > 1000 and first.table.nbytes > 0
    moved = f(ev, pose_from_xyz_rpy(0.3, 0.2, 0.1))
    assert moved.table is None                                   # a moving radar never records
    monkeypatch.setattr(fusion_cached, "STILL_TABLE_SHARE", 1e-9)
    g = Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST)
    g(ev, POSE)
    assert g(ev, POSE).table is None                             # too large for the budget: the gather
    forced = Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST, still=True)
    forced(ev, POSE)
    assert forced(ev, POSE).table is not None                    # still=True ignores the budget
    with pytest.raises(ConfigError, match="still"):
        Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST, still="yes")


def test_a_tilting_stand_reuses_each_positions_plan(runtime):
    """The plans of recent poses are kept: a stand cycling through its tilts gets a table for
    each position on its second visit; grid.clear() drops them."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=False"]
    grid = EvidenceGrid(runtime, SMALL)
    f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    tilts = [pose_from_xyz_rpy(0.0, 0.0, 0.5, pitch=math.radians(p)) for p in (-6.0, -4.0, -2.0)]
    ev = evidence(lattice, seed=8)
    first = [f(ev, pose) for pose in tilts]
    again = [f(ev, pose) for pose in tilts]
    assert all(a is b and a.table is not None for a, b in zip(first, again))
    grid.clear()
    assert f(ev, tilts[0]) is not first[0] and len(f._plans) == 1


def test_live_segments_of_the_wrong_form_are_refused(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    ok = np.full((N_BINS, 2), 0xF, np.uint8)
    for bad in (ok.astype(np.int32), ok[:-1], ok[:, :1], ok.tolist()):
        with pytest.raises(ShapeError, match="live_segments must be a uint8 array"):
            Fusion(runtime, EvidenceGrid(runtime, SMALL, knowledge=True), lattice, model, N_BINS, SPACING, FIRST, LAST,
                   detstats=True, live_segments=bad)
    with pytest.raises(ConfigError, match="one bit per segment"):
        Fusion(runtime, EvidenceGrid(runtime, SMALL, knowledge=True), lattice, model, N_BINS, SPACING, FIRST, LAST,
               detstats=True, live_segments=ok | 0x10)
    with pytest.raises(ConfigError, match="detection-statistics"):
        Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST, live_segments=ok)
