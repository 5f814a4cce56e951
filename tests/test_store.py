"""The map store: round trips, incremental saves, atomic for readers against a killed writer,
newer formats refused, conversion to and from .npz, and the point-query API."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.errors import ConfigError, FrameFormatError
from radarcl.gridspec import GridSpec, assemble
from radarcl.maps import store
from radarcl.maps.disk import read
from radarcl.maps.map import UNKNOWN, Map

SPEC = GridSpec((-2.0, -3.0, -1.0), 0.25, (40, 30, 20))


def random_map(seed=0, n=20):
    rng = np.random.default_rng(seed)
    all_keys = np.array([(x, y, z) for x in range(5) for y in range(4) for z in range(3)], np.int32)
    keys = all_keys[rng.choice(len(all_keys), n, replace=False)]
    return keys, rng.integers(-4000, 4000, (n, 8, 8, 8)).astype(np.int32)


def same(spec, keys, data, keys2, data2):
    return np.array_equal(assemble(spec, keys, data), assemble(spec, keys2, data2))


def test_round_trip_and_incremental_saves(tmp_path):
    keys, data = random_map()
    path = tmp_path / "m.rcmap"
    w = store.StoreWriter(path, SPEC, sensor_toml='name = "x"', config={"grid.voxel_m": 0.25}, inputs=[__file__])
    assert w.save(keys, data) == len(keys)
    spec, k, d = read(path)
    assert spec == SPEC and same(SPEC, keys, data, k, d)
    changed = data.copy()
    changed[3, 1, 2, 3] += 7                                       # one brick changes
    grown_keys = np.concatenate([keys, [[4, 3, 2]]]).astype(np.int32)
    grown = np.concatenate([changed, np.full((1, 8, 8, 8), 9, np.int32)])
    assert w.save(grown_keys, grown) == 2                          # the changed brick and the new one
    assert w.save(grown_keys, grown) == 0
    spec, k, d = read(path)
    assert same(SPEC, grown_keys, grown, k, d)
    manifest = store.read_manifest(path)
    assert manifest["version"] == 3 and manifest["provenance"]["inputs"][0]["sha256"]
    assert manifest["sensor"] == 'name = "x"' and manifest["config"] == {"grid.voxel_m": 0.25}
    # continued by a new writer, and compacted when segments pile up
    w2 = store.StoreWriter(path, SPEC)
    for i in range(store.COMPACT_SEGMENTS + 2):
        grown[0, 0, 0, 0] = i
        w2.save(grown_keys, grown)
    assert len(store.read_manifest(path)["segments"]) <= store.COMPACT_SEGMENTS
    assert same(SPEC, grown_keys, grown, *read(path)[1:])
    assert len([p for p in path.iterdir() if p.name.startswith("segment_")]) <= store.COMPACT_SEGMENTS + 1
    with pytest.raises(ConfigError, match="holds a map of grid"):
        store.StoreWriter(path, GridSpec((0.0, 0.0, 0.0), 0.25, (40, 30, 20)))


def test_newer_or_foreign_stores_are_refused(tmp_path):
    keys, data = random_map()
    path = tmp_path / "m.rcmap"
    store.StoreWriter(path, SPEC).save(keys, data)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["format_version"] = 99
    (path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(FrameFormatError, match="written in store format 99; this radarcl reads formats 1 to 3"):
        read(path)
    (path / "manifest.json").write_text("{ torn")
    with pytest.raises(FrameFormatError, match="manifest.json is not readable"):
        read(path)
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("x")
    with pytest.raises(ConfigError, match="a directory that is not a map store"):
        store.StoreWriter(other, SPEC)


WRITER = """
import sys, numpy as np
from radarcl.maps import store
from radarcl.gridspec import GridSpec
spec = GridSpec((-2.0, -3.0, -1.0), 0.25, (160, 120, 80))
rng = np.random.default_rng(0)
keys = np.array([(x, y, z) for x in range(20) for y in range(15) for z in range(10)], np.int32)
data = rng.integers(-4000, 4000, (len(keys), 8, 8, 8)).astype(np.int32)
w = store.StoreWriter(sys.argv[1], spec)
for version in range(1, 10 ** 6):
    data[:, 0, 0, 0] = version          # every brick changes: every save is a full one
    w.save(keys, data)
    print(version, flush=True)
"""


def test_a_killed_writer_never_leaves_a_mixed_map(tmp_path):
    """A writer saving 3,000 bricks over and over, killed with SIGKILL at random moments: the
    store always reads as one complete version (every brick carries the same version number),
    says what the killed save left behind, and the next writer cleans it up."""
    path = tmp_path / "m.rcmap"
    rng = np.random.default_rng(1)
    for trial in range(4):
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline().strip() == "1"                 # one save has landed
        time.sleep(float(rng.uniform(0.05, 0.6)))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        spec, keys, data, manifest = store.read(path)
        versions = np.unique(data[:, 0, 0, 0])
        assert len(versions) == 1 and len(keys) == 3000, f"a mixed map: versions {versions}"
        if trial % 2:                                                 # a new writer continues, cleaning up
            store.StoreWriter(path, spec).save(keys, data)
            assert not store.read(path)[3]["incomplete"] and not list(path.glob(".manifest.json.*.tmp"))


def test_convert_between_npz_and_store(tmp_path, capsys):
    keys, data = random_map(2)
    npz = tmp_path / "m.npz"
    with open(npz, "wb") as f:
        np.savez_compressed(f, version=1, origin_m=np.asarray(SPEC.origin_m), voxel_m=SPEC.voxel_m,
                            shape=np.asarray(SPEC.shape), keys=keys, data=data)
    assert main(["convert", str(npz), str(tmp_path / "m.rcmap")]) == 0
    assert main(["convert", str(tmp_path / "m.rcmap"), str(tmp_path / "back.npz")]) == 0
    assert same(SPEC, keys, data, *read(tmp_path / "back.npz")[1:])
    assert main(["convert", str(npz), str(tmp_path / "m.rcmap")]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    (tmp_path / "plain").mkdir()
    (tmp_path / "plain" / "x").write_text("x")
    assert main(["convert", str(npz), str(tmp_path / "plain"), "--force"]) == 2
    assert "a directory that is not a map store" in capsys.readouterr().err



def test_a_map_format_added_to_the_table_alone_is_written_and_read_everywhere(tmp_path, capsys, monkeypatch):
    """A toy map format (a JSON file, ``.jmap``) registered in ``disk.FORMATS`` and nowhere else:
    ``radarcl convert`` writes it (by the name) and reads it back into a store, ``Map.open`` and
    ``radarcl export`` read it, and the built-in formats keep their files."""
    from pathlib import Path

    from radarcl.maps import disk

    monkeypatch.setattr(disk, "FORMATS", dict(disk.FORMATS))

    def recognises(path):
        return Path(path).is_file() and Path(path).suffix == ".jmap"

    def read_json(path, salvage):
        j = json.loads(Path(path).read_text())
        return (GridSpec(*j["spec"]), np.array(j["keys"], np.int32).reshape(-1, 3),
                np.array(j["data"], np.int32).reshape(-1, 8, 8, 8), [], None)

    def writer(path, spec, sensor_toml="", config=None, inputs=(), reading=None):
        def save(keys, data, poses=None, channels=None, meta=None):
            Path(path).write_text(json.dumps(dict(spec=[list(spec.origin_m), spec.voxel_m, list(spec.shape)],
                                                  keys=np.asarray(keys).tolist(), data=np.asarray(data).tolist(),
                                                  sensor=sensor_toml)))
        return save

    disk.register(disk.MapFormat("json", (".jmap",), recognises, read_json, lambda path: None,
                                 lambda path, key: json.loads(Path(path).read_text()).get(key), Path, writer), first=True)
    keys, data = random_map(3)
    npz = tmp_path / "m.npz"
    disk.npz.write(npz, SPEC, keys, data, meta=dict(sensor='name = "x"'))
    assert main(["convert", str(npz), str(tmp_path / "m.jmap")]) == 0
    assert f"wrote {tmp_path / 'm.jmap'}: {len(keys)} bricks" in capsys.readouterr().out
    assert disk.format_of(tmp_path / "m.jmap") == "json" and disk.format_of(npz) == "npz"
    assert same(SPEC, keys, data, *read(tmp_path / "m.jmap")[1:])
    assert main(["convert", str(tmp_path / "m.jmap"), str(tmp_path / "back.rcmap")]) == 0
    assert disk.format_of(tmp_path / "back.rcmap") == "store" and same(SPEC, keys, data, *read(tmp_path / "back.rcmap")[1:])
    assert disk.read_meta(tmp_path / "back.rcmap", "sensor") == 'name = "x"'
    assert Map.open(tmp_path / "m.jmap").counts() == Map.open(npz).counts()
    assert main(["export", str(tmp_path / "m.jmap"), "--to", "vti", "--out", str(tmp_path / "m.vti")]) == 0
    assert "vti:" in capsys.readouterr().out
    with pytest.raises(ConfigError, match="registered already"):
        disk.register(disk.FORMATS["json"])

def test_point_queries_agree_with_the_dense_map(tmp_path):
    keys, data = random_map(3)
    m = Map(SPEC, keys, data)
    dense = assemble(SPEC, keys, data)
    rng = np.random.default_rng(4)
    idx = np.stack([rng.integers(0, n, 500) for n in SPEC.shape], axis=1)
    points = SPEC.index_to_world(idx) + rng.uniform(-0.12, 0.12, (500, 3))     # anywhere inside the voxel
    assert np.array_equal(m.units_at(points), dense[idx[:, 2], idx[:, 1], idx[:, 0]])
    assert np.allclose(m.log_odds_at(points), dense[idx[:, 2], idx[:, 1], idx[:, 0]] / 1024)
    assert np.isnan(m.log_odds_at([[100.0, 0, 0]])).all() and m.units_at(np.zeros((0, 3))).shape == (0,)
    centres, nats = m.occupied(1.0)
    back = SPEC.world_to_index(centres)
    assert np.array_equal(np.sort(dense[dense > 1024]), np.sort(np.rint(nats * 1024).astype(np.int32)))
    assert (dense[back[:, 2], back[:, 1], back[:, 0]] > 1024).all()
    grid = m.projection((-1.0, 4.0), 1.0, -1.0)
    assert grid.shape == (30, 40) and set(np.unique(grid)) <= {0, 100, UNKNOWN}
    col = dense.max(axis=0) > 1024
    assert np.array_equal(grid == 100, col)
    assert np.array_equal(grid == 0, ~col & (dense.min(axis=0) < -1024))
    assert np.allclose(m.slice(0.1), dense[int((0.1 + 1.0) / 0.25)] / 1024)
    with pytest.raises(ConfigError, match="holds no voxel centre"):
        m.projection((50.0, 60.0))
    hi, lo = dense.max(axis=0), dense.min(axis=0)             # unseen voxels are 0
    assert np.array_equal(m.column_extremes(), np.where(hi > 0, hi, lo) / 1024)


# -- the knowledge channel (the detection-statistics model) ---------------------------------------------------------
READING = dict(look_limit=4.0, prior_nats=-2.0, prior_looks=0.5, known_looks=0.5)


def knowledge_map(seed=1):
    keys, data = random_map(seed)
    rng = np.random.default_rng(seed + 100)
    knowledge = rng.integers(0, 20 * 4096, data.shape).astype(np.int32)
    knowledge[0] = 0                                     # a brick never observed: no evidence either
    data[0] = 0
    looks = (knowledge // 2048).astype(np.int32)
    return keys, data, knowledge, looks


def test_knowledge_round_trips_through_npz_store_and_conversion(tmp_path):
    """A version 3 npz and a format 3 store hold the same sums, knowledge and reading, and convert
    into each other; a map without knowledge is still written as npz version 1."""
    from radarcl.maps import npz
    from radarcl.maps.disk import convert, read_channels

    keys, data, knowledge, looks = knowledge_map()
    plain = tmp_path / "plain.npz"
    npz.write(plain, SPEC, keys, data)
    with np.load(plain) as f:
        assert int(f["version"]) == 1 and "knowledge" not in f.files
    assert read_channels(plain)[3] is None
    path = tmp_path / "k.npz"
    npz.write(path, SPEC, keys, data, channels=npz.Channels(knowledge, looks, READING))
    spec, k, d, ch = read_channels(path)
    assert spec == SPEC and np.array_equal(d, data) and np.array_equal(ch.knowledge, knowledge) and ch.reading == READING
    assert np.array_equal(ch.looks, looks)
    target = tmp_path / "k.rcmap"
    convert(path, target)
    assert store.read_manifest(target)["format_version"] == store.KNOWLEDGE_FORMAT
    back = tmp_path / "back.npz"
    convert(target, back)
    _, k2, d2, ch2 = read_channels(back)
    assert same(SPEC, keys, data, k2, d2) and same(SPEC, keys, knowledge, k2, ch2.knowledge) and ch2.reading == READING
    assert same(SPEC, keys, looks, k2, ch2.looks)
    w = store.StoreWriter(target, SPEC, reading=READING)          # continued: a second save writes what changed
    knowledge[3, 0, 0, 0] += 4096
    assert w.save(keys, data, knowledge=knowledge, looks=looks) == 1
    assert same(SPEC, keys, knowledge, *read_channels(target)[1:2], read_channels(target)[3].knowledge)
    with pytest.raises(ConfigError, match="holds a map with the knowledge channel"):
        store.StoreWriter(target, SPEC)


def test_damaged_knowledge_is_refused(tmp_path):
    from radarcl.maps import npz

    keys, data, knowledge, looks = knowledge_map()
    path = tmp_path / "k.npz"
    npz.write(path, SPEC, keys, data, channels=npz.Channels(knowledge, looks, READING))
    with np.load(path) as f:
        members = {name: f[name] for name in f.files}
    for change, message in ((dict(knowledge=-knowledge - 1), "knowledge must be int32 in"),
                            (dict(reading=np.str_('{"look_limit": 0, "prior_nats": 0, "prior_looks": 1}')),
                             "reading look_limit = 0 is not a positive number"),
                            (dict(knowledge=knowledge[:3]), "knowledge bricks .* do not match")):
        bad = tmp_path / "bad.npz"
        np.savez(bad, **{**members, **change})
        with pytest.raises(FrameFormatError, match=message):
            Map.open(bad)


def test_a_stores_knowledge_is_checked_like_its_sums(tmp_path):
    """The knowledge and looks arrays of a format 3 store carry their own chunk checksums: a
    zeroed knowledge chunk is refused naming the array, and --salvage lists the bricks it lost;
    a manifest without the knowledge checksums is refused."""
    import json

    import zarr

    keys, data, knowledge, looks = knowledge_map()
    path = tmp_path / "k.rcmap"
    store.StoreWriter(path, SPEC, reading=READING).save(keys, data, knowledge=knowledge, looks=looks)
    stored = zarr.open_array(str(path / "knowledge_0"), mode="a")
    stored[1] = stored[1] + 1                        # one brick changed after the save
    with pytest.raises(FrameFormatError, match="knowledge_0 chunk 0 does not match its checksum"):
        Map.open(path)
    m = Map.open(path, salvage=True)
    assert len(m.keys) < len(keys) and any("knowledge_0" in e["reason"] for e in m.lost)
    manifest = json.loads((path / "manifest.json").read_text())
    manifest["checksums"].pop("looks")
    manifest["crc32"] = store.seal(manifest)
    (path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(FrameFormatError, match="looks 0 has no checksum entry"):
        Map.open(path)


def test_map_queries_read_through_the_knowledge_channel(tmp_path):
    """log_odds_at applies the reading; a voxel never observed is UNKNOWN and reads 0 whatever
    the prior; knowledge_at is in looks; a map without knowledge refuses knowledge queries."""
    from radarcl.maps import npz
    from radarcl.maps.map import FREE, OCCUPIED, UNDECIDED
    from radarcl.sensor_model import read_log_odds

    keys, data, knowledge, looks = knowledge_map()
    path = tmp_path / "k.npz"
    npz.write(path, SPEC, keys, data, channels=npz.Channels(knowledge, looks, READING))
    m = Map.open(path)
    assert m.has_knowledge
    rng = np.random.default_rng(3)
    idx = np.concatenate([keys[rng.integers(0, len(keys), 300)] * 8 + rng.integers(0, 8, (300, 3)),
                          keys[:1] * 8 + rng.integers(0, 8, (20, 3))])                # the unobserved brick
    idx = idx[SPEC.contains(idx)]
    points = SPEC.index_to_world(idx)
    dense_e, dense_k, dense_n = (assemble(SPEC, keys, a) for a in (data, knowledge, looks))
    e, k, n = (a[idx[:, 2], idx[:, 1], idx[:, 0]] for a in (dense_e, dense_k, dense_n))
    assert np.allclose(m.log_odds_at(points), read_log_odds(e, k, n, READING))
    assert np.allclose(m.knowledge_at(points), k / 4096)
    state = m.state_at(points)
    nats = read_log_odds(e, k, n, READING)
    assert np.array_equal(state == UNKNOWN, k < 0.5 * 4096)
    assert (state[(k >= 2048) & (nats > 1)] == OCCUPIED).all() and (state[(k >= 2048) & (nats < -1)] == FREE).all()
    assert (state[(k >= 2048) & (np.abs(nats) <= 1)] == UNDECIDED).all()
    unseen = points[-1:] if dense_k[idx[-1, 2], idx[-1, 1], idx[-1, 0]] == 0 else None
    assert unseen is not None and m.log_odds_at(unseen)[0] == 0.0 and m.state_at(unseen)[0] == UNKNOWN
    assert np.isnan(m.log_odds_at([[1e3, 0, 0]]))[0] and m.state_at([[1e3, 0, 0]])[0] == UNKNOWN
    idx_all, units, looks = m.voxels(with_knowledge=True)
    assert (looks >= 0.5).all() and len(idx_all) == int((dense_k >= 2048).sum())
    keys2, data2 = random_map()
    plain = Map(SPEC, keys2, data2)
    with pytest.raises(ConfigError, match="has no knowledge channel"):
        plain.knowledge_at(points)
