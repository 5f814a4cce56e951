"""Planar bricks (8 x 8 x 1, a spinning radar's one-voxel-thick maps) everywhere a map goes: the
files (npz and the map store record the brick depth; an older reader refuses them naming both
versions), the queries, the exports and the viewer give what the same voxels in 8^3 bricks give."""

import numpy as np
import pytest
from radarcl.viewer import volume

from radarcl.errors import FrameFormatError
from radarcl.gridspec import GridSpec, assemble, rebrick
from radarcl.maps import disk, exports, npz, store
from radarcl.maps.map import Map

PLANAR = GridSpec((-2.0, -3.0, -0.125), 0.25, (40, 30, 1), brick_z=1)
THICK = GridSpec((-2.0, -3.0, -1.0), 0.25, (40, 30, 11), brick_z=1)


def planar_map(spec, seed=0, n=12):
    rng = np.random.default_rng(seed)
    nbx, nby, nbz = spec.brick_shape
    every = np.array([(x, y, z) for x in range(nbx) for y in range(nby) for z in range(nbz)], np.int32)
    keys = every[rng.choice(len(every), min(n, len(every)), replace=False)]
    data = rng.integers(-4000, 4000, (len(keys), 1, 8, 8)).astype(np.int32)
    data[rng.random(data.shape) < 0.3] = 0                      # unobserved voxels too
    return keys, data


@pytest.mark.parametrize("spec", [PLANAR, THICK], ids=["one voxel thick", "11 layers"])
def test_rebrick_keeps_every_voxel(spec):
    keys, data = planar_map(spec, n=40)
    cubic, k8, d8 = rebrick(spec, keys, data, 8)
    assert cubic.brick_z == 8 and d8.shape[1:] == (8, 8, 8)
    assert np.array_equal(assemble(cubic, k8, d8), assemble(spec, keys, data))
    back, k1, d1 = rebrick(cubic, k8, d8, 1)
    assert back == spec and np.array_equal(assemble(back, k1, d1), assemble(spec, keys, data))


@pytest.mark.parametrize("name", ["m.npz", "m.rcmap"])
def test_files_record_the_brick_depth(tmp_path, name):
    keys, data = planar_map(THICK)
    path = tmp_path / name
    if name.endswith(".npz"):
        npz.write(path, THICK, keys, data)
    else:
        store.StoreWriter(path, THICK).save(keys, data)
    spec, k, d = disk.read(path)
    assert spec == THICK and spec.brick_z == 1 and d.shape[1:] == (1, 8, 8)
    assert np.array_equal(assemble(spec, k, d), assemble(THICK, keys, data))
    # converted both ways, the depth stays
    other = tmp_path / ("c.rcmap" if name.endswith(".npz") else "c.npz")
    disk.convert(path, other)
    assert disk.read(other)[0] == THICK


def test_an_older_reader_refuses_a_planar_map_naming_both_versions(tmp_path, monkeypatch):
    keys, data = planar_map(PLANAR)
    store.StoreWriter(tmp_path / "p.rcmap", PLANAR).save(keys, data)
    npz.write(tmp_path / "p.npz", PLANAR, keys, data)
    cubic_keys = np.zeros((1, 3), np.int32)
    store.StoreWriter(tmp_path / "c.rcmap", GridSpec((0.0, 0.0, 0.0), 0.25, (8, 8, 8))).save(
        cubic_keys, np.ones((1, 8, 8, 8), np.int32))
    assert store.read_manifest(tmp_path / "p.rcmap")["format_version"] == store.PLANAR_FORMAT == 3
    assert store.read_manifest(tmp_path / "c.rcmap")["format_version"] == 2     # cubic maps: readable by older radarcl
    monkeypatch.setattr(store, "FORMAT_VERSION", 2)                             # the reader of the previous release
    monkeypatch.setattr(npz, "FILE_VERSION", 1)
    with pytest.raises(FrameFormatError, match="store format 3; this radarcl reads formats 1 to 2"):
        disk.read(tmp_path / "p.rcmap")
    with pytest.raises(FrameFormatError, match="grid file version 2, this radarcl reads versions 1 to 1"):
        disk.read(tmp_path / "p.npz")
    assert disk.read(tmp_path / "c.rcmap")[0].brick_z == 8


@pytest.mark.parametrize("spec", [PLANAR, THICK], ids=["one voxel thick", "11 layers"])
def test_queries_exports_and_the_viewer_read_both_shapes(tmp_path, spec):
    keys, data = planar_map(spec, n=40)
    planar = Map(spec, keys, data)
    cubic = Map(*rebrick(spec, keys, data, 8))
    rng = np.random.default_rng(5)
    lo = np.asarray(spec.origin_m)
    points = lo + rng.random((2000, 3)) * np.asarray(spec.shape) * spec.voxel_m * 1.1 - 0.05
    assert np.array_equal(planar.units_at(points), cubic.units_at(points))
    assert (planar.units_at(points) != 0).sum() > 100, "the points must hit observed voxels"
    for a, b in zip(planar.voxels(), cubic.voxels()):
        order_a, order_b = np.lexsort(planar.voxels()[0].T), np.lexsort(cubic.voxels()[0].T)
        assert np.array_equal(a[order_a], b[order_b])
    assert np.array_equal(planar.dense(), cubic.dense()) and np.array_equal(planar.dense(), assemble(spec, keys, data))
    assert np.array_equal(planar.projection(), cubic.projection())
    assert np.array_equal(planar.column_extremes(), cubic.column_extremes())
    assert planar.counts() == cubic.counts()
    for m, name in ((planar, "p"), (cubic, "c")):
        exports.costmap(m, tmp_path / f"{name}.pgm")
        exports.ply_points(m, tmp_path / f"{name}.ply", occupied_nats=0.5)
    assert (tmp_path / "p.pgm").read_bytes() == (tmp_path / "c.pgm").read_bytes()
    from plyfile import PlyData  # the same points, listed brick by brick

    rows = [np.sort(PlyData.read(str(tmp_path / f"{n}.ply"))["vertex"].data) for n in "pc"]
    assert len(rows[0]) > 50 and np.array_equal(rows[0], rows[1])
    v_planar, v_cubic = volume.from_bricks(spec, keys, data), volume.from_bricks(*rebrick(spec, keys, data, 8))
    assert np.array_equal(v_planar.values, v_cubic.values) and np.array_equal(v_planar.coarse, v_cubic.coarse)


@pytest.mark.parametrize("name", ["k.npz", "k.rcmap"])
def test_a_planar_map_with_the_knowledge_channel_keeps_both(tmp_path, name):
    """A spinning radar's map of the detection-statistics model: planar bricks and the knowledge
    channel in one file (npz version 2, store format 3), read back and converted, brick for brick."""
    keys, data = planar_map(THICK)
    knowledge = np.abs(data) * 4
    looks = (knowledge > 0).astype(np.int32)
    reading = dict(look_limit=4.0, prior_nats=0.0, prior_looks=0.5, known_looks=0.5)
    path = tmp_path / name
    if name.endswith(".npz"):
        npz.write(path, THICK, keys, data, channels=npz.Channels(knowledge, looks, reading))
    else:
        store.StoreWriter(path, THICK, reading=reading).save(keys, data, knowledge=knowledge, looks=looks)
    other = tmp_path / ("c.rcmap" if name.endswith(".npz") else "c.npz")
    disk.convert(path, other)
    for p in (path, other):
        spec, k, d, channels = disk.read_channels(p)
        assert spec == THICK and channels.reading == reading
        for got, want in ((d, data), (channels.knowledge, knowledge), (channels.looks, looks)):
            assert np.array_equal(assemble(spec, k, got), assemble(THICK, keys, want))
    m = Map.open(other)
    assert m.has_knowledge and m.known().shape == m.data.shape == (len(keys), 1, 8, 8)
