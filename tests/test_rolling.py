"""radarcl/maps/rolling.py: a drive in a bounded window. A radar drives out and back over the
ground it mapped (a loop closure: its bricks left the device and come back from the store); the
store after the drive holds exactly the map an unbounded grid gives, the device never holds more
than the window's bricks, and a window or a store that cannot work is refused with a sentence."""

import math

import numpy as np
import pytest

from radarcl.config.stage_config import RadarConfig
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec, assemble
from radarcl.maps import disk, store
from radarcl.maps.rolling import RollingStore, RollingWindow
from radarcl.stages.fusion import Fusion

N_BINS, SPACING, FIRST, LAST = 160, 0.1, 5, 150           # evidence out to 15 m
LATTICE = BeamLattice.spinning(90, az0_rad=0.1)
MODEL = BeamModel.from_radar(RadarConfig())
SPEC = GridSpec((-20.0, -20.0, -0.125), 0.25, (400, 160, 1), brick_z=1)
REACH_M = (LAST + 0.5) * SPACING


def drive():
    """Out along x 57 m and back, turning a little, one frame every 3 m: the way back is ground
    the window left behind."""
    xs = np.concatenate([np.arange(0.0, 60.0, 3.0), np.arange(57.0, -1.0, -3.0)])
    return [pose_from_xyz_rpy(x, 0.3 * math.sin(x / 7), 0.0, yaw=0.02 * j) for j, x in enumerate(xs)]


def fuse_drive(runtime, window=None):
    grid = EvidenceGrid(runtime, SPEC) if window is None else window.grid
    fusion = Fusion(runtime, grid, LATTICE, MODEL, N_BINS, SPACING, FIRST, LAST)
    most = 0
    for j, pose in enumerate(drive()):
        if window is not None:
            window.update(pose[:3, 3])
        ev = np.random.default_rng(j).integers(-3000, 3000, (LATTICE.n_beams, N_BINS)).astype(np.int32)
        fusion(ev, pose)
        most = max(most, grid.n_bricks)
    if window is not None:
        window.finish()
    return grid, most


def test_a_drive_out_and_back_gives_the_unbounded_map_bit_for_bit(runtime, tmp_path):
    unbounded, most_unbounded = fuse_drive(runtime)
    keys, data = unbounded.bricks()
    grid = EvidenceGrid(runtime, SPEC, chunk_bricks=64)
    backing = RollingStore(tmp_path / "drive.rcmap", SPEC, segment_bricks=100)
    window = RollingWindow(grid, backing, REACH_M + 4.0)
    window.check_reach(REACH_M)
    fusion = Fusion(runtime, grid, LATTICE, MODEL, N_BINS, SPACING, FIRST, LAST)
    most = most_device = 0
    for j, pose in enumerate(drive()):
        window.update(pose[:3, 3])
        ev = np.random.default_rng(j).integers(-3000, 3000, (LATTICE.n_beams, N_BINS)).astype(np.int32)
        fusion(ev, pose)
        most, most_device = max(most, grid.n_bricks), max(most_device, grid.memory()["device_bytes"])
    stored = window.finish()
    # the loop closed: bricks left the device, were written, and came back from the disk
    assert window.evicted > 200 and backing.stats["restored_from_disk"] > 50 and backing.stats["segments"] > 3
    spec, k, d = disk.read(tmp_path / "drive.rcmap")
    assert spec == SPEC and stored == len(keys) == len(k)
    a, b = np.lexsort(keys.T[::-1]), np.lexsort(k.T[::-1])
    assert np.array_equal(keys[a], k[b]) and np.array_equal(data[a], d[b])
    # the device held the window's bricks, not the drive's: a disc of radius window + a brick
    edge = 8 * SPEC.voxel_m
    bound = math.pi * (window.window_m + edge) ** 2 / edge ** 2
    assert most <= bound < most_unbounded, (most, bound, most_unbounded)
    assert most_device <= (most // 64 + 2) * 64 * SPEC.brick_bytes        # grown a chunk at a time


def test_a_window_smaller_than_a_frame_and_a_store_that_cannot_be_written(runtime, tmp_path, monkeypatch):
    grid = EvidenceGrid(runtime, SPEC)
    window = RollingWindow(grid, RollingStore(tmp_path / "a.rcmap", SPEC), 10.0)
    with pytest.raises(ConfigError, match="smaller than one frame's reach.*at least 18 m"):
        window.check_reach(REACH_M)
    for i, bad in enumerate((0.0, -3, float("nan"), "far")):
        with pytest.raises(ConfigError, match="window must be a"):
            RollingWindow(grid, RollingStore(tmp_path / f"w{i}.rcmap", SPEC), bad)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="cannot be written"):
        RollingStore(tmp_path / "file" / "m.rcmap", SPEC)             # before the drive starts
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "x.txt").write_text("not a store")
    with pytest.raises(ConfigError, match="exists"):
        RollingStore(tmp_path / "other", SPEC)
    # mid-drive: the disk fills after two segments; the drive stops with a sentence, the map so far saved
    real, calls = store.write_segment, []

    def full_disk(*args):
        calls.append(1)
        if len(calls) > 2:
            raise OSError(28, "No space left on device")
        return real(*args)

    monkeypatch.setattr(store, "write_segment", full_disk)
    grid = EvidenceGrid(runtime, SPEC)
    backing = RollingStore(tmp_path / "full.rcmap", SPEC, segment_bricks=60)
    with pytest.raises(ConfigError, match="No space left on device.*saved up to its last complete segment"):
        fuse_drive(runtime, RollingWindow(grid, backing, REACH_M + 4.0))
    backing.close()
    assert len(calls) == 3, "the drive stops at the first failed write"
    spec, keys, _ = disk.read(tmp_path / "full.rcmap")
    assert spec == SPEC and len(keys) == backing.bricks_stored >= 60


OXFORD = ["--sensor", "navtech-cts350x", "--voxel", "0.4", "--set", "interpret.range_max_m=20", "--no-report",
          "--no-progress"]


def test_radarcl_fuse_window_on_the_oxford_scans(shared_data, tmp_path, capsys):
    """`radarcl fuse --window`: the 11 Oxford scans (about 20 m of road) mapped out to 20 m in a
    26 m window give the unbounded map bit for bit; the default window is said; a window a frame
    does not fit, an .npz output and a store that cannot be written are refused with a sentence
    before anything is written."""
    from radarcl.cli import main

    scans = str(shared_data / "navtech_oxford")
    grid = ["--set", "grid.origin_m=[-20, -20, -0.2]", "--set", "grid.size_m=[60.4, 40.8, 0.4]"]
    assert main(["fuse", scans, *OXFORD, *grid, "--out", str(tmp_path / "all.npz")]) == 0
    assert main(["fuse", scans, *OXFORD, *grid, "--window", "26", "--out", str(tmp_path / "w.rcmap")]) == 0
    out = capsys.readouterr().out
    left = int(out.split(" bricks left the window")[0].rsplit(" ", 1)[1])
    assert "within 26 m of the sensor" in out and left > 20
    spec, keys, data = disk.read(tmp_path / "all.npz")
    spec_w, keys_w, data_w = disk.read(tmp_path / "w.rcmap")
    a, b = np.lexsort(keys.T[::-1]), np.lexsort(keys_w.T[::-1])
    assert spec == spec_w and len(keys) > 100
    assert np.array_equal(keys[a], keys_w[b]) and np.array_equal(data[a], data_w[b])
    assert len(disk.read_poses(tmp_path / "w.rcmap")) == 11
    # --window alone: 1.5 x the mapped range, said; the grid spans the drive
    assert main(["fuse", scans, *OXFORD, "--window", "--out", str(tmp_path / "d.rcmap")]) == 0
    assert "within 30 m of the sensor (the default, 1.5 x the mapped range)" in capsys.readouterr().out
    # refused before the drive, nothing written
    for args, said in ((["--window", "10"], "smaller than one frame's reach"), (["--window", "far"], "distance"),
                       (["--window", "-3"], "positive distance")):
        assert main(["fuse", scans, *OXFORD, *args, "--out", str(tmp_path / "bad.rcmap")]) == 2
        assert said in capsys.readouterr().err and not (tmp_path / "bad.rcmap").exists()
    assert main(["fuse", scans, *OXFORD, "--window", "--out", str(tmp_path / "m.npz")]) == 2
    assert "give --out a store name" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main(["fuse", scans, *OXFORD, "--window", "--out", str(tmp_path / "file" / "m.rcmap")]) == 2
    assert "cannot create the directory of map" in capsys.readouterr().err


def test_a_detection_statistics_drive_rolls_its_knowledge_channel_bit_for_bit(runtime, tmp_path):
    """A grid with the knowledge channel rolls too: its knowledge and looks leave the device and
    come back with its sums, and the store after the drive out and back holds the unbounded
    grid's three channels, bit for bit, with the map's reading."""
    from radarcl import logodds, node_pairs, sensor_model
    from radarcl.maps.map import Map

    reading = sensor_model.ModelParams().reading
    shape = (LATTICE.n_beams, N_BINS, node_pairs.N_CLASSES)

    def frame(j):
        rng = np.random.default_rng(j)
        e = rng.integers(-3000, 3000, (*shape, node_pairs.NODES))
        d = rng.integers(0, logodds.KNOWLEDGE_SCALE + 1, (*shape, node_pairs.NODES))
        return node_pairs.pack_nodes(e, d)

    def run(window):
        grid = window.grid if window else EvidenceGrid(runtime, SPEC, knowledge=True)
        fusion = Fusion(runtime, grid, LATTICE, MODEL, N_BINS, SPACING, FIRST, LAST, detstats=True)
        for j, pose in enumerate(drive()):
            if window:
                window.update(pose[:3, 3])
            fusion(frame(j), pose)
        return grid

    unbounded = run(None)
    want = {c: assemble(SPEC, *unbounded.bricks(c)) for c in unbounded.channels}
    backing = RollingStore(tmp_path / "ds.rcmap", SPEC, segment_bricks=100, reading=reading)
    window = RollingWindow(EvidenceGrid(runtime, SPEC, knowledge=True, chunk_bricks=64), backing, REACH_M + 4.0)
    run(window)
    window.finish()
    assert window.evicted > 200 and backing.stats["restored_from_disk"] > 50
    m = Map.open(tmp_path / "ds.rcmap")
    assert m.reading == reading
    for channel, got in (("evidence", m.data), ("knowledge", m.knowledge), ("looks", m.looks)):
        assert np.array_equal(assemble(SPEC, m.keys, got), want[channel]) and want[channel].any(), channel
