"""radarcl/bench/drive.py: a small drive (Oxford scans along the full_seq_1 odometry, where the
car moves) with its memory high-water marks asserted: the rolling map's device holds the
window's bricks, not the drive's, and the unbounded baseline on the same frames holds more;
the store after the drive is the unbounded map bit for bit."""

import math

import numpy as np

import radarcl.grid
from radarcl.bench import drive
from radarcl.gridspec import BRICK
from radarcl.maps import disk

FIRST, FRAMES, VOXEL, RANGE, WINDOW = 8361, 24, 0.4, 20.0, 27.0
HOST_GROWTH_MIB = 1024        # a bound on the drive's own resident growth (its maps, scans and pools), well above it


def test_a_small_drive_keeps_its_memory_high_water_marks(shared_data, tmp_path, monkeypatch):
    monkeypatch.setattr(radarcl.grid, "CHUNK_BYTES", 1 << 16)       # 256 planar bricks a chunk: the pool follows them
    data = shared_data / "navtech_oxford"
    track, stamps = drive.drive_track(data)
    moved = np.linalg.norm(np.diff(track.at(stamps[[FIRST, FIRST + FRAMES]])[:, :2, 3], axis=0))
    assert moved > 2 * WINDOW, f"the car moves {moved:.0f} m over these scans"
    common = dict(data=data, n_frames=FRAMES, voxel_m=VOXEL, progress=False, first=FIRST, range_m=RANGE)
    resident = drive._rss_bytes() / 2**20          # the test process's own, before the drive
    rolling = drive.run_drive(**common, window_m=WINDOW, store=tmp_path / "d.rcmap")
    unbounded = drive.run_drive(**common)
    edge = BRICK * VOXEL
    disc = math.pi * (WINDOW + edge) ** 2 / edge ** 2                # the window's bricks, at most
    assert rolling["evicted"] > 0 and rolling["bricks"] == unbounded["bricks"]
    assert rolling["device_bricks_max"] <= disc < unbounded["device_bricks_max"]
    assert rolling["device_mib_max"] < unbounded["device_mib_max"]
    # the drive's own host memory: what the suite's earlier tests left resident is not the drive's
    assert rolling["host_mib_max"] - resident < HOST_GROWTH_MIB
    assert rolling["latency_p99_ms"] >= rolling["latency_p50_ms"] > 0
    assert rolling["frames"] == FRAMES and 0 < rolling["realtime_factor"]
    spec, keys, data_w = disk.read(tmp_path / "d.rcmap")
    assert len(keys) == rolling["bricks"] and len(disk.read_poses(tmp_path / "d.rcmap")) == FRAMES
