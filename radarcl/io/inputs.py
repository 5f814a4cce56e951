"""What a sensor's reader opens, as frames with their poses: ``open_input(sensor, path)``.

It opens whatever the sensor profile's reader reads (its [reader] ``format``, one of
``READERS``): a radarcl recording (``recording``), a directory of polar PNG scans in any of the
published layouts (``polar-png``, ``io.polar_layout``), a TI raw ADC capture (``ti-openradar``).
Each is a ``Reader`` of that table; sensor profiles (``config.sensors``) and ``radarcl fuse
--help`` take the formats from it, so a new one is a ``register`` here and its test. It returns a
``FrameSource``: the sensor (with its bin count filled from the data where the profile leaves
it out), the frames, one pose (or one per beam) and optional flags per frame, whether the
poses came from somewhere (``posed``: a caller refuses to fuse a moving radar at the origin),
notes, and a line saying what was read. Every size is checked against the sensor before a
frame reaches a device. No pyopencl imports here.

Poses of polar scans: the trajectory given (``poses``, any ``io.poses`` format), else the one
found beside the scans (``io.poses.find_beside``: Oxford odometry, RADIATE's GPS/IMU, Boreas'
applanix poses), put in the first scan's frame, checked for jumps and for covering every
azimuth's time, and interpolated per azimuth (the radar moves during its turn).
"""

import dataclasses
import operator
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.io import polar_png, recording, rosbag, scan_poses
from radarcl.io import poses as pose_files
from radarcl.io.polar_layout import PolarLayout
from radarcl.io.ti_adc import load_capture
from radarcl.io.trajectory import DEFAULT_MAX_SPEED_M_S
from radarcl.oracle import FLAG_SILENT


@dataclass
class FrameSource:
    """What ``open_input`` read: ``frames[i]`` with ``poses[i]`` ((4, 4) or (n_beams, 4, 4))
    and ``flags[i]`` (or None), for ``sensor``; ``summary`` says what was read, ``posed``
    whether the poses came from the data (False: every frame at the origin), ``notes`` what
    the readers repaired or assumed, ``trajectory`` the ``Trajectory`` the poses came from,
    ``times_ns`` each frame's UNIX time [ns] (its middle beam's; None where the input has none).
    Polar scans also offer ``levels[i]``, frame i as its uint8 levels of ``db_per_level`` dB
    each (``frames[i]`` is their power): a quarter of the bytes, for a mapping that converts
    them on the device (``Mapping.fuse_source``); None where frames are not levels; where
    ``differenced[i]`` is true, ``levels[i]`` holds its rows' differences instead
    (``polar_png.PolarScan.differenced``: the device sums them)."""

    sensor: object
    frames: object
    poses: object
    flags: object
    summary: str
    posed: bool = True
    notes: tuple = ()
    trajectory: object = None
    times_ns: object = None
    levels: object = None
    db_per_level: float = None
    differenced: object = None

    def __len__(self):
        return len(self.frames)

    def head(self, n):
        """The first ``n`` frames (all when there are fewer), read as lazily as these are."""
        n = min(int(n), len(self))
        return dataclasses.replace(self, frames=_Head(self.frames, n), poses=self.poses[:n], flags=self.flags[:n],
                                   summary=f"the first {n} of {self.summary}",
                                   times_ns=None if self.times_ns is None else self.times_ns[:n],
                                   levels=None if self.levels is None else _Head(self.levels, n),
                                   differenced=None if self.differenced is None else self.differenced[:n])


class _Head:
    """The first ``n`` items of a sequence that may read its items only when asked."""

    def __init__(self, items, n):
        self.items, self.n = items, n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        if not -self.n <= i < self.n:
            raise IndexError(i)
        return self.items[i % self.n]


def open_input(sensor, path, odometry=None, poses=None, poses_format=None, clock_offset_s=None,
               max_speed_m_s=DEFAULT_MAX_SPEED_M_S, poses_times=None, report=None, progress=None, **options):
    """A ``FrameSource`` for ``path`` read as ``sensor``'s [reader] format says (a file whose
    extension a reader claims, a recording's ``.npz``, is read by that reader whatever the
    profile says). Polar scans: their poses from ``poses`` (a file in ``poses_format``, see
    ``io.poses``; ``odometry`` is the older name for an Oxford odometry file), else found beside
    them; ``clock_offset_s``: how far the pose file's clock runs ahead of the radar's; a
    trajectory faster than ``max_speed_m_s`` is refused with the jump named. ``report(line)``
    hears what the readers repaired or assumed, ``progress(done, total, what)`` how far a long read
    has come. ``options``: a reader's own (``Reader.options``; None values are left out), e.g. a
    bag's ``topic``."""
    if isinstance(sensor, (str, Path)):
        raise ConfigError(f"open_input takes a sensor profile, got the name {str(sensor)!r}: load it with "
                          "radarcl.config.sensors.load, or call radarcl.open_input, which takes names")
    fmt = sensor.get("reader", "format", "recording")
    path = Path(path)
    if not path.exists():
        raise FrameFormatError(f"{path} does not exist")
    if fmt not in READERS:
        raise ConfigError(f"sensor {sensor.name} is read as {fmt!r}, which no reader reads; readers: "
                          f"{', '.join(READERS)}")
    reader = next((r for r in READERS.values() if (path.is_file() and path.suffix in r.claims)
                   or (r.recognises is not None and r.recognises(path))), READERS[fmt])
    options = {k: v for k, v in options.items() if v is not None}
    foreign = sorted(set(options) - set(reader.options))
    if foreign:
        raise ConfigError(f"{path} is read as {reader.what}, which takes no "
                          f"{', '.join('--' + k.replace('_', '-') for k in foreign)}")
    return reader.open(sensor, path, poses=poses or odometry,
                       poses_format=poses_format or ("oxford" if odometry and not poses else None),
                       clock_offset_s=clock_offset_s, max_speed_m_s=max_speed_m_s, poses_times=poses_times,
                       report=report, **({"progress": progress} if progress is not None else {}), **options)


def _check_frame(sensor, shape, dtype, what):
    expected = sensor.frame_shape()
    if tuple(shape) != tuple(expected) or np.dtype(dtype) != sensor.sample_dtype:
        hint = ""
        if not sensor.raw and tuple(shape[:-1]) == tuple(expected[:-1]) and shape[-1] != expected[-1]:
            hint = (f" ([range] n_bins = {expected[-1]}: leave it out to read the count from the data, and check "
                    "bin_spacing_m and [reader] meta_columns)")
        raise FrameFormatError(f"{what}: frames are {tuple(shape)} {np.dtype(dtype)}; sensor {sensor.name} "
                               f"expects {tuple(expected)} {sensor.sample_dtype}{hint}")


def _recording(sensor, path, **_):
    """A radarcl recording (``io.recording``): frames of any sensor with their poses and flags."""
    rec = recording.load(path)
    if not sensor.raw and sensor.n_bins() is None:
        sensor = sensor.with_bins(rec.frames.shape[-1])
    _check_frame(sensor, rec.frames.shape[1:], rec.frames.dtype, str(path))
    n_beams = sensor.lattice().n_beams
    if rec.poses.ndim == 4 and rec.poses.shape[1] != n_beams:
        raise FrameFormatError(f"{path}: per-beam poses for {rec.poses.shape[1]} beams; sensor {sensor.name} has {n_beams}")
    note = "" if rec.sensor == sensor.name else f" (recorded as sensor {rec.sensor})"
    flags = rec.flags if rec.flags is not None else [None] * len(rec)
    return FrameSource(sensor, rec.frames, rec.poses, flags, f"{len(rec)} frames of {path}{note}")


def _ti_capture(sensor, path, **_):
    """A TI raw ADC capture (``io.ti_adc``): one chirp per frame, the sensor still at the origin."""
    iq = load_capture(path)
    n = sensor.radar.n_samples
    if iq.shape[-1] != n:
        raise FrameFormatError(f"{path}: chirps of {iq.shape[-1]} samples; sensor {sensor.name} has {n}")
    chirps = iq.reshape(-1, n)
    frames = chirps.reshape(len(chirps), 1, 1, n)
    _check_frame(sensor, frames.shape[1:], frames.dtype, str(path))
    poses = np.broadcast_to(np.eye(4), (len(frames), 4, 4))
    return FrameSource(sensor, frames, poses, [None] * len(frames),
                       f"{len(frames)} chirps of {path} (one per frame, the sensor still at the origin)", posed=False)


def _polar(sensor, path, poses=None, poses_format=None, clock_offset_s=None, max_speed_m_s=DEFAULT_MAX_SPEED_M_S,
           poses_times=None, report=None, progress=None):
    """Polar PNG scans (``io.polar_png``) in the sensor's layout, placed by the trajectory given
    or found beside them (see the module docstring)."""
    layout = polar_png.PolarLayout.of(sensor)
    sequence = polar_png.read_sequence(path, layout, odometry=False, keep_levels=False,    # levels read as fused
                                       progress=progress)
    found = (Path(poses), poses_format) if poses else pose_files.find_beside(sequence.directory)
    track = None
    if found is not None:
        if not sequence.timed:
            raise FrameFormatError(f"{sequence.directory}: the scans have no times ([reader] timestamps = "
                                   f"{layout.timestamps!r} gave none), so no trajectory can place them; set "
                                   "[reader] timestamps, or fuse them with --still")
        track = pose_files.read_trajectory(found[0], found[1], clock_offset_s, poses_times, report)
    return place_scans(sensor, sequence.scans, track, f"polar scans of {sequence.directory}", max_speed_m_s)


def place_scans(sensor, scans, track, what, max_speed_m_s=DEFAULT_MAX_SPEED_M_S, notes=()):
    """A ``FrameSource`` of polar scans (``polar_png.PolarScan``, any reader's) placed by
    ``track`` (a ``Trajectory`` in any frame, or None: a still radar at the origin): the sensor's
    bin count from the scans where its profile leaves it out, every scan's size checked, the
    trajectory checked for jumps and put in the first scan's frame, a pose per azimuth."""
    notes = tuple(notes)
    if sensor.n_bins() is None:
        sensor = sensor.with_bins(scans[0].n_bins)
        notes += sensor.notes
    for s in scans:
        _check_frame(sensor, s.shape, np.float32, str(s.path))
    if track is not None:
        track.check_motion(max_speed_m_s)
        notes += track.notes
        track = track.relative_to(scans[0].start_ns)
        how = f"poses from {track.source}, in the first scan's frame"
    else:
        how = "no poses: a still radar at the origin"
    per_beam = scan_poses.BeamPoses(scans, track, sensor.n_azimuth)         # computed a scan at a time, as fused
    source = polar_source(sensor, scans, per_beam, f"{len(scans)} {what} ({how})")
    source.posed, source.notes, source.trajectory = track is not None, notes, track
    if track is not None:
        source.times_ns = np.array([s.middle_ns for s in scans], np.int64)
    return source


def _bag(sensor, path, poses=None, poses_format=None, clock_offset_s=None, max_speed_m_s=DEFAULT_MAX_SPEED_M_S,
         poses_times=None, report=None, topic=None, pose_topic=None, msg_dir=None, progress=None):
    """A ROS 2 bag (``io.rosbag``): its radar topic's scans, placed by the trajectory file given or
    the bag's own poses; a damaged bag gives the scans before the damage, named in the notes."""
    try:
        layout = PolarLayout.of(sensor)
    except ConfigError:
        raise ConfigError(f"{path} is a ROS 2 bag of polar radar scans; sensor {sensor.name} is no spinning radar "
                          "read from polar scans: give --sensor (e.g. navtech-cts350x; radarcl sensors lists them)") from None
    read = rosbag.read_scans(path, layout, topic=topic, msg_dir=msg_dir)
    track = None
    if poses:
        track = pose_files.read_trajectory(Path(poses), poses_format, clock_offset_s, poses_times, report)
    else:
        track = rosbag.read_trajectory(path, read.frame_id, pose_topic, msg_dir=msg_dir)
        if track is not None and clock_offset_s:
            track = track.shifted(int(round(clock_offset_s * 1e9)))
    return place_scans(sensor, read.scans, track, read.what, max_speed_m_s, read.notes)


def polar_source(sensor, scans, per_beam, summary):
    """A ``FrameSource`` of polar scans (``polar_png.PolarScan``) at per-azimuth poses
    (n, n_az, 4, 4), an array or a ``scan_poses.BeamPoses``: their power converted one scan at a
    time, azimuths not measured flagged silent (no evidence); their levels too, where every scan
    has the same dB per level."""
    flags = [np.where(s.valid, 0, FLAG_SILENT).astype(np.uint8) for s in scans]
    source = FrameSource(sensor, _PerScan(scans, operator.methodcaller("power")), per_beam, flags, summary)
    scales = {s.db_per_level for s in scans}
    if len(scales) == 1:
        source.levels, source.db_per_level = _PerScan(scans, operator.attrgetter("coded_levels")), scales.pop()
        source.differenced = [s.differenced for s in scans]
    return source


class _PerScan:
    """Polar scans read one at a time as ``read(scan)`` (their power is converted on access: a
    scan's float32 power is 4x its levels); ``scans`` the scans themselves."""

    def __init__(self, scans, read):
        self.scans, self.read = scans, read

    def __len__(self):
        return len(self.scans)

    def __getitem__(self, i):
        return self.read(self.scans[i])


@dataclass(frozen=True)
class Reader:
    """One [reader] format of a sensor profile.

    name: the profile's ``[reader] format``; what: what it reads, in a few words (``radarcl fuse``'s
    INPUT); describes: the same at length (its help); open(sensor, path, poses=, poses_format=,
    clock_offset_s=, max_speed_m_s=, poses_times=, report=, progress=): the ``FrameSource`` (a
    reader takes the trajectory options it uses and ignores the others; ``progress`` comes only
    when a caller asks for it); claims: extensions of files it reads whatever the profile's
    format; check_profile(sensor): raises ``ConfigError`` where the profile's [reader] table does
    not describe files it can read (run when a profile is loaded), or None; recognises(path): True
    for inputs it reads whatever the profile's format (a bag's folder), or None; options: the
    names of its own keyword arguments to ``open``."""

    name: str
    what: str
    describes: str
    open: Callable
    claims: tuple = ()
    check_profile: Callable = None
    recognises: Callable = None
    options: tuple = ()


def register(reader):
    """Add ``reader`` (a ``Reader``) to ``READERS``: sensor profiles may name it from then on."""
    if reader.name in READERS:
        raise ConfigError(f"input format {reader.name!r} is registered already")
    READERS[reader.name] = reader
    return reader


READERS = {}
register(Reader("recording", "a recording (.npz)", "a radarcl recording", _recording, claims=(".npz",)))
register(Reader("polar-png", "a directory of polar scans",
                "a directory of polar PNG scans in the sensor's layout, or a recording's directory holding them, with "
                "their poses from --poses or found beside them: Oxford's radar_odometry.csv, RADIATE's GPS/IMU, "
                "Boreas' applanix poses", _polar, check_profile=PolarLayout.of))
register(Reader("ti-openradar", "a TI capture", "a TI capture .npy/.txt", _ti_capture))
register(Reader("rosbag", "a ROS 2 bag", "a ROS 2 bag (its folder, or one .db3 or .mcap file): radar topics of "
                "Navtech's driver or polar sensor_msgs/Image scans in the sensor's layout, placed by --poses or the "
                "bag's nav_msgs/Odometry or /tf", _bag, claims=(".db3", ".mcap"), recognises=rosbag.is_bag,
                options=("topic", "pose_topic", "msg_dir")))
