"""radarcl.pipeline.Mapping: the chained stages give exactly what the stages give one by one,
and a refused frame leaves the map as it was."""

import numpy as np
import pytest

from radarcl import oracle
from radarcl.config.stage_config import PAPER_RADAR, InterpretConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec
from radarcl.pipeline import Detection, Mapping
from radarcl.scene.echoes import paper_like_samples
from radarcl.stages.fusion import Fusion
from radarcl.stages.range_fft import RangeFFT

TILT = -7.0
SPEC = GridSpec((-2.0, -20.0, -6.0), 0.25, (96, 160, 40))
N_FFT = 512


def staged(runtime, samples, pose, lattice, model):
    """The same frame through each stage separately, via the host."""
    fft = RangeFFT(runtime, samples.shape[:2], samples.shape[2], N_FFT, dtype=np.float32, output="power")(samples)
    spacing = PAPER_RADAR.bin_spacing_m(N_FFT)
    det = Detection(runtime, samples.shape[:2], N_FFT // 2, spacing)(fft.profiles, fft.flags)
    grid = EvidenceGrid(runtime, SPEC)
    it = det.interpret
    first, last = InterpretConfig().bin_interval(spacing, N_FFT // 2)
    Fusion(runtime, grid, lattice, model, N_FFT // 2, spacing, first, last)(
        it.evidence.reshape(lattice.n_beams, -1), pose)
    return grid.snapshot(), it.flags


def test_raw_frames_chain_exactly_like_the_stages(runtime):
    lattice, model = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT), BeamModel.from_radar(PAPER_RADAR)
    samples = paper_like_samples(seed=2, tilt_deg=TILT)
    samples[3, 1, 7] = np.nan                       # one beam gives no evidence, its pair still does
    pose = pose_from_xyz_rpy(0.0, 0.0, 1.5, yaw=0.02)
    grid = EvidenceGrid(runtime, SPEC)
    m = Mapping(runtime, grid, lattice, model, radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32)
    plan = m.fuse(samples, pose)
    got = m.snapshot()
    want, flags = staged(runtime, samples, pose, lattice, model)
    assert np.array_equal(got, want)
    assert np.array_equal(m.flags(), flags) and flags[3, 1] & oracle.FLAG_NONFINITE and not flags[3, 0]
    assert (got > 0).sum() > 1000 and (got < 0).sum() > 10000 and plan.beams_outside == 0


def test_profiles_enter_at_cfar(runtime):
    lattice, model = BeamLattice.spinning(64), BeamModel.from_radar(PAPER_RADAR)
    rng = np.random.default_rng(0)
    profiles = rng.exponential(size=(64, 256)).astype(np.float32)
    profiles[:, 100] = 1e4
    spacing = 0.1
    spec = GridSpec.around((0, 0, 0), (60, 60, 1), 0.25)
    grid = EvidenceGrid(runtime, spec)
    m = Mapping(runtime, grid, lattice, model, n_bins=256, bin_spacing_m=spacing)
    m.fuse(profiles, np.eye(4))
    ev = Detection(runtime, (64,), 256, spacing)(profiles).interpret.evidence
    ref = EvidenceGrid(runtime, spec)
    it = m.detection.interpreter
    Fusion(runtime, ref, lattice, model, 256, spacing, it.first_bin, it.last_bin)(ev, np.eye(4))
    got = m.snapshot()
    assert np.array_equal(got, ref.snapshot()) and got.max() > 0


def test_levels_become_the_same_power_on_the_device(runtime):
    """A polar scan's uint8 levels (``db_per_level``) fuse into the map its power makes, bit for
    bit (the device converts through the host's table); a refused frame of levels leaves it."""
    from radarcl.errors import FrameFormatError
    from radarcl.io.polar_png import levels_to_power

    lattice, model = BeamLattice.spinning(64), BeamModel.from_radar(PAPER_RADAR)
    rng = np.random.default_rng(5)
    spec = GridSpec.around((0, 0, 0), (60, 60, 1), 0.25)
    scans = rng.integers(0, 40, size=(3, 64, 256), dtype=np.uint8)
    for k in range(3):
        scans[k, :, 100 + 10 * k] = 200
    maps = {}
    for how in ("power", "levels"):
        m = Mapping(runtime, EvidenceGrid(runtime, spec), lattice, model, n_bins=256, bin_spacing_m=0.1)
        for k, (levels, db) in enumerate(zip(scans, (1.0, 0.5, 1.0))):       # the table follows the scale
            pose = pose_from_xyz_rpy(0.3 * k, 0.0, 0.0, yaw=0.1 * k)
            if how == "power":
                m.fuse(levels_to_power(levels, db), pose)
            else:
                m.fuse(levels, pose, db_per_level=db)
        maps[how] = m.snapshot()
    assert np.array_equal(maps["levels"], maps["power"]) and maps["power"].max() > 0
    before = m.frames
    with pytest.raises(ShapeError, match=r"expected levels of shape \(64, 256\) uint8, got \(64, 256\) float32"):
        m.fuse(levels_to_power(levels), np.eye(4), db_per_level=1.0)
    with pytest.raises(FrameFormatError, match=r"db_per_level must be in \(0, 1.4\]"):
        m.fuse(levels, np.eye(4), db_per_level=3.0)
    with pytest.raises(ConfigError, match="differenced frames are polar scans' levels; pass db_per_level with them"):
        m.fuse(levels, np.eye(4), differenced=True)
    assert np.array_equal(m.snapshot(), maps["levels"]) and m.frames == before
    raw = Mapping(runtime, EvidenceGrid(runtime, SPEC), BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT), model,
                  radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32)
    with pytest.raises(ConfigError, match="raw frames are samples, not levels"):
        raw.fuse(paper_like_samples(seed=1, tilt_deg=TILT), np.eye(4), db_per_level=1.0)


def test_a_refused_frame_leaves_the_map_as_it_was(runtime):
    lattice, model = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT), BeamModel.from_radar(PAPER_RADAR)
    grid = EvidenceGrid(runtime, SPEC)
    m = Mapping(runtime, grid, lattice, model, radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32)
    samples = paper_like_samples(seed=1, tilt_deg=TILT)
    m.fuse(samples, np.eye(4))
    before = m.snapshot()
    bad_pose = np.eye(4)
    bad_pose[2, 2] = np.inf
    with pytest.raises(ConfigError, match="NaN or Inf"):
        m.fuse(samples, bad_pose)
    with pytest.raises(ShapeError, match="expected a frame of shape"):
        m.fuse(samples[:, :, :100], np.eye(4))
    with pytest.raises(ShapeError):
        m.fuse(samples.astype(np.float64), np.eye(4))
    assert np.array_equal(m.snapshot(), before) and m.frames == 1
    with pytest.raises(ConfigError, match="either radar"):
        Mapping(runtime, grid, lattice, model)


def test_a_still_radar_makes_only_the_node_pairs_its_voxels_read(runtime):
    """The default model on a still radar: once its pose's table is recorded, the interpreter makes
    only the node pairs the table reads (``StillTable.node_use``) and leaves the others. Frame
    after frame at that pose, alternating with another pose (whose first frame makes the pairs its
    beams may reach, and whose own table then makes its own), the map (evidence, knowledge, looks)
    is the one a Mapping that never records a table and makes every pair makes, integer for
    integer; the pairs read are that Mapping's, and some not read were left."""
    from radarcl.config.presets import paper_config
    from radarcl.pipeline import bin_model
    from radarcl.sensor_model import terrain_dz

    config = paper_config(SPEC.voxel_m)
    lattice, model = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT), BeamModel.from_radar(PAPER_RADAR)
    still, moved = np.eye(4), pose_from_xyz_rpy(0.4, 0.2, 0.0, yaw=0.03)
    maps = []
    for record in (True, False):
        m = Mapping(runtime, EvidenceGrid(runtime, SPEC, knowledge=True), lattice, model, radar=PAPER_RADAR,
                    n_fft=config.n_fft, dtype=np.float32, interpret_config=config.interpret_config(), bin_model=bin_model(config, SPEC.voxel_m),
                    terrain_dz=terrain_dz(config.model_params()))
        m.fusion.still, m.every_node_pair = record, not record
        for seed in range(3):
            samples = paper_like_samples(seed=seed, tilt_deg=TILT)
            plan = m.fuse(samples, still)
            m.fuse(samples, moved)
            m.fuse(paper_like_samples(seed=seed + 5, tilt_deg=TILT), still)
        assert (plan.table is not None) == record
        maps.append(m)
        table = plan.table if record else table
    grids = [(m.grid.snapshot(), m.grid.knowledge_snapshot(), m.grid.knowledge_snapshot("looks")) for m in maps]
    assert all(np.array_equal(a, b) for a, b in zip(*grids))
    assert (grids[0][0] > 0).sum() > 1000 and (grids[0][2] > 3).any()
    use = table.node_use.get().reshape(-1)
    nodes = [m.detection.interpreter.arrays["evidence"].get().reshape(len(use), 2, -1) for m in maps]
    read = np.stack([use & 1, use & 2], -1).astype(bool)     # (beam x bin, class)
    assert np.array_equal(nodes[0][read], nodes[1][read])
    assert read.any() and not read.all() and not np.array_equal(nodes[0], nodes[1])


def test_a_moving_radar_makes_only_the_node_pairs_its_beams_may_reach(runtime):
    """The default model on a moving radar (a new pose every frame, pitched and rolled, no table):
    the interpreter makes only the node pairs inside the bound from the frame's beams
    (``Fusion.node_reach``). Its map (evidence, knowledge, looks) is, frame after frame, the one
    made with every node pair (``every_node_pair``), integer for integer; the pairs in the bound
    are that Mapping's, and the bound left some of each class out."""
    from radarcl.config.presets import paper_config
    from radarcl.pipeline import bin_model
    from radarcl.sensor_model import terrain_dz

    config = paper_config(SPEC.voxel_m)
    lattice, model = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT), BeamModel.from_radar(PAPER_RADAR)
    poses = [pose_from_xyz_rpy(0.3 * k, -0.2 * k, 0.1 * (k % 2), roll=0.02 * k, pitch=-0.03 * k, yaw=0.05 * k)
             for k in range(4)]
    maps, nodes = [], []
    for every in (False, True):
        m = Mapping(runtime, EvidenceGrid(runtime, SPEC, knowledge=True), lattice, model, radar=PAPER_RADAR,
                    n_fft=config.n_fft, dtype=np.float32, interpret_config=config.interpret_config(),
                    bin_model=bin_model(config, SPEC.voxel_m), terrain_dz=terrain_dz(config.model_params()))
        m.every_node_pair = every
        steps = []
        for k, pose in enumerate(poses):
            plan = m.fuse(paper_like_samples(seed=k, tilt_deg=TILT), pose)
            assert plan.table is None
            steps.append((m.grid.snapshot(), m.grid.knowledge_snapshot(), m.grid.knowledge_snapshot("looks")))
        maps.append(steps)
        nodes.append(m.detection.interpreter.arrays["evidence"].get())
        if not every:
            use = m.fusion.node_reach(plan)[0].get()               # the last frame's bound, made again
    for a, b in zip(*maps):
        assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert (maps[0][-1][0] != 0).sum() > 1000 and (maps[0][-1][2] > 0).any()
    within = np.stack([use & 1, use & 2], -1).astype(bool)              # (beams, bins, class)
    pairs = [n.reshape(*use.shape, 2, -1) for n in nodes]
    assert np.array_equal(pairs[0][within], pairs[1][within]) and not np.array_equal(pairs[0], pairs[1])
    it = m.detection.interpreter
    window = within[:, it.first_bin:it.last_bin + 1]
    for c in (0, 1):
        assert window[..., c].any() and not window[..., c].all()
