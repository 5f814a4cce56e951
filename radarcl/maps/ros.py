"""The map for ROS: a map_server costmap (PGM + YAML) and a ROS 2 bag, both of the same trinary
projection (``Map.projection``: occupied, free, unknown), so Nav2 plans on what the map says.

The costmap is map_server's trinary image: 0 (black) occupied, 254 free, 205 unknown, rows
from the top (the largest y), with a YAML beside it (``mode: trinary``; map_server reads p =
(255 - pixel) / 255 against ``occupied_thresh`` 0.65 and ``free_thresh`` 0.196, which puts the
three values in the three classes). The bag is written by rosbags (no ROS install) as
``ros2 bag record`` would: its data file ``<bag>_0.db3`` named after the bag, with
  /map           nav_msgs/OccupancyGrid in ``frame_id`` (default ``map``), offered transient-local
                 and reliable (the latched map that Nav2's map_server serves and RViz's and
                 Nav2's map subscribers ask for)
  /map/points    sensor_msgs/PointCloud2 of the occupied voxels: x, y, z [m], log_odds [nat],
                 probability
  /trajectory    nav_msgs/Path: the sensor's pose of every frame, each stamped with its frame's time
  /tf_static     ``frame_id`` -> ``odom``, the identity (latched as /tf_static is): radarcl's map is
                 built in the frame of the first scan, which is where odometry starts (REP-105)
  /tf            ``odom`` -> ``radar`` at every frame's time: the sensor on its way
The map's messages are stamped with the recording's time (its last frame's, where the map
keeps its frames' times), else with when the map was saved; never with when the bag is written.
A ROS 2 user plays the bag and sees the map, the points, the path and the radar's frame in RViz
with the fixed frame ``map``.
"""

import contextlib
import os
import shutil
import time
from pathlib import Path

import numpy as np

from radarcl.io.files import atomic, clean_stale
from radarcl.io.trajectory import quaternions
from radarcl.maps.map import FREE_NATS, OCCUPIED_NATS, UNKNOWN

PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205
ODOM, SENSOR_FRAME = "odom", "radar"   # REP-105's odometry frame; the sensor's frame on /tf
INFINITE = (2147483647, 4294967295)   # rosbag2's "default" (infinite) duration in QoS profiles


def _cells(grid):
    return dict(occupied_cells=int((grid == 100).sum()), free_cells=int((grid == 0).sum()),
                unknown_cells=int((grid == UNKNOWN).sum()))


def costmap(m, path, band=None, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS):
    """The projection over ``band`` as a ROS map_server map: ``path`` (.pgm) and the ``.yaml``
    beside it (trinary, resolution, origin of the lower-left cell). Returns a dict: the files
    written and the cells by class."""
    grid = m.projection(band, occupied_nats, free_nats)
    pixels = np.where(grid == 100, PGM_OCCUPIED, np.where(grid == 0, PGM_FREE, PGM_UNKNOWN)).astype(np.uint8)[::-1]
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
    return dict(files=[pgm, yaml_path], shape=grid.shape, **_cells(grid))


def _latched():
    """The QoS ``/map`` is offered with: reliable, transient local, the last message kept."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    forever = QosTime(*INFINITE)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, forever, forever,
               QosLiveliness.AUTOMATIC, forever, False)


def _static():
    """The QoS /tf_static is offered with: reliable, transient local, the last message kept."""
    return _latched()


def rosbag(m, path, band=None, occupied_nats=OCCUPIED_NATS, free_nats=FREE_NATS, frame_id="map", stamp_ns=None,
           poses=None, times_ns=None):
    """A ROS 2 bag (sqlite3) at the directory ``path`` (see the module docstring): ``/map``
    (OccupancyGrid of the projection over ``band``), ``/map/points`` (the voxels above
    ``occupied_nats``) in ``frame_id``, and with the sensor ``poses`` (n, 4, 4) ``/trajectory``,
    ``/tf_static`` and ``/tf``, each pose at ``times_ns[i]`` (its frame's time; None: all at the
    map's stamp). The map is stamped with the last of ``times_ns``, else ``stamp_ns`` (default:
    now). Written beside ``path`` and renamed over it whole. Returns a dict: the files written,
    the points, the cells by class and the poses."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    poses = np.zeros((0, 4, 4)) if poses is None else np.asarray(poses, np.float64).reshape(-1, 4, 4)
    if times_ns is not None and len(times_ns) != len(poses):
        times_ns = None                 # times that do not match the poses place nothing
    if times_ns is not None and len(times_ns):
        stamp_ns = int(times_ns[-1])
    stamp_ns = int(stamp_ns) if stamp_ns is not None else time.time_ns()
    pose_ns = [stamp_ns] * len(poses) if times_ns is None else [int(t) for t in times_ns]

    def time_msg(t):
        return T["builtin_interfaces/msg/Time"](sec=t // 10 ** 9, nanosec=t % 10 ** 9)

    stamp = time_msg(stamp_ns)
    header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)
    centres, nats = m.occupied(occupied_nats)
    cloud = np.empty(len(centres), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("log_odds", "<f4"),
                                          ("probability", "<f4")])
    cloud["x"], cloud["y"], cloud["z"] = centres.T
    cloud["log_odds"], cloud["probability"] = nats, 1.0 / (1.0 + np.exp(-nats))
    fields = [T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)        # 7 = FLOAT32
              for i, n in enumerate(cloud.dtype.names)]
    step = cloud.dtype.itemsize
    points = T["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=len(cloud), fields=fields,
                                              is_bigendian=False, point_step=step, row_step=step * len(cloud),
                                              data=np.frombuffer(cloud.tobytes(), np.uint8), is_dense=True)
    grid = m.projection(band, occupied_nats, free_nats)
    x0, y0, _ = m.spec.origin_m
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x0), y=float(y0), z=0.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    info = T["nav_msgs/msg/MapMetaData"](map_load_time=stamp, resolution=float(m.spec.voxel_m),
                                         width=grid.shape[1], height=grid.shape[0], origin=pose)
    occupancy = T["nav_msgs/msg/OccupancyGrid"](header=header, info=info, data=grid.reshape(-1).astype(np.int8))
    q = quaternions(poses[:, :3, :3]) if len(poses) else np.zeros((0, 4))

    def transform(t, parent, child, p, r):
        return T["geometry_msgs/msg/TransformStamped"](
            header=T["std_msgs/msg/Header"](stamp=time_msg(t), frame_id=parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=float(p[0, 3]), y=float(p[1, 3]), z=float(p[2, 3])),
                rotation=T["geometry_msgs/msg/Quaternion"](x=float(r[1]), y=float(r[2]), z=float(r[3]), w=float(r[0]))))

    def pose_stamped(t, p, r):
        return T["geometry_msgs/msg/PoseStamped"](
            header=T["std_msgs/msg/Header"](stamp=time_msg(t), frame_id=frame_id),
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(p[0, 3]), y=float(p[1, 3]), z=float(p[2, 3])),
                orientation=T["geometry_msgs/msg/Quaternion"](x=float(r[1]), y=float(r[2]), z=float(r[3]), w=float(r[0]))))
    path = Path(path)
    clean_stale(path)
    # the bag is written whole in a hidden folder beside, under its own name (rosbag2 names the
    # data file after the bag), then renamed over ``path``
    work = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with Writer(work / path.name, version=8) as writer:
            c_map = writer.add_connection("/map", "nav_msgs/msg/OccupancyGrid", typestore=ts,
                                          offered_qos_profiles=[_latched()])
            c_points = writer.add_connection("/map/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
            tf_msg = "tf2_msgs/msg/TFMessage"
            if len(poses):
                c_static = writer.add_connection("/tf_static", tf_msg, typestore=ts, offered_qos_profiles=[_static()])
                c_tf = writer.add_connection("/tf", tf_msg, typestore=ts)
                c_path = writer.add_connection("/trajectory", "nav_msgs/msg/Path", typestore=ts)
                first = min(pose_ns[0], stamp_ns)
                if frame_id != ODOM:
                    writer.write(c_static, first, ts.serialize_cdr(T[tf_msg](transforms=[
                        transform(first, frame_id, ODOM, np.eye(4), (1.0, 0.0, 0.0, 0.0))]), tf_msg))
                for t, p, r in zip(pose_ns, poses, q):
                    writer.write(c_tf, t, ts.serialize_cdr(T[tf_msg](transforms=[
                        transform(t, ODOM if frame_id != ODOM else frame_id, SENSOR_FRAME, p, r)]), tf_msg))
            writer.write(c_map, stamp_ns, ts.serialize_cdr(occupancy, "nav_msgs/msg/OccupancyGrid"))
            writer.write(c_points, stamp_ns, ts.serialize_cdr(points, "sensor_msgs/msg/PointCloud2"))
            if len(poses):
                path_msg = T["nav_msgs/msg/Path"](header=header, poses=[pose_stamped(t, p, r)
                                                                       for t, p, r in zip(pose_ns, poses, q)])
                writer.write(c_path, stamp_ns, ts.serialize_cdr(path_msg, "nav_msgs/msg/Path"))
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
        os.replace(work / path.name, path)
    finally:
        with contextlib.suppress(OSError):
            shutil.rmtree(work)
    files = sorted(p for p in path.iterdir() if p.is_file())
    return dict(files=files, points=len(cloud), **_cells(grid), poses=len(poses))
