"""kernels/fusion.cl <-> radarcl/stages/fusion.py against radarcl.oracle.fusion (eq. 9, §3.4).

The integer grid is compared with the float64 oracle voxel by voxel, and is shown to be
bit-identical across repetitions, frame orders, beam orders (splits), local sizes and vector
widths, and to give each voxel at most one update per beam.
"""

import math

import numpy as np
import pytest
from tolerances import FUSION_AMBIGUOUS_MAX, FUSION_DECISION_MARGIN, FUSION_UNITS_PER_UPDATE

from radarcl import node_pairs, oracle
from radarcl.config.stage_config import RadarConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GRID_LIMIT, GridSpec
from radarcl.maps.disk import load_grid
from radarcl.stages.fusion import Fusion

RADAR = RadarConfig()
N_BINS, SPACING, FIRST, LAST = 160, 0.1, 5, 150
SMALL = GridSpec((-1.0, -6.0, -3.0), 0.25, (48, 48, 24))   # the sensor sits inside
POSE = pose_from_xyz_rpy(0.3, 0.2, 0.1, roll=0.02, pitch=-0.03, yaw=0.05)


def evidence(lattice, seed=0, low=-3000, high=3000):
    return np.random.default_rng(seed).integers(low, high, (lattice.n_beams, N_BINS)).astype(np.int32)


def fuse_frame(runtime, spec, lattice, model, ev, poses, **options):
    grid = EvidenceGrid(runtime, spec)
    plan = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, **options)(ev, poses)
    return grid, plan


def check_against_oracle(got, spec, lattice, model, ev, poses, min_reached=100):
    sums, updates, ambiguous = oracle.fusion(spec, ev, lattice, model, poses, SPACING, FIRST, LAST,
                                              margin=FUSION_DECISION_MARGIN)
    reached = updates > 0
    assert reached.sum() >= min_reached, "the case reaches too few voxels to test anything"
    assert ambiguous.sum() <= FUSION_AMBIGUOUS_MAX * reached.sum()
    clear = ~ambiguous
    diff = np.abs(got.astype(np.int64) - sums)[clear]
    if model.gaussian:
        assert (diff <= FUSION_UNITS_PER_UPDATE * updates[clear]).all()
    else:
        assert (diff == 0).all()
    return sums, updates


LATTICES = {
    "paper, tilt -10 deg": BeamLattice.from_radar(RADAR, tilt_deg=-10.0),
    "spinning, 90 azimuths": BeamLattice.spinning(90, az0_rad=0.3),
}
MODELS = {f"near_field={n}, gaussian={g}": BeamModel.from_radar(RADAR, near_field=n, gaussian=g)
          for n in (True, False) for g in (True, False)}


@pytest.mark.parametrize("model", MODELS.values(), ids=MODELS.keys())
@pytest.mark.parametrize("lattice", LATTICES.values(), ids=LATTICES.keys())
def test_matches_oracle(runtime, lattice, model):
    ev = evidence(lattice)
    grid, _ = fuse_frame(runtime, SMALL, lattice, model, ev, POSE)
    check_against_oracle(grid.snapshot(), SMALL, lattice, model, ev, POSE)


@pytest.mark.parametrize("voxel", [0.05, 0.6, 1.5], ids=["far below the footprint", "about it", "far above"])
def test_voxel_sizes_match_oracle_without_holes(runtime, voxel):
    """Small voxels: no aliasing holes (every centre inside a beam is updated, exactly as the
    oracle's brute force says); voxels wider than the beam: only those whose centre is inside."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=False"]
    extent = {0.05: (2.4, 2.4, 1.2), 0.6: (32.0, 32.0, 12.0), 1.5: (32.0, 32.0, 12.0)}[voxel]
    spec = GridSpec.around((0.5 * extent[0] - 0.4, 0.0, -1.0), extent, voxel)
    pose = pose_from_xyz_rpy(0.013, -0.021, 0.007, yaw=0.003)   # off the voxel lattice's symmetries
    ev = np.full((lattice.n_beams, N_BINS), 700, np.int32)
    grid, _ = fuse_frame(runtime, spec, lattice, model, ev, pose)
    got = grid.snapshot()
    _, updates = check_against_oracle(got, spec, lattice, model, ev, pose, min_reached=20)
    assert (got[updates > 0] >= 700).mean() >= 1 - FUSION_AMBIGUOUS_MAX


@pytest.mark.parametrize("rows", [1, 2])
def test_per_beam_poses_match_oracle(runtime, rows):
    lattice, model = LATTICES["spinning, 90 azimuths"], MODELS["near_field=True, gaussian=True"]
    # the radar drives 1.5 m along x and turns 5 deg during the scan
    poses = np.stack([pose_from_xyz_rpy(1.5 * f, 0.1 * f, 0.0, yaw=math.radians(5) * f)
                      for f in np.linspace(0, 1, lattice.n_beams)])
    ev = evidence(lattice, seed=3)
    grid, _ = fuse_frame(runtime, SMALL, lattice, model, ev, poses, per_beam_poses=True, rows=rows)
    check_against_oracle(grid.snapshot(), SMALL, lattice, model, ev, poses)


def test_sensor_outside_the_grid(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    pose = pose_from_xyz_rpy(-6.0, 0.5, 1.0, yaw=0.1)
    ev = evidence(lattice, seed=4)
    grid, plan = fuse_frame(runtime, SMALL, lattice, model, ev, pose)
    assert plan.beams_outside == 0
    check_against_oracle(grid.snapshot(), SMALL, lattice, model, ev, pose)


def test_beams_outside_the_grid_are_counted(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    behind = pose_from_xyz_rpy(20.0, 0.0, 0.0, yaw=0.0)         # looking away from the grid
    grid, plan = fuse_frame(runtime, SMALL, lattice, model, evidence(lattice), behind)
    assert plan.beams_outside == lattice.n_beams
    assert grid.n_bricks == 0 and not grid.snapshot().any()
    sideways = pose_from_xyz_rpy(-3.0, -8.0, 0.0, yaw=math.radians(90))   # some azimuths miss it
    _, plan = fuse_frame(runtime, SMALL, lattice, model, evidence(lattice), sideways)
    assert 0 < plan.beams_outside < lattice.n_beams


def test_one_update_per_beam_per_voxel(runtime):
    """Near the sensor a cone sampled by points hits voxels many times; the gather cannot."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=False"]
    spec = GridSpec.around((2.0, 0.0, 0.0), (4.0, 4.0, 2.0), 0.02)
    for beam in (0, 130):
        ev = np.zeros((lattice.n_beams, N_BINS), np.int32)
        ev[beam] = 1000
        grid, _ = fuse_frame(runtime, spec, lattice, model, ev, np.eye(4))
        got = grid.snapshot()
        assert set(np.unique(got)) == {0, 1000}


def test_deterministic_across_orders_sizes_and_widths(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    frames = [(evidence(lattice, seed=s), pose_from_xyz_rpy(0.4 * s, 0.1, 0.0, yaw=0.1 * s)) for s in range(3)]

    def run(order, **options):
        grid = EvidenceGrid(runtime, SMALL)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, **options)
        for i in order:
            f(*frames[i])
        return grid.snapshot()

    first = run([0, 1, 2])
    assert first.any()
    assert np.array_equal(first, run([0, 1, 2]))                 # repetition
    assert np.array_equal(first, run([2, 0, 1]))                 # frame order
    for options in ({"local_size": 1}, {"local_size": 4}, {"vector_width": 4}, {"rows": 1}, {"rows": 2}):
        assert np.array_equal(first, run([1, 2, 0], **options)), options
    # beam order: the beams of each frame fused in two launches, odd azimuths first
    grid = EvidenceGrid(runtime, SMALL)
    f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    odd = (np.arange(lattice.n_beams) // lattice.n_el) % 2 == 1
    for ev, pose in frames[::-1]:
        f(np.where(odd[:, None], ev, 0).astype(np.int32), pose)
        f(np.where(odd[:, None], 0, ev).astype(np.int32), pose)
    assert np.array_equal(first, grid.snapshot())


def test_sums_saturate_at_the_grid_limit(runtime, tmp_path):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=False"]
    spec = GridSpec.around((3.0, 0.0, -0.5), (2.0, 2.0, 1.0), 0.25)
    ev = np.full((lattice.n_beams, N_BINS), 16384, np.int32)
    grid, _ = fuse_frame(runtime, spec, lattice, model, ev, np.eye(4))
    keys, data = grid.bricks()
    reached = data > 0
    data[reached] = GRID_LIMIT - 1
    np.savez_compressed(tmp_path / "g.npz", version=1, origin_m=np.asarray(spec.origin_m), voxel_m=spec.voxel_m,
                        shape=np.asarray(spec.shape), keys=keys, data=data)
    loaded = load_grid(runtime, tmp_path / "g.npz")
    Fusion(runtime, loaded, lattice, model, N_BINS, SPACING, FIRST, LAST)(ev, np.eye(4))
    _, after = loaded.bricks()
    assert (after[reached] == GRID_LIMIT).all() and (after[~reached] == 0).all()


def test_bad_input(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    grid = EvidenceGrid(runtime, SMALL)
    f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    ev = evidence(lattice)
    nan_pose = np.eye(4)
    nan_pose[0, 3] = np.nan
    scaled = np.diag([1.0, 1.0, 2.0, 1.0])
    mirror = np.diag([1.0, -1.0, 1.0, 1.0])
    for pose, words in ((nan_pose, "NaN"), (scaled, "not a proper rotation"), (mirror, "det"),
                        (np.eye(3), r"\(4, 4\)"), (np.stack([np.eye(4)] * lattice.n_beams), "per_beam_poses")):
        with pytest.raises(ConfigError, match=words):
            f(ev, pose)
    with pytest.raises(ShapeError, match="expected evidence of shape"):
        f(ev.astype(np.float32), np.eye(4))
    with pytest.raises(ShapeError, match="expected evidence of shape"):
        f(ev[:, :10], np.eye(4))
    with pytest.raises(ConfigError, match="no bin carries evidence"):
        Fusion(runtime, grid, lattice, model, N_BINS, SPACING, 100, 50)
    for widths in ({"rows": 3}, {"rows": 2, "vector_width": 4}):
        with pytest.raises(ConfigError, match="rows must be 1, or 2 with vector_width 8"):
            Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, **widths)
    assert grid.n_bricks == 0, "a refused frame must leave the map untouched"


def test_low_level_enqueue_refuses_foreign_stale_and_wrong_arrays(runtime):
    """Fusion.enqueue with a plan of another Fusion, a plan made before grid.clear(), or a device
    array of the wrong size or dtype is refused before any launch (each of these once wrote
    garbage into the map or crashed the process); the map is unchanged."""
    import pyopencl.array as cla

    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    grid, other_grid = EvidenceGrid(runtime, SMALL), EvidenceGrid(runtime, SMALL)
    f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    other = Fusion(runtime, other_grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    ev = evidence(lattice)
    f(ev, POSE)
    before = grid.snapshot()
    q = runtime.queue
    with pytest.raises(ConfigError, match="made by this Fusion"):
        f.enqueue(plan=other.plan(POSE))
    with pytest.raises(ShapeError, match="expected evidence of shape"):
        f.enqueue(cla.to_device(q, np.zeros(16, np.int32)), f.plan(POSE))
    with pytest.raises(ShapeError, match="expected evidence of shape"):
        f.enqueue(cla.to_device(q, ev.astype(np.float32)), f.plan(POSE))
    with pytest.raises(ShapeError, match="device array"):
        f.enqueue(ev, f.plan(POSE))
    assert np.array_equal(grid.snapshot(), before)
    stale = f.plan(POSE)
    grid.clear()
    with pytest.raises(ConfigError, match="before grid.clear"):
        f.enqueue(plan=stale)
    assert grid.n_bricks == 0


def test_updates_beyond_the_evidence_limit_are_refused(runtime):
    """Two beams of 2^30 once summed to -2^30 (fully free): host evidence beyond +-16 nat per
    update is refused; within it, a voxel's sum saturates instead of wrapping (the stability
    suite takes it to the grid limit)."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=False"]
    grid = EvidenceGrid(runtime, SMALL)
    f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST)
    ev = np.zeros((lattice.n_beams, N_BINS), np.int32)
    ev[:2] = 2 ** 30
    with pytest.raises(ConfigError, match="evidence must lie within \\+-16384 units"):
        f(ev, POSE)
    assert grid.n_bricks == 0


# -- the detection-statistics model (DETSTATS): node pairs interpolated in rho2, the knowledge pool -----------------
def random_nodes(lattice, seed=0, spread=3000):

    rng = np.random.default_rng(seed)
    e = rng.integers(-spread, spread, (lattice.n_beams, N_BINS, node_pairs.N_CLASSES, node_pairs.NODES))
    d = rng.integers(0, logodds_scale() + 1, e.shape)
    d[:, ::3] = 0                                    # bins whose looks see nothing: not counted as looks
    return e, d, node_pairs.pack_nodes(e, d)


def logodds_scale():
    from radarcl import logodds

    return logodds.KNOWLEDGE_SCALE


def detstats_grid(runtime, spec, lattice, model, packed, poses, terrain_dz, **options):
    grid = EvidenceGrid(runtime, spec, knowledge=True)
    fusion = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True, terrain_dz=terrain_dz,
                    **options)
    plan = fusion(packed, poses)
    return grid, fusion, plan


@pytest.mark.parametrize("accumulators", ["packed", "separate"])
@pytest.mark.parametrize("widths", [{"rows": 1}, {"rows": 2}, {"vector_width": 4, "rows": 1}], ids=["8x1", "8x2", "4x1"])
@pytest.mark.parametrize("model", [MODELS["near_field=True, gaussian=True"], MODELS["near_field=False, gaussian=False"]],
                         ids=["cylindrical-conical", "uniform cone"])
def test_detstats_matches_its_oracle(runtime, model, widths, accumulators, monkeypatch):
    """Each voxel takes its class's nodes (terrain below terrain_dz) interpolated at its quantised
    rho2: the evidence and knowledge sums equal the oracle's within one quantisation step of rho2
    per update (float32 vs float64 rho2: 1 + |step between nodes| / 4096 units) and are exact
    integers: the still table gives the gather's. The gather keeps knowledge and looks in one
    accumulator for lattices under 512 beams, in two above (forced here by a smaller limit)."""
    import radarcl.stages.fusion as fusion_module

    if accumulators == "separate":
        monkeypatch.setattr(fusion_module, "PACKED_LOOKS", 12)          # 256 beams x 4096 > 2^12
    lattice = LATTICES["paper, tilt -10 deg"]
    e, d, packed = random_nodes(lattice)
    grid, fusion, _ = detstats_grid(runtime, SMALL, lattice, model, packed, POSE, -0.8, still=True, **widths)
    assert ("PACKED_LOOKS" in fusion._defines) == (accumulators == "packed")
    reached, ambiguous, known = check_detstats_frame(grid, fusion, lattice, model, e, d, packed, -0.8)
    clear = ~ambiguous
    assert ambiguous.sum() <= FUSION_AMBIGUOUS_MAX * reached.sum()
    nz, ny, nx = SMALL.array_shape
    iz, iy, ix = np.indices((nz, ny, nx)).reshape(3, -1)
    terrain = (SMALL.index_to_world(np.stack([ix, iy, iz], 1))[:, 2] - POSE[2, 3] < -0.8).reshape(nz, ny, nx)
    assert (reached & terrain).sum() > 100 and (reached & ~terrain).sum() > 100    # both classes are tested
    assert not known[~reached & clear].any()


def test_detstats_without_terrain_reads_the_upright_nodes_only(runtime):
    """terrain_dz = -inf (no ground plane: a spinning radar's one beam): every voxel takes the
    upright class's nodes; the sums equal the oracle's as with both classes, though the terrain
    class's nodes are not 0, from the gather and from the still table."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    e, d, packed = random_nodes(lattice, seed=4)
    assert e[..., 1, :].any() and d[..., 1, :].any()
    grid, fusion, _ = detstats_grid(runtime, SMALL, lattice, model, packed, POSE, -math.inf, still=True)
    check_detstats_frame(grid, fusion, lattice, model, e, d, packed, -math.inf)


def one_class_nodes(lattice, seed):
    """Random node pairs (e, d) of both classes with the terrain class all 0, packed as both
    classes and as the upright class alone (a scene without a terrain class)."""
    e, d, _ = random_nodes(lattice, seed=seed)
    e[..., 1, :] = 0
    d[..., 1, :] = 0
    return e, d, node_pairs.pack_nodes(e, d), node_pairs.pack_nodes(e[..., :1, :], d[..., :1, :])


@pytest.mark.parametrize("accumulators", ["packed", "separate"])
@pytest.mark.parametrize("widths", [{"rows": 1}, {"rows": 2}, {"vector_width": 4, "rows": 1}], ids=["8x1", "8x2", "4x1"])
def test_detstats_one_class_gives_the_integers_of_two_with_zero_terrain(runtime, widths, accumulators, monkeypatch):
    """classes 1 (the node array holds the upright class alone, half the bytes) with a finite
    terrain_dz: a voxel below it takes nothing, the same integers (evidence, knowledge, looks) as
    classes 2 whose terrain nodes are all 0, from the gather and from the still table, both the
    float64 oracle's; terrain voxels are reached (their masking is tested) and the upright
    nodes are not 0 (a terrain voxel reading them would show)."""
    import radarcl.stages.fusion as fusion_module

    if accumulators == "separate":
        monkeypatch.setattr(fusion_module, "PACKED_LOOKS", 12)
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    e, d, two, one = one_class_nodes(lattice, seed=7)
    assert e[..., 0, :].any() and d[..., 0, :].any()
    maps = {}
    for classes, packed in ((2, two), (1, one)):
        grid, fusion, _ = detstats_grid(runtime, SMALL, lattice, model, packed, POSE, -0.8, still=True, classes=classes,
                                        **widths)
        assert fusion.evidence_shape == (lattice.n_beams, N_BINS, classes, 4, 2)
        assert ("PACKED_LOOKS" in fusion._defines) == (accumulators == "packed")
        reached, _, _ = check_detstats_frame(grid, fusion, lattice, model, e, d, packed, -0.8)
        maps[classes] = grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")
    nz, ny, nx = SMALL.array_shape
    iz, iy, ix = np.indices((nz, ny, nx)).reshape(3, -1)
    terrain = (SMALL.index_to_world(np.stack([ix, iy, iz], 1))[:, 2] - POSE[2, 3] < -0.8).reshape(nz, ny, nx)
    assert (reached & terrain).sum() > 100 and (reached & ~terrain).sum() > 100
    assert not maps[1][0][terrain].any() and maps[1][0][~terrain].any() and maps[1][2].sum() > 1000
    assert all(np.array_equal(a, b) for a, b in zip(maps[1], maps[2]))


def test_detstats_classes_are_checked(runtime):
    """classes is 1 or 2; the frame's shape follows it."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    grid = EvidenceGrid(runtime, SMALL, knowledge=True)
    with pytest.raises(ConfigError, match=r"classes must be 1 \(upright targets only\) or 2 \(and terrain\), got 0"):
        Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True, classes=0)
    fusion = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True, classes=1)
    with pytest.raises(ShapeError, match=r"expected evidence nodes of shape \(64, 4, 160, 1, 4, 2\) int32"):
        fusion(one_class_nodes(lattice, 0)[2], POSE)
    assert grid.n_bricks == 0


def check_detstats_frame(grid, fusion, lattice, model, e, d, packed, terrain_dz):
    """One frame of node pairs (e, d) fused into ``grid`` against the float64 oracle: evidence and
    knowledge within one quantisation step of rho2 per update and exact on most voxels, the looks
    counted as the oracle's; the pose fused twice more (recorded into the still table, then
    streamed from it) gives three times each. Returns (reached, ambiguous, knowledge sums)."""
    got, known, counted = grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")
    nz, ny, nx = SMALL.array_shape
    iz, iy, ix = np.indices((nz, ny, nx)).reshape(3, -1)
    centres = SMALL.index_to_world(np.stack([ix, iy, iz], axis=1))
    sums, updates, ambiguous, knowledge, looks = (a.reshape(nz, ny, nx) for a in oracle.fusion_at_points(
        centres, None, lattice, model, POSE, SPACING, FIRST, LAST, FUSION_DECISION_MARGIN, nodes=(e, d),
        terrain_dz=terrain_dz))
    reached, clear = updates > 0, ~ambiguous
    assert reached.sum() > 1000
    step = 1 + -(-max(np.abs(np.diff(e, axis=-1)).max(), np.abs(np.diff(d, axis=-1)).max()) // 4096)
    assert (np.abs(got - sums)[clear] <= step * updates[clear]).all()
    assert (np.abs(known - knowledge)[clear] <= step * updates[clear]).all()
    # the step is the rare float32/float64 disagreement on rho2's quantisation, not a licence: the
    # integer interpolation itself (its rounding included) is exact on most voxels (98 % here)
    assert (got == sums)[clear & reached].mean() > 0.95 and (known == knowledge)[clear & reached].mean() > 0.95
    # a look counts where its interpolated opportunity is above 0: the same as the oracle's except
    # where one quantisation step of rho2 moves a node value across 0 (then by one)
    assert (np.abs(counted - looks)[clear] <= (np.abs(known - knowledge)[clear] > 0)).all() and counted.sum() > 1000
    fusion(packed, POSE)                             # the pose comes back: the table is recorded
    fusion(packed, POSE)                             # and streamed
    assert fusion.plan(POSE).table is not None
    assert np.array_equal(grid.snapshot(), 3 * got) and np.array_equal(grid.knowledge_snapshot(), 3 * known)
    assert np.array_equal(grid.knowledge_snapshot("looks"), 3 * counted)
    return reached, ambiguous, known


def test_detstats_sums_do_not_depend_on_the_order_of_frames(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    poses = [POSE, pose_from_xyz_rpy(0.5, -0.3, 0.1, pitch=0.05, yaw=-0.08), pose_from_xyz_rpy(1.0, 0.4, 0.0, yaw=0.1)]
    frames = [random_nodes(lattice, seed=s)[2] for s in range(3)]
    maps = []
    for order in ((0, 1, 2), (2, 0, 1), (1, 2, 0)):
        grid = EvidenceGrid(runtime, SMALL, knowledge=True)
        fusion = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True, terrain_dz=-0.8)
        for k in order:
            fusion(frames[k], poses[k])
        maps.append((grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")))
    for e_map, k_map, n_map in maps[1:]:
        assert np.array_equal(e_map, maps[0][0]) and np.array_equal(k_map, maps[0][1]) and np.array_equal(n_map, maps[0][2])
    assert maps[0][1].min() >= 0 and maps[0][1].any()


def test_detstats_refusals(runtime):
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    with pytest.raises(ConfigError, match=r"EvidenceGrid\(\.\.\., knowledge=True\)"):
        Fusion(runtime, EvidenceGrid(runtime, SMALL), lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True)
    fusion = Fusion(runtime, EvidenceGrid(runtime, SMALL, knowledge=True), lattice, model, N_BINS, SPACING, FIRST,
                    LAST, detstats=True)
    with pytest.raises(ShapeError, match=r"expected evidence nodes of shape \(64, 4, 160, 2, 4, 2\) int32"):
        fusion(evidence(lattice), POSE)
    e, d, _ = random_nodes(lattice)

    bad = node_pairs.pack_nodes(e, d)
    bad[0, 0, 0, 0, 1] = -1                          # an opportunity below 0
    with pytest.raises(ConfigError, match="opportunity within"):
        fusion(bad, POSE)


# -- bricks shaped to the sensor (-D BRICK_Z): 8 x 8 x 1 for a planar sensor ------------------------------
PLANAR_CASES = {
    # lattice, per-beam poses, grid (the same voxels, in either brick shape), still, vector width, rows
    "spinning, one voxel thick, moving": (LATTICES["spinning, 90 azimuths"], True,
                                          ((-5.0, -5.5, -0.125), 0.25, (40, 45, 1)), False, 8, 2),
    "spinning, one voxel thick, still table": (LATTICES["spinning, 90 azimuths"], False,
                                               ((-5.0, -5.5, -0.125), 0.25, (40, 45, 1)), True, 8, 2),
    "paper, 11 layers, vec 4": (LATTICES["paper, tilt -10 deg"], False, ((-1.0, -6.0, -2.0), 0.25, (48, 48, 11)),
                                False, 4, 1),
    "paper, 11 layers, still table": (LATTICES["paper, tilt -10 deg"], False, ((-1.0, -6.0, -2.0), 0.25, (48, 48, 11)),
                                      True, 8, 2),
}


@pytest.mark.parametrize("case", PLANAR_CASES.values(), ids=PLANAR_CASES.keys())
def test_planar_bricks_give_the_same_integers(runtime, case):
    """A grid of 8 x 8 x 1 bricks (kernels built with -D BRICK_Z=1) gives exactly the integers of
    8^3 bricks over the same voxels (the gather and the still table, several frames), within the
    float64 oracle's tolerance, in an eighth of the memory of a one-voxel-thick grid; and the
    same again with the pool in many small chunks (launches per chunk)."""
    lattice, per_beam, (origin, voxel, shape), still, vec, rows = case
    model = MODELS["near_field=True, gaussian=True"]
    poses = POSE if not per_beam else np.stack(
        [pose_from_xyz_rpy(0.8 * f, 0.1, 0.0, yaw=0.05 * f) for f in np.linspace(0, 1, lattice.n_beams)])
    frames = [evidence(lattice, seed=s) for s in (21, 22)]
    maps, memory = {}, {}
    for brick_z, chunk in ((8, None), (1, None), (1, 5)):
        spec = GridSpec(origin, voxel, shape, brick_z=brick_z)
        grid = EvidenceGrid(runtime, spec, chunk_bricks=chunk)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, per_beam_poses=per_beam, still=still,
                   vector_width=vec, rows=rows)
        for ev in frames:
            plan = f(ev, poses)
        assert (plan.table is not None) == still
        maps[brick_z, chunk], memory[brick_z, chunk] = grid.snapshot(), grid.memory()
    assert memory[1, 5]["bricks"] > 5 * 4, "the chunked grid must span several chunks"
    assert np.array_equal(maps[8, None], maps[1, None]) and np.array_equal(maps[1, None], maps[1, 5])
    if shape[2] == 1:                       # one voxel thick: a planar brick is an eighth of a cubic one
        assert memory[1, None]["bricks"] == memory[8, None]["bricks"]
        assert memory[1, None]["sparse_bytes"] < memory[8, None]["sparse_bytes"] / 6
    spec = GridSpec(origin, voxel, shape, brick_z=1)
    one = EvidenceGrid(runtime, spec)
    Fusion(runtime, one, lattice, model, N_BINS, SPACING, FIRST, LAST, per_beam_poses=per_beam)(frames[1], poses)
    check_against_oracle(one.snapshot(), spec, lattice, model, frames[1], poses)


@pytest.mark.parametrize("classes", [2, 1])
@pytest.mark.parametrize("still", [False, True], ids=["gather", "still table"])
def test_planar_bricks_and_chunks_give_the_same_knowledge(runtime, still, classes):
    """The detection-statistics model on 8 x 8 x 1 bricks and on a pool of many small chunks: the
    sums, the knowledge and the looks equal those of 8^3 bricks over the same voxels, exactly
    (with both classes, and with the upright class alone)."""
    lattice, model = LATTICES["paper, tilt -10 deg"], MODELS["near_field=True, gaussian=True"]
    frames = [(random_nodes(lattice, seed=s)[2] if classes == 2 else one_class_nodes(lattice, s)[3]) for s in (5, 6)]
    got = {}
    for brick_z, chunk in ((8, None), (1, None), (1, 5)):
        spec = GridSpec((-1.0, -6.0, -2.0), 0.25, (48, 48, 11), brick_z=brick_z)
        grid = EvidenceGrid(runtime, spec, knowledge=True, chunk_bricks=chunk)
        f = Fusion(runtime, grid, lattice, model, N_BINS, SPACING, FIRST, LAST, detstats=True, terrain_dz=-0.8,
                   still=still, classes=classes)
        for packed in frames:
            plan = f(packed, POSE)
        assert (plan.table is not None) == still
        got[brick_z, chunk] = [grid.snapshot(), grid.knowledge_snapshot(), grid.knowledge_snapshot("looks")]
        if chunk:
            assert len(grid.pools["knowledge"]) > 4, "the chunked grid must span several chunks"
    assert got[8, None][1].sum() > 0 and got[8, None][2].sum() > 0
    for other in ((1, None), (1, 5)):
        assert all(np.array_equal(a, b) for a, b in zip(got[8, None], got[other]))
