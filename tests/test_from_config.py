"""One way to build a pipeline: ``Mapping.from_config`` maps the paper's radar, a TI capture and an
Oxford Navtech scan with their profiles; `radarcl tune --save` feeds `radarcl fuse --config`;
a sensor that does not match its input is refused with both shapes and nothing written."""

import numpy as np
import pytest
from tolerances import CFAR_RTOL, DECISION_MARGIN, EVIDENCE_UNITS_TOL, RANGE_FFT_RTOL

from radarcl import logodds, oracle
from radarcl.cli import main
from radarcl.config import mapconfig
from radarcl.errors import ConfigError, DeviceCapabilityError, FrameFormatError
from radarcl.config.presets import EQ12
from radarcl.io.inputs import open_input
from radarcl.maps.map import Map
from radarcl.pipeline import Mapping


def _axis_nats(grid, points):
    spec = grid.spec
    idx = spec.world_to_index(points)
    snap = grid.snapshot()
    return snap[idx[:, 2], idx[:, 1], idx[:, 0]] / logodds.SCALE


def test_paper_radar(runtime):
    """One tilt of the reference scene: the air in front of the stand is free, the fence
    (x = 14 m) is occupied where the stand's beams cross it."""
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    obs = observe(paper_scene(), [-5.2], seed=1)
    config = mapconfig.resolve("paper", flags={"grid.voxel_m": 0.5})
    m = Mapping.from_config(runtime, "paper", config)
    assert m.frame_shape == (64, 4, 256) and m.fusion.per_beam_poses is False
    assert m.detection.cfar.config.guard == 16 and m.detection.interpreter.wide_bins == 15
    m.fuse(obs.samples[0], obs.poses[0])
    snap = m.snapshot()
    assert (snap > 0).any() and (snap < 0).any()
    spec = m.grid.spec
    fence = snap[:, :, spec.world_to_index([[14.0, 0, 0]])[0, 0]].max() / logodds.SCALE
    ahead = snap[:, :, spec.world_to_index([[8.0, 0, 0]])[0, 0]].min() / logodds.SCALE
    assert fence > 1.0 and ahead < -1.0


def test_ti_capture_maps_its_reflector(runtime, shared_data):
    """simple_frame_1: 128 chirps of one virtual antenna (the data README: a strong static
    reflector near 1.95 m). Fused along the boresight with eq. 12, the map is occupied at 1.95 m
    and free at 1.0 m in front of it; the kernel chain equals the float64 one."""
    source = open_input(mapconfig.resolve("ti-xwr-openradar").sensor,
                           shared_data / "ti_adc_openradar" / "simple_frame_1.npy")
    assert len(source) == 128 and source.frames.shape[1:] == (1, 1, 128) and source.frames.dtype == np.complex64
    m = Mapping.from_config(runtime, "ti-xwr-openradar", mapconfig.resolve("ti-xwr-openradar", flags=EQ12))
    for frame, pose in zip(source.frames, source.poses):
        m.fuse(frame, pose)
    nats = _axis_nats(m.grid, [[1.975, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert nats[0] > 50 and nats[1] < -50
    # the kernel chain (range FFT -> CFAR -> eq. 12) of the last chirp fused, against the
    # float64 chain on the same samples
    c, q = m.config, runtime.queue
    last = source.frames[-1]
    power = oracle.range_profile(last.astype(np.complex128), c.n_fft, window=c["range_fft.window"],
                                 output="power").reshape(1, -1)
    noise, _, mask = oracle.cfar(power, c.cfar_config())
    evidence = oracle.interpret(power, noise, mask, c.interpret_config(), c.bin_spacing_m,
                                oracle.beam_flags(last).reshape(1))[0]
    got_power = m.range_fft.arrays["profiles"].get(q).reshape(1, -1)
    got_noise = m.detection.cfar.arrays["noise"].get(q).reshape(1, -1)
    got_mask = m.detection.cfar.arrays["mask"].get(q).reshape(1, -1).astype(bool)
    got_evidence = m.detection.interpreter.arrays["evidence"].get(q).reshape(1, -1)
    assert np.abs(got_power - power).max() <= 2 * RANGE_FFT_RTOL * power.max()      # power: twice the magnitude's
    with np.errstate(divide="ignore", invalid="ignore"):
        close = np.abs(power / (c.cfar_config().alpha * noise) - 1) < DECISION_MARGIN
    assert close.sum() <= 2 and mask.sum() >= 3, (close.sum(), mask.sum())
    assert np.array_equal(got_mask[~close], mask[~close])
    np.testing.assert_allclose(got_noise, noise, rtol=CFAR_RTOL)
    assert np.abs(got_evidence.astype(np.int64) - evidence)[~close].max() <= EVIDENCE_UNITS_TOL
    assert (evidence > 0).any() and (evidence < 0).any()


def test_ti_capture_with_the_default_model(runtime, shared_data):
    """The same 128 chirps with radarcl's default, the detection-statistics model, read as the map
    reads them: the reflector occupied (p > 0.9), the air in front of it free (p < 0.1), both known."""
    config = mapconfig.resolve("ti-xwr-openradar")
    assert config["interpret.model"] == "detstats"
    source = open_input(config.sensor, shared_data / "ti_adc_openradar" / "simple_frame_1.npy")
    m = Mapping.from_config(runtime, "ti-xwr-openradar", config)
    for frame, pose in zip(source.frames, source.poses):
        m.fuse(frame, pose)
    points = np.array([[1.975, 0.0, 0.0], [1.0, 0.0, 0.0]])
    shown = Map.of_grid(m.grid, config)
    p = shown.probability_at(points)
    assert p[0] > 0.9 and p[1] < 0.1 and (shown.knowledge_at(points) > 100).all()


def test_oxford_navtech_scan(runtime, shared_data):
    """One scan read as the navtech-cts350x profile (bins, layout, per-azimuth poses from the
    encoder): free space in front of the car, the walls of the street and the echoes behind
    them (through the blockers' gaps) occupied, the rest of the grid never observed."""
    sensor = mapconfig.resolve("navtech-cts350x").sensor
    source = open_input(sensor, shared_data / "navtech_oxford" / "radar" / "1547131046353776.png")
    assert len(source) == 1 and source.poses[0].shape == (400, 4, 4)
    config = mapconfig.resolve(sensor, flags={"grid.voxel_m": 0.5})
    m = Mapping.from_config(runtime, sensor, config)
    assert m.fusion.per_beam_poses and m.frame_shape == (400, 3768)
    m.fuse(source.frames[0], source.poses[0], flags=source.flags[0])
    counts = Map.of_grid(m.grid, config).counts(1.0, -1.0)
    assert counts["occupied"] > 100 and counts["free"] > 2000
    assert counts["unobserved"] > 10 * (counts["free"] + counts["occupied"])


def test_a_generic_polar_profile_learns_its_bins_from_the_data(runtime, shared_data):
    sensor = mapconfig.resolve("polar-png").sensor
    assert sensor.n_bins() is None
    source = open_input(sensor, shared_data / "navtech_oxford" / "radar" / "1547131046353776.png")
    assert source.sensor.n_bins() == 3768
    with pytest.raises(ConfigError, match="does not say how many range bins"):
        Mapping.from_config(runtime, sensor)
    Mapping.from_config(runtime, source.sensor, mapconfig.resolve("polar-png", flags={"grid.voxel_m": 1.0})
                        .for_sensor(source.sensor))


def test_a_frame_that_cannot_fit_is_refused_before_anything_runs(runtime):
    config = mapconfig.resolve("paper", flags={"grid.voxel_m": 0.01})
    with pytest.raises(DeviceCapabilityError, match=r"one frame of sensor paper at 0.01 m voxels reaches at least "
                                                    r".* GiB of int32\), more than the largest buffer .*use voxels of "
                                                    r"at least"):
        Mapping.from_config(runtime, config=config)


def _two_frame_recording(path):
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    recording.save(path, observe(paper_scene(), (-9.2, -5.2), seed=1))


def test_tune_save_feeds_fuse_config(runtime, tmp_path, capsys):
    """The configuration `tune --save` writes is what `fuse --config` uses: its values show as
    coming from the file, and the fused map is bit-identical to one built from those values."""
    rec, cfg, out = tmp_path / "rec.npz", tmp_path / "tuned.toml", tmp_path / "map.npz"
    _two_frame_recording(rec)
    assert main(["tune", "--replay", str(rec), "--voxel", "0.8", "--save", str(cfg), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "chosen:" in said and f"wrote {cfg}" in said
    tuned = mapconfig.resolve(None, cfg)
    # every value from the file but the default prior, which follows the voxel and the file leaves out
    prior = "sensor_model.prior_nats"
    assert all(o.startswith(f"file {cfg}:") for k, o in tuned.origins.items() if k != prior)
    assert "prior_nats is left out" in cfg.read_text() and tuned.origins[prior].startswith("radarcl default")
    assert main(["fuse", str(rec), "--config", str(cfg), "--out", str(out), "--no-progress"]) == 0
    assert main(["config", "show", "--config", str(cfg)]) == 0
    assert f"file {cfg}" in capsys.readouterr().out
    from radarcl.maps.disk import read
    from radarcl.scene.observe import load_observations

    m = Mapping.from_config(runtime, "paper", tuned)
    obs = load_observations(rec)
    for frame, pose in zip(obs.samples, obs.poses):
        m.fuse(frame, pose)
    from radarcl.gridspec import assemble

    spec, keys, data = read(out)
    fused = assemble(spec, keys, data)
    assert spec == m.grid.spec and np.array_equal(fused, m.snapshot()) and (fused > 0).any()
    # ... and not the map of the defaults the file overrides (the comparison can tell them apart)
    plain = Mapping.from_config(runtime, "paper", mapconfig.resolve("paper", flags={"grid.voxel_m": 0.8}))
    for frame, pose in zip(obs.samples, obs.poses):
        plain.fuse(frame, pose)
    assert plain.grid.spec == spec and not np.array_equal(plain.snapshot(), fused)


def test_a_sensor_that_does_not_match_its_input_is_refused(tmp_path, capsys):
    rec, out = tmp_path / "rec.npz", tmp_path / "map.npz"
    _two_frame_recording(rec)
    assert main(["fuse", str(rec), "--sensor", "ti-xwr-openradar", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "frames are (64, 4, 256) int16; sensor ti-xwr-openradar expects (1, 1, 128) complex64" in err
    assert not out.exists()
    assert main(["fuse", str(tmp_path / "none.npz"), "--out", str(out)]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "x.npy").write_bytes(b"\x93NUMPY garbage")
    assert main(["fuse", str(tmp_path / "x.npy"), "--out", str(out)]) == 2
    assert "is not a readable .npz file" in capsys.readouterr().err
    with pytest.raises(FrameFormatError, match="not a readable .npz"):
        open_input(mapconfig.resolve("paper").sensor, tmp_path / "x.npy")



TOY_PROFILE = """name = "toy"
description = "a toy spinning radar whose frames are an .npy of power profiles"
input = "profiles"
[range]
range_min_m = 1.0
range_max_m = 20.0
bin_spacing_m = 0.25
n_bins = 80
resolution_m = 0.5
carrier_hz = 76.5e9
[beams]
n_azimuth = 32
n_elevation = 1
spinning = true
beamwidth_az_deg = 11.25
beamwidth_el_deg = 20.0
[reader]
format = "toy-npy"
[defaults.grid]
voxel_m = 0.5
"""


def test_an_input_format_added_to_the_table_alone_is_fused(runtime, tmp_path, capsys, monkeypatch):
    """A toy input format (an .npy of power profiles, the radar still) registered in
    ``io.inputs.READERS`` and nowhere else: a sensor profile may name it, ``radarcl fuse
    --help`` lists it, and ``radarcl fuse`` reads it and maps its echo."""
    from radarcl.io import inputs

    monkeypatch.setattr(inputs, "READERS", dict(inputs.READERS))

    def open_npy(sensor, path, **_):
        frames = np.load(path)
        return inputs.FrameSource(sensor, frames, np.broadcast_to(np.eye(4), (len(frames), 4, 4)),
                                  [None] * len(frames), f"{len(frames)} toy frames of {path}", posed=False)

    profile = tmp_path / "toy.toml"
    profile.write_text(TOY_PROFILE)
    with pytest.raises(ConfigError, match="must be one of 'recording', 'polar-png', 'ti-openradar', 'rosbag', got 'toy-npy'"):
        mapconfig.resolve(str(profile))
    inputs.register(inputs.Reader("toy-npy", "a toy .npy", "a toy .npy of power profiles", open_npy))
    sensor = mapconfig.resolve(str(profile)).sensor
    rng = np.random.default_rng(5)
    frames = rng.exponential(1.0, (2, *sensor.frame_shape())).astype(np.float32)
    frames[..., 40] = 1e4                                        # an echo at 40 x 0.25 = 10 m on every beam
    np.save(tmp_path / "toy.npy", frames)
    out = tmp_path / "toy_map.npz"
    assert main(["fuse", str(tmp_path / "toy.npy"), "--sensor", str(profile), "--still", "--out", str(out),
                 "--no-report", "--no-progress"]) == 0
    assert f"fusing 2 toy frames of {tmp_path / 'toy.npy'} with sensor toy" in capsys.readouterr().out
    centres, _ = Map.open(out).occupied(1.0)
    reach = np.hypot(centres[:, 0], centres[:, 1])
    assert len(centres) >= 32 and (np.abs(reach - 10.0) < 0.5).all()
    with pytest.raises(SystemExit):
        main(["fuse", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "; a toy .npy of power profiles)" in text and "a TI capture, a ROS 2 bag, or a toy .npy" in text

def test_the_paper_profile_rebuilds_the_pre_profile_pipeline_bit_for_bit(runtime):
    """docs/guide/sensors.md: the paper's profile derives the paper's constants
    from its geometry alone, so `radarcl demo`'s maps are bit-identical to those made before
    profiles existed. The pipeline of then, with its constants written out as they stood in
    commit d49131d (the last before sensor profiles; ``evaluation/evaluate.py``'s ``MapConfig``
    and ``make_mapping``, ``config.py``'s ``CfarConfig`` and ``InterpretConfig`` defaults,
    ``scene/outdoor.py``'s ``paper_grid``), and the demo's pipeline of now (``presets.paper_config``
    through ``Mapping.from_config``), on the same two frames: the same integers."""
    import math

    from radarcl.config.presets import paper_config
    from radarcl.config.stage_config import PAPER_RADAR, PAPER_WIDE_PULSE_M, CfarConfig, InterpretConfig
    from radarcl.geometry import BeamLattice, BeamModel
    from radarcl.grid import EvidenceGrid
    from radarcl.gridspec import GridSpec
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    voxel = 0.4
    obs = observe(paper_scene(), (-9.2, -5.2), seed=1)
    paper_grid = GridSpec((-8.0, -35.0, -10.0), voxel, tuple(math.ceil(n / voxel - 1e-9) for n in (80.0, 70.0, 20.0)))
    then = Mapping(runtime, EvidenceGrid(runtime, paper_grid), BeamLattice.from_radar(PAPER_RADAR),
                   BeamModel.from_radar(PAPER_RADAR, near_field=True, gaussian=True),
                   radar=PAPER_RADAR, n_fft=1024, dtype=np.int16,
                   cfar_config=CfarConfig(kind="ca", guard=16, train=16, pfa=1e-3, rank=None, noise_floor=1e-30),
                   interpret_config=InterpretConfig(k_occ=1.0, e_high=-1.0, e_low=-0.1, range_min_m=1.0,
                                                    range_max_m=64.0, wide_pulse_m=PAPER_WIDE_PULSE_M, max_pulses=32))
    now = Mapping.from_config(runtime, "paper", paper_config(voxel, EQ12))       # eq. 12, as then
    assert now.grid.spec == then.grid.spec
    for frame, pose in zip(obs.samples, obs.poses):
        then.fuse(frame, pose)
        now.fuse(frame, pose)
    got = now.snapshot()
    assert np.array_equal(got, then.snapshot()) and (got > 0).sum() > 1000 and (got < 0).sum() > 10000
