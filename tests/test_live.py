"""`radarcl live` end to end: the emulator on a pseudo-terminal, pyserial reading it, the
parser, beam-by-beam fusion. The live map must equal the map of the same beams fused offline,
a replay of its recording must give the same map bit for bit, and bad radars, lost ports and
Ctrl-C must end with the map saved."""

import os
import time

import numpy as np
import pytest
from conftest import SHARED_DATA

from radarcl import livemap
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.gridspec import assemble
from radarcl.io import emulator
from radarcl.io.inputs import open_input
from radarcl.io.stream import PortReader, StreamRecorder, open_port
from radarcl.jobs import live
from radarcl.maps.disk import MapSaver, read, read_channels, read_meta
from radarcl.pipeline import Mapping
from radarcl.scene.observe import observe
from radarcl.scene.outdoor import paper_scene

VOXEL = 0.4


@pytest.fixture(scope="module")
def scene():
    """Two frames of the reference scene (two tilts), as the paper's radar sends them."""
    obs = observe(paper_scene(), (-9.2, -5.2), seed=1)
    return obs.samples, obs.poses


def paper_config():
    return mapconfig.resolve("paper", program={"grid.voxel_m": VOXEL})


def offline(runtime, config, frames, poses, keep):
    """The map of the beams ``keep`` (n_frames, n_az, n_el) bool, fused a whole frame at a time
    (the beam protocol carries the poses in float64: the same poses)."""
    m = Mapping.from_config(runtime, config=config)
    for frame, pose, k in zip(frames, poses, keep):
        m.fuse(np.where(k[..., None], frame, 0).astype(frame.dtype), pose)
    return m.snapshot()


def over_pty(runtime, config, packets, faults=emulator.Faults(), baud=None, recorder=None, saver=None):
    return live.over_pty(runtime, config, packets, faults, baud, saver, recorder, timeout_s=120)


def test_a_frame_fused_in_azimuth_ranges_equals_the_whole_frame(runtime, scene):
    frames, poses = scene
    config = paper_config()
    whole, parts = Mapping.from_config(runtime, config=config), Mapping.from_config(runtime, config=config)
    rng = np.random.default_rng(0)
    for frame, pose in zip(frames, poses):
        whole.fuse(frame, pose)
        bounds = [0, *np.sort(rng.choice(np.arange(1, 64), 9, replace=False)), 64]
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            part = np.zeros_like(frame)
            part[lo:hi] = frame[lo:hi]
            parts.fuse(part, pose, azimuths=(lo, hi - 1))
    a, b = whole.snapshot(), parts.snapshot()
    assert np.abs(a).max() > 1000 and np.array_equal(a, b)
    # the default model's knowledge and looks too: each part makes the node pairs of its own beams
    assert whole.grid.has_knowledge and parts.detection.interpreter.nodes is not None
    for channel in ("knowledge", "looks"):
        assert np.array_equal(whole.grid.knowledge_snapshot(channel), parts.grid.knowledge_snapshot(channel))
    with pytest.raises(ConfigError, match="not a range"):
        parts.fuse(frames[0], poses[0], azimuths=(5, 64))


def test_a_spinning_radar_is_not_fused_by_azimuth_ranges(runtime):
    config = mapconfig.resolve("navtech-cts350x", program={"grid.voxel_m": 1.0})
    mapper = livemap.LiveMapper(runtime, config.for_sensor(config.sensor.with_bins(3768)))
    with pytest.raises(ConfigError, match="spins"):
        mapper.prepare()


def test_beams_over_a_pty_with_faults_give_the_offline_map_of_the_beams_that_arrived(runtime, scene, tmp_path):
    frames, poses = scene
    config = paper_config()
    packets = emulator.beam_packets(frames, poses)
    faults = emulator.Faults(ber=2e-5, noise=0.02, dup=1e-5, seed=4)
    mapper, s, emu, intact = over_pty(runtime, config, packets, faults, saver=MapSaver(tmp_path / "m.rcmap"))
    intact = np.asarray(intact).reshape(len(frames), 64, 4)
    assert 0 < intact.sum() < intact.size                     # some damage, most beams whole
    assert s["beams"] == intact.sum()                         # every intact beam, and nothing else, fused
    assert s["crc_failures"] + s["header_failures"] > 0
    want = offline(runtime, config, frames, poses, intact)
    assert np.array_equal(mapper.mapping.snapshot(), want)
    saved = read(tmp_path / "m.rcmap")
    assert np.array_equal(assemble(*saved), want)              # the final save holds every beam
    assert read_meta(tmp_path / "m.rcmap", "stream")["saved_beams"] == s["beams"]


def test_ti_demo_frames_over_a_pty(runtime, tmp_path):
    raw = mapconfig.resolve("ti-xwr-openradar").sensor
    src = open_input(raw, SHARED_DATA / "ti_adc_openradar" / "simple_frame_1.npy")
    chirps = np.stack([src.frames[j] for j in range(24)]).reshape(24, -1)
    power = np.abs(np.fft.fft(chirps * np.hanning(chirps.shape[1]), axis=1)) ** 2
    config = mapconfig.resolve("ti-xwr18xx-uart")
    antennas, q_bits = livemap.ti_scaling(config.sensor)
    q9 = emulator.q9_of_power(power, antennas, q_bits)
    assert q9.max() < 65535                                    # the demo's scaling holds the capture
    mapper, s, _, _ = over_pty(runtime, config, emulator.ti_packets(q9), baud=None)
    assert s["beams"] == 24 and s["frames"] == 24
    from radarcl.io.ti_uart import profile_power

    m = Mapping.from_config(runtime, config=config.for_sensor(config.sensor.with_bins(q9.shape[1])))
    for row in q9:
        m.fuse(profile_power(row, antennas, q_bits)[None], np.eye(4))
    assert np.array_equal(mapper.mapping.snapshot(), m.snapshot())
    from radarcl.maps.map import Map

    shown = Map.of_grid(mapper.mapping.grid, config)            # the default model: read through its reading
    nats = shown.log_odds_at([[1.975, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert nats[0] > 2 and nats[1] < -5                        # the 1.95 m reflector, free space before it
    # damaged: nothing raises, and most frames still arrive (TI has no CRC: a damaged one may too)
    faults = emulator.Faults(ber=1e-4, drop=1e-4, seed=2)
    _, s, _, intact = over_pty(runtime, config, emulator.ti_packets(q9), faults)
    assert s["beams"] >= sum(intact) - 2


def test_record_then_replay_gives_the_same_map(runtime, scene, tmp_path):
    frames, poses = scene
    config = paper_config()
    rec = tmp_path / "stream.rcs"
    recorder = StreamRecorder(rec, dict(protocol="beams", sensor="paper"))
    packets = emulator.beam_packets(frames[:1], poses[:1])
    mapper, s, _, _ = over_pty(runtime, config, packets, emulator.Faults(noise=0.05, ber=1e-5, seed=7),
                               recorder=recorder)
    recorder.close()
    replayed, s2, header = live.replay(rec, lambda h: (config.sensor, livemap.LiveMapper(runtime, config)))
    assert header["sensor"] == "paper" and s2["beams"] == s["beams"] > 0
    assert np.array_equal(replayed.mapping.snapshot(), mapper.mapping.snapshot())
    with pytest.raises(ConfigError, match="exists"):
        StreamRecorder(rec, {})                               # a stream is never overwritten
    torn = tmp_path / "torn.rcs"
    torn.write_bytes(rec.read_bytes()[:-100])                 # the writer was killed mid-record
    again, s3, _ = live.replay(torn, lambda h: (config.sensor, livemap.LiveMapper(runtime, config)))
    assert 0 < s3["beams"] <= s["beams"]


def test_a_radar_of_another_shape_is_refused_before_anything_is_fused(runtime):
    mapper = livemap.LiveMapper(runtime, paper_config())
    beam = livemap.Beam(0, 0, 0, 0, np.zeros(128, np.complex64))
    with pytest.raises(ConfigError, match="128 complex64 samples; sensor paper expects 256 int16"):
        mapper.add([beam])
    assert mapper.stats["beams"] == 0


def test_ctrl_c_finishes_the_fuse_saves_and_reports(runtime, scene, tmp_path, monkeypatch):
    frames, poses = scene
    config = paper_config()
    session = livemap.Session(config.sensor)
    session.feed(0, b"".join(emulator.beam_packets(frames[:1], poses[:1])))
    mapper = livemap.LiveMapper(runtime, config, MapSaver(tmp_path / "m.rcmap"))
    calls = []

    def drain(wait=0.1):
        calls.append(wait)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return livemap.Session.drain(session, wait)

    monkeypatch.setattr(session, "drain", drain)
    s = live.run(session, mapper)
    assert s["interrupted"] and s["beams"] == 256 and s["saved_beams"] == 256
    assert read_meta(tmp_path / "m.rcmap", "stream")["saved_beams"] == 256


def _live(args, name):
    """`radarcl live` in its own process on the pty ``name``; returns it once it reads."""
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "radarcl", "live", name, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    lines = []
    while not lines or "radarcl live: reading" not in lines[-1]:
        lines.append(proc.stderr.readline())
        assert lines[-1], "".join(lines) + proc.stderr.read()
    return proc, lines


def test_the_cli_saves_and_says_so_when_the_pty_closes(tmp_path, scene):
    """The far end of a pty closing part way (the emulator's disconnect fault) is the end of the
    stream: saved, said, exit 0; `radarcl replay` of its --record gives the same map,
    bit for bit (docs/guide/live.md); a device that goes away is tested in test_live_ends."""
    from radarcl.cli import main

    frames, poses = scene
    master, name, slave = emulator.open_pty()
    out, rec = tmp_path / "m.rcmap", tmp_path / "run.rcs"
    proc, _ = _live(["--voxel", str(VOXEL), "--out", str(out), "--quiet", "--checkpoint", "0.2", "--duration", "60",
                     "--record", str(rec)], name)
    emu = emulator.Emulator(emulator.beam_packets(frames[:1], poses[:1]), lambda b: os.write(master, b), None,
                            emulator.Faults(disconnect=100), close=lambda: (os.close(master), os.close(slave))).start()
    try:
        stdout, err = proc.communicate(timeout=120)
    finally:
        emu.stop()
        proc.kill()
    assert proc.returncode == 0 and "ended" in err, err
    assert "Traceback" not in err and "fused" in stdout
    saved = read_meta(out, "stream")["saved_beams"]
    assert 0 < saved <= 100
    again = tmp_path / "again.rcmap"
    assert main(["replay", str(rec), "--out", str(again), "--voxel", str(VOXEL)]) == 0
    live_map, replayed = read(out), read(again)
    assert read_meta(again, "stream")["saved_beams"] == saved and live_map[0] == replayed[0]
    assert np.array_equal(assemble(*live_map), assemble(*replayed)) and (assemble(*replayed) != 0).any()


def _free_port():
    with __import__("socket").socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_radarcl_live_serves_viewers_records_and_survives_kill_9(runtime, tmp_path, scene):
    """`radarcl live` in its own process on a pty: a viewer following it sees the map grow, the
    status file and the recording appear, and kill -9 loses at most the beams since the last
    checkpoint: the map holds a checkpoint's beams (exactly the offline map of the first
    ``saved_beams`` that arrived, at least those of the checkpoint seen before the kill) and no
    temporary file anywhere but one a save under way left, which the next writer removes."""
    import json
    import signal
    import time

    from radarcl.viewer.app import follow_engine

    from radarcl.io.beam_protocol import BeamParser
    from radarcl.io.files import check
    from radarcl.maps.store import StoreWriter

    frames, poses = scene
    master, name, slave = emulator.open_pty()
    port = _free_port()
    out, status, rec = tmp_path / "m.rcmap", tmp_path / "status.json", tmp_path / "s.rcs"
    proc, lines = _live(["--voxel", str(VOXEL), "--out", str(out), "--checkpoint", "0.3", "--json-status", str(status),
                         "--record", str(rec), "--serve", f"127.0.0.1:{port}", "--quiet"], name)
    emu = None
    try:
        assert any("serving the map" in line for line in lines), lines
        emu = emulator.Emulator(emulator.beam_packets(frames, poses), lambda b: os.write(master, b), 400_000).start()
        sub, volume = follow_engine(f"127.0.0.1:{port}", timeout_s=60)
        sub.close()
        assert volume.spec.voxel_m == VOXEL
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if status.exists() and json.loads(status.read_text())["checkpoints"] >= 2:
                break
            emu.done.wait(0.1)
        seen = json.loads(status.read_text())
        assert seen["checkpoints"] >= 2 and seen["beams"] > 0 and seen["saved_beams"] > 0
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    finally:
        if emu is not None:
            emu.stop()
        proc.kill()
        os.close(master)
        os.close(slave)
    saved = read_meta(out, "stream")["saved_beams"]
    assert seen["saved_beams"] <= saved <= emu.packets_sent
    # a checkpoint's count: the map is the offline map of the first `saved` beams sent
    parser = BeamParser()
    for packet in emulator.beam_packets(frames, poses):
        parser.data_received(packet)
    keep = np.zeros((len(frames), 64, 4), bool)
    for b in parser.take()[:saved]:
        keep[b.frame, b.azimuth, b.elevation] = True
    spec, keys, data = read(out)
    assert keep.sum() == saved and np.array_equal(assemble(spec, keys, data), offline(runtime, paper_config(), frames,
                                                                                    poses, keep))
    # temporary files, at any depth: only those of a write the kill cut short, named for its
    # process; the next writers of the status file and the map remove them
    temporary = [p for p in tmp_path.rglob("*") if ".tmp" in p.name]
    assert all(p.name.endswith(f".{proc.pid}.tmp") for p in temporary), temporary
    check(status, force=True)
    _, _, _, channels = read_channels(out)                     # the default model's map: knowledge and looks too
    StoreWriter(out, spec, reading=channels.reading).save(keys, data, knowledge=channels.knowledge,
                                                          looks=channels.looks)
    assert not [p for p in tmp_path.rglob("*") if ".tmp" in p.name]
    assert rec.stat().st_size > 1000


def test_radarcl_emulate_plays_a_recording_onto_a_pty(tmp_path, scene):
    """The emulator as a command: a recording in, beam packets out on a new pty whose path it
    prints, with the faults asked for, once the reader says it is ready (--wait-for: no head
    start to guess); the parser reads every intact packet."""
    import subprocess
    import sys

    from radarcl.io import recording
    from radarcl.io.beam_protocol import BeamParser

    frames, poses = scene
    rec = tmp_path / "rec.npz"
    recording.save(rec, recording.Recording(frames, poses, "paper"))
    link, ready = tmp_path / "radar", tmp_path / "reading"
    proc = subprocess.Popen([sys.executable, "-m", "radarcl", "emulate", str(rec), "--pty", "--link", str(link),
                             "--baud", "max", "--frames", "1", "--faults", "noise=0.05,seed=3",
                             "--wait-for", str(ready)],
                            stdout=subprocess.PIPE, text=True)
    first = proc.stdout.readline()
    assert "emulating on /dev/pts/" in first and "256 packets" in first, first
    parser = BeamParser()
    reader = PortReader(open_port(str(link)), lambda t, d: parser.data_received(d)).start()
    ready.touch()                                   # the port is open (and flushed): go
    try:
        out, _ = proc.communicate(timeout=60)
        reader.closed.wait(10)
    finally:
        reader.stop()
        proc.kill()
    assert "sent" in out and "(256 intact)" in out and proc.returncode == 0
    got = parser.take()
    assert len(got) == 256 and parser.counters.bytes_dropped > 0          # the noise bursts, dropped
    assert np.array_equal(got[5].samples, frames[0][1, 1])


def test_the_first_frame_of_a_new_pose_waits_for_no_planner_growth_or_recording(runtime, scene, monkeypatch):
    """What stalled the stream at a new pose, asserted on the work done, not on wall time: the
    planner's kernel is built and the pool's first chunks are there before the first beam; a
    frame fused in parts never records a still table (each part plans the same pose again);
    the pool grows during the stream only by chunks grown ahead on their own thread. The
    beams of each frame's first fuse are in the latencies, and the map is the offline one."""
    import radarcl.grid
    from radarcl.stages.fusion import Fusion

    monkeypatch.setattr(radarcl.grid, "CHUNK_BYTES", 1 << 17)         # 64 bricks a chunk: the stream grows
    frames, poses = scene
    config = paper_config()
    mapper = livemap.LiveMapper(runtime, config)
    mapper.prepare()
    grid, fusion = mapper.mapping.grid, mapper.mapping.fusion
    assert fusion._planner is not None and grid.capacity > 0
    before = dict(grid.stats)

    def no_recording(self, plan):
        raise AssertionError("a still table was recorded in the stream")

    monkeypatch.setattr(Fusion, "record", no_recording)
    n_az, n_el = frames.shape[1:3]
    for j, (frame, pose) in enumerate(zip(frames, poses)):
        beams = [livemap.Beam(j, i, k, 0, frame[i, k], pose, time.perf_counter()) for i in range(n_az) for k in range(n_el)]
        for lo in range(0, len(beams), 16):
            mapper.add(beams[lo:lo + 16])
    mapper.flush()
    runtime.queue.finish()
    assert grid.stats["chunks_waited"] == before["chunks_waited"], "a frame waited for the pool to grow"
    assert grid.stats["chunks"] > before["chunks"], "the stream reached new ground"
    assert len(mapper.new_pose_latencies) == 2 * 16 and len(mapper.latencies) == len(frames) * n_az * n_el
    keep = np.ones(frames.shape[:3], bool)
    assert np.array_equal(mapper.mapping.snapshot(), offline(runtime, config, frames, poses, keep))


def test_a_detection_statistics_map_is_served_as_it_reads_not_as_its_sums(runtime):
    """--serve sends a viewer the bricks of a grid with the knowledge channel as the map reads
    them where it knows and 0 where it does not (``Map.shown_units``, what `radarcl view` draws
    of a saved map), the whole snapshot and a changed-slots update alike: not the raw sums,
    which lack the look limit and the prior."""
    from radarcl.commands.live import shown
    from radarcl.config.presets import paper_config
    from radarcl.maps.map import Map
    from radarcl.pipeline import Mapping
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    config = paper_config(0.8, {"interpret.model": "detstats"})
    mapping = Mapping.from_config(runtime, config=config)
    obs = observe(paper_scene(), [-5.2], seed=3)
    mapping.fuse(obs.samples[0], obs.poses[0])
    grid = mapping.grid
    keys, data = grid.bricks()
    whole = shown(grid, keys, {"evidence": data, "knowledge": grid.knowledge_bricks(),
                               "looks": grid.knowledge_bricks("looks")}, config)
    slot_keys, channels = grid.read_slots(np.arange(len(keys)), ("evidence", "knowledge", "looks"))
    want = Map.of_grid(grid, config.model_params().reading)
    assert np.array_equal(slot_keys, keys) and np.array_equal(shown(grid, slot_keys, channels, config), whole)
    assert np.array_equal(whole, np.where(want.known(), want.read_units(), 0))
    assert (whole != 0).any() and not np.array_equal(whole, data)
