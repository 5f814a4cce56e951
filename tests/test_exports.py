"""Every export read back by the tool it is for: OctoMap, plyfile, VTK, a PGM/YAML parser as
map_server reads it, rosbags; an empty map gives valid empty files."""

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.grid import GridSpec, assemble
from radarcl.maps import exports
from radarcl.maps.map import Map

SPEC = GridSpec((-2.0, -3.0, -1.0), 0.25, (24, 16, 16))


@pytest.fixture(scope="module")
def m():
    """A small map: free air (-2 nat), a wall at x = 1 m (+5 nat), a column (+3 nat), unseen
    voxels (0), and values beyond OctoMap's clamp (+20 nat)."""
    dense = np.zeros(SPEC.array_shape, np.int32)               # (z, y, x)
    dense[2:14, 2:14, 2:20] = -2048
    dense[2:14, 2:14, 12] = 5 * 1024
    dense[4:10, 6, 5] = 3 * 1024
    dense[8, 8, 12] = 20 * 1024
    keys, data = [], []
    for bz in range(2):
        for by in range(2):
            for bx in range(3):
                block = dense[bz * 8:bz * 8 + 8, by * 8:by * 8 + 8, bx * 8:bx * 8 + 8]
                if block.any():
                    keys.append((bx, by, bz))
                    data.append(block)
    return Map(SPEC, np.array(keys, np.int32), np.array(data, np.int32))


def test_octomap_bt_and_ot_load_in_octomap(m, tmp_path):
    import octomap
    for name in ("m.bt", "m.ot"):
        n = exports.octomap(m, tmp_path / name)
        idx, units = m.voxels()
        assert n == len(idx)
        tree = octomap.OcTree(0.1)
        if name.endswith(".bt"):
            assert tree.readBinary(str(tmp_path / name).encode())
        else:
            tree = octomap.OcTree.read(str(tmp_path / name).encode())
        assert abs(tree.getResolution() - SPEC.voxel_m) < 1e-12
        centres = SPEC.index_to_world(idx)
        occupied = np.array([tree.isNodeOccupied(tree.search(c)) for c in centres])
        assert np.array_equal(occupied, units > 0)             # occupancy threshold 0 nat
        if name.endswith(".ot"):
            got = np.array([tree.search(c).getLogOdds() for c in centres])
            want = np.clip(units / 1024, -exports.CLAMP_NATS, exports.CLAMP_NATS)
            assert np.allclose(got, want, atol=1e-3)           # float32 in the tree
        leaves = sum(1 for _ in tree.begin_leafs())
        assert leaves <= len(idx)                              # pruning may merge equal siblings


def test_ply_points_and_mesh_read_back_with_plyfile(m, tmp_path):
    import plyfile
    n = exports.ply_points(m, tmp_path / "p.ply", threshold_nats=1.0)
    ply = plyfile.PlyData.read(str(tmp_path / "p.ply"))
    v = ply["vertex"]
    centres, nats = m.occupied(1.0)
    assert n == len(v) == len(centres)
    order = np.lexsort((v["z"], v["y"], v["x"]))
    want = np.lexsort(centres.T[::-1])
    assert np.allclose(np.stack([v["x"], v["y"], v["z"]], 1)[order], centres[want], atol=1e-5)
    assert np.allclose(v["log_odds"][order], nats[want], atol=1e-4)
    assert np.allclose(v["probability"], 1 / (1 + np.exp(-v["log_odds"])), atol=1e-6)
    nv, nf = exports.ply_mesh(m, tmp_path / "mesh.ply", threshold_nats=1.0)
    mesh = plyfile.PlyData.read(str(tmp_path / "mesh.ply"))
    assert nv == len(mesh["vertex"]) > 0 and nf == len(mesh["face"]) > 0
    xs = mesh["vertex"]["x"]
    # the wall's surface lies within a voxel of x = 1 m (the voxel of index 12 spans 1.0-1.25 m)
    assert np.mean(np.abs(xs - 1.125) < 0.3) > 0.5


def test_vti_reads_back_in_vtk_with_the_same_values_and_spacing(m, tmp_path):
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    exports.vti(m, tmp_path / "m.vti")
    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "m.vti"))
    reader.Update()
    image = reader.GetOutput()
    assert image.GetDimensions() == SPEC.shape and np.allclose(image.GetSpacing(), (0.25,) * 3)
    assert np.allclose(image.GetOrigin(), np.asarray(SPEC.origin_m) + 0.125)
    values = vtk_to_numpy(image.GetPointData().GetArray("log_odds")).reshape(SPEC.array_shape)
    assert np.array_equal(values, (assemble(SPEC, m.keys, m.data) / 1024).astype(np.float32))


def test_costmap_follows_map_server(m, tmp_path):
    exports.costmap(m, tmp_path / "c.pgm", band=(-0.5, 2.0), threshold_nats=1.0)
    raw = (tmp_path / "c.pgm").read_bytes()
    lines = raw.split(b"\n", 4)
    assert lines[0] == b"P5" and lines[2] == b"24 16" and lines[3] == b"255"
    pixels = np.frombuffer(lines[4], np.uint8).reshape(16, 24)[::-1]     # row 0 = lowest y, as the origin
    grid = m.projection((-0.5, 2.0), 1.0)
    assert np.array_equal(pixels == 0, grid == 100) and np.array_equal(pixels == 254, grid == 0)
    assert (pixels[grid == -1] == 205).all()
    meta = dict(line.split(": ", 1) for line in (tmp_path / "c.yaml").read_text().splitlines())
    assert meta["image"] == "c.pgm" and float(meta["resolution"]) == 0.25 and meta["mode"] == "trinary"
    assert meta["origin"] == "[-2.0, -3.0, 0.0]"
    assert (grid == 100)[6, 5] and (grid == 100)[8, 12] and (grid == 0)[8, 15] and (grid == -1)[0, 0]


def test_rosbag_reads_back_with_rosbags(m, tmp_path):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    exports.rosbag(m, tmp_path / "bag", band=(-0.5, 2.0))
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(tmp_path / "bag") as reader:
        msgs = {c.topic: ts.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()}
    cloud = msgs["/map/points"]
    points = np.frombuffer(cloud.data.tobytes(), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("l", "<f4")])
    centres, nats = m.occupied(1.0)
    assert cloud.width == len(centres) and cloud.header.frame_id == "map"
    assert np.allclose(np.sort(points["l"]), np.sort(nats), atol=1e-4)
    grid = msgs["/map/grid"]
    assert (grid.info.width, grid.info.height) == (24, 16) and abs(grid.info.resolution - 0.25) < 1e-9
    assert np.array_equal(np.asarray(grid.data).reshape(16, 24), m.projection((-0.5, 2.0), 1.0))


def test_an_empty_map_exports_valid_empty_files(tmp_path, caplog):
    import plyfile

    empty = Map(SPEC, np.zeros((0, 3), np.int32), np.zeros((0, 8, 8, 8), np.int32))
    assert exports.ply_points(empty, tmp_path / "e.ply") == 0
    assert exports.ply_mesh(empty, tmp_path / "e_mesh.ply") == (0, 0)
    assert exports.costmap(empty, tmp_path / "e.pgm") == (16, 24)
    assert len(plyfile.PlyData.read(str(tmp_path / "e.ply"))["vertex"]) == 0
    assert "wrote a valid empty file" in caplog.text


def test_cli_export(m, tmp_path, capsys):
    path = tmp_path / "m.npz"
    with open(path, "wb") as f:
        np.savez_compressed(f, version=1, origin_m=np.asarray(SPEC.origin_m), voxel_m=SPEC.voxel_m,
                            shape=np.asarray(SPEC.shape), keys=m.keys, data=m.data)
    assert main(["export", str(path), "--to", "ply", "--out", str(tmp_path / "o.ply")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["export", str(path), "--to", "costmap", "--out", str(tmp_path / "o.pgm"), "--band", "3", "1"]) == 2
    assert "height band must be two finite numbers z_min < z_max" in capsys.readouterr().err
    assert main(["export", str(path), "--to", "ply", "--out", str(tmp_path / "o.ply")]) == 2
    assert "exists" in capsys.readouterr().err


@pytest.fixture(scope="module")
def known():
    """A map with the knowledge channel (the detection-statistics model): free air (-2 nat, one
    look), a wall at x = 1 m (+5 nat, two looks) and behind it, x >= 1.25 m, voxels whose sums
    are as negative as the free air's but which the radar could not see (a quarter look):
    never observed, whatever their sums say."""
    dense = np.zeros(SPEC.array_shape, np.int32)
    knowledge = np.zeros(SPEC.array_shape, np.int32)
    dense[2:14, 2:14, 2:20] = -2048
    knowledge[2:14, 2:14, 2:20] = 4096
    dense[2:14, 2:14, 12] = 5 * 1024
    knowledge[2:14, 2:14, 12] = 2 * 4096
    knowledge[2:14, 2:14, 13:20] = 1024                        # a quarter look: below KNOWN_LOOKS
    keys, blocks = [], []
    for bz in range(2):
        for by in range(2):
            for bx in range(3):
                s = np.s_[bz * 8:bz * 8 + 8, by * 8:by * 8 + 8, bx * 8:bx * 8 + 8]
                if knowledge[s].any():
                    keys.append((bx, by, bz))
                    blocks.append((dense[s], knowledge[s]))
    data, k = (np.array([b[i] for b in blocks], np.int32) for i in range(2))
    return Map(SPEC, np.array(keys, np.int32), data, k, np.minimum(k // 4096, 2).astype(np.int32),
               dict(look_limit=4.0, prior_nats=0.0, prior_looks=0.5))


def test_unknown_stays_unknown_in_the_costmap_occupancy_grid_and_octomap(known, tmp_path):
    """Columns the radar never observed are -1 in the OccupancyGrid and 205 in the costmap (not
    free, though their sums are negative); free columns are free; OctoMap leaves them out."""
    import octomap
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    grid = known.projection((-0.5, 2.0), 1.0)
    columns = known.known_columns()                            # what the top-down pictures draw grey
    assert np.array_equal(columns, known.projection(None, 1.0) != -1) and not columns[2:14, 13:20].any()
    assert (grid[2:14, 13:20] == -1).all() and (grid[2:14, 2:12] == 0).all() and (grid[2:14, 12] == 100).all()
    exports.costmap(known, tmp_path / "c.pgm", band=(-0.5, 2.0), threshold_nats=1.0)
    pixels = np.frombuffer((tmp_path / "c.pgm").read_bytes().split(b"\n", 4)[4], np.uint8).reshape(16, 24)[::-1]
    assert (pixels[2:14, 13:20] == 205).all() and (pixels[2:14, 2:12] == 254).all() and (pixels[2:14, 12] == 0).all()
    exports.rosbag(known, tmp_path / "bag", band=(-0.5, 2.0))
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(tmp_path / "bag") as reader:
        msgs = {c.topic: ts.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()}
    assert np.array_equal(np.asarray(msgs["/map/grid"].data).reshape(16, 24), grid)
    n = exports.octomap(known, tmp_path / "k.ot")
    tree = octomap.OcTree.read(str(tmp_path / "k.ot").encode())
    assert n == 12 * 12 * 11                                   # free air and wall, not the 12 x 12 x 7 unseen
    behind = SPEC.index_to_world(np.array([[15, 8, 8]]))[0]
    before = SPEC.index_to_world(np.array([[8, 8, 8]]))[0]
    boxes = [(np.asarray(leaf.getCoordinate()), leaf.getSize()) for leaf in tree.begin_leafs()]
    inside = [any((np.abs(p - c) < size / 2).all() for c, size in boxes) for p in (behind, before)]
    assert inside == [False, True]                             # OctoMap: absent means unknown
