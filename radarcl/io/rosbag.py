"""ROS 2 bags as radar input, read with rosbags (sqlite3 and MCAP storage; no ROS install).

A bag is its folder (``metadata.yaml`` beside the data files) or one ``.db3`` or ``.mcap`` file.
Radar topics of these types are read (``RADAR_TYPES``), each turn of the radar becoming one
``polar_png.PolarScan`` exactly as a polar PNG of the same rows would:

  sensor_msgs/msg/Image            one turn per image, 8-bit (mono8), in the sensor profile's
                                   polar layout ([reader] table, as for PNG scans: Oxford's
                                   azimuth rows with metadata columns, or RADIATE's range rows);
                                   without timestamp columns the image's header stamp times it
  <pkg>/msg/RadarFftDataMessage    Navtech's ROS 2 driver: one message per azimuth, its fields
                                   network-order byte arrays; a turn ends where the azimuth
                                   counter wraps, the encoder size and azimuth count from the
                                   driver's RadarConfigurationMessage (else the profile's); each
                                   azimuth timed by its header stamp (the driver stamps it on
                                   receipt; the radar's NTP fields are not trusted to be set)

TI's ROS 2 driver (mmwave-ti-ros) publishes detected points (PointCloud2), not range profiles,
so no TI topic carries what the evidence model reads.

Message definitions: ROS 2 Humble's standard types, Navtech's driver messages (below), every
definition the bag carries (rosbag2 metadata version 8, an MCAP's schemas), and ``.msg`` files
of a folder (``<package>/msg/<Name>.msg``). Poses (``read_trajectory``): a nav_msgs/Odometry
topic, or /tf (with /tf_static to the radar's frame), of the radar's frame or a frame fixed to
it; quaternions turned into matrices as a TUM file's are (``trajectory.rotations``), so the same
numbers give the same map. A bag damaged part-way gives the scans before the damage and says
where it stopped; nothing after it is guessed.
"""

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.io import bag_salvage
from radarcl.io.polar_png import assemble_scan, decode_scan
from radarcl.io.trajectory import Trajectory, rotations

# Navtech's ROS 2 driver messages, as defined in Navtech's IA SDK (github.com/norlab-ulaval/
# iasdk_navtech_radar, ros2/src/messages/msg/, a copy of Navtech's own; its publisher
# colossus_publisher.cpp fills every field with Navtech::Networking::to_vector of a network-order
# integer). Older driver releases name the package ``messages``, newer ones ``nav_messages``.
NAVTECH_FFT = """std_msgs/Header header
uint8[] angle
uint8[] azimuth
uint8[] sweep_counter
uint8[] ntp_seconds
uint8[] ntp_split_seconds
uint8[] data
uint8[] data_length
"""
NAVTECH_CONFIG = """std_msgs/Header header
uint8[] azimuth_samples
uint8[] encoder_size
uint8[] bin_size
uint8[] range_in_bins
uint8[] expected_rotation_rate
"""
NAVTECH_PACKAGES = ("nav_messages", "messages")
IMAGE = "sensor_msgs/msg/Image"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"


def _navtech_types():
    from rosbags.typesys import get_types_from_msg

    types = {}
    for pkg in NAVTECH_PACKAGES:
        types.update(get_types_from_msg(NAVTECH_FFT, f"{pkg}/msg/RadarFftDataMessage"))
        types.update(get_types_from_msg(NAVTECH_CONFIG, f"{pkg}/msg/RadarConfigurationMessage"))
    return types


def is_bag(path):
    """True for a rosbag2 folder (one holding ``metadata.yaml``)."""
    path = Path(path)
    return path.is_dir() and (path / "metadata.yaml").is_file()


def stamp_ns(header):
    """A std_msgs/Header's stamp as UNIX ns."""
    return int(header.stamp.sec) * 10 ** 9 + int(header.stamp.nanosec)


class Bag:
    """An open bag (a context manager) with every type it needs registered: ``topics`` lists
    them, ``messages(topics)`` yields (topic, type, log time [ns], message) in time order and
    stops at damage, which ``damage`` then names. A storage file that rosbags cannot open (a
    truncated MCAP has no summary; SQLite refuses a damaged page) is read record by record as
    far as it goes (``io.bag_salvage``), its damage named from the start."""

    def __init__(self, path, msg_dir=None):
        from rosbags.rosbag2 import Reader
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(path)
        self.damage = self.reader = self.salvage = None
        try:
            self.reader = Reader(self.path)
            self.reader.open()
            self.connections = [(c.topic, c.msgtype, c.msgdef.format.name, c.msgdef.data)
                                for c in self.reader.connections]
        except Exception as exc:            # noqa: BLE001 - rosbags raises its own, sqlite3's, yaml's, OSError
            self.salvage = bag_salvage.Salvage(self.path, f"{type(exc).__name__}: {exc}")
            self.connections = self.salvage.connections
        self.typestore = get_typestore(Stores.ROS2_HUMBLE)
        self.typestore.register(_navtech_types())
        if msg_dir is not None:
            self.typestore.register(msg_folder_types(msg_dir))
        self.unknown = {}
        for topic, msgtype, fmt, data in self.connections:
            if msgtype not in self.typestore.fielddefs:
                self._register_carried(msgtype, fmt, data)

    def _register_carried(self, msgtype, fmt, data):
        """The bag's own definition of a type (MSG or IDL text), when it carries one."""
        from rosbags.typesys import get_types_from_idl, get_types_from_msg

        try:
            if fmt == "MSG" and data:
                self.typestore.register(get_types_from_msg(data, msgtype))
                return
            if fmt == "IDL" and data:
                self.typestore.register(get_types_from_idl(data))
                return
        except Exception as exc:            # noqa: BLE001 - a definition that does not parse
            self.unknown[msgtype] = f"its definition in the bag does not parse ({exc})"
            return
        self.unknown[msgtype] = "the bag carries no definition of it"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.salvage is not None:
            self.salvage.close()
        elif self.reader is not None:
            self.reader.close()

    @property
    def topics(self):
        """[(topic, type, message count)] in name order (counts of a damaged file: as far as it reads)."""
        if self.salvage is not None:
            return self.salvage.topics()
        return [(name, info.msgtype, info.msgcount) for name, info in sorted(self.reader.topics.items())]

    def listing(self):
        """The topics as lines: name, type, count, and what radarcl reads it as."""
        topics = self.topics
        width = max((len(t) for t, _, _ in topics), default=5)
        if self.salvage is None:
            head = (f"{self.path}: {self.reader.message_count} messages, {self.reader.duration / 1e9:.3f} s from "
                    f"t = {self.reader.start_time / 1e9:.3f} s")
        else:
            head = f"{self.path}: {self.salvage.damage}; the messages before it:"
        lines = [head]
        for topic, msgtype, count in topics:
            use = ("radar" if radar_kind(msgtype) else "poses" if msgtype == ODOMETRY or topic == "/tf" else
                   "fixed frames" if topic == "/tf_static" else
                   "unknown type" if msgtype in self.unknown else "")
            lines.append(f"  {topic:<{width}}  {msgtype}  {count}{'  (' + use + ')' if use else ''}")
        return lines

    def _raw(self, topics):
        if self.salvage is not None:
            yield from self.salvage.messages(topics)
            return
        conns = [c for c in self.reader.connections if c.topic in topics]
        for c, t, raw in self.reader.messages(connections=conns):
            yield c.topic, c.msgtype, t, raw

    def messages(self, topics):
        """(topic, type, log time [ns], message) of ``topics`` in time order; damage (a message
        that cannot be read or decoded) ends the walk and is kept in ``damage``."""
        for topic, msgtype, _, _ in self.connections:
            if topic in topics and msgtype in self.unknown:
                raise ConfigError(unknown_type(topic, msgtype, self.unknown[msgtype]))
        n, last = 0, None
        it = self._raw(topics)
        while True:
            try:
                item = next(it, None)
                if item is None:
                    break
                topic, msgtype, t, raw = item
                msg = self.typestore.deserialize_cdr(raw, msgtype)
            except Exception as exc:        # noqa: BLE001 - sqlite3, MCAP, zstd and CDR errors alike
                where = f"after message {n} (t = {last / 1e9:.3f} s)" if last is not None else "before its first message"
                self.damage = f"{self.path} is damaged {where}: {bag_salvage.said(exc)}"
                return
            n, last = n + 1, t
            yield topic, msgtype, t, msg
        if self.salvage is not None:
            self.damage = f"{self.salvage.damage}, after message {n}" + (f" (t = {last / 1e9:.3f} s)" if n else "")


def unknown_type(topic, msgtype, why):
    """The sentence for a topic whose type cannot be decoded."""
    return (f"topic {topic} has type {msgtype}, which radarcl cannot decode ({why}); register it with "
            f"--msg-dir FOLDER holding {msgtype.split('/')[0]}/msg/{msgtype.split('/')[-1]}.msg")


def msg_folder_types(folder):
    """Types of every ``<package>/msg/<Name>.msg`` under ``folder`` (rosbags parses them)."""
    from rosbags.typesys import get_types_from_msg

    folder = Path(folder)
    files = sorted(folder.rglob("*.msg")) if folder.is_dir() else []
    if not files:
        raise ConfigError(f"--msg-dir {folder}: no .msg files under it; expected <package>/msg/<Name>.msg")
    types = {}
    for f in files:
        if f.parent.name != "msg":
            raise ConfigError(f"{f}: a message definition must sit in <package>/msg/ to be named")
        try:
            types.update(get_types_from_msg(f.read_text(), f"{f.parent.parent.name}/msg/{f.stem}"))
        except Exception as exc:            # noqa: BLE001 - rosbags' parser errors
            raise ConfigError(f"{f}: not a ROS message definition ({exc})") from exc
    return types


def radar_kind(msgtype):
    """'image', 'navtech' or None: how a topic of ``msgtype`` is read."""
    if msgtype == IMAGE:
        return "image"
    if any(msgtype == f"{p}/msg/RadarFftDataMessage" for p in NAVTECH_PACKAGES):
        return "navtech"
    return None


@dataclass
class BagScans:
    """What ``read_scans`` read: the scans, the radar's frame id, what was read, notes."""

    scans: list
    frame_id: str
    what: str
    notes: tuple = ()


def choose_topic(bag, topic):
    """(topic, kind) of the radar topic: ``topic`` when given, else the one radar topic."""
    types = {t: m for t, m, _ in bag.topics}
    if topic is not None:
        if topic not in types:
            raise ConfigError(f"{bag.path} has no topic {topic}; its topics: {', '.join(types) or 'none'}")
        if types[topic] in bag.unknown:
            raise ConfigError(unknown_type(topic, types[topic], bag.unknown[types[topic]]))
        kind = radar_kind(types[topic])
        if kind is None:
            raise ConfigError(f"topic {topic} has type {types[topic]}, which is no radar type radarcl reads "
                              f"(sensor_msgs/msg/Image polar scans, Navtech's RadarFftDataMessage)")
        return topic, kind
    radar = [t for t, m in types.items() if radar_kind(m)]
    if len(radar) == 1:
        return radar[0], radar_kind(types[radar[0]])
    listed = "; ".join(f"{t} ({m})" for t, m in types.items()) or "none"
    if not radar:
        unknown = [t for t, m in types.items() if m in bag.unknown]
        hint = f"; {unknown_type(unknown[0], types[unknown[0]], bag.unknown[types[unknown[0]]])}" if unknown else ""
        raise ConfigError(f"{bag.path} has no radar topic radarcl reads; its topics: {listed}{hint}")
    raise ConfigError(f"{bag.path} has {len(radar)} radar topics ({', '.join(radar)}); choose one with --topic")


def read_scans(path, layout, topic=None, msg_dir=None):
    """``BagScans`` of the radar topic (``topic``, or the bag's only one) read with ``layout``."""
    with Bag(path, msg_dir) as bag:
        topic, kind = choose_topic(bag, topic)
        read = _images if kind == "image" else _navtech
        scans, frame_id, notes = read(bag, topic, layout)
        if bag.damage:
            notes += (f"{bag.damage}; the {len(scans)} scans before it are fused",)
    if not scans:
        raise FrameFormatError(f"{path}: no whole scan on {topic}" + (f" ({bag.damage})" if bag.damage else ""))
    return BagScans(scans, frame_id, f"scans of {path} topic {topic}", notes)


def _images(bag, topic, layout):
    """sensor_msgs/Image polar scans: decoded as a PNG of the same pixels is (``decode_scan``)."""
    raws = []
    for _, _, t, msg in bag.messages({topic}):
        name = Path(f"{bag.path}:{topic}#{len(raws)}")
        if msg.encoding not in ("mono8", "8UC1"):
            raise FrameFormatError(f"{name}: image encoding {msg.encoding!r}; polar scans are 8-bit (mono8)")
        h, w, step = int(msg.height), int(msg.width), int(msg.step)
        data = np.asarray(msg.data, np.uint8)
        if step < w or data.size < step * h:
            raise FrameFormatError(f"{name}: {data.size} bytes for {h} rows of step {step} (width {w})")
        raws.append((name, stamp_ns(msg.header), data[:step * h].reshape(h, step)[:, :w], msg.header.frame_id))
    period = None
    times = np.array([r[1] for r in raws], np.int64)
    if len(times) > 1 and (np.diff(times) > 0).all():
        period = int(np.median(np.diff(times)))
    stamped = layout.timestamp_column < 0
    scans = [decode_scan(raw, layout, name, t if stamped else None, period) for name, t, raw, _ in raws]
    return scans, raws[0][3] if raws else "", ()


def _be(field, fmt, what, name):
    data = bytes(np.asarray(field, np.uint8))
    if len(data) != struct.calcsize(fmt):
        raise FrameFormatError(f"{name}: {what} holds {len(data)} bytes; Navtech's driver writes "
                               f"{struct.calcsize(fmt)} (network order)")
    return struct.unpack(fmt, data)[0]


def _navtech(bag, topic, layout):
    """Navtech FFT messages, one per azimuth, gathered into turns where the azimuth wraps."""
    config_topics = {t for t, m, _ in bag.topics if m.endswith("/msg/RadarConfigurationMessage")}
    encoder, n_az, notes = layout.encoder_counts, layout.n_azimuth, ()
    scans, turn, frame_id, dropped = [], [], "", 0

    def close():
        nonlocal dropped
        if not turn:
            return
        if n_az is not None and len(turn) != n_az:
            dropped += 1
        else:
            t, counts, levels = zip(*turn)
            counts = np.array(counts)
            scans.append(assemble_scan(Path(f"{bag.path}:{topic}@{t[0]}"), np.array(t, np.int64),
                                       counts / encoder * 2 * np.pi, np.ones(len(turn), bool),
                                       np.stack(levels), layout))
        turn.clear()

    for tpc, _, _, msg in bag.messages({topic} | config_topics):
        name = f"{bag.path}:{tpc}"
        if tpc in config_topics:
            encoder = _be(msg.encoder_size, ">H", "encoder_size", name)
            n_az = _be(msg.azimuth_samples, ">H", "azimuth_samples", name)
            continue
        frame_id = msg.header.frame_id
        azimuth = _be(msg.azimuth, ">H", "azimuth", name)
        if azimuth >= encoder:
            raise FrameFormatError(f"{name}: azimuth {azimuth} is past the encoder's {encoder} counts per turn")
        if turn and azimuth <= turn[-1][1]:
            close()
        turn.append((stamp_ns(msg.header), azimuth, np.asarray(msg.data, np.uint8)))
        if len({len(x[2]) for x in turn}) > 1:
            raise FrameFormatError(f"{name}: azimuths of one turn hold {len(turn[0][2])} and {len(msg.data)} bins")
    if bag.damage is None:
        close()                             # the last turn, unless damage cut it short
    elif turn:
        dropped += 1
    if dropped:
        notes += (f"{dropped} turn(s) of {topic} without all {n_az} azimuths left out",)
    return scans, frame_id, notes


def _matrix(translation, rotation):
    p = np.eye(4)
    p[:3, :3] = rotations(np.array([[rotation.w, rotation.x, rotation.y, rotation.z]], np.float64))[0]
    p[:3, 3] = translation.x, translation.y, translation.z
    return p


def read_trajectory(path, frame_id, pose_topic=None, msg_dir=None):
    """The radar's ``Trajectory`` from the bag: ``pose_topic`` (nav_msgs/Odometry or
    tf2_msgs/TFMessage), else its one Odometry topic, else /tf; the poses of ``frame_id`` or of
    the frame /tf_static fixes it to (composed with that fixed transform). None where the bag
    holds no poses."""
    with Bag(path, msg_dir) as bag:
        types = {t: m for t, m, _ in bag.topics}
        if pose_topic is not None:
            if types.get(pose_topic) not in (ODOMETRY, TF):
                raise ConfigError(f"--pose-topic {pose_topic}: {'no such topic' if pose_topic not in types else types[pose_topic]}"
                                  f"; poses come from {ODOMETRY} or {TF}")
            topic = pose_topic
        else:
            odometry = [t for t, m in types.items() if m == ODOMETRY]
            if len(odometry) > 1:
                raise ConfigError(f"{path} has {len(odometry)} odometry topics ({', '.join(odometry)}); choose one "
                                  "with --pose-topic")
            topic = odometry[0] if odometry else ("/tf" if types.get("/tf") == TF else None)
        if topic is None:
            return None
        fixed = {}                          # child -> (parent, T_parent_child) from /tf_static
        if types.get("/tf_static") == TF:
            for _, _, _, msg in bag.messages({"/tf_static"}):
                for tr in msg.transforms:
                    fixed[tr.child_frame_id] = (tr.header.frame_id, _matrix(tr.transform.translation,
                                                                            tr.transform.rotation))
        samples = {}                        # child frame -> [(t, T_world_child)]
        for _, msgtype, _, msg in bag.messages({topic}):
            if msgtype == ODOMETRY:
                p = msg.pose.pose
                samples.setdefault(msg.child_frame_id, []).append((stamp_ns(msg.header), _matrix(p.position, p.orientation)))
            else:
                for tr in msg.transforms:
                    samples.setdefault(tr.child_frame_id, []).append(
                        (stamp_ns(tr.header), _matrix(tr.transform.translation, tr.transform.rotation)))
        damage = bag.damage
    mount, frame = np.eye(4), frame_id
    while frame not in samples and frame in fixed:     # up the fixed frames to one that moves
        parent, t_parent_child = fixed[frame]
        mount, frame = t_parent_child @ mount, parent
    if frame not in samples:
        moving = ", ".join(sorted(samples)) or "none"
        raise FrameFormatError(f"{path}: {topic} moves the frames {moving}, and neither the radar's frame "
                               f"{frame_id!r} nor a frame /tf_static fixes it to; give --poses FILE")
    rows = sorted(samples[frame], key=lambda s: s[0])
    times = np.array([t for t, _ in rows], np.int64)
    poses = np.stack([p for _, p in rows]) @ mount
    notes = (f"poses of {path} end early: {damage}",) if damage else ()
    return Trajectory(times, poses, f"{path} topic {topic} ({frame})", notes)
