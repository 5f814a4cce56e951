"""The stability suite: stiff and extreme cases, each named, each with an assertion and a float64
comparison where one applies (docs/guide/evaluation.md, "Stability suite"). The map must stay finite, exact
where integers are exact, and intact when an input is refused."""

import math

import numpy as np
import pytest
from test_fusion import MODELS, check_against_oracle, evidence, fuse_frame
from tolerances import (
    CFAR_RTOL,
    DECISION_MARGIN,
    EVIDENCE_UNITS_TOL,
    FUSION_AMBIGUOUS_MAX,
    FUSION_DECISION_MARGIN,
    FUSION_UNITS_PER_UPDATE,
)

from radarcl import oracle
from radarcl.config.stage_config import PAPER_RADAR, CfarConfig, InterpretConfig, RadarConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GRID_LIMIT, GridSpec
from radarcl.pipeline import Detection, Mapping
from radarcl.scene.fmcw import simulate_beams
from radarcl.stages.fusion import Fusion

COARSE = GridSpec((-8.0, -35.0, -10.0), 1.0, (80, 70, 20))
LATTICE = BeamLattice.from_radar(PAPER_RADAR)
MODEL = BeamModel.from_radar(PAPER_RADAR)
POSE = pose_from_xyz_rpy(0.0, 0.0, 1.5, pitch=math.radians(7.0))


def mapping(runtime, dtype=np.int16):
    grid = EvidenceGrid(runtime, COARSE)
    return grid, Mapping(runtime, grid, LATTICE, MODEL, radar=PAPER_RADAR, n_fft=512, dtype=dtype)


def detection_vs_oracle(runtime, samples):
    """Kernel range FFT + CFAR + eq. 12 against the float64 chain on the same samples: returns
    (kernel evidence, oracle evidence, bins whose decision is too close to call)."""
    grid, m = mapping(runtime, samples.dtype)
    m.fuse(samples, POSE)
    runtime.queue.finish()
    it = m.detection.interpreter
    got = it.arrays["evidence"].get(runtime.queue).reshape(LATTICE.n_beams, it.n_bins)
    profiles = oracle.range_profile(samples.astype(np.float64), 512, output="power")
    flags = oracle.beam_flags(samples, clip_level=32767 if samples.dtype == np.int16 else np.inf)
    noise, ratio, mask = oracle.cfar(profiles, CfarConfig())
    ev = oracle.interpret(profiles, noise, mask, InterpretConfig(), PAPER_RADAR.bin_spacing_m(512), flags)[0]
    alpha = CfarConfig().alpha
    with np.errstate(invalid="ignore", divide="ignore"):
        close = np.abs(profiles / (alpha * noise) - 1) < DECISION_MARGIN
    close = np.where(np.isfinite(close), close, False).reshape(got.shape)
    return got, ev.reshape(got.shape), grid, m, close


@pytest.fixture
def zero_frame():
    return np.zeros((64, 4, 256), np.int16)


def test_all_zero_frame(runtime, zero_frame):
    """Zeros: every beam flagged, no evidence, the map stays zero, as the oracle says."""
    got, ev, grid, m, _ = detection_vs_oracle(runtime, zero_frame)
    assert np.array_equal(got, ev) and not got.any()
    assert (m.flags() != 0).all() and not m.snapshot().any()


def test_full_scale_clipped_adc(runtime):
    """A full-scale square wave in every beam: clipped beams are flagged yet still give evidence,
    equal to the float64 chain's."""
    samples = np.where(np.arange(256) % 8 < 4, 32767, -32768).astype(np.int16)
    frame = np.broadcast_to(samples, (64, 4, 256)).copy()
    got, ev, grid, m, close = detection_vs_oracle(runtime, frame)
    assert (m.flags() & oracle.FLAG_CLIPPED).all()
    assert got.any() and np.abs(got - ev)[~close].max() <= EVIDENCE_UNITS_TOL
    # the full-scale evidence in the map: within the grid's limits, and at 3,000 voxels (half of
    # them updated) the float64 fusion of the same evidence (every voxel: 25 s of numpy)
    snap = grid.snapshot()
    assert (snap > 0).any() and np.abs(snap).max() < GRID_LIMIT
    rng = np.random.default_rng(0)
    flat = np.concatenate([rng.choice(np.flatnonzero(snap), 1500, replace=False),
                           rng.choice(np.flatnonzero(snap == 0), 1500, replace=False)])
    iz, iy, ix = np.unravel_index(flat, snap.shape)
    it = m.detection.interpreter
    sums, updates, ambiguous = oracle.fusion_at_points(
        COARSE.index_to_world(np.stack([ix, iy, iz], axis=1)), got, LATTICE, MODEL, POSE,
        PAPER_RADAR.bin_spacing_m(512), it.first_bin, it.last_bin, margin=FUSION_DECISION_MARGIN)
    clear = ~ambiguous
    assert (updates > 0).sum() >= 1500 and ambiguous.sum() <= FUSION_AMBIGUOUS_MAX * (updates > 0).sum() + 10
    diff = np.abs(snap[iz, iy, ix].astype(np.int64) - sums)
    assert (diff[clear] <= FUSION_UNITS_PER_UPDATE * updates[clear]).all()


def test_nan_and_inf_beams(runtime):
    """NaN / Inf / -Inf in three beams of a float32 frame: those beams give no evidence, the
    others give exactly what they give without the bad beams."""
    rng = np.random.default_rng(0)
    clean = (1e-3 * rng.standard_normal((64, 4, 256))).astype(np.float32)
    bad = clean.copy()
    bad[3, 1, 17], bad[40, 2, :], bad[63, 0, 200] = np.nan, np.inf, -np.inf
    got_bad, ev_bad, _, m, _ = detection_vs_oracle(runtime, bad)
    got_clean, *_ = detection_vs_oracle(runtime, clean)
    beams = [3 * 4 + 1, 40 * 4 + 2, 63 * 4 + 0]
    assert not got_bad[beams].any() and np.array_equal(got_bad[beams], ev_bad[beams])
    keep = np.setdiff1d(np.arange(256), beams)
    assert np.array_equal(got_bad[keep], got_clean[keep])
    assert (m.flags().reshape(-1)[beams] & oracle.FLAG_NONFINITE).all()


def test_120_db_corner_reflector_beside_a_weak_target(runtime):
    """A corner reflector 120 dB (power) above the receiver noise at 12 m and a target 80 dB
    weaker at 30 m: both detected by the kernels, with noise estimates within CFAR_RTOL of
    float64 around the weak one."""
    samples = simulate_beams(PAPER_RADAR, np.array([[1.0, 1e-4]]), np.array([[12.0, 30.0]]),
                             noise_rms=1e-6, seed=1).samples.astype(np.float32)
    det = Detection(runtime, (1,), 256, PAPER_RADAR.bin_spacing_m(512), CfarConfig(), InterpretConfig())
    profiles = oracle.range_profile(samples.astype(np.float64), 512, output="power").astype(np.float32)
    result = det(profiles)
    spacing = PAPER_RADAR.bin_spacing_m(512)
    hits = np.flatnonzero(result.cfar.mask[0]) * spacing
    assert (np.abs(hits - 12.0) < 1).any() and (np.abs(hits - 30.0) < 1).any()
    noise, _, _ = oracle.cfar(profiles.astype(np.float64), CfarConfig())
    weak = slice(int(29 / spacing), int(31 / spacing))
    np.testing.assert_allclose(result.cfar.noise[0, weak], noise[0, weak], rtol=CFAR_RTOL)


def test_a_million_updates_of_one_voxel_on_a_one_voxel_grid(runtime):
    """2 x 10^6 updates of +16 nat into a one-voxel grid saturate at GRID_LIMIT (unsaturated,
    16384 x 2 x 10^6 would wrap int32 fifteen times); 2 x 10^6 of -16 nat then go to
    exactly -GRID_LIMIT, never wrapping."""
    spec = GridSpec((4.5, -0.5, -0.5), 1.0, (1, 1, 1))                 # one voxel around (5, 0, 0)
    lattice = BeamLattice(250, 40, -1e-4, 1e-6, -1e-4, 5e-6)           # 10^4 beams, all through it
    model = BeamModel(0.1, 0.1, 0.0, 0.0, near_field=False, gaussian=False)
    grid = EvidenceGrid(runtime, spec)
    fusion = Fusion(runtime, grid, lattice, model, 64, 0.1, 1, 63)
    for sign, expected in ((1, GRID_LIMIT), (-1, -GRID_LIMIT)):
        fusion.upload(np.full((lattice.n_beams, 64), sign * 16384, np.int32))
        plan = fusion.plan(np.eye(4))
        for _ in range(200):                                            # 200 x 10^4 = 2 x 10^6 updates
            fusion.enqueue(plan=plan)
        assert grid.snapshot().item() == expected


@pytest.mark.parametrize("case", ["along x", "along y", "through corners", "elevation +90", "elevation -90",
                                  "outside the grid"])
def test_degenerate_beam_geometry(runtime, case):
    """Beams along grid axes, through voxel corners and edges, straight up and down, and from
    a sensor outside the grid: the kernel equals the float64 oracle (uniform and Gaussian)."""
    spec = GridSpec((-4.0, -4.0, -4.0), 0.25, (32, 32, 32))
    pose = {"along x": pose_from_xyz_rpy(0.0, 0.0, 0.0),
            "along y": pose_from_xyz_rpy(0.0, 0.0, 0.0, yaw=math.pi / 2),
            "through corners": pose_from_xyz_rpy(0.25, -0.5, 0.75, yaw=math.pi / 4),
            "elevation +90": pose_from_xyz_rpy(0.0, 0.0, 0.0, pitch=-math.pi / 2),
            "elevation -90": pose_from_xyz_rpy(0.0, 0.0, 0.0, pitch=math.pi / 2),
            "outside the grid": pose_from_xyz_rpy(-6.0, 0.5, 0.3)}[case]
    lattice = BeamLattice(8, 3, -0.07, 0.02, -0.035, 0.035)
    for name in ("near_field=True, gaussian=True", "near_field=False, gaussian=False"):
        model = MODELS[name]
        ev = evidence(lattice, seed=3)
        grid, _ = fuse_frame(runtime, spec, lattice, model, ev, pose)
        check_against_oracle(grid.snapshot(), spec, lattice, model, ev, pose, min_reached=20)


def test_float32_kernels_against_float64_on_the_reference_scene(runtime):
    """A frame of the reference scene through the kernels: eq. 12 evidence within
    EVIDENCE_UNITS_TOL of the float64 chain on every bin whose CFAR decision is not a tie."""
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    frame = observe(paper_scene(), [-9.2], seed=7).samples[0]
    got, ev, _, _, close = detection_vs_oracle(runtime, frame)
    assert close.mean() < 1e-3
    assert np.abs(got.astype(np.int64) - ev)[~close].max() <= EVIDENCE_UNITS_TOL


@pytest.mark.parametrize("make, reason", [
    (lambda: RadarConfig(range_max_m=200.0), "eq. 10"),
    (lambda: RadarConfig(n_samples=0), "n_samples"),
    (lambda: PAPER_RADAR.check_n_fft(128), "shorter than"),
    (lambda: CfarConfig(pfa=1.5), "pfa"),
    (lambda: CfarConfig(kind="os", rank=99), "rank"),
    (lambda: InterpretConfig(e_high=0.5), "E_h and E_l"),
    (lambda: GridSpec((0, 0, 0), 0.0, (1, 1, 1)), "voxel_m"),
    (lambda: GridSpec((0, 0, 0), 1.0, (2 ** 21, 1, 1)), "2\\^20"),
    (lambda: BeamModel(math.pi, 0.1, 0.0, 0.0), "beamwidth_az_rad"),
    (lambda: pose_from_xyz_rpy(pitch=math.nan) @ np.eye(4), None),
])
def test_extreme_configurations_are_refused(make, reason):
    if reason is None:                  # a NaN pose is refused where it is used
        from radarcl.geometry import check_pose

        with pytest.raises(ConfigError, match="(?i)nan|finite"):
            check_pose(make())
        return
    with pytest.raises(ConfigError, match=reason):
        make()


def test_refused_frame_leaves_the_map_intact(runtime):
    grid, m = mapping(runtime)
    frame = np.zeros((64, 4, 256), np.int16)
    frame[10, 1] = 1000 * np.sin(np.arange(256))
    m.fuse(frame, POSE)
    before = m.snapshot()
    for bad in (frame[:32], frame.astype(np.float64)):
        with pytest.raises(ShapeError):
            m.fuse(bad, POSE)
    assert np.array_equal(m.snapshot(), before)
