"""The map store believes nothing it reads: each damage the hostile corpus found is
refused with what is wrong, or read with --salvage that lists exactly the bricks lost; never
uninitialised memory; only radarcl's own directories are replaced; poses survive convert."""

import json
import shutil

import numpy as np
import pytest
import zarr

from radarcl.cli import main
from radarcl.errors import FrameFormatError
from radarcl.gridspec import GridSpec, assemble
from radarcl.maps import disk, store
from radarcl.maps.map import Map

SPEC = GridSpec((-2.0, -3.0, -1.0), 0.25, (80, 64, 40))         # 10 x 8 x 5 bricks


def bricks(n=700, seed=0):
    """``n`` distinct bricks (more than two chunks of 256) of non-zero values."""
    rng = np.random.default_rng(seed)
    grid = np.array([(x, y, z) for x in range(10) for y in range(8) for z in range(5)], np.int32)
    keys = grid[np.sort(rng.choice(len(grid), min(n, len(grid)), replace=False))]
    data = rng.integers(1, 4000, (len(keys), 8, 8, 8)).astype(np.int32)
    return keys, data


@pytest.fixture
def saved(tmp_path):
    keys, data = bricks(400)
    path = tmp_path / "m.rcmap"
    store.StoreWriter(path, SPEC).save(keys, data)
    return path, keys, data


def edit(path, fn, sealed=False):
    """``fn(group, manifest)`` on the store; the manifest is written back, its checksum left as it
    was (damage, or a hand edit) or made to match (``sealed``: a writer with a bug, which only
    the structural checks can catch)."""
    group = zarr.open_group(str(path), mode="a")
    manifest = json.loads((path / "manifest.json").read_text())
    fn(group, manifest)
    if sealed:
        manifest["crc32"] = store.seal(manifest)
    (path / "manifest.json").write_text(json.dumps(manifest))


def rewrite(group, name, array):
    del group[name]
    group.create_array(name, data=array, chunks=(256,) + array.shape[1:])


def chunk_file(path, segment=0, chunk=1):
    return path / f"segment_{segment}" / "c" / str(chunk) / "0" / "0" / "0"


CHECKSUM = "manifest.json does not match its checksum"
DAMAGE = {
    "a deleted chunk": (lambda p: chunk_file(p).unlink(), "segment_0 chunk 1 does not match its checksum"),
    "segments []": (lambda p: edit(p, lambda g, m: m.update(segments=[])), CHECKSUM),
    "segments [] by a writer": (lambda p: edit(p, lambda g, m: m.update(segments=[]), sealed=True),
                                "a segment the manifest does not list"),
    "a duplicate key": (lambda p: edit(p, lambda g, m: _index(g, m, lambda a: a.__setitem__((1, slice(0, 3)), a[0, :3]),
                                                              crc=True), sealed=True), "a key listed more than once"),
    "a key outside the grid": (lambda p: edit(p, lambda g, m: _index(g, m, lambda a: a.__setitem__((0, 0), 10000),
                                                                     crc=True), sealed=True), "a key outside the grid"),
    "a negative key": (lambda p: edit(p, lambda g, m: _index(g, m, lambda a: a.__setitem__((0, 1), -3), crc=True),
                                      sealed=True), "a key outside the grid"),
    "an unlisted segment": (lambda p: edit(p, lambda g, m: _index(g, m, lambda a: a.__setitem__((5, 3), 7), crc=True),
                                           sealed=True), "a segment the manifest does not list"),
    "saturated values": (lambda p: edit(p, lambda g, m: _segment(g, m, lambda a: a.__setitem__((3, 0, 0, 0), 2**31 - 1),
                                                                 crc=True), sealed=True), "beyond the grid's saturation"),
    "a float32 segment": (lambda p: edit(p, lambda g, m: rewrite(g, "segment_0", g["segment_0"][:].astype("float32"))),
                          r"float32, not \(n, 8, 8, 8\) int32 bricks"),
    "a shape smaller than the index": (lambda p: edit(p, lambda g, m: m["grid"].update(shape=[8, 8, 8])), CHECKSUM),
    "a shape smaller than the index, by a writer": (lambda p: edit(p, lambda g, m: m["grid"].update(shape=[8, 8, 8]),
                                                                  sealed=True), "a key outside the grid"),
    "a grid moved": (lambda p: edit(p, lambda g, m: m["grid"].update(origin_m=[8, 8, 8])), CHECKSUM),
    "a zeroed chunk": (lambda p: edit(p, lambda g, m: _segment(g, m, lambda a: a.__setitem__(slice(256, 400), 0))),
                       "segment_0 chunk 1 does not match its checksum"),
    "an index that lies about its rows": (lambda p: edit(p, lambda g, m: _index(g, m, lambda a: a.__setitem__((5, 4), 9999))),
                                          "does not match its checksum"),
    "the manifest's brick count": (lambda p: edit(p, lambda g, m: m.update(bricks=5)), CHECKSUM),
    "the brick count, by a writer": (lambda p: edit(p, lambda g, m: m.update(bricks=5), sealed=True),
                                     "lists 400 bricks, the manifest 5"),
    "a missing segment": (lambda p: shutil.rmtree(p / "segment_0"), "segment_0 is missing"),
}


def _index(group, manifest, change, crc=False):
    a = group[manifest["index"]][:]
    change(a)
    rewrite(group, manifest["index"], a)
    if crc:                      # a store whose index was rewritten with a matching checksum: a writer's bug
        manifest["checksums"]["index"] = int(__import__("zlib").crc32(np.ascontiguousarray(a, "<i4")))


def _segment(group, manifest, change, crc=False):
    a = group["segment_0"][:]
    change(a)
    group["segment_0"][:] = a
    if crc:
        manifest["checksums"]["segments"]["0"]["crc32"] = store.chunk_crcs(a)


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_damage_is_refused_with_what_is_wrong(saved, damage):
    path, keys, data = saved
    hurt, says = DAMAGE[damage]
    hurt(path)
    with pytest.raises(FrameFormatError, match=says):
        disk.read(path)


def test_salvage_reads_the_rest_and_lists_exactly_the_lost_bricks(saved, capsys, tmp_path):
    path, keys, data = saved
    chunk_file(path).unlink()                                   # bricks 256..399 of segment 0
    spec, k, d, lost = disk.read_salvaged(path)
    assert len(k) == 256 and np.array_equal(k, keys[:256]) and np.array_equal(d, data[:256])
    assert sorted(map(tuple, lost[0]["keys"])) == sorted(map(tuple, keys[256:].tolist()))
    out = tmp_path / "salvaged.npz"
    assert main(["convert", str(path), str(out)]) == 2
    assert "144 of 400 bricks cannot be read" in capsys.readouterr().err and not out.exists()
    assert main(["convert", str(path), str(out), "--salvage"]) == 0
    err = capsys.readouterr().err
    assert "lost 144 brick(s)" in err and all(f"({x},{y},{z})" in err for x, y, z in keys[256:].tolist())
    assert np.array_equal(assemble(*disk.read(out)), assemble(SPEC, keys[:256], data[:256]))
    m = Map.open(path, salvage=True)
    assert len(m.keys) == 256 and sum(len(e["keys"]) for e in m.lost) == 144


def test_no_segment_reads_as_no_bricks_never_as_heap_memory(tmp_path):
    keys, data = bricks(3)
    path = tmp_path / "m.rcmap"
    store.StoreWriter(path, SPEC).save(keys, np.full_like(data, 1000))
    edit(path, lambda g, m: m.update(segments=[]), sealed=True)
    with pytest.raises(FrameFormatError, match="3 of 3 bricks cannot be read"):
        disk.read(path)
    _, k, d, lost = disk.read_salvaged(path)
    assert len(k) == 0 and d.shape == (0, 8, 8, 8) and len(lost[0]["keys"]) == 3


def test_a_bare_zarr_group_is_not_a_store_and_force_never_removes_it(tmp_path, capsys):
    keys, data = bricks(20)
    npz = tmp_path / "m.npz"
    disk.npz.write(npz, SPEC, keys, data)
    other = tmp_path / "theirs"
    other.mkdir()
    (other / "zarr.json").write_text('{"zarr_format": 3, "node_type": "group", "attributes": {}}')
    (other / "NOTES.txt").write_text("another program's data")
    assert not store.recognises(other)
    assert main(["convert", str(npz), str(other), "--force"]) == 2
    assert "not a map store" in capsys.readouterr().err and (other / "NOTES.txt").exists()
    with pytest.raises(FrameFormatError, match="not a radarcl map store"):
        disk.read(other)
    ours = tmp_path / "ours.rcmap"                            # our own: replaced with --force
    assert main(["convert", str(npz), str(ours)]) == 0 and store.recognises(ours)
    assert main(["convert", str(npz), str(ours), "--force"]) == 0


def test_convert_keeps_the_poses_both_ways(tmp_path):
    keys, data = bricks(20)
    poses = np.stack([np.eye(4)] * 3)
    poses[:, 0, 3] = [1.0, 2.0, 3.0]
    npz = tmp_path / "m.npz"
    disk.npz.write(npz, SPEC, keys, data, poses=poses, meta=dict(sensor='name = "x"', config={"grid.voxel_m": 0.25}))
    assert main(["convert", str(npz), str(tmp_path / "m.rcmap")]) == 0
    assert np.array_equal(disk.read_poses(tmp_path / "m.rcmap"), poses)
    assert disk.read_meta(tmp_path / "m.rcmap", "sensor") == 'name = "x"'
    assert main(["convert", str(tmp_path / "m.rcmap"), str(tmp_path / "back.npz")]) == 0
    assert np.array_equal(disk.read_poses(tmp_path / "back.npz"), poses)
    assert disk.read_meta(tmp_path / "back.npz", "config") == {"grid.voxel_m": 0.25}


def test_format_1_stores_are_still_read_and_continued(saved):
    """A store of format 1 (no checksums) is read with every structural check, and the next
    save rewrites it whole, with checksums."""
    path, keys, data = saved
    manifest = json.loads((path / "manifest.json").read_text())
    manifest.pop("checksums")
    manifest.pop("crc32")
    manifest["format_version"] = 1
    (path / "manifest.json").write_text(json.dumps(manifest))
    assert np.array_equal(assemble(*disk.read(path)), assemble(SPEC, keys, data))
    w = store.StoreWriter(path, SPEC)
    assert w.save(keys, data) == len(keys)                     # everything, into one checked segment
    assert store.read_manifest(path)["format_version"] == store.PLAIN_FORMAT == 2   # a cubic map: every reader since 2 reads it
    assert np.array_equal(assemble(*disk.read(path)), assemble(SPEC, keys, data))


def test_a_newer_store_names_both_versions(saved):
    path, _, _ = saved
    edit(path, lambda g, m: m.update(format_version=store.FORMAT_VERSION + 1))
    with pytest.raises(FrameFormatError, match=f"written in store format {store.FORMAT_VERSION + 1}; this radarcl "
                                               f"reads formats 1 to {store.FORMAT_VERSION}"):
        disk.read(path)


def test_the_group_metadata_is_not_needed(saved):
    """zarr.json of the group holds nothing the manifest does not: reading without it is exact."""
    path, keys, data = saved
    (path / "zarr.json").unlink()
    assert np.array_equal(assemble(*disk.read(path)), assemble(SPEC, keys, data))
