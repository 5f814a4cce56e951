"""radarcl/bench/drive.py: a small drive (Oxford scans along the full_seq_1 odometry, where the
car moves) with its memory high-water marks asserted: the rolling map's device holds the
window's bricks, not the drive's, and the unbounded baseline on the same frames holds more;
the store after the drive is the unbounded map bit for bit."""

import math

import numpy as np
import pytest

import radarcl.grid
from radarcl.bench import drive
from radarcl.errors import ConfigError
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


def test_a_drive_reading_ahead_makes_the_inline_drive_s_map_bit_for_bit(shared_data, tmp_path, monkeypatch):
    """The reader thread changes when frames are decoded, never what is fused: the rolling
    store and the unbounded grid of a drive read ahead digest as those of the drive read
    inline, and as those of a drive whose scans hold their levels (not the PNG's row
    differences the device sums); the inline run's reading and fusing are timed apart."""
    import dataclasses

    from radarcl.io import polar_png

    common = dict(data=shared_data / "navtech_oxford", n_frames=8, voxel_m=VOXEL, progress=False, first=FIRST,
                  range_m=RANGE)
    ahead = drive.run_drive(**common, window_m=WINDOW, store=tmp_path / "a.rcmap", read_ahead=2)
    inline = drive.run_drive(**common, window_m=WINDOW, store=tmp_path / "i.rcmap", read_ahead=0)
    assert ahead["bricks"] > 0 and ahead["map_digest"] == inline["map_digest"]
    unbounded = drive.run_drive(**common, read_ahead=0)["map_digest"]
    assert drive.run_drive(**common, read_ahead=3)["map_digest"] == unbounded
    with monkeypatch.context() as m:
        load = polar_png.load_scan

        def levels_summed(*args, **kwargs):
            scan = load(*args, **kwargs)
            assert scan.differenced                                  # the Oxford PNGs' rows are "Sub"
            return dataclasses.replace(scan, stored_levels=scan.levels, differenced=False)

        m.setattr(polar_png, "load_scan", levels_summed)
        assert drive.run_drive(**common, read_ahead=0)["map_digest"] == unbounded
    assert inline["read_s"] + inline["fuse_s"] <= inline["wall_s"]
    timing = drive.run_drive(**common, window_m=WINDOW, store=tmp_path / "t.rcmap", alternate=3)
    # frames 0-2 and 6-7 read ahead, 3-5 inline: 1 and 6 timed end to end (read beside the fuse before
    # them, fused beside the next read; 0 and 7 have no neighbour), 3-5 read alone, 2-4 fused alone
    assert (timing["overlapped_frames"], timing["read_frames"], timing["fused_frames"]) == (2, 3, 3)
    figures = drive.overlap_figures(timing, ahead)
    assert figures["same_map"] and figures["decode_alone_per_s"] > 0 and figures["fuse_alone_per_s"] > 0
    assert all(math.isfinite(figures[k]) and figures[k] > 0 for k in ("end_to_end_per_s", "end_to_end_over_fuse_alone"))
    with pytest.raises(ConfigError, match="read one ahead"):
        drive.run_drive(**common, window_m=WINDOW, store=tmp_path / "u.rcmap", alternate=3, read_ahead=0)
