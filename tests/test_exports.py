"""Every export read back by the tool it is for: OctoMap, plyfile, VTK, a PGM/YAML parser as
map_server reads it, rosbags; an empty map gives valid empty files."""


import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarcl import logodds, sensor_model
from radarcl.cli import main
from radarcl.errors import ConfigError
from radarcl.gridspec import GridSpec, assemble
from radarcl.maps import exports
from radarcl.maps.map import UNOBSERVED, Map

SPEC = GridSpec((-2.0, -3.0, -1.0), 0.25, (24, 16, 16))


@pytest.fixture(scope="module")
def m():
    """A small map: free air (-2 nat), a wall at x = 1 m (+5 nat), a column (+3 nat), unseen
    voxels (0), and values beyond OctoMap's clamp (+20 nat)."""
    dense = np.zeros(SPEC.array_shape, np.int32)               # (z, y, x)
    dense[2:14, 2:14, 2:20] = -2048
    dense[2:14, 2:14, 12] = 6 * 1024
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


def octomap_leaves(tree):
    """{(x, y, z) voxel centre rounded to 1e-6 m: log-odds} of an OcTree's leaves."""
    out = {}
    for leaf in tree.begin_leafs():
        out[tuple(np.round(leaf.getCoordinate(), 6))] = leaf.getValue()          # log-odds
    return out


def test_octomap_files_hold_the_occupied_and_free_voxels_where_the_ply_has_them(m, tmp_path):
    """OctoMap reads both files back; their leaves are the map's occupied and free voxels,
    voxel for voxel at the PLY's coordinates (the map's origin lies on OctoMap's lattice), with
    the .ot's log-odds and the .bt's classes; undecided voxels (between the thresholds) and
    unseen ones are not in the tree."""
    import octomap
    import plyfile

    exports.ply_points(m, tmp_path / "p.ply", 1.0)
    ply = plyfile.PlyData.read(str(tmp_path / "p.ply"))["vertex"]
    ply_centres = {tuple(np.round(c, 6)) for c in np.stack([ply["x"], ply["y"], ply["z"]], 1).astype(np.float64)}
    idx, units = m.voxels()
    centres = SPEC.index_to_world(idx)
    want_occ = {tuple(np.round(c, 6)) for c in centres[units > 1024]}
    want_free = {tuple(np.round(c, 6)) for c in centres[units < -1024]}
    assert want_occ == ply_centres and want_free and want_occ
    for name in ("m.bt", "m.ot"):
        out = exports.octomap(m, tmp_path / name, occupied_nats=1.0, free_nats=-1.0)
        assert out["occupied_voxels"] == len(want_occ) and out["free_voxels"] == len(want_free)
        if name.endswith(".bt"):
            tree = octomap.OcTree(0.1)
            assert tree.readBinary(str(tmp_path / name).encode())
        else:
            tree = octomap.OcTree.read(str(tmp_path / name).encode())
        assert abs(tree.getResolution() - SPEC.voxel_m) < 1e-12
        leaves = octomap_leaves(tree)
        occupied = {c for c, v in leaves.items() if v > 0}
        assert occupied == want_occ and set(leaves) - occupied == want_free
        if name.endswith(".ot"):
            got = np.array([leaves[tuple(np.round(c, 6))] for c in centres[np.abs(units) > 1024]])
            want = np.clip(units[np.abs(units) > 1024] / 1024, -exports.CLAMP_NATS, exports.CLAMP_NATS)
            assert np.allclose(got, want, atol=1e-6)                       # float32 in the tree


def test_an_origin_off_octomaps_lattice_is_refused_with_the_shift_or_resampled(tmp_path):
    """Half a voxel off in y: refused, naming the 0.125 m the map would move; with resample each
    lattice voxel takes the mean of the two voxels it straddles."""
    import octomap

    spec = GridSpec((0.0, 0.125, 0.0), 0.25, (8, 8, 8))
    data = np.full((1, 8, 8, 8), 2048, np.int32)              # +2 nat everywhere ...
    data[0, :, 4:, :] = -2048                                 # ... but -2 from y index 4 up
    half = Map(spec, np.zeros((1, 3), np.int32), data)
    with pytest.raises(ConfigError, match=r"would move by \[0.0, 0.125, 0.0\] m; pass --resample"):
        exports.octomap(half, tmp_path / "h.ot")
    out = exports.octomap(half, tmp_path / "h.ot", occupied_nats=0.5, free_nats=-0.5, resample=True)
    leaves = octomap_leaves(octomap.OcTree.read(str(tmp_path / "h.ot").encode()))
    # lattice voxel j (y from 0.25 j) mixes our voxels j - 1 and j half and half: 0 nat at the step
    ys = sorted({c[1] for c in leaves})
    by_y = {y: np.mean([v for c, v in leaves.items() if c[1] == y]) for y in ys}
    assert by_y[0.125] == pytest.approx(2.0) and by_y[0.875] == pytest.approx(2.0) and by_y[2.125] == pytest.approx(-2.0)
    assert 1.125 not in by_y                                  # the step's voxel is 0 nat: undecided, left out
    assert out["occupied_voxels"] and out["free_voxels"] and out["lattice"] == "resampled onto OctoMap's lattice"


def test_ply_points_and_mesh_read_back_with_plyfile(m, tmp_path):
    import plyfile
    n = exports.ply_points(m, tmp_path / "p.ply", 1.0)["points"]
    ply = plyfile.PlyData.read(str(tmp_path / "p.ply"))
    v = ply["vertex"]
    centres, nats = m.occupied(1.0)
    assert n == len(v) == len(centres)
    assert {"red", "green", "blue"} <= set(v.data.dtype.names) and np.ptp(v["red"].astype(int)) > 100
    order = np.lexsort((v["z"], v["y"], v["x"]))
    want = np.lexsort(centres.T[::-1])
    assert np.allclose(np.stack([v["x"], v["y"], v["z"]], 1)[order], centres[want], atol=1e-5)
    assert np.allclose(v["log_odds"][order], nats[want], atol=1e-4)
    assert np.allclose(v["probability"], 1 / (1 + np.exp(-v["log_odds"])), atol=1e-6)
    out = exports.ply_mesh(m, tmp_path / "mesh.ply", 1.0)
    mesh = plyfile.PlyData.read(str(tmp_path / "mesh.ply"))
    assert out["vertices"] == len(mesh["vertex"]) > 0 and out["faces"] == len(mesh["face"]) > 0
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
    dense = assemble(SPEC, m.keys, m.data)
    assert np.array_equal(values, (dense / 1024).astype(np.float32))
    observed = vtk_to_numpy(image.GetPointData().GetArray("observed")).reshape(SPEC.array_shape)
    assert np.array_equal(observed, (dense != 0).astype(np.uint8))


def test_costmap_follows_map_server(m, tmp_path):
    """The PGM is map_server's trinary image of the projection: occupied where some voxel of the
    column is occupied, free where none is and some is free, unknown elsewhere; the YAML beside."""
    out = exports.costmap(m, tmp_path / "c.pgm", band=(-0.5, 2.0), occupied_nats=1.0, free_nats=-1.0)
    assert out["files"] == [tmp_path / "c.pgm", tmp_path / "c.yaml"]
    raw = (tmp_path / "c.pgm").read_bytes()
    lines = raw.split(b"\n", 4)
    assert lines[0] == b"P5" and lines[2] == b"24 16" and lines[3] == b"255"
    pixels = np.frombuffer(lines[4], np.uint8).reshape(16, 24)[::-1]     # row 0 = lowest y, as the origin
    grid = m.projection((-0.5, 2.0), 1.0, -1.0)
    assert set(np.unique(grid)) == {0, 100, -1}
    assert np.array_equal(pixels == 0, grid == 100) and np.array_equal(pixels == 254, grid == 0)
    assert np.array_equal(pixels == 205, grid == -1)
    assert (out["occupied_cells"], out["free_cells"], out["unknown_cells"]) == tuple(
        int((grid == v).sum()) for v in (100, 0, -1))
    meta = dict(line.split(": ", 1) for line in (tmp_path / "c.yaml").read_text().splitlines())
    assert meta["image"] == "c.pgm" and float(meta["resolution"]) == 0.25 and meta["mode"] == "trinary"
    assert meta["origin"] == "[-2.0, -3.0, 0.0]"
    # map_server's trinary reading: p = (255 - pixel) / 255 against the YAML's thresholds
    p = (255 - pixels.astype(float)) / 255
    read = np.where(p > float(meta["occupied_thresh"]), 100, np.where(p < float(meta["free_thresh"]), 0, -1))
    assert np.array_equal(read, grid)
    assert (grid == 100)[6, 5] and (grid == 100)[8, 12] and (grid == 0)[8, 15] and (grid == -1)[0, 0]


def test_rosbag_reads_back_with_rosbags_as_ros2_would(m, tmp_path):
    """The bag is named as a bag (its data file after it, no temporary name), stamped with the
    map's own time, in the frame asked for; /map is the same trinary grid as the costmap and is
    offered transient-local (latched); /map/points holds the occupied voxels."""
    from rosbags.interfaces import QosDurability, QosReliability
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    stamp = 1_700_000_000_123_456_789
    out = exports.rosbag(m, tmp_path / "bag", band=(-0.5, 2.0), frame_id="odom", stamp_ns=stamp)
    names = sorted(p.name for p in (tmp_path / "bag").iterdir())
    assert names == ["bag.db3", "metadata.yaml"] and not list(tmp_path.glob(".*"))
    assert "relative_file_paths:\n  - bag.db3" in (tmp_path / "bag" / "metadata.yaml").read_text()
    assert sorted(out["files"]) == sorted((tmp_path / "bag").iterdir())
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(tmp_path / "bag") as reader:
        assert reader.message_count == 2 and reader.start_time == stamp
        conns = {c.topic: c for c in reader.connections}
        msgs = {c.topic: (t, ts.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages()}
    qos = conns["/map"].ext.offered_qos_profiles
    assert [q.durability for q in qos] == [QosDurability.TRANSIENT_LOCAL]
    assert [q.reliability for q in qos] == [QosReliability.RELIABLE] and qos[0].depth == 1
    t, grid = msgs["/map"]
    assert t == stamp and (grid.header.stamp.sec, grid.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert grid.header.frame_id == "odom" and (grid.info.width, grid.info.height) == (24, 16)
    assert abs(grid.info.resolution - 0.25) < 1e-9
    assert np.array_equal(np.asarray(grid.data).reshape(16, 24), m.projection((-0.5, 2.0), 1.0, -1.0))
    _, cloud = msgs["/map/points"]
    names = [f.name for f in cloud.fields]
    points = np.frombuffer(cloud.data.tobytes(), dtype=[(n, "<f4") for n in names])
    centres, nats = m.occupied(1.0)
    assert cloud.width == len(centres) and cloud.header.frame_id == "odom" and "probability" in names
    assert np.allclose(np.sort(points["log_odds"]), np.sort(nats), atol=1e-4)


def test_an_empty_map_exports_valid_empty_files(tmp_path, caplog):
    import plyfile

    empty = Map(SPEC, np.zeros((0, 3), np.int32), np.zeros((0, 8, 8, 8), np.int32))
    assert exports.ply_points(empty, tmp_path / "e.ply")["points"] == 0
    assert exports.ply_mesh(empty, tmp_path / "e_mesh.ply")["vertices"] == 0
    assert exports.costmap(empty, tmp_path / "e.pgm")["unknown_cells"] == 16 * 24
    assert exports.octomap(empty, tmp_path / "e.bt")["nodes"] == 0
    assert len(plyfile.PlyData.read(str(tmp_path / "e.ply"))["vertex"]) == 0
    assert "wrote a valid empty file" in caplog.text


def _map_file(m, path):
    """``m`` as a version-1 map file at ``path``."""
    with open(path, "wb") as f:
        np.savez_compressed(f, version=1, origin_m=np.asarray(SPEC.origin_m), voxel_m=SPEC.voxel_m,
                            shape=np.asarray(SPEC.shape), keys=m.keys, data=m.data)
    return path


def test_cli_export(m, tmp_path, capsys):
    path = _map_file(m, tmp_path / "m.npz")
    assert main(["export", str(path), "--to", "ply", "--out", str(tmp_path / "o.ply")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["export", str(path), "--to", "costmap", "--out", str(tmp_path / "c.pgm"), "--band", "-0.5", "2"]) == 0
    said = capsys.readouterr().out
    assert f"{tmp_path / 'c.pgm'} (" in said and f"{tmp_path / 'c.yaml'} (" in said       # every file named
    assert "occupied cells" in said and "free cells" in said and "free below -1 nat" in said
    for to, wrong, right in (("mesh", "x.obj", ".ply"), ("vti", "x.vtk", ".vti"), ("costmap", "x.png", ".pgm"),
                             ("octomap", "x.octomap", ".bt"), ("rosbag", "bag.db3", "without an extension")):
        assert main(["export", str(path), "--to", to, "--out", str(tmp_path / wrong)]) == 2
        assert right in capsys.readouterr().err and not (tmp_path / wrong).exists()
    assert main(["export", str(path), "--to", "costmap", "--out", str(tmp_path / "d.pgm"),
                 "--occupied-threshold", "-1", "--free-threshold", "1"]) == 2
    assert "free <= 0 <= occupied" in capsys.readouterr().err
    assert main(["export", str(path), "--to", "costmap", "--out", str(tmp_path / "o.pgm"), "--band", "3", "1"]) == 2
    assert "height band must be two finite numbers z_min < z_max" in capsys.readouterr().err
    assert main(["export", str(path), "--to", "ply", "--out", str(tmp_path / "o.ply")]) == 2
    assert "exists" in capsys.readouterr().err



def test_a_format_added_to_the_table_alone_is_exported_by_radarcl_export(m, tmp_path, capsys, monkeypatch):
    """A toy format (the occupied voxel centres as text) registered in ``exports.FORMATS`` and
    nowhere else: ``radarcl export --to toy`` takes it, its help lists it, its extension is
    checked, its exporter gets the options it names and the summary states its threshold."""
    monkeypatch.setattr(exports, "FORMATS", dict(exports.FORMATS))

    def toy(m, path, occupied_nats=1.0, band=None):
        centres, _ = m.occupied(occupied_nats)
        np.savetxt(path, centres, fmt="%.3f")
        return dict(files=[path], points=len(centres), band=int(band is not None))

    exports.register(exports.Export("toy", (".toy",), "the occupied voxel centres as text", toy))
    path = _map_file(m, tmp_path / "m.npz")
    assert main(["export", str(path), "--to", "toy", "--out", str(tmp_path / "o.toy"), "--band", "-1", "3"]) == 0
    said = capsys.readouterr().out
    want, _ = m.occupied(1.0)
    assert np.allclose(np.loadtxt(tmp_path / "o.toy"), want, atol=1e-3) and len(want)
    assert f"(toy: {len(want):,} points, 1 band; occupied above 1 nat)" in said
    assert main(["export", str(path), "--to", "toy", "--out", str(tmp_path / "o.ply")]) == 2
    assert "--to toy writes .toy files; " in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "toy: the occupied voxel centres as text." in text and ".pgm, .toy; a directory for rosbag" in text
    with pytest.raises(ConfigError, match="registered already"):
        exports.register(exports.Export("toy", (".toy",), "again", toy))
    with pytest.raises(ConfigError, match="takes colours, which radarcl export does not give"):
        exports.register(exports.Export("bad", (".bad",), "bad", lambda m, path, colours: None))


def test_the_command_gives_every_option_and_the_readme_lists_every_format():
    """``radarcl export`` maps each of ``exports.OPTIONS`` from its command line, the docs' table
    of formats (docs/guide/maps.md) has one row per format of ``exports.FORMATS``, in order, with
    its files, and the README's "Export it" names every format."""
    from pathlib import Path

    from radarcl.commands import export

    assert list(export.OPTIONS) == list(exports.OPTIONS)
    root = Path(__file__).resolve().parents[1]
    page = (root / "docs" / "guide" / "maps.md").read_text()
    table = page.split("\n| `--to` | file |", 1)[1].split("\n\n", 1)[0]
    rows = [[c.strip() for c in line.split("|")[1:3]] for line in table.splitlines() if line.startswith("| `")]
    want = [[f"`{f.name}`", "a directory" if f.suffixes == ("",) else " / ".join(f"`{s}`" for s in f.suffixes)
             + "".join(f" + `{c}`" for c, _ in f.companions)] for f in exports.FORMATS.values()]
    assert rows == want
    readme = (root / "README.md").read_text().split("\n## Export it\n", 1)[1].split("\n## ", 1)[0]
    assert [name for name in exports.FORMATS if f"`{name}`" not in readme] == []

def test_every_format_counts_the_same_voxels_at_the_thresholds(tmp_path):
    """A voxel exactly at a threshold is undecided in every format (occupied means strictly
    above, free strictly below): the PLY, the OctoMap file and the bag's cloud hold the same
    occupied voxels, and the costmap the same classes as the map's own query."""
    import plyfile

    spec = GridSpec((0.0, 0.0, 0.0), 0.25, (8, 8, 8))
    data = np.zeros((1, 8, 8, 8), np.int32)
    data[0, 0, 0, :4] = [1024, 1025, -1024, -1025]                  # at and just beyond each threshold
    data[0, 1, 1, :2] = [2048, -2048]
    m = Map(spec, np.zeros((1, 3), np.int32), data)
    occupied = {1025, 2048}
    ply = exports.ply_points(m, tmp_path / "p.ply", 1.0)
    tree = exports.octomap(m, tmp_path / "o.ot", 1.0, -1.0)
    bag = exports.rosbag(m, tmp_path / "bag", occupied_nats=1.0, free_nats=-1.0)
    assert ply["points"] == tree["occupied_voxels"] == bag["points"] == len(occupied)
    assert tree["free_voxels"] == 2
    got = np.rint(plyfile.PlyData.read(str(tmp_path / "p.ply"))["vertex"]["log_odds"] * 1024).astype(int)
    assert set(got.tolist()) == occupied
    assert m.counts(1.0, -1.0) == dict(occupied=2, free=2, undecided=2, unobserved=spec.n_voxels - 6)


@pytest.fixture(scope="module")
def known():
    """A map with the knowledge channel (the detection-statistics model): free air (-2 nat, one
    look), a wall at x = 1 m (+6 nat, two looks: +2 read with the default reading) and behind it, x >= 1.25 m, voxels whose sums
    are as negative as the free air's but which the radar could not see (a quarter look):
    never observed, whatever their sums say."""
    dense = np.zeros(SPEC.array_shape, np.int32)
    knowledge = np.zeros(SPEC.array_shape, np.int32)
    dense[2:14, 2:14, 2:20] = -2048
    knowledge[2:14, 2:14, 2:20] = 4096
    dense[2:14, 2:14, 12] = 6 * 1024
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
               sensor_model.ModelParams().reading)                # the default: the prior everywhere


def test_a_known_map_reads_the_prior_where_unknown_and_vti_marks_only_what_it_knows(known, tmp_path):
    """With the default reading a voxel never observed reads the prior (the base rate), in a
    brick or outside every brick alike, and so does one whose evidence came with too little
    knowledge to call it observed; the .vti's observed mask is the knowledge, not the value. A
    map written before the reading kept ``known_looks`` reads such a voxel by its sums."""
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    prior = known.reading["prior_nats"]
    d = known.dense() / logodds.SCALE
    assert d[0, 0, 0] == pytest.approx(prior, abs=1e-3)                 # no brick there
    assert d[8, 8, 15] == pytest.approx(prior, abs=1e-3)                # behind the wall: a quarter look
    legacy = dataclasses.replace(known, reading={k: v for k, v in known.reading.items() if k != "known_looks"})
    assert legacy.dense()[8, 8, 15] / logodds.SCALE == pytest.approx(-2.0 + prior, abs=1e-3)
    assert known.probability_at(SPEC.index_to_world(np.array([0, 0, 0]))) == pytest.approx(1 / (1 + np.exp(-prior)))
    exports.vti(known, tmp_path / "k.vti")
    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "k.vti"))
    reader.Update()
    observed = vtk_to_numpy(reader.GetOutput().GetPointData().GetArray("observed")).reshape(SPEC.array_shape)
    assert observed.sum() == 12 * 12 * 11 and observed[8, 8, 8] == 1 and observed[8, 8, 15] == 0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), look_limit=st.sampled_from([0.5, 2.0, 4.0]),
       prior=st.sampled_from([-6.0, -4.0, -0.5]))
def test_no_query_reads_occupied_where_the_map_has_not_observed(seed, look_limit, prior):
    """Whatever sums a voxel holds (any evidence, up to the fusion's limit, any knowledge and
    looks), a voxel the map classes unobserved reads the prior through every query: log_odds_at,
    probability_at (never above 1/2), dense, state_at; the observed ones read their sums."""
    rng = np.random.default_rng(seed)
    n = 3
    data = rng.integers(-30 * 1024, 30 * 1024, (n, 8, 8, 8)).astype(np.int32)
    knowledge = (rng.choice([0, 1, 2047, 2048, 2049, 4096, 20000], (n, 8, 8, 8))).astype(np.int32)
    looks = np.where(knowledge > 0, rng.integers(1, 9, (n, 8, 8, 8)), rng.integers(0, 3, (n, 8, 8, 8))).astype(np.int32)
    keys = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 1)], np.int32)
    reading = dict(sensor_model.ModelParams().reading, look_limit=look_limit, prior_nats=prior)
    m = Map(SPEC, keys, data, knowledge, looks, reading)
    centres = SPEC.index_to_world(np.stack(np.meshgrid(*(np.arange(k) for k in SPEC.shape), indexing="ij"),
                                           -1).reshape(-1, 3))
    state = m.state_at(centres)
    nats, p = m.log_odds_at(centres), m.probability_at(centres)
    unobserved = state == UNOBSERVED
    assert unobserved.any() and (~unobserved).any()
    assert np.all(nats[unobserved] == prior) and np.all(p[unobserved] <= 0.5)
    k_at = m.units_at(centres, "knowledge")
    assert np.array_equal(unobserved, k_at < sensor_model.KNOWN_LOOKS * logodds.KNOWLEDGE_SCALE)
    dense = m.dense()                                                       # (z, y, x)
    idx = SPEC.world_to_index(centres)
    assert np.all(dense[idx[:, 2], idx[:, 1], idx[:, 0]][unobserved] == logodds.to_fixed(prior))
    seen = ~unobserved
    e, n_looks = m.units_at(centres)[seen] / logodds.SCALE, m.units_at(centres, "looks")[seen]
    assert np.allclose(nats[seen], e / np.maximum(1.0, n_looks / look_limit) + prior)


def test_unknown_stays_unknown_in_the_costmap_occupancy_grid_and_octomap(known, tmp_path):
    """Columns the radar never observed are -1 in the OccupancyGrid and 205 in the costmap (not
    free, though their sums are negative); free columns are free; OctoMap leaves them out."""
    import octomap
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    grid = known.projection((-0.5, 2.0), 1.0, -1.0)
    columns = known.known_columns()                            # what the top-down pictures draw grey
    assert np.array_equal(columns, known.projection(None, 1.0, -1.0) != -1) and not columns[2:14, 13:20].any()
    assert (grid[2:14, 13:20] == -1).all() and (grid[2:14, 2:12] == 0).all() and (grid[2:14, 12] == 100).all()
    exports.costmap(known, tmp_path / "c.pgm", band=(-0.5, 2.0), occupied_nats=1.0, free_nats=-1.0)
    pixels = np.frombuffer((tmp_path / "c.pgm").read_bytes().split(b"\n", 4)[4], np.uint8).reshape(16, 24)[::-1]
    assert (pixels[2:14, 13:20] == 205).all() and (pixels[2:14, 2:12] == 254).all() and (pixels[2:14, 12] == 0).all()
    exports.rosbag(known, tmp_path / "bag", band=(-0.5, 2.0))
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(tmp_path / "bag") as reader:
        msgs = {c.topic: ts.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()}
    assert np.array_equal(np.asarray(msgs["/map"].data).reshape(16, 24), grid)
    written = exports.octomap(known, tmp_path / "k.ot")
    n = written["occupied_voxels"] + written["free_voxels"]
    tree = octomap.OcTree.read(str(tmp_path / "k.ot").encode())
    assert n == 12 * 12 * 11                                   # free air and wall, not the 12 x 12 x 7 unseen
    behind = SPEC.index_to_world(np.array([[15, 8, 8]]))[0]
    before = SPEC.index_to_world(np.array([[8, 8, 8]]))[0]
    boxes = [(np.asarray(leaf.getCoordinate()), leaf.getSize()) for leaf in tree.begin_leafs()]
    inside = [any((np.abs(p - c) < size / 2).all() for c, size in boxes) for p in (behind, before)]
    assert inside == [False, True]                             # OctoMap: absent means unknown
