"""Hostile input for the map store and the stream recordings, beside tests/test_fuzz.py:
property-based damage (hypothesis) to a store's manifest, its index and its chunk files, and to a
`--record` stream's records. Every case must end in a radarcl error (a sentence) or in exactly
what was written: a store read back whole is the original brick for brick; a store read with
``salvage`` gives only original bricks and lists every other one as lost; a stream replays
without another exception, a thread's traceback or a hang.

CI runs a short pass (seconds); RADARCL_FUZZ=long (`make fuzz`) 16x more examples, and
RADARCL_FUZZ_STORE_REPORT=FILE writes the counts as JSON.
"""

import json
import os
import shutil
import time
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radarcl.errors import RadarclError
from radarcl.gridspec import GridSpec
from radarcl.maps import store

LONG = os.environ.get("RADARCL_FUZZ", "") == "long"
EXAMPLES = 400 if LONG else 25
RUN = settings(max_examples=EXAMPLES, deadline=None, derandomize=not LONG,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
COUNTS = {"store_cases": 0, "refused": 0, "read_whole": 0, "salvaged": 0, "bricks_lost": 0, "silent_wrong": 0,
          "other_exceptions": 0, "stream_cases": 0, "stream_refused": 0, "stream_read": 0, "slow": 0}
SPEC = GridSpec((-2.0, -3.0, -1.0), 0.25, (80, 64, 40))         # 10 x 8 x 5 bricks


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    path = os.environ.get("RADARCL_FUZZ_STORE_REPORT")
    if path:
        with open(path, "w") as f:
            json.dump(COUNTS, f, indent=1)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A store of two saves (two segments, 520 bricks: chunks of 256 and a partial one) and its content."""
    rng = np.random.default_rng(5)
    grid = np.array([(x, y, z) for x in range(10) for y in range(8) for z in range(5)], np.int32)
    keys = grid[np.sort(rng.choice(len(grid), 300, replace=False))]
    data = rng.integers(-4000, 4000, (len(keys), 8, 8, 8)).astype(np.int32)
    path = tmp_path_factory.mktemp("store") / "m.rcmap"
    w = store.StoreWriter(path, SPEC)
    w.save(keys[:200], data[:200])
    w.save(keys, data)
    return path, {tuple(k): d for k, d in zip(keys.tolist(), data)}


def check_read(path, original, moved=False):
    """Read ``path`` strictly and with salvage; classify; fail on anything but a sentence or the
    truth. ``moved``: the index was rewritten consistently (its checksum made to match, as a writer
    with a bug would), so a brick may sit under another key; its values must still be ones
    that were written (nothing invented)."""
    from radarcl.maps.disk import read_salvaged

    COUNTS["store_cases"] += 1
    for salvage in (False, True):
        try:
            spec, keys, data, lost = read_salvaged(path, salvage)
        except RadarclError as exc:
            assert str(exc)
            COUNTS["refused"] += 1
            continue
        except Exception as exc:                               # noqa: BLE001 - the point of the test
            COUNTS["other_exceptions"] += 1
            raise AssertionError(f"{type(exc).__name__} instead of a radarcl error: {exc}") from exc
        got = {tuple(k): d for k, d in zip(keys.tolist(), data)}
        if any(e["reason"] == store.UNSEALED for e in lost):
            moved = True                                       # salvage believed an edited manifest, and said so
        if moved:
            written = {d.tobytes() for d in original.values()}
            wrong = [k for k, d in got.items() if d.tobytes() not in written]
            if wrong:
                COUNTS["silent_wrong"] += 1
                raise AssertionError(f"salvage={salvage}: {len(wrong)} bricks hold values never written")
            COUNTS["salvaged" if salvage else "read_whole"] += 1
            continue
        wrong = [k for k, d in got.items() if k not in original or not np.array_equal(d, original[k])]
        lost_keys = {tuple(k) for e in lost for k in e["keys"]}
        missing = set(original) - set(got) - lost_keys
        if wrong or missing or spec != SPEC or (not salvage and lost):
            COUNTS["silent_wrong"] += 1
            raise AssertionError(f"salvage={salvage}: {len(wrong)} bricks read wrong, {len(missing)} lost unsaid")
        if lost:
            COUNTS["salvaged"] += 1
            COUNTS["bricks_lost"] += len(lost_keys)
        else:
            COUNTS["read_whole"] += 1


def copy(pristine, tmp_path):
    path = tmp_path / f"s{time.perf_counter_ns()}.rcmap"
    shutil.copytree(pristine[0], path)
    return path


JSON = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-2 ** 40, 2 ** 40),
                              st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12)),
                    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner,
                                                                                         max_size=3)),
                    max_leaves=8)
MANIFEST_PATHS = st.sampled_from([("format",), ("format_version",), ("version",), ("index",), ("segments",),
                                  ("previous",), ("grid",), ("grid", "origin_m"), ("grid", "voxel_m"),
                                  ("grid", "shape"), ("bricks",), ("checksums",), ("checksums", "index"),
                                  ("checksums", "segments"), ("checksums", "segments", "0"),
                                  ("checksums", "segments", "1"), ("poses",), ("sensor",), ("config",)])


@RUN
@given(MANIFEST_PATHS, st.one_of(JSON, st.sampled_from([[], [0], [1], [0, 1, 2], "index_1", "index_9", -1, 0, 3,
                                                       [8, 8, 8], [80, 64, 41], 1.0, "../../x"])))
def test_manifests(pristine, tmp_path_factory, where, value):
    path = copy(pristine, tmp_path_factory.mktemp("m"))
    manifest = json.loads((path / "manifest.json").read_text())
    node = manifest
    for key in where[:-1]:
        node = node.setdefault(key, {}) if isinstance(node, dict) else {}
    if isinstance(node, dict):
        node[where[-1]] = value
    (path / "manifest.json").write_text(json.dumps(manifest))
    check_read(path, pristine[1])


@RUN
@given(st.integers(0, 2 ** 31), st.integers(0, 5), st.sampled_from(["flip", "truncate", "delete", "zero", "swap",
                                                                    "append"]))
def test_chunk_files(pristine, tmp_path_factory, seed, n, how):
    path = copy(pristine, tmp_path_factory.mktemp("c"))
    rng = np.random.default_rng(seed)
    files = sorted(p for p in path.rglob("*") if p.is_file() and not p.name.startswith("."))
    for _ in range(n + 1):
        f = files[int(rng.integers(0, len(files)))]
        if not f.exists():
            continue
        raw = bytearray(f.read_bytes())
        if how == "flip" and raw:
            i = int(rng.integers(0, len(raw)))
            raw[i] ^= 1 << int(rng.integers(0, 8))
        elif how == "truncate":
            raw = raw[:int(rng.integers(0, len(raw) + 1))]
        elif how == "zero":
            raw = bytearray(len(raw))
        elif how == "swap":
            g = files[int(rng.integers(0, len(files)))]
            if g.exists():
                raw, other = bytearray(g.read_bytes()), bytes(raw)
                g.write_bytes(other)
        elif how == "append":
            raw += rng.integers(0, 256, int(rng.integers(1, 64)), np.uint8).tobytes()
        if how == "delete":
            f.unlink()
        else:
            f.write_bytes(bytes(raw))
    check_read(path, pristine[1])


@RUN
@given(st.lists(st.tuples(st.integers(0, 299), st.integers(0, 4), st.integers(-3, 2 ** 31)), min_size=1, max_size=4),
       st.booleans())
def test_index_cells(pristine, tmp_path_factory, cells, fix_crc):
    """Index cells rewritten, with the checksum left stale (damage) or made to match (a writer
    with a bug): keys, segments and rows that do not hold are refused or lost, never read wrong."""
    import zarr

    path = copy(pristine, tmp_path_factory.mktemp("i"))
    manifest = json.loads((path / "manifest.json").read_text())
    group = zarr.open_group(str(path), mode="a")
    index = group[manifest["index"]][:]
    for row, col, value in cells:
        index[row, col] = np.int32(value % 2 ** 31) if value >= 0 else value
    group[manifest["index"]][:] = index
    if fix_crc:
        manifest["checksums"]["index"] = zlib.crc32(np.ascontiguousarray(index, "<i4"))
        (path / "manifest.json").write_text(json.dumps(manifest))
    check_read(path, pristine[1], moved=fix_crc)


# -- stream recordings -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def packets():
    from radarcl.io import emulator

    rng = np.random.default_rng(3)
    frames = rng.integers(-2000, 2000, (1, 64, 4, 256)).astype(np.int16)
    return emulator.beam_packets(frames, np.broadcast_to(np.eye(4), (1, 4, 4)))[:24]


def stream_bytes(records, header=b'{"protocol": "beams", "sensor": "paper"}'):
    return b"RCSTREAM1\n" + header + b"\n" + b"".join(np.array([t], "<u8").tobytes() + np.array([len(d)], "<u4").tobytes()
                                                       + d for t, d in records)


@RUN
@given(st.integers(0, 2 ** 31), st.lists(st.tuples(st.sampled_from(["length", "time", "flip", "cut", "insert"]),
                                                   st.integers(0, 2 ** 32 - 1)), max_size=4))
def test_stream_records(packets, tmp_path_factory, seed, damage):
    """A recorded stream with its record lengths, times and bytes damaged: read and parsed to the
    end, or refused with a sentence, in well under a second; never another exception."""
    from radarcl.config import sensors
    from radarcl.io.stream import RECORD, read_stream
    from radarcl.livemap import Session

    rng = np.random.default_rng(seed)
    raw = bytearray(stream_bytes([(1_700_000_000 * 10 ** 9 + i, p) for i, p in enumerate(packets)]))
    start_of_records = raw.index(b"\n", 10) + 1
    for what, value in damage:
        at = start_of_records + (value % max(1, len(raw) - start_of_records))
        if what == "length":
            at = start_of_records + (value % len(packets)) * (RECORD.size + len(packets[0]))
            raw[at + 8:at + 12] = np.uint32(value).tobytes()
        elif what == "time":
            raw[at:at + 8] = np.uint64(value * 2 ** 31).tobytes()[:len(raw[at:at + 8])]
        elif what == "flip" and at < len(raw):
            raw[at] ^= 1 << int(rng.integers(0, 8))
        elif what == "cut":
            del raw[at:]
        else:
            raw[at:at] = rng.integers(0, 256, int(rng.integers(1, 40)), np.uint8).tobytes()
    path = tmp_path_factory.mktemp("s") / "s.rcs"
    path.write_bytes(bytes(raw))
    COUNTS["stream_cases"] += 1
    session = Session(sensors.load("paper"))
    start = time.perf_counter()
    try:
        _, records = read_stream(path)
        for t, data in records:
            session.feed(t, data)
        COUNTS["stream_read"] += 1
    except RadarclError as exc:
        assert str(exc)
        COUNTS["stream_refused"] += 1
    except Exception as exc:                                   # noqa: BLE001 - the point of the test
        COUNTS["other_exceptions"] += 1
        raise AssertionError(f"{type(exc).__name__} instead of a radarcl error: {exc}") from exc
    COUNTS["slow"] += time.perf_counter() - start > 1.0
    c = session.counters
    assert c.bytes_in == c.bytes_in_packets + c.bytes_dropped + c.bytes_pending
    assert len(session.drain(wait=0)) <= len(packets)
    assert COUNTS["slow"] == 0


@settings(max_examples=8 if LONG else 2, deadline=None, derandomize=not LONG,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.integers(0, 2 ** 31))
def test_damaged_streams_replay_to_a_saved_map_or_a_sentence(runtime, packets, tmp_path_factory, seed):
    """The whole replay (parser, mapper, save) on a damaged recording: a map of at most the beams
    sent, or a sentence; the replay's threads never end in a traceback."""
    import threading

    from radarcl.config import mapconfig
    from radarcl.jobs import live
    from radarcl.livemap import LiveMapper
    from radarcl.maps.disk import MapSaver

    rng = np.random.default_rng(seed)
    raw = bytearray(stream_bytes([(i, p) for i, p in enumerate(packets)]))
    for _ in range(3):
        i = int(rng.integers(10, len(raw)))
        raw[i] ^= 1 << int(rng.integers(0, 8))
    path = tmp_path_factory.mktemp("r") / "s.rcs"
    path.write_bytes(bytes(raw))
    config = mapconfig.resolve("paper", program={"grid.voxel_m": 2.0})
    out = path.with_suffix(".npz")
    crashed = []
    previous = threading.excepthook
    threading.excepthook = lambda a: crashed.append(a.exc_value)
    try:
        _, s, _ = live.replay(path, lambda h: (config.sensor, LiveMapper(runtime, config, MapSaver(out))))
        assert s["beams"] <= len(packets) and (out.exists() or s["beams"] == 0)
    except RadarclError as exc:
        assert str(exc)
    finally:
        threading.excepthook = previous
    assert not crashed, crashed
