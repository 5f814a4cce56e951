"""`radarcl live` and `radarcl replay`: a radar's byte stream fused into a map as it arrives.

Bytes -> a protocol parser (``io.beam_protocol`` or ``io.ti_uart``, in the port's reader thread)
-> beams in a queue -> ``LiveMapper`` (this thread): the beams that arrived since the last fuse
are fused at once, each frame's share restricted to the azimuths that arrived
(``Fusion.restrict``), so the map lags the radar by one fuse, not by a frame. A part of a frame
fused this way sums to exactly what the whole frame gives (integer log-odds): the live map, a
replay of its recording and an offline fusion of the same beams are bit-identical.

The map is saved every ``checkpoint_s`` (a map store writes the changed bricks only): a crash
loses at most the beams since the last checkpoint, whose count the store's manifest keeps
("stream"). Ctrl-C finishes the fuse under way, saves and ends with a summary.
"""

import json
import logging
import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io import beam_protocol, ti_uart
from radarcl.io.stream import StreamCounters

log = logging.getLogger(__name__)
KEPT_FRAMES = 8          # beams of this many frames back are still taken (and told from duplicates)


@dataclass
class Beam:
    """One beam as the mapper takes it, from either protocol."""

    frame: int
    azimuth: int
    elevation: int
    timestamp_ns: int          # the radar's clock (beam protocol) or the receive time (TI UART)
    samples: np.ndarray
    pose: np.ndarray = None
    arrived: float = 0.0       # time.perf_counter() when its last byte was parsed


def parser_for(sensor, on_beam, clock):
    """The parser of ``sensor``'s protocol, delivering ``Beam``s to ``on_beam``; ``clock()`` is
    the receive time [ns] of the chunk being parsed (TI frames carry no usable time)."""
    if sensor.protocol == "ti":
        antennas, q_bits = ti_scaling(sensor)

        def ti_frame(frame):
            values = frame.range_profile
            if values is None:                     # a frame without the range profile TLV: nothing to map
                return
            on_beam(Beam(frame.frame_number, 0, 0, clock(), ti_uart.profile_power(values, antennas, q_bits),
                         arrived=time.perf_counter()))
        return ti_uart.TiParser(ti_frame)

    def beam(p):
        on_beam(Beam(p.frame, p.azimuth, p.elevation, p.timestamp_ns, p.samples, p.pose, time.perf_counter()))
    return beam_protocol.BeamParser(beam)


def ti_scaling(sensor):
    """(antennas, Q bits) of a TI range profile, from the sensor profile's [stream] keys."""
    return int(sensor.get("stream", "range_profile_antennas", 1)), int(sensor.get("stream", "range_profile_q", 9))


class PoseSource:
    """Where a frame's pose comes from: the packets' own (first beam of the frame), else a
    pose file interpolated at the beam's time, else a fixed ``mount`` (4, 4)."""

    def __init__(self, mount=None, track=None):
        self.mount = np.eye(4) if mount is None else np.asarray(mount, np.float64)
        self.track = track                     # (times_ns (n,), poses (n, 4, 4)) or None

    def __call__(self, beam):
        if beam.pose is not None:
            return beam.pose
        if self.track is not None:
            return interpolate_pose(*self.track, beam.timestamp_ns)
        return self.mount


def interpolate_pose(times_ns, poses, t_ns):
    """The pose at ``t_ns``: positions interpolated linearly, rotations by slerp of the two
    nearest poses' quaternions; held at the ends."""
    i = int(np.searchsorted(times_ns, t_ns))
    if i <= 0 or i >= len(times_ns):
        return poses[0 if i <= 0 else -1]
    a = (t_ns - times_ns[i - 1]) / max(1, times_ns[i] - times_ns[i - 1])
    out = np.eye(4)
    out[:3, 3] = (1 - a) * poses[i - 1][:3, 3] + a * poses[i][:3, 3]
    q0, q1 = _quaternion(poses[i - 1][:3, :3]), _quaternion(poses[i][:3, :3])
    if q0 @ q1 < 0:
        q1 = -q1
    theta = np.arccos(np.clip(q0 @ q1, -1, 1))
    q = q0 if theta < 1e-9 else (np.sin((1 - a) * theta) * q0 + np.sin(a * theta) * q1) / np.sin(theta)
    out[:3, :3] = _rotation(q / np.linalg.norm(q))
    return out


def _quaternion(r):
    w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
    if w > 1e-6:
        return np.array([w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)])
    k = int(np.argmax(np.diag(r)))                 # a half turn: from the largest diagonal term
    i, j = (k + 1) % 3, (k + 2) % 3
    q = np.zeros(4)
    q[1 + k] = np.sqrt(max(0.0, 1 + r[k, k] - r[i, i] - r[j, j])) / 2
    q[1 + i] = (r[i, k] + r[k, i]) / (4 * q[1 + k])
    q[1 + j] = (r[j, k] + r[k, j]) / (4 * q[1 + k])
    q[0] = (r[j, i] - r[i, j]) / (4 * q[1 + k])
    return q


def _rotation(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def read_pose_file(path):
    """A pose file: CSV or whitespace rows ``t_s x y z roll pitch yaw`` (REP-103, metres and
    radians; # comments) -> (times_ns, poses (n, 4, 4)), sorted and checked."""
    from radarcl.errors import FrameFormatError

    try:
        rows = np.loadtxt(path, delimiter=None if not str(path).endswith(".csv") else ",", ndmin=2, comments="#")
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"{path} is not a pose file of rows 't_s x y z roll pitch yaw' ({exc})") from exc
    if rows.shape[1] != 7 or len(rows) < 1 or not np.isfinite(rows).all():
        raise FrameFormatError(f"{path}: expected finite rows of 7 numbers (t_s x y z roll pitch yaw), got {rows.shape}")
    if np.any(np.diff(rows[:, 0]) <= 0):
        raise FrameFormatError(f"{path}: times must increase row by row")
    poses = np.stack([pose_matrix(r[1:]) for r in rows])
    return np.rint(rows[:, 0] * 1e9).astype(np.int64), poses


def pose_matrix(values):
    """(x, y, z, roll, pitch, yaw) [m, rad] -> 4x4 (REP-103: ``geometry.pose_from_xyz_rpy``)."""
    from radarcl.geometry import pose_from_xyz_rpy

    return pose_from_xyz_rpy(*(float(v) for v in values))


class LiveMapper:
    """Beams -> the map. Built on the first beam (which must match the sensor: refused with both
    shapes otherwise, before anything is fused); ``add(beams)`` fuses them, ``save()`` checkpoints.

    runtime: an OpenCL ``Runtime``; config: a ``mapconfig.Resolved``; saver: a ``store.MapSaver``
    (or None); poses: a ``PoseSource``; on_fused(bricks): told the bricks each fuse changed,
    rows (bx, by, bz, pool slot) (the view stream)."""

    def __init__(self, runtime, config, saver=None, poses=None, on_fused=None):
        self.runtime, self.config, self.saver = runtime, config, saver
        self.poses = poses or PoseSource()
        self.on_fused = on_fused
        self.mapping = None
        self.stats = dict(beams=0, frames=0, fuses=0, duplicates=0, refused=0, late=0, checkpoints=0,
                          saved_beams=0)
        self.latencies = []                     # seconds from a beam's last byte to its evidence in the map
        self.fused_log = None                   # a list: (frame, azimuth, elevation) of every beam fused
        self.trajectory = []                    # one pose per frame
        self._frame_poses = {}
        self._seen = {}                         # frame id -> the beams of it fused so far
        self._newest = None

    # -- the pipeline is built before the stream (or on the first beam, when it fixes the bin count)
    def prepare(self, first=None):
        """Build the pipeline (compiling its kernels takes a second or two: better before the
        radar streams). A sensor whose bin count comes from the data waits for ``first``.
        Returns True when built."""
        from radarcl.pipeline import Mapping

        if self.mapping is not None:
            return True
        sensor, config = self.config.sensor, self.config
        if sensor.raw:
            want = (sensor.radar.n_samples, np.dtype(sensor.sample_dtype))
        elif sensor.n_bins() is not None:
            want = (sensor.n_bins(), np.dtype(np.float32))
        elif first is not None:
            want = (len(first.samples), np.dtype(np.float32))
            if first.samples.dtype == np.float32:
                config = config.for_sensor(sensor.with_bins(len(first.samples)))
        else:
            return False
        if sensor.spinning:
            raise ConfigError(f"sensor {sensor.name} spins: live fusion takes radars that scan a sector "
                              "(a turn cannot be fused azimuth range by azimuth range)")
        self.config, self._want = config, want
        self.mapping = Mapping.from_config(self.runtime, config=config)
        self._frame = np.zeros(self.mapping.frame_shape, self.mapping.range_fft.dtype
                               if self.mapping.range_fft is not None else np.float32)
        return True

    def _index(self, beam):
        lat = self.mapping.fusion.lattice
        if not (0 <= beam.azimuth < lat.n_az and 0 <= beam.elevation < lat.n_el):
            return None
        return (beam.azimuth,) if lat.n_el == 1 else (beam.azimuth, beam.elevation)

    # -- fusing ---------------------------------------------------------------------------------------
    def add(self, beams):
        """Fuse ``beams`` (arrival order): one fuse per frame they belong to. Returns the number fused."""
        if not beams:
            return 0
        self.prepare(beams[0])
        first = beams[0]
        if self.stats["beams"] == 0 and (len(first.samples), first.samples.dtype) != self._want:
            raise ConfigError(f"the radar sends beams of {len(first.samples)} {first.samples.dtype} samples; sensor "
                              f"{self.config.sensor.name} expects {self._want[0]} {self._want[1]} (choose the "
                              "matching --sensor)")
        groups = {}
        for b in beams:
            index = self._index(b) if (len(b.samples), b.samples.dtype) == self._want else None
            if index is None:
                self.stats["refused"] += 1
                continue
            newest = self._newest
            if newest is not None and b.frame < newest - KEPT_FRAMES:       # the radar restarted its count
                self._seen.clear()
                self._frame_poses.clear()
                newest = None
            if b.frame not in self._seen:
                if newest is not None and b.frame < newest:
                    self.stats["late"] += 1
                for old in [f for f in self._seen if f < b.frame - KEPT_FRAMES]:
                    self._seen.pop(old)
                    self._frame_poses.pop(old, None)
            self._newest = b.frame if newest is None else max(newest, b.frame)
            seen = self._seen.setdefault(b.frame, set())
            if index in seen:
                self.stats["duplicates"] += 1
                continue
            seen.add(index)
            groups.setdefault(b.frame, []).append((index, b))
        fused = sum(self._fuse(frame_id, items) for frame_id, items in groups.items())
        self.runtime.queue.finish()
        done = time.perf_counter()
        for items in groups.values():
            self.latencies.extend(done - b.arrived for _, b in items)
        return fused

    def _fuse(self, frame_id, items):
        if frame_id not in self._frame_poses:
            pose = self.poses(items[0][1])
            self._frame_poses[frame_id] = pose
            self.trajectory.append(pose)
            self.stats["frames"] += 1
        frame = self._frame
        frame[...] = 0
        for index, b in items:
            frame[index] = b.samples
        if self.fused_log is not None:
            self.fused_log.extend((frame_id, b.azimuth, b.elevation) for _, b in items)
        azimuths = [b.azimuth for _, b in items]
        plan = self.mapping.fuse(frame, self._frame_poses[frame_id], azimuths=(min(azimuths), max(azimuths)))
        self.stats["beams"] += len(items)
        self.stats["fuses"] += 1
        if self.on_fused is not None and len(plan.bricks):
            self.on_fused(plan.bricks)
        return len(items)

    # -- checkpoints ----------------------------------------------------------------------------------
    def save(self, extra=None):
        """Write the map (and the stream's counts) through the saver; returns the beams it holds."""
        if self.saver is None or self.mapping is None:
            return self.stats["saved_beams"]
        self.runtime.queue.finish()
        stream = dict(self.stats, **(extra or {}))
        stream["saved_beams"] = self.stats["beams"]
        self.saver(self.mapping.grid, np.array(self.trajectory) if self.trajectory else None, stream=stream)
        self.stats["saved_beams"] = self.stats["beams"]
        self.stats["checkpoints"] += 1
        return self.stats["saved_beams"]


class Session:
    """Feeds bytes (with their receive time) to a recorder and the sensor's parser; parsed
    beams wait in ``beams`` (a queue) for the mapper's thread. ``feed`` is what the port's
    reader thread, a replay or a test calls."""

    def __init__(self, sensor, recorder=None):
        self.beams = queue.Queue()
        self.recorder = recorder
        self._now = 0
        self.parser = parser_for(sensor, self.beams.put, lambda: self._now)
        self.parse_s = 0.0

    def feed(self, t_ns, data):
        if self.recorder is not None:
            self.recorder(t_ns, data)
        self._now = t_ns
        start = time.thread_time()
        self.parser.data_received(data)
        self.parse_s += time.thread_time() - start

    def drain(self, wait=0.1):
        """The beams parsed so far (waits up to ``wait`` seconds for the first)."""
        out = []
        try:
            out.append(self.beams.get(timeout=wait) if wait else self.beams.get_nowait())
            while True:
                out.append(self.beams.get_nowait())
        except queue.Empty:
            pass
        return out

    @property
    def counters(self):
        return self.parser.counters


def status(mapper, counters, wall_s, parse_s):
    """The figures a status line and ``--json-status`` show."""
    lat = np.asarray(mapper.latencies[-10000:]) * 1e3
    c = counters.as_dict() if isinstance(counters, StreamCounters) else dict(counters)
    return dict(beams=mapper.stats["beams"], frames=mapper.stats["frames"], beams_per_s=mapper.stats["beams"] / max(wall_s, 1e-9),
                bytes_per_s=c["bytes_in"] / max(wall_s, 1e-9),
                latency_p50_ms=float(np.percentile(lat, 50)) if lat.size else None,
                latency_p99_ms=float(np.percentile(lat, 99)) if lat.size else None,
                parser_cpu_share=parse_s / max(wall_s, 1e-9), wall_s=wall_s,
                saved_beams=mapper.stats["saved_beams"], checkpoints=mapper.stats["checkpoints"],
                duplicates=mapper.stats["duplicates"] + c["duplicates"], refused=mapper.stats["refused"],
                late=mapper.stats["late"], **{k: c[k] for k in ("bytes_in", "bytes_dropped", "crc_failures",
                                                                   "header_failures", "sequence_gaps", "packets")})


def status_line(s):
    lat = "-" if s["latency_p50_ms"] is None else f"{s['latency_p50_ms']:.0f}/{s['latency_p99_ms']:.0f} ms"
    return (f"live: {s['beams']} beams in {s['frames']} frames ({s['beams_per_s']:.0f}/s, "
            f"{s['bytes_per_s'] / 1e3:.1f} kB/s), latency p50/p99 {lat}, dropped {s['bytes_dropped']} B, "
            f"CRC {s['crc_failures']}, gaps {s['sequence_gaps']}, saved {s['saved_beams']}")


def write_status(path, s):
    """``--json-status``: the status as JSON, replaced atomically."""
    from radarcl.outputs import atomic

    with atomic(path) as tmp:
        with open(tmp, "w") as f:
            json.dump(s, f)


def run(session, mapper, *, until=None, checkpoint_s=5.0, status_every_s=1.0, say=None, json_status=None,
        stop=None, after_fuse=None):
    """The mapper's loop: fuse what arrives, checkpoint every ``checkpoint_s``, report status,
    until ``until()`` is true and nothing is left, or ``stop`` (an Event) is set, or Ctrl-C /
    SIGTERM (the fuse under way finishes and the map is saved; SIGTERM re-raises after that).
    ``after_fuse()`` runs after each pass (the view stream). Returns the final status dict."""
    start = last_save = last_status = time.perf_counter()
    interrupted = None
    try:
        while not (stop is not None and stop.is_set()):
            mapper.add(session.drain())
            if after_fuse is not None:
                after_fuse()
            now = time.perf_counter()
            if checkpoint_s and now - last_save >= checkpoint_s and mapper.stats["beams"] > mapper.stats["saved_beams"]:
                mapper.save(extra=dict(counters=session.counters.as_dict()))
                last_save = now
            if now - last_status >= status_every_s:
                s = status(mapper, session.counters, now - start, session.parse_s)
                if say is not None:
                    say(status_line(s))
                if json_status:
                    write_status(json_status, s)
                last_status = now
            if until is not None and until() and session.beams.empty():
                mapper.add(session.drain(wait=0))
                break
    except (KeyboardInterrupt, SystemExit) as exc:
        interrupted = exc
    mapper.add(session.drain(wait=0))
    mapper.save(extra=dict(counters=session.counters.as_dict()))
    s = status(mapper, session.counters, time.perf_counter() - start, session.parse_s)
    if json_status:
        write_status(json_status, s)
    if isinstance(interrupted, SystemExit):
        raise interrupted
    s["interrupted"] = interrupted is not None
    return s


def replay(path, mapper_factory, speed="max", say=None):
    """Feed a ``--record`` stream file through the same parser and mapper: at the recorded pace
    (``speed`` "recorded") or as fast as it parses ("max"). Returns (mapper, status, header)."""
    from radarcl.io.stream import read_stream

    header, records = read_stream(path)
    sensor, mapper = mapper_factory(header)
    session = Session(sensor)
    done = threading.Event()
    start_wall, first_t = time.perf_counter(), None

    def feed_all():
        nonlocal first_t
        try:
            for t_ns, data in records:
                if speed == "recorded":
                    first_t = t_ns if first_t is None else first_t
                    due = start_wall + (t_ns - first_t) / 1e9 - time.perf_counter()
                    if due > 0 and done.wait(due):
                        return
                session.feed(t_ns, data)
        finally:
            done.set()

    feeder = threading.Thread(target=feed_all, name="radarcl-replay", daemon=True)
    feeder.start()
    s = run(session, mapper, until=done.is_set, say=say)
    feeder.join()
    if records.torn and say is not None:
        say(f"the recording ends in a torn record ({records.torn} bytes left over: the writer was stopped mid-write)")
    return mapper, s, header


def over_pty(runtime, config, packets, faults=None, baud=None, saver=None, recorder=None, timeout_s=600):
    """Play ``packets`` (bytes) through the emulator on a fresh pseudo-terminal into a live
    session, as `radarcl live` reads a radar (the bench and the tests). Returns (mapper, status,
    emulator, intact flags per packet); ``mapper.fused_log`` lists the beams that reached the map."""
    import os

    from radarcl.io import emulator
    from radarcl.io.stream import PortReader, open_port

    faults = faults or emulator.Faults()
    master, name, slave = emulator.open_pty()
    try:
        session = Session(config.sensor, recorder)
        mapper = LiveMapper(runtime, config, saver)
        mapper.fused_log = []
        mapper.prepare()
        reader = PortReader(open_port(name), session.feed).start()      # reading before anything is sent
        damaged, intact = faults.apply(packets)
        emu = emulator.Emulator(damaged, lambda b: os.write(master, b), baud, faults).start()
        stop = threading.Event()
        timer = threading.Timer(timeout_s, stop.set)
        timer.start()
        try:
            s = run(session, mapper, until=lambda: emu.done.is_set() and session.counters.bytes_in >= emu.sent,
                    checkpoint_s=0.5 if saver is not None else 0, stop=stop)
        finally:
            timer.cancel()
            reader.stop()
            emu.stop()
        if stop.is_set():
            raise TimeoutError(f"the emulated stream did not arrive in {timeout_s} s")
        return mapper, s, emu, intact
    finally:
        os.close(master)
        os.close(slave)
