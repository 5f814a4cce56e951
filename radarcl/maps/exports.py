"""Maps out of the engine, in the formats the field's tools read (``radarcl export``).

| format | file | read back by | holds |
|---|---|---|---|
| ``octomap`` | ``.bt`` / ``.ot`` | OctoMap (``octomap.OcTree``, octovis) | every observed voxel at its log-odds (clamped to OctoMap's +-CLAMP_NATS); ``.bt`` keeps occupied/free only |
| ``ply`` | ``.ply`` | plyfile, MeshLab, CloudCompare | the voxels above the threshold: x, y, z [m], log_odds [nat], probability |
| ``mesh`` | ``.ply`` | plyfile, MeshLab | the isosurface at the threshold (marching cubes, PyMCubes), vertices in metres |
| ``vti`` | ``.vti`` | VTK, ParaView, pyvista | the dense log-odds [nat] as zlib-compressed VTK image data, origin and spacing of the grid |
| ``costmap`` | ``.pgm`` + ``.yaml`` | ROS map_server / Nav2 | the projection over ``band``: 0 free, 100 occupied, -1 unknown |
| ``rosbag`` | a ROS 2 bag directory | rosbags, ros2 bag | ``/map/points`` PointCloud2 of the occupied voxels and ``/map/grid`` OccupancyGrid |

Every exporter takes a ``maps.Map``; an empty map gives a valid empty file and a warning.
Coordinates are the map's world frame (x forward, y left, z up, REP-103).
"""

import logging
import math
from pathlib import Path

import numpy as np

from radarcl import logodds
from radarcl.errors import ConfigError
from radarcl.io.files import atomic
from radarcl.maps.map import UNKNOWN

log = logging.getLogger(__name__)
CLAMP_NATS = 13.8            # OctoMap keeps log-odds within its clamping thresholds: p in [1e-6, 1 - 1e-6]


def _need(module, extra="export"):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ConfigError(f"this export needs {module.split('.')[0]} (pip install 'radarcl[{extra}]'): {exc}") from None


def _warn_empty(m, what, n):
    if n == 0:
        log.warning("%s: the map has no %s; wrote a valid empty file", what, "voxel to export")


def octomap(m, path, threshold_nats=0.0, binary=None, progress=None):
    """Every observed voxel (``|log-odds| >= threshold_nats``) as an OctoMap of the map's voxel
    size; ``.bt`` (binary: occupied/free at the occupancy threshold 0 nat) or ``.ot`` (full:
    log-odds). Returns the voxel count."""
    octo = _need("octomap")
    path = Path(path)
    binary = path.suffix == ".bt" if binary is None else binary
    tree = octo.OcTree(m.spec.voxel_m)
    p = 1.0 / (1.0 + math.exp(CLAMP_NATS))
    tree.setClampingThresMin(p)
    tree.setClampingThresMax(1.0 - p)
    tree.setOccupancyThres(0.5)
    idx, units = m.voxels()
    keep = np.abs(units) >= threshold_nats * logodds.SCALE
    centres, values = m.spec.index_to_world(idx[keep]), np.clip(logodds.to_nats(units[keep]), -CLAMP_NATS, CLAMP_NATS)
    for k, (c, v) in enumerate(zip(centres, values.tolist())):
        tree.updateNode(c, v, True)                 # lazy: inner nodes once, below
        if progress is not None and (k + 1) % 200000 == 0:
            progress(k + 1, len(values), "voxels")
    tree.updateInnerOccupancy()
    _warn_empty(m, path, len(values))
    with atomic(path) as tmp:
        ok = tree.writeBinary(str(tmp).encode()) if binary else tree.write(str(tmp).encode())
        if ok is False:
            raise ConfigError(f"OctoMap could not write {path}")
    return len(values)


def ply_points(m, path, threshold_nats=1.0):
    """The voxels above ``threshold_nats`` as a PLY point cloud with log_odds and probability."""
    plyfile = _need("plyfile")
    centres, nats = m.occupied(threshold_nats)
    v = np.empty(len(centres), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("log_odds", "f4"), ("probability", "f4")])
    v["x"], v["y"], v["z"] = centres.T
    v["log_odds"], v["probability"] = nats, 1.0 / (1.0 + np.exp(-nats))
    _warn_empty(m, path, len(v))
    with atomic(path) as tmp:
        plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")], text=False).write(str(tmp))
    return len(v)


def ply_mesh(m, path, threshold_nats=1.0, band=None):
    """The isosurface at ``threshold_nats`` (marching cubes over the dense log-odds, unseen = 0)
    as a PLY mesh in metres. Returns (vertices, faces)."""
    plyfile = _need("plyfile")
    mcubes = _need("mcubes")
    d = m.dense(band)
    z0 = 0 if band is None else m._band(band)[0]
    above = np.argwhere(d >= threshold_nats * logodds.SCALE)          # (z, y, x)
    verts, faces = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    if len(above):
        lo = np.maximum(above.min(axis=0) - 1, 0)
        hi = np.minimum(above.max(axis=0) + 2, d.shape)
        sub = d[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        # float32 nats in (x, y, z) order (what marching cubes wants), padded with "free" so the
        # surface closes at the box: one allocation beside the dense copy
        volume = np.full(np.asarray(sub.shape[::-1]) + 2, min(-1.0, threshold_nats - 1.0), np.float32)
        volume[1:-1, 1:-1, 1:-1] = sub.transpose(2, 1, 0) * np.float32(1.0 / logodds.SCALE)
        verts, faces = mcubes.marching_cubes(volume, float(threshold_nats))
        first = np.array([lo[2], lo[1], lo[0] + z0]) - 1                # voxel index of volume[0, 0, 0]
        verts = np.asarray(m.spec.origin_m) + (verts + first + 0.5) * m.spec.voxel_m
    vertex = np.empty(len(verts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    if len(verts):
        vertex["x"], vertex["y"], vertex["z"] = np.asarray(verts).T
    face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,))])
    face["vertex_indices"] = faces
    _warn_empty(m, path, len(vertex))
    with atomic(path) as tmp:
        plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex"), plyfile.PlyElement.describe(face, "face")],
                        text=False).write(str(tmp))
    return len(vertex), len(face)


VTI_BLOCK = 1 << 20            # bytes per zlib block of the .vti data


def vti(m, path, band=None):
    """Dense log-odds [nat] (float32) as VTK XML image data, zlib-compressed in blocks (VTK's
    vtkZLibDataCompressor layout): origin at the first voxel centre, spacing the voxel size, x
    fastest (VTK's point order). Returns the point count."""
    import base64
    import zlib

    d = m.dense(band)
    z0 = 0 if band is None else m._band(band)[0]
    nz, ny, nx = d.shape
    n_values = d.size
    per_block = VTI_BLOCK // 4
    blocks = []
    for start in range(0, n_values, per_block):
        chunk = (d.reshape(-1)[start:start + per_block] * np.float32(1.0 / logodds.SCALE)).astype("<f4")
        blocks.append(zlib.compress(chunk.tobytes(), 1))
    last = (n_values * 4) % VTI_BLOCK or (VTI_BLOCK if n_values else 0)
    header = np.array([len(blocks), VTI_BLOCK, last] + [len(b) for b in blocks], "<u8")
    payload = base64.b64encode(header.tobytes()).decode() + base64.b64encode(b"".join(blocks)).decode()
    origin = np.asarray(m.spec.origin_m) + 0.5 * m.spec.voxel_m + np.array([0, 0, z0 * m.spec.voxel_m])
    s = m.spec.voxel_m
    xml = (f'<?xml version="1.0"?>\n'
           f'<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
           f'compressor="vtkZLibDataCompressor">\n'
           f'  <ImageData WholeExtent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}" '
           f'Origin="{float(origin[0])!r} {float(origin[1])!r} {float(origin[2])!r}" Spacing="{s!r} {s!r} {s!r}">\n'
           f'    <Piece Extent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}">\n'
           f'      <PointData Scalars="log_odds">\n'
           f'        <DataArray type="Float32" Name="log_odds" format="binary">\n{payload}\n        </DataArray>\n'
           f'      </PointData>\n    </Piece>\n  </ImageData>\n</VTKFile>\n')
    with atomic(path) as tmp:
        Path(tmp).write_text(xml)
    return n_values


def costmap(m, path, band=None, threshold_nats=1.0):
    """The 2D projection over ``band`` as a ROS map_server map: ``path`` (.pgm) and ``.yaml``
    beside it (trinary mode, resolution, origin of the lower-left cell). Returns (ny, nx)."""
    grid = m.projection(band, threshold_nats)
    # map_server's trinary PGM: 0 (black) occupied, 254 free, 205 unknown; rows from the top (max y)
    pixels = np.where(grid == 100, 0, np.where(grid == 0, 254, 205)).astype(np.uint8)[::-1]
    pgm = Path(path)
    yaml_path = pgm.with_suffix(".yaml")
    header = f"P5\n# radarcl costmap\n{pixels.shape[1]} {pixels.shape[0]}\n255\n".encode()
    with atomic(pgm) as tmp:
        Path(tmp).write_bytes(header + pixels.tobytes())
    x0, y0, _ = m.spec.origin_m
    text = (f"image: {pgm.name}\nmode: trinary\nresolution: {m.spec.voxel_m!r}\norigin: [{x0!r}, {y0!r}, 0.0]\n"
            f"negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with atomic(yaml_path) as tmp:
        Path(tmp).write_text(text)
    if not (grid != UNKNOWN).any():
        log.warning("%s: no column of the band was observed; the costmap is all unknown", pgm)
    return grid.shape


def is_bag(path):
    """True when ``path`` is a ROS 2 bag directory (it holds the bag's metadata.yaml)."""
    return (Path(path) / "metadata.yaml").is_file()


def rosbag(m, path, band=None, threshold_nats=1.0, frame_id="map"):
    """A ROS 2 bag (sqlite3, rosbags, no ROS install) with ``/map/points`` (PointCloud2 of the
    voxels above the threshold: x, y, z, log_odds float32) and ``/map/grid`` (OccupancyGrid of
    the projection over ``band``). Returns (points, cells)."""
    _need("rosbags")
    import time

    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    stamp_ns = time.time_ns()
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10 ** 9,
                                                                            nanosec=stamp_ns % 10 ** 9),
                                      frame_id=frame_id)
    centres, nats = m.occupied(threshold_nats)
    cloud = np.empty(len(centres), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("log_odds", "<f4")])
    cloud["x"], cloud["y"], cloud["z"] = centres.T
    cloud["log_odds"] = nats
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)        # 7 = FLOAT32
              for i, n in enumerate(("x", "y", "z", "log_odds"))]
    points = T["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=len(cloud), fields=fields,
                                              is_bigendian=False, point_step=16, row_step=16 * len(cloud),
                                              data=np.frombuffer(cloud.tobytes(), np.uint8), is_dense=True)
    grid = m.projection(band, threshold_nats)
    x0, y0, _ = m.spec.origin_m
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x0), y=float(y0), z=0.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    info = T["nav_msgs/msg/MapMetaData"](map_load_time=header.stamp, resolution=float(m.spec.voxel_m),
                                         width=grid.shape[1], height=grid.shape[0], origin=pose)
    occupancy = T["nav_msgs/msg/OccupancyGrid"](header=header, info=info, data=grid.reshape(-1).astype(np.int8))
    path = Path(path)
    with atomic(path) as tmp:                         # the bag is a directory: written whole, then renamed
        with Writer(tmp, version=8) as writer:
            c1 = writer.add_connection("/map/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
            c2 = writer.add_connection("/map/grid", "nav_msgs/msg/OccupancyGrid", typestore=ts)
            writer.write(c1, stamp_ns, ts.serialize_cdr(points, "sensor_msgs/msg/PointCloud2"))
            writer.write(c2, stamp_ns, ts.serialize_cdr(occupancy, "nav_msgs/msg/OccupancyGrid"))
    _warn_empty(m, path, len(cloud))
    return len(cloud), grid.size


FORMATS = {"octomap": octomap, "ply": ply_points, "mesh": ply_mesh, "vti": vti, "costmap": costmap, "rosbag": rosbag}
