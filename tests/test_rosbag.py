"""ROS 2 bags in (``io.rosbag``): bags built here from the shared Oxford scans with rosbags' own
writer, in both storages, fused to the same map as the PNG folder, bit for bit; poses from
nav_msgs/Odometry and /tf; `radarcl info BAG`; bad bags refused or cut at the damage."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from radarcl.cli import main
from radarcl.io import rosbag
from radarcl.io.poses import read_trajectory
from radarcl.io.trajectory import quaternions

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "navtech_oxford"
SCANS = DATA / "radar"
ODOMETRY = DATA / "gt" / "radar_odometry.csv"
# every array of the map file; only 'meta' (which names the input) may differ
MAP_ARRAYS = ("version", "origin_m", "voxel_m", "shape", "keys", "data", "poses", "brick_z", "knowledge", "looks",
              "reading")

pytestmark = pytest.mark.skipif(not SCANS.is_dir(), reason="the shared Oxford scans are not beside the checkout")


def typestore(pkg="nav_messages"):
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(rosbag.NAVTECH_FFT, f"{pkg}/msg/RadarFftDataMessage"))
    ts.register(get_types_from_msg(rosbag.NAVTECH_CONFIG, f"{pkg}/msg/RadarConfigurationMessage"))
    return ts


def _stamp(T, t_ns):
    return T["builtin_interfaces/msg/Time"](sec=int(t_ns) // 10 ** 9, nanosec=int(t_ns) % 10 ** 9)


def _pixels():
    from PIL import Image

    return [(int(p.stem) * 1000, np.asarray(Image.open(p))) for p in sorted(SCANS.glob("*.png"))]


def write_bag(path, storage="sqlite3", radar="image", poses=None, pose_topic="/odom", mount=None, extra=(),
              pkg="nav_messages"):
    """A rosbag2 of the Oxford scans: ``radar`` 'image' (sensor_msgs/Image of each PNG's
    pixels) or 'navtech' (Navtech driver messages, one per azimuth, as its publisher fills them),
    with ``poses`` (a Trajectory) as Odometry on ``pose_topic`` or as /tf of base_link with
    /tf_static ``mount`` (T_base_radar); ``extra``: (topic, type, [(t, message)]) more; ``pkg``: the
    Navtech driver's message package (``messages`` in its older releases)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = typestore(pkg)
    T = ts.types
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        def connection(topic, msgtype):
            return w.add_connection(topic, msgtype, typestore=ts)

        def put(conn, t, msg, msgtype):
            w.write(conn, t, ts.serialize_cdr(msg, msgtype))

        if radar == "image":
            c = connection("/radar/polar", "sensor_msgs/msg/Image")
            for t, px in _pixels():
                header = T["std_msgs/msg/Header"](stamp=_stamp(T, t), frame_id="radar")
                put(c, t, T["sensor_msgs/msg/Image"](header=header, height=px.shape[0], width=px.shape[1],
                                                     encoding="mono8", is_bigendian=0, step=px.shape[1],
                                                     data=px.reshape(-1).copy()), "sensor_msgs/msg/Image")
        elif radar == "navtech":
            fft, cfg = f"{pkg}/msg/RadarFftDataMessage", f"{pkg}/msg/RadarConfigurationMessage"
            c = connection("/radar_data/fft_data", fft)
            cc = connection("/radar_data/configuration_data", cfg)

            def be(v, fmt):
                return np.frombuffer(np.array(v, dtype=fmt).tobytes(), np.uint8).copy()

            pixels = _pixels()
            header = T["std_msgs/msg/Header"](stamp=_stamp(T, pixels[0][0] - 1000), frame_id="radar")
            put(cc, pixels[0][0] - 1000, T[cfg](header=header, azimuth_samples=be(400, ">u2"), encoder_size=be(5600, ">u2"),
                                                bin_size=be(0.0432, ">f8"), range_in_bins=be(3768, ">u2"),
                                                expected_rotation_rate=be(4, ">u2")), cfg)
            for k, (_, px) in enumerate(pixels):
                times = np.ascontiguousarray(px[:, :8]).view("<i8")[:, 0] * 1000
                counts = np.ascontiguousarray(px[:, 8:10]).view("<u2")[:, 0]
                for row in range(px.shape[0]):
                    t = int(times[row])
                    header = T["std_msgs/msg/Header"](stamp=_stamp(T, t), frame_id="radar")
                    data = px[row, 11:].copy()
                    put(c, t, T[fft](header=header, angle=be(counts[row] / 5600 * 360, ">u2"),
                                     azimuth=be(counts[row], ">u2"), sweep_counter=be(k, ">u2"),
                                     ntp_seconds=be(t // 10 ** 9, ">u4"), ntp_split_seconds=be(t % 10 ** 9, ">u4"),
                                     data=data, data_length=be(len(data), ">u2")), fft)
        if poses is not None:
            q = quaternions(poses.poses[:, :3, :3])
            quat = [T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=wq) for wq, x, y, z in q]
            points = [p[:3, 3] for p in poses.poses]
            if mount is None:
                c = connection(pose_topic, "nav_msgs/msg/Odometry")
                for t, p, r in zip(poses.times_ns, points, quat):
                    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                                                       orientation=r)
                    msg = T["nav_msgs/msg/Odometry"](
                        header=T["std_msgs/msg/Header"](stamp=_stamp(T, t), frame_id="odom"), child_frame_id="radar",
                        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](
                            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                            covariance=np.zeros(36)))
                    put(c, int(t), msg, "nav_msgs/msg/Odometry")
            else:
                def transform(t, parent, child, m):
                    (w_, x, y, z), = quaternions(m[None, :3, :3])
                    return T["geometry_msgs/msg/TransformStamped"](
                        header=T["std_msgs/msg/Header"](stamp=_stamp(T, t), frame_id=parent), child_frame_id=child,
                        transform=T["geometry_msgs/msg/Transform"](
                            translation=T["geometry_msgs/msg/Vector3"](x=m[0, 3], y=m[1, 3], z=m[2, 3]),
                            rotation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w_)))
                cs = connection("/tf_static", "tf2_msgs/msg/TFMessage")
                put(cs, int(poses.times_ns[0]), T["tf2_msgs/msg/TFMessage"](
                    transforms=[transform(poses.times_ns[0], "base_link", "radar", mount)]), "tf2_msgs/msg/TFMessage")
                c = connection("/tf", "tf2_msgs/msg/TFMessage")
                for t, p in zip(poses.times_ns, poses.poses):
                    put(c, int(t), T["tf2_msgs/msg/TFMessage"](transforms=[transform(t, "odom", "base_link", p)]),
                        "tf2_msgs/msg/TFMessage")
        for topic, msgtype, msgs in extra:
            c = connection(topic, msgtype)
            for t, msg in msgs:
                put(c, t, msg, msgtype)
    return Path(path)


def tum_file(path, track):
    """``track`` as a TUM file holding every float exactly (repr), the times to the nanosecond."""
    q = quaternions(track.poses[:, :3, :3])
    lines = [f"{t // 10 ** 9}.{t % 10 ** 9:09d} " + " ".join(repr(float(v)) for v in (*p[:3, 3], x, y, z, w))
             for t, p, (w, x, y, z) in zip(track.times_ns, track.poses, q)]
    Path(path).write_text("\n".join(lines) + "\n")
    return path


def fuse(inp, out, *more):
    assert main(["fuse", str(inp), "--sensor", "navtech-cts350x", "--out", str(out), "--no-report", "--no-progress",
                 *map(str, more)]) == 0
    return out


def same_map(a, b):
    za, zb = np.load(a), np.load(b)
    for k in MAP_ARRAYS:
        assert za[k].dtype == zb[k].dtype and np.array_equal(za[k], zb[k]), k
    assert int((za["data"] != 0).sum()) > 1000          # a map, not an empty one


@pytest.fixture(scope="module")
def from_files(tmp_path_factory):
    return fuse(SCANS, tmp_path_factory.mktemp("files") / "files.npz", "--poses", ODOMETRY)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize("radar", ["image", "navtech"])
def test_a_bag_fuses_to_the_same_map_as_the_files_bit_for_bit(from_files, tmp_path, storage, radar):
    bag = write_bag(tmp_path / "bag", storage, radar)
    same_map(fuse(bag, tmp_path / "bag.npz", "--poses", ODOMETRY), from_files)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_odometry_in_the_bag_places_the_scans_as_the_same_poses_from_a_file(tmp_path, storage):
    track = read_trajectory(ODOMETRY)
    bag = write_bag(tmp_path / "bag", storage, poses=track)
    tum = tum_file(tmp_path / "poses.tum", track)
    same_map(fuse(bag, tmp_path / "bag.npz"), fuse(SCANS, tmp_path / "files.npz", "--poses", tum))


def test_tf_through_a_fixed_mount_gives_the_radar_trajectory(tmp_path):
    track = read_trajectory(ODOMETRY)
    mount = np.eye(4)
    mount[:3, 3] = 1.2, -0.3, 0.8
    c, s = np.cos(0.3), np.sin(0.3)
    mount[:2, :2] = [[c, -s], [s, c]]
    base = track.poses @ np.linalg.inv(mount)            # base_link's poses that put the radar on track
    from radarcl.io.trajectory import Trajectory

    bag = write_bag(tmp_path / "bag", "mcap", poses=Trajectory(track.times_ns, base), mount=mount)
    got = rosbag.read_trajectory(bag, "radar")
    np.testing.assert_array_equal(got.times_ns, track.times_ns)
    np.testing.assert_allclose(got.poses, track.poses, rtol=0, atol=1e-12)   # float64 rounding of a product
    assert "/tf" in got.source


def test_info_lists_topics_types_and_counts(tmp_path, capsys):
    track = read_trajectory(ODOMETRY)
    bag = write_bag(tmp_path / "bag", "mcap", poses=track)
    assert main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "/radar/polar  sensor_msgs/msg/Image  11  (radar)" in out
    assert f"/odom         nav_msgs/msg/Odometry  {len(track)}  (poses)" in out


def test_a_single_storage_file_is_a_bag_too(from_files, tmp_path):
    bag = write_bag(tmp_path / "bag", "mcap")
    same_map(fuse(next(bag.glob("*.mcap")), tmp_path / "one.npz", "--poses", ODOMETRY), from_files)


def test_a_bag_without_radar_lists_its_topics(tmp_path, capsys):
    from rosbags.typesys import Stores, get_typestore

    T = get_typestore(Stores.ROS2_HUMBLE).types
    bag = write_bag(tmp_path / "bag", "sqlite3", radar="none",
                    extra=[("/chatter", "std_msgs/msg/String", [(1, T["std_msgs/msg/String"](data="hi"))])])
    assert main(["fuse", str(bag), "--sensor", "navtech-cts350x", "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert "has no radar topic radarcl reads; its topics: /chatter (std_msgs/msg/String)" in err
    assert not (tmp_path / "m.npz").exists()


def test_an_unknown_type_is_named_with_how_to_register_it(tmp_path, capsys):
    from rosbags.rosbag2 import Writer

    bag = tmp_path / "bag"
    with Writer(bag, version=8) as w:                   # a type whose definition the bag does not carry
        c = w.add_connection("/radar/custom", "acme_msgs/msg/Sweep", msgdef="", rihs01="RIHS01_" + "0" * 64)
        w.write(c, 1, b"\x00\x01\x00\x00")
    assert main(["fuse", str(bag), "--sensor", "navtech-cts350x", "--topic", "/radar/custom",
                 "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert "topic /radar/custom has type acme_msgs/msg/Sweep" in err
    assert "--msg-dir FOLDER holding acme_msgs/msg/Sweep.msg" in err
    msg = tmp_path / "defs" / "acme_msgs" / "msg"
    msg.mkdir(parents=True)
    (msg / "Sweep.msg").write_text("uint8[] data\n")
    assert main(["info", str(bag), "--msg-dir", str(tmp_path / "defs")]) == 0
    assert "acme_msgs/msg/Sweep  1" in capsys.readouterr().out


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_truncated_bag_fuses_the_scans_before_the_damage_and_names_it(tmp_path, storage, capsys):
    bag = write_bag(tmp_path / "bag", storage)
    data = next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
    cut = tmp_path / "cut"
    shutil.copytree(bag, cut)
    with open(cut / data.name, "r+b") as f:
        f.truncate(int(data.stat().st_size * 0.6))
    before = (cut / data.name).read_bytes()
    fuse(cut, tmp_path / "cut.npz", "--poses", ODOMETRY)
    err = capsys.readouterr().err
    kept = len(np.load(tmp_path / "cut.npz")["poses"])
    assert 0 < kept < 11
    assert f"{cut} is damaged after message {kept} (t = " in err and f"the {kept} scans before it are fused" in err
    assert (cut / data.name).read_bytes() == before                # the damaged bag is read, never repaired
    first = tmp_path / "first"
    first.mkdir()
    for p in sorted(SCANS.glob("*.png"))[:kept]:
        (first / p.name).symlink_to(p)
    same_map(tmp_path / "cut.npz", fuse(first, tmp_path / "first.npz", "--poses", ODOMETRY))


def test_a_bag_cut_before_its_first_whole_scan_is_refused(tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", "mcap")
    data = next(bag.glob("*.mcap"))
    with open(data, "r+b") as f:
        f.truncate(data.stat().st_size // 20)
    assert main(["fuse", str(bag), "--sensor", "navtech-cts350x", "--poses", str(ODOMETRY),
                 "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err
    assert f"{bag} is damaged" in err and "the file ends inside a record (cut short)" in err
    assert "so no scan is fused" in err
    assert not (tmp_path / "m.npz").exists()


def test_the_exported_bag_carries_tf_and_the_trajectory_stamped_with_the_recording_time(from_files, tmp_path):
    """`radarcl export --to rosbag` of the Oxford map: /tf_static (map -> odom, latched), /tf
    (odom -> radar per scan), /trajectory (nav_msgs/Path), each at its scan's time, the map at the
    last scan's, none at the time the bag was written; fused back, its poses are the map's."""
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    bag = tmp_path / "out"
    assert main(["export", str(from_files), "--to", "rosbag", "--out", str(bag)]) == 0
    ts = get_typestore(Stores.ROS2_HUMBLE)
    starts = [t for t, _ in _pixels()]          # not the scans' first azimuths: those of the file's columns
    poses = np.load(from_files)["poses"]
    got = {}
    with Reader(bag) as r:
        for c, t, raw in r.messages():
            got.setdefault(c.topic, []).append((t, ts.deserialize_cdr(raw, c.msgtype)))
        qos = {c.topic: c.ext.offered_qos_profiles for c in r.connections}
    assert set(got) == {"/map", "/map/points", "/tf", "/tf_static", "/trajectory"}
    assert qos["/tf_static"][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos["/map"][0].durability == QosDurability.TRANSIENT_LOCAL
    (t_static, static), = got["/tf_static"]
    tr = static.transforms[0]
    assert (tr.header.frame_id, tr.child_frame_id) == ("map", "odom") and tr.transform.rotation.w == 1.0
    times = [t for t, _ in got["/tf"]]
    scan_times = np.array(times, np.int64)
    assert len(times) == 11 and (np.diff(scan_times) > 0).all()
    # each pose at the time it was the sensor's, its scan's middle azimuth: the trajectory file's times,
    # half a turn (of 0.25 s) after the scan's start
    from radarcl.jobs.api import trajectory_path

    tum = [int(line.split()[0].replace(".", "")) for line in trajectory_path(from_files).read_text().splitlines()
           if not line.startswith("#")]
    assert times == tum, (times[:2], tum[:2])
    assert all(0.1e9 < t - s < 0.15e9 for t, s in zip(times, starts)), (times[:2], starts[:2])
    (t_map, occupancy), = got["/map"]
    assert t_map == times[-1] and occupancy.header.stamp.sec == times[-1] // 10 ** 9
    assert occupancy.header.frame_id == "map"
    path = got["/trajectory"][0][1]
    assert [p.header.stamp.sec * 10 ** 9 + p.header.stamp.nanosec for p in path.poses] == times
    from radarcl.io.trajectory import rotations

    for p, (_, tf), expected in zip(path.poses, got["/tf"], poses):
        q = p.pose.orientation
        m = np.eye(4)
        m[:3, :3] = rotations(np.array([[q.w, q.x, q.y, q.z]]))[0]
        m[:3, 3] = p.pose.position.x, p.pose.position.y, p.pose.position.z
        np.testing.assert_allclose(m, expected, rtol=0, atol=1e-9)   # float64 -> quaternion -> float64
        t = tf.transforms[0]
        assert (t.header.frame_id, t.child_frame_id) == ("odom", "radar")
        assert t.transform.translation.x == p.pose.position.x


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_type_the_bag_defines_is_decoded_from_its_own_definition(tmp_path, storage, capsys):
    """A custom type radarcl has never seen, written with its definition in the bag (rosbag2
    metadata version 8 in sqlite3, a schema in MCAP): listed as known, decoded field by field."""
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg("std_msgs/Header header\nfloat64 temperature_c\nstring mode\n",
                                   "acme_msgs/msg/RadarStatus"))
    msgs = [(10 ** 9 * k, ts.types["acme_msgs/msg/RadarStatus"](
        header=ts.types["std_msgs/msg/Header"](stamp=ts.types["builtin_interfaces/msg/Time"](sec=k, nanosec=0),
                                               frame_id="radar"), temperature_c=40.5 + k, mode="scan"))
            for k in range(1, 4)]
    from rosbags.rosbag2 import StoragePlugin, Writer

    bag = tmp_path / "bag"
    with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3) as w:
        c = w.add_connection("/radar/status", "acme_msgs/msg/RadarStatus", typestore=ts)
        for t, m in msgs:
            w.write(c, t, ts.serialize_cdr(m, "acme_msgs/msg/RadarStatus"))
    assert main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "/radar/status  acme_msgs/msg/RadarStatus  3" in out and "unknown" not in out
    with rosbag.Bag(bag) as b:
        got = [(t, m.temperature_c, m.mode) for _, _, t, m in b.messages({"/radar/status"})]
    assert got == [(10 ** 9, 41.5, "scan"), (2 * 10 ** 9, 42.5, "scan"), (3 * 10 ** 9, 43.5, "scan")]


def test_topic_chooses_among_radar_topics(from_files, tmp_path, capsys):
    from rosbags.typesys import Stores, get_typestore

    T = get_typestore(Stores.ROS2_HUMBLE).types
    t, px = _pixels()[0]
    other = T["sensor_msgs/msg/Image"](header=T["std_msgs/msg/Header"](stamp=_stamp(T, t), frame_id="radar2"),
                                       height=px.shape[0], width=px.shape[1], encoding="mono8", is_bigendian=0,
                                       step=px.shape[1], data=px.reshape(-1).copy())
    bag = write_bag(tmp_path / "bag", "sqlite3", extra=[("/radar2/polar", "sensor_msgs/msg/Image", [(t, other)])])
    assert main(["fuse", str(bag), "--sensor", "navtech-cts350x", "--poses", str(ODOMETRY),
                 "--out", str(tmp_path / "m.npz")]) == 2
    assert "has 2 radar topics (/radar/polar, /radar2/polar); choose one with --topic" in capsys.readouterr().err
    same_map(fuse(bag, tmp_path / "m.npz", "--poses", ODOMETRY, "--topic", "/radar/polar"), from_files)
    assert main(["fuse", str(bag), "--sensor", "navtech-cts350x", "--topic", "/radar3", "--poses", str(ODOMETRY),
                 "--out", str(tmp_path / "n.npz")]) == 2
    assert "has no topic /radar3; its topics: /radar/polar, /radar2/polar" in capsys.readouterr().err


def test_the_older_navtech_package_name_reads_the_same(from_files, tmp_path):
    bag = write_bag(tmp_path / "bag", "sqlite3", "navtech", pkg="messages")
    same_map(fuse(bag, tmp_path / "bag.npz", "--poses", ODOMETRY), from_files)
