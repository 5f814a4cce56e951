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
from radarcl.grid import EvidenceGrid, GridSpec
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
