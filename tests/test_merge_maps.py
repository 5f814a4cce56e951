"""The fleet's merge (``jobs.merge_maps``): partial map stores summed as a Dask reduction
partitioned by brick key, the merged store's chunks written by the workers, give file for file
the store of the one-process merge on 1, 2 and 3 workers; maps on another lattice are refused
before any work; a failed worker leaves nothing behind and the output as it was."""

import json
import os
from pathlib import Path

import numpy as np
import pytest
from dask.distributed import Client, LocalCluster

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.gridspec import GridSpec
from radarcl.jobs import merge_maps
from radarcl.maps import npz, store

PLANAR = GridSpec((0.0, 0.0, 0.0), 0.5, (400, 400, 8), 1)
CUBIC = GridSpec((0.0, 0.0, 0.0), 0.5, (400, 400, 8), 8)


def synthetic_maps(root, spec, inputs=4, bricks=1500, seed=1):
    """``inputs`` map stores of ``bricks`` random bricks each, drawn from one pool of keys (so
    they overlap), stored in shuffled order; some values near saturation (sums clamp)."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(50), np.arange(50), indexing="ij")
    pool = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size, int)], 1).astype(np.int32)
    paths, parts = [], []
    for i in range(inputs):
        keys = pool[rng.choice(len(pool), bricks, replace=False)]
        data = rng.integers(-100, 100, (bricks, *spec.brick_data_shape)).astype(np.int32)
        data[:20] = 2 ** 29 + 7 * i                # four of these sum beyond +2^30
        paths.append(Path(root) / f"part{i}.rcmap")
        store.StoreWriter(paths[-1], spec).save(keys, data)
        parts.append((keys, data))
    return paths, parts


def files_of(path):
    return {p.relative_to(path).as_posix(): p.read_bytes() for p in Path(path).rglob("*") if p.is_file()}


def untimed(manifest):
    """A manifest's entries but when it was written (and the seal over that)."""
    m = json.loads(manifest)
    m["provenance"].pop("created")
    return {k: v for k, v in m.items() if k not in ("saved", "crc32")}


@pytest.fixture(scope="module")
def clusters():
    made = {}
    for n in (1, 2, 3):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=False, dashboard_address=None)
        made[n] = (cluster, Client(cluster))
    yield {n: client for n, (_, client) in made.items()}
    for cluster, client in made.values():
        client.close()
        cluster.close()


def test_partitioned_merge_is_the_one_process_store_file_for_file(clusters, tmp_path):
    paths, parts = synthetic_maps(tmp_path, PLANAR)
    keys, data = merge_maps.merge(parts)
    assert (data == 2 ** 30).any(), "no brick saturated: the clamp is not exercised"
    reference = tmp_path / "one_process.rcmap"
    store.StoreWriter(reference, PLANAR).save(keys, data)
    want = files_of(reference)
    for workers, client in clusters.items():
        out = tmp_path / f"merged{workers}.rcmap"
        result = merge_maps.merge_stores(client, paths[::-1] if workers == 2 else paths, out)
        assert result["partitions"] >= 3 * workers and len(result["workers_used"]) == workers
        spec, got_keys, got_data, manifest = store.read(out)              # verifies every CRC
        assert spec == PLANAR and manifest["lost"] == [] and manifest["format_version"] == 3
        assert np.array_equal(got_keys, keys) and np.array_equal(got_data, data)
        got = files_of(out)
        assert got.keys() == want.keys()
        assert {k for k in want if got[k] != want[k]} <= {"manifest.json"}, f"{workers} workers wrote other files"
        assert untimed(got["manifest.json"]) == untimed(want["manifest.json"])


def test_npz_output_and_cubic_bricks(clusters, tmp_path):
    paths, parts = synthetic_maps(tmp_path, CUBIC, inputs=3, bricks=600, seed=2)
    keys, data = merge_maps.merge(parts)
    out = tmp_path / "merged.npz"
    merge_maps.merge_stores(clusters[3], paths, out)
    spec, got_keys, got_data = npz.read(out)
    assert spec == CUBIC and np.array_equal(got_keys, keys) and np.array_equal(got_data, data)


def test_merge_sums_exactly_and_saturates():
    k = np.array([[0, 0, 0], [1, 0, 0]], np.int32)
    a = np.full((2, 8, 8, 8), 2 ** 29 + 1, np.int32)
    keys, data = merge_maps.merge([(k, a), (k[:1], a[:1]), (np.array([[2, 0, 0]], np.int32), -a[:1])])
    assert keys.tolist() == [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    assert (data[0] == 2 ** 30).all() and (data[1] == 2 ** 29 + 1).all() and (data[2] == -(2 ** 29 + 1)).all()


class NoWork:
    """A client that fails the test if any work is asked of it."""

    def __getattr__(self, name):
        raise AssertionError(f"work started (client.{name}) before the inputs were checked")


@pytest.mark.parametrize("other", [GridSpec((0.0, 0.0, 0.0), 0.5, (400, 400, 8), 8),
                                   GridSpec((0.0, 0.0, 0.0), 0.4, (400, 400, 8), 1)])
def test_a_map_on_another_lattice_is_refused_before_any_work(tmp_path, other):
    paths, _ = synthetic_maps(tmp_path, PLANAR, inputs=2, bricks=50)
    odd = tmp_path / "odd.rcmap"
    store.StoreWriter(odd, other).save(np.zeros((1, 3), np.int32), np.ones((1, *other.brick_data_shape), np.int32))
    out = tmp_path / "m.rcmap"
    with pytest.raises(ConfigError) as err:
        merge_maps.merge_stores(NoWork(), [*paths, odd], out)
    message = str(err.value)
    assert str(odd) in message and str(paths[0]) in message and "another lattice" in message
    assert merge_maps.describe(other) in message and merge_maps.describe(PLANAR) in message
    assert not out.exists()
    with pytest.raises(ConfigError, match="is not a map store"):
        merge_maps.merge_stores(NoWork(), [paths[0], tmp_path], out)


READING = dict(look_limit=4.0, prior_nats=-3.5, prior_looks=0.0, known_looks=0.5)


def knowing_maps(root, spec, inputs=3, bricks=700, seed=3, reading=READING):
    """Map stores of the detection-statistics model: sums, knowledge and looks per brick, some
    knowledge near saturation (it clamps at [0, 2^30])."""
    rng = np.random.default_rng(seed)
    paths, parts = [], []
    for i in range(inputs):
        keys = np.unique(np.stack([rng.choice(50, bricks), np.arange(bricks) % 50, np.zeros(bricks, int)], 1)
                         .astype(np.int32), axis=0)            # overlapping across inputs
        n = len(keys)
        data = rng.integers(-100, 100, (n, *spec.brick_data_shape)).astype(np.int32)
        knowledge = rng.integers(0, 5000, (n, *spec.brick_data_shape)).astype(np.int32)
        knowledge[:10] = 2 ** 29 + 11 * i          # these sum beyond 2^30
        looks = rng.integers(0, 3, (n, *spec.brick_data_shape)).astype(np.int32)
        paths.append(Path(root) / f"k{i}.rcmap")
        store.StoreWriter(paths[-1], spec, reading=reading).save(keys, data, knowledge=knowledge, looks=looks)
        parts.append((keys, np.stack([data, knowledge, looks], axis=1)))
    return paths, parts


def test_maps_with_the_knowledge_channel_merge_file_for_file_with_their_reading(clusters, tmp_path):
    """Knowledge and looks are sums too: merged like the sums (clamped at [0, 2^30]), written
    with the inputs' reading, file for file the store one process writes, as .npz too."""
    paths, parts = knowing_maps(tmp_path, PLANAR)
    keys, data = merge_maps.merge(parts, channels=True)
    assert (data[:, 1] == 2 ** 30).any() and (data[:, 1] >= 0).all()
    reference = tmp_path / "one_process.rcmap"
    store.StoreWriter(reference, PLANAR, reading=READING).save(keys, data[:, 0], knowledge=data[:, 1],
                                                               looks=data[:, 2])
    want = files_of(reference)
    for workers in (1, 3):
        out = tmp_path / f"merged{workers}.rcmap"
        merge_maps.merge_stores(clusters[workers], paths, out)
        _, got_keys, got_data, manifest = store.read(out)
        assert manifest["lost"] == [] and manifest["reading"] == READING
        assert np.array_equal(got_keys, keys) and np.array_equal(got_data, data[:, 0])
        assert np.array_equal(manifest["knowledge"], data[:, 1]) and np.array_equal(manifest["looks"], data[:, 2])
        got = files_of(out)
        assert got.keys() == want.keys() and {k for k in want if got[k] != want[k]} <= {"manifest.json"}
        assert untimed(got["manifest.json"]) == untimed(want["manifest.json"])
    merge_maps.merge_stores(clusters[2], paths, tmp_path / "m.npz")
    spec, got_keys, got_data, channels = npz.read_channels(tmp_path / "m.npz")
    assert spec == PLANAR and np.array_equal(got_keys, keys) and np.array_equal(got_data, data[:, 0])
    assert np.array_equal(channels.knowledge, data[:, 1]) and np.array_equal(channels.looks, data[:, 2])
    assert channels.reading == READING


def test_maps_of_two_readings_or_models_are_refused_before_any_work(tmp_path):
    """A map with the knowledge channel beside one without, or two readings: the sums mean
    different things, so the merge refuses, naming both inputs, before a worker is asked."""
    paths, _ = synthetic_maps(tmp_path, PLANAR, inputs=2, bricks=50)
    knowing, _ = knowing_maps(tmp_path / "a", PLANAR, inputs=1, bricks=20)
    other, _ = knowing_maps(tmp_path / "b", PLANAR, inputs=1, bricks=20, reading=dict(READING, prior_nats=-2.0))
    out = tmp_path / "m.rcmap"
    with pytest.raises(ConfigError, match=f"{knowing[0]} holds a map with the reading .*, {paths[0]} one with no "
                                          "knowledge channel"):
        merge_maps.merge_stores(NoWork(), [*paths, *knowing], out)
    with pytest.raises(ConfigError, match="merge only with one sensor model and one reading"):
        merge_maps.merge_stores(NoWork(), [*knowing, *other], out)
    assert not out.exists()


def test_a_damaged_chunk_stops_the_merge_and_writes_nothing(clusters, tmp_path):
    paths, _ = synthetic_maps(tmp_path, PLANAR, inputs=3, bricks=800)
    first, second = sorted(p for p in (paths[1] / "segment_0").rglob("*") if p.is_file() and p.name != "zarr.json")[:2]
    a, b = first.read_bytes(), second.read_bytes()
    first.write_bytes(b)                # two chunks swapped: each decodes, the index is intact,
    second.write_bytes(a)               # only a worker's CRC-32 of what it read can find it
    out = tmp_path / "m.rcmap"
    with pytest.raises(FrameFormatError, match=f"{paths[1]}.*chunk 0 does not match its checksum"):
        merge_maps.merge_stores(clusters[2], paths, out)
    assert not out.exists() and not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_a_failed_worker_leaves_the_output_as_it_was(clusters, tmp_path, monkeypatch):
    paths, _ = synthetic_maps(tmp_path, PLANAR, inputs=2, bricks=600)
    out = tmp_path / "m.rcmap"
    merge_maps.merge_stores(clusters[1], paths[:1], out)      # an earlier map there (the caller's --force)
    before = files_of(out)

    def full(target, row0, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(merge_maps, "write_rows", full)       # the workers are threads of this process
    with pytest.raises(ConfigError, match="the merge failed on a worker .*No space left on device.*nothing was written"):
        merge_maps.merge_stores(clusters[3], paths, out)
    assert files_of(out) == before and not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]
