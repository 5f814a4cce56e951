"""radarcl/io/prefetch.py: frames read ahead on a thread come in order, at most ``depth``
ahead; the reader's error surfaces at its frame, the same exception, after the frames before
it; a consumer that leaves stops the reader. A fuse with the reader thread makes the inline
fuse's map bit for bit, and a frame that cannot be read mid-fuse keeps the map before it."""

import threading

import numpy as np
import pytest

from radarcl.config import mapconfig
from radarcl.errors import FrameFormatError
from radarcl.io import inputs, prefetch
from radarcl.jobs import fuse
from radarcl.maps import disk


def test_items_come_in_order_at_most_depth_ahead():
    read_up_to = []
    seen = []

    def read(j):
        read_up_to.append(j)
        return j * j

    for j, item in enumerate(prefetch.prefetched(read, 50, depth=3)):
        assert max(read_up_to) <= j + 3                  # never more than ``depth`` ahead of the one in hand
        seen.append(item)
    assert seen == [j * j for j in range(50)]
    assert list(prefetch.prefetched(read, 5, depth=0)) == [0, 1, 4, 9, 16]


def test_an_item_not_to_overlap_is_read_only_once_the_consumer_is_back():
    """``overlap(j)`` False: item j is read after the consumer is done with item j - 1 (the
    bench's inline frames); the others may be read while it works, and all come in order."""
    log, lock = [], threading.Lock()
    started = [threading.Event() for _ in range(12)]

    def read(j):
        with lock:
            log.append(("read", j))
        started[j].set()
        return j

    inline = {3, 4, 5, 9}
    got = []
    for j in prefetch.prefetched(read, 12, depth=1, overlap=lambda j: j not in inline):
        got.append(j)
        if j + 1 < 12 and j + 1 not in inline:      # the consumer's work, which the next read runs beside
            assert started[j + 1].wait(30), f"item {j + 1} was not read while the consumer held item {j}"
        with lock:
            log.append(("done", j))
    assert got == list(range(12))
    for j in inline:
        assert log.index(("read", j)) > log.index(("done", j - 1)), log
    assert all(log.index(("read", j)) < log.index(("done", j - 1)) for j in set(range(1, 12)) - inline), log


def test_a_reader_error_surfaces_at_its_item_with_its_sentence():
    def read(j):
        if j == 4:
            raise FrameFormatError("scan 4.png: the PNG is truncated; expected a whole 8-bit greyscale PNG")
        return j

    got = []
    with pytest.raises(FrameFormatError, match=r"^scan 4.png: the PNG is truncated; expected a whole"):
        for item in prefetch.prefetched(read, 10, depth=2):
            got.append(item)
    assert got == [0, 1, 2, 3]
    assert not [t for t in threading.enumerate() if t.name == "radarcl-reader"]


def test_a_consumer_that_leaves_stops_the_reader():
    before = threading.active_count()
    items = prefetch.prefetched(lambda j: np.zeros(4) + j, 10_000, depth=2)
    assert next(items)[0] == 0 and next(items)[0] == 1
    items.close()                                   # the consumer leaves (an error of its own, Ctrl-C)
    assert threading.active_count() == before
    assert not [t for t in threading.enumerate() if t.name == "radarcl-reader"]


class _Frames:
    """Frames that fail at ``bad`` as a corrupt scan would when it is decoded."""

    def __init__(self, frames, bad=None):
        self.frames, self.bad = frames, bad

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, j):
        if j == self.bad:
            raise FrameFormatError(f"frame {j}: the scan is truncated; expected its whole PNG")
        return self.frames[j]


def _source(frames, bad=None, levels=False, differenced=False):
    """A source of ``frames``; levels=True: ``frames`` are uint8 levels offered as such (with
    ``differenced``: their rows' differences), and the source's power (``frames``) cannot be
    read, so a fuse that reads it fails."""
    config = mapconfig.resolve("navtech-cts350x", program={"grid.voxel_m": 0.8, "interpret.range_max_m": 40.0})
    sensor = config.sensor.with_bins(frames.shape[-1])
    config = config.for_sensor(sensor)
    rng = np.random.default_rng(3)
    n = len(frames)
    poses = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    poses[:, 0, 3] = np.arange(n) * 1.5 + rng.uniform(0, 0.1, n)          # driving along x
    flags = [np.zeros(sensor.n_azimuth, np.uint8)] * n
    if not levels:
        return config, inputs.FrameSource(sensor, _Frames(frames, bad), poses, flags, f"{n} test scans")
    return config, inputs.FrameSource(sensor, _NoPower(n), poses, flags, f"{n} test scans",
                                      levels=_Frames(frames, bad), db_per_level=1.0,
                                      differenced=[differenced] * n if differenced else None)


class _NoPower:
    """A source's power that a fuse of its levels must not read."""

    def __init__(self, n):
        self.n = n

    def __len__(self):
        return self.n

    def __getitem__(self, j):
        raise AssertionError(f"frame {j}'s power was read; the levels should have been fused")


def _frames(n=6, n_bins=600):
    rng = np.random.default_rng(11)
    frames = rng.exponential(1.0, (n, 400, n_bins)).astype(np.float32)
    frames[:, ::7, 300] = 1e5                                                   # walls 300 bins out
    return frames


def _digest(path):
    """The digest of a map's bricks that hold anything: a drive's grid spans every frame's
    position, so the broken drive's is larger than the four frames' and may keep bricks near the
    sensor that stay empty."""
    spec, keys, data, _, channels = disk.read_map(path)
    from radarcl.bench.drive import map_digest

    arrays = {"evidence": data}
    if channels is not None:
        arrays.update(knowledge=channels.knowledge, looks=channels.looks)
    full = np.zeros(len(keys), bool)
    for a in arrays.values():
        full |= np.asarray(a).reshape(len(keys), -1).any(axis=1)
    assert full.any()
    return map_digest(keys[full], {name: np.asarray(a)[full] for name, a in arrays.items()})


def test_a_fuse_reading_ahead_makes_the_inline_map_bit_for_bit(runtime, tmp_path, monkeypatch):
    frames = _frames()
    config, source = _source(frames)
    fuse.run(runtime, source, config, tmp_path / "ahead.npz", report=lambda _: None)
    from radarcl import pipeline

    inline = pipeline.Mapping.fuse_source
    monkeypatch.setattr(pipeline.Mapping, "fuse_source",
                        lambda self, *a, **k: inline(self, *a, **{**k, "read_ahead": 0}))
    fuse.run(runtime, source, config, tmp_path / "inline.npz", report=lambda _: None)
    assert _digest(tmp_path / "ahead.npz") == _digest(tmp_path / "inline.npz")
    assert len(disk.read(tmp_path / "ahead.npz")[1]) > 0


def _levels(n=6, n_bins=600):
    rng = np.random.default_rng(12)
    levels = rng.integers(0, 50, (n, 400, n_bins), dtype=np.uint8)
    levels[:, ::7, 300] = 190                                                  # walls 300 bins out
    return levels


def test_a_source_of_levels_makes_its_powers_map_bit_for_bit(runtime, tmp_path):
    """Polar scans travel as their uint8 levels, or as their rows' differences (a "Sub" PNG's,
    summed on the device), and become power on the device: the same map as their power fused
    (and the source's power is never read)."""
    from radarcl.io.polar_png import levels_to_power

    levels = _levels()
    coded = levels.copy()
    coded[..., 1:] -= levels[..., :-1]
    config, as_levels = _source(levels, levels=True)
    _, as_differences = _source(coded, levels=True, differenced=True)
    _, as_power = _source(levels_to_power(levels))
    for name, source in (("levels", as_levels), ("differences", as_differences), ("power", as_power)):
        fuse.run(runtime, source, config, tmp_path / f"{name}.npz", report=lambda _: None)
    assert _digest(tmp_path / "levels.npz") == _digest(tmp_path / "differences.npz") == _digest(tmp_path / "power.npz")
    _, head = _source(levels, levels=True)
    assert len(head.head(2).levels) == 2 and np.array_equal(head.head(2).levels[1], levels[1])
    assert as_differences.head(2).differenced == [True, True]


@pytest.mark.parametrize("rolling", [False, True], ids=["map file", "rolling store"])
@pytest.mark.parametrize("levels", [False, True], ids=["power", "levels"])
def test_a_frame_that_cannot_be_read_keeps_the_map_before_it(runtime, tmp_path, rolling, levels):
    frames = _levels() if levels else _frames()
    config, broken = _source(frames, bad=4, levels=levels)
    _, first_four = _source(frames[:4], levels=levels)
    name = "m.rcmap" if rolling else "m.npz"
    window = dict(window_m=60.0) if rolling else {}
    said = []
    (tmp_path / "broken").mkdir()
    (tmp_path / "four").mkdir()
    with pytest.raises(FrameFormatError, match=r"^frame 4: the scan is truncated; expected its whole PNG$"):
        fuse.run(runtime, broken, config, tmp_path / "broken" / name, report=said.append, **window)
    assert said[-1] == f"kept the map of the 4 frames fused before the error in {tmp_path / 'broken' / name}"
    fuse.run(runtime, first_four, config, tmp_path / "four" / name, report=lambda _: None, **window)
    assert _digest(tmp_path / "broken" / name) == _digest(tmp_path / "four" / name)
    assert len(disk.read_poses(tmp_path / "broken" / name)) == 4
    assert len(disk.read(tmp_path / "broken" / name)[1]) > 0
