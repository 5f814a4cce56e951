"""Every default map of the shared recordings (``radarcl fuse DIR`` with nothing else: the
sensor from the directory's layout, the default grid; the TI capture with its sensor, still)
exports to every format of
``radarcl export`` without ``--resample``, and reads back in that format's own library
(octomap-python, plyfile, vtk, Pillow for map_server's PGM, rosbags) with the map's occupied
count; PLY and .vti carry their frame, units and voxel size."""

from pathlib import Path

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.maps import exports

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
RECORDINGS = {                      # the command line a user first fuses each with (a directory: its layout says)
    "navtech_oxford": ["navtech_oxford"],
    "radiate_fog": ["radiate_fog"],
    "ti_adc_openradar": ["ti_adc_openradar/simple_frame_1.npy", "--sensor", "ti-xwr-openradar", "--still"],
}


@pytest.fixture(scope="module", params=[name for name in RECORDINGS if (DATA / name).is_dir()])
def default_map(request, tmp_path_factory):
    """(path, Map) of the recording fused as a user would first fuse it."""
    from radarcl.maps.disk import read_meta, read_poses
    from radarcl.maps.map import Map

    out = tmp_path_factory.mktemp(request.param) / "map.npz"
    data, *options = RECORDINGS[request.param]
    assert main(["fuse", str(DATA / data), *options, "--out", str(out), "--no-report", "--no-progress"]) == 0
    m = Map.open(out)
    assert m.counts()["occupied"] > 1000
    if request.param != "ti_adc_openradar":                       # a still radar has no trajectory
        track = out.with_name(out.name + ".tum").read_text().splitlines()   # the trajectory, beside the map
        assert len([line for line in track if not line.startswith("#")]) == len(read_poses(out)) > 1
    assert (read_meta(out, "geo_anchor") is not None) == (request.param == "radiate_fog")    # GPS: RADIATE only
    return out, m


def occupied_read_back(fmt, path):
    """The occupied voxels (points, cells) the format's own library reads from ``path``."""
    if fmt == "octomap":
        import octomap

        tree = octomap.OcTree(0.1)
        assert tree.readBinary(str(path).encode())
        res = tree.getResolution()                   # a pruned leaf stands for all the voxels it covers
        return sum(round((leaf.getSize() / res) ** 3) for leaf in tree.begin_leafs() if tree.isNodeOccupied(leaf))
    if fmt == "ply":
        import plyfile

        return len(plyfile.PlyData.read(str(path))["vertex"])
    if fmt == "vti":
        import vtk
        from vtk.util.numpy_support import vtk_to_numpy

        reader = vtk.vtkXMLImageDataReader()
        reader.SetFileName(str(path))
        reader.Update()
        data = reader.GetOutput().GetPointData()
        nats, seen = (vtk_to_numpy(data.GetArray(name)) for name in ("log_odds", "observed"))
        return int(((nats > 1.0) & (seen == 1)).sum())
    if fmt == "costmap":
        from PIL import Image

        return int((np.asarray(Image.open(path)) == 0).sum())         # map_server: black is occupied
    if fmt == "rosbag":
        from rosbags.rosbag2 import Reader
        from rosbags.typesys import Stores, get_typestore

        ts = get_typestore(Stores.ROS2_HUMBLE)
        with Reader(path) as reader:
            clouds = [ts.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/map/points"]
        return clouds[0].width
    raise AssertionError(fmt)


@pytest.mark.parametrize("fmt", list(exports.FORMATS))
def test_every_default_map_exports_to_every_format_with_its_occupied_count(default_map, fmt, tmp_path, capsys):
    path, m = default_map
    suffix = {"octomap": ".bt", "costmap": ".pgm", "rosbag": ""}.get(fmt, exports.FORMATS[fmt].suffixes[0])
    out = tmp_path / f"out{suffix}"
    assert main(["export", str(path), "--to", fmt, "--out", str(out)]) == 0, capsys.readouterr().err
    said = capsys.readouterr().out
    occupied = m.counts()["occupied"]
    if fmt == "mesh":                          # a surface, not voxels: read back whole, in the map's box
        import plyfile

        mesh = plyfile.PlyData.read(str(out))
        xyz = np.stack([mesh["vertex"][a] for a in "xyz"], 1)
        lo = np.asarray(m.spec.origin_m) - m.spec.voxel_m
        assert len(mesh["face"]) > 0 and (xyz >= lo).all()
    elif fmt == "costmap":                       # cells seen from above: a 3D map's columns, a planar map's voxels
        assert occupied_read_back(fmt, out) == int((m.projection() == 100).sum())
        assert m.spec.shape[2] > 1 or int((m.projection() == 100).sum()) == occupied
    else:
        assert occupied_read_back(fmt, out) == occupied, said
    if fmt == "octomap":
        assert "on OctoMap's lattice" in said and ("the planar map's one layer" in said) == (m.spec.shape[2] == 1)
    if fmt in ("ply", "mesh"):
        import plyfile

        comments = plyfile.PlyData.read(str(out)).comments
        assert {"frame_id map", "units m", f"voxel_m {m.spec.voxel_m:g}"} <= set(comments)
    if fmt == "vti":
        import vtk

        reader = vtk.vtkXMLImageDataReader()
        reader.SetFileName(str(out))
        reader.Update()
        field = reader.GetOutput().GetFieldData()
        assert field.GetAbstractArray("frame_id").GetValue(0) == "map"
        assert field.GetAbstractArray("units").GetValue(0) == "m"
        assert field.GetArray("voxel_m").GetValue(0) == m.spec.voxel_m


def test_default_grids_lie_on_octomaps_lattice():
    from radarcl.config import mapconfig, sensors
    from radarcl.maps.exports import lattice_shift

    for name in sensors.builtin_names():
        spec = mapconfig.resolve(name).grid_spec()
        shift = lattice_shift(spec)
        assert np.allclose(shift[:2], 0, atol=1e-9), (name, spec)
        assert abs(shift[2]) < 1e-9 or (spec.shape[2] == 1 and np.isclose(abs(shift[2]), spec.voxel_m / 2)), name
