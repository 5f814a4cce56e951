"""The live map's library half: a radar's beams, parsed from its byte stream, fused as they come.

Bytes -> a protocol parser (``io.beam_protocol`` or ``io.ti_uart``; ``parser_for``) -> ``Beam``s
in a queue (``Session``, fed by the port's reader thread) -> ``LiveMapper`` (the mapper's
thread): the beams that arrived since the last fuse are fused at once, each frame's share
restricted to the azimuths that arrived (``Fusion.restrict``), so the map lags the radar by one
fuse, not by a frame. A part of a frame fused this way sums to exactly what the whole frame gives
(integer log-odds). A frame's pose comes from the packets, a pose file or a fixed mount
(``PoseSource``). The loop that runs them, with checkpoints and status, is ``jobs.live``.
The live path's design and invariants: docs/design/live.md.
"""

import bisect
import queue
import time
from dataclasses import dataclass

import numpy as np

from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.geometry import check_pose, interpolate_pose
from radarcl.io import beam_protocol, ti_uart
from radarcl.pipeline import Mapping

KEPT_FRAMES = 8          # beams of this many frames back are still taken (and told from duplicates)
FIRST_FRAME_RESERVE = 3  # slots made before the stream: this times a level frame's bricks at the grid's
                         # centre (the paper's stand tilted reaches 2.4 times as many)


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


class LiveMapper:
    """Beams -> the map. Built on the first beam (which must match the sensor: refused with both
    shapes otherwise, before anything is fused); ``add(beams)`` fuses them, ``flush()`` fuses
    what waits for its pair, ``save()`` checkpoints.

    The map does not depend on how the stream was cut into fuses: the range FFT transforms real
    beams in pairs (flat beams 2j and 2j + 1 share one complex FFT, and its rounding), so a beam
    waits for its pair before it is fused, and is fused alone only when its pair is lost (a
    beam of a later frame came first, or the stream ended); either way the decision depends on
    the order of the beams alone. So the live map, the replay of its recording and the offline
    map of the same beams are bit-identical.

    runtime: an OpenCL ``Runtime``; config: a ``mapconfig.Resolved`` (or a sensor's name); saver: a ``maps.disk.MapSaver``
    (or None); poses: a ``PoseSource``; on_fused(bricks): told the bricks each fuse changed,
    rows (bx, by, bz, pool slot) (the view stream)."""

    LATENCY_WINDOW_S = 10.0     # the status line's latency covers the beams of the last 10 s

    def __init__(self, runtime, config, saver=None, poses=None, on_fused=None):
        self.runtime, self.config, self.saver = runtime, mapconfig.as_resolved(config), saver
        self.poses = poses or PoseSource()
        self.on_fused = on_fused
        self.mapping = None
        self.stats = dict(beams=0, frames=0, fuses=0, duplicates=0, refused=0, late=0, checkpoints=0,
                          saved_beams=0, bad_poses=0, beams_missing=0)
        self.latencies = []                     # seconds from a beam's last byte to its evidence in the map
        self.latency_times = []                 # time.perf_counter() when each of those was fused
        self.new_pose_latencies = []            # those of the beams fused in a frame's first fuse (a new pose planned)
        self.fused_log = None                   # a list: (frame, azimuth, elevation) of every beam fused
        self.trajectory = []                    # one pose per frame
        self._frame_poses = {}
        self._seen = {}                         # frame id -> the beams of it fused or waiting so far
        self._held = {}                         # (frame, pair) -> (index, beam): waiting for its pair
        self._alone = set()                     # (frame, pair) whose first beam was fused alone
        self._newest = None

    # -- the pipeline is built before the stream (or on the first beam, when it fixes the bin count)
    def prepare(self, first=None):
        """Build the pipeline (compiling its kernels takes a second or two: better before the
        radar streams). A sensor whose bin count comes from the data waits for ``first``.
        Returns True when built."""
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
        # what a frame would otherwise wait for: the planner's kernel, the pool's first chunk, and
        # (as the map reaches new ground) the next chunk, grown ahead on a thread of its own
        grid = self.mapping.grid
        frame_bricks = self.mapping.fusion.warm_up()          # a frame at the grid's centre, level
        grid.reserve(FIRST_FRAME_RESERVE * frame_bricks)        # a tilted one reaches more
        self.mapping.fusion.warm_up()                           # now the gather too, on the pool
        grid.grow_ahead(max(frame_bricks, grid.chunk_bricks))
        fft = self.mapping.range_fft
        self._paired = fft is not None and not fft.complex_input      # real beams share an FFT in pairs
        self._frame = np.zeros(self.mapping.frame_shape, fft.dtype if fft is not None else np.float32)
        return True

    def _index(self, beam):
        lat = self.mapping.fusion.lattice
        if not (0 <= beam.azimuth < lat.n_az and 0 <= beam.elevation < lat.n_el):
            return None
        return (beam.azimuth,) if lat.n_el == 1 else (beam.azimuth, beam.elevation)

    def _pair(self, beam):
        """(pair number, the flat index of the other beam of the pair or None)."""
        lat = self.mapping.fusion.lattice
        flat = beam.azimuth * lat.n_el + beam.elevation
        other = flat ^ 1
        return flat >> 1, (other if other < lat.n_az * lat.n_el else None)

    # -- fusing ---------------------------------------------------------------------------------------
    def add(self, beams):
        """Fuse ``beams`` (arrival order): one fuse per frame they belong to (a beam whose pair
        has not arrived waits, see the class docstring). Returns the number fused."""
        if not beams:
            return 0
        self.prepare(beams[0])
        first = beams[0]
        if self.stats["beams"] == 0 and not self._seen and (len(first.samples), first.samples.dtype) != self._want:
            raise ConfigError(f"the radar sends beams of {len(first.samples)} {first.samples.dtype} samples; sensor "
                              f"{self.config.sensor.name} expects {self._want[0]} {self._want[1]} (choose the "
                              "matching --sensor)")
        ready = []                              # (frame, index, beam, fused with its pair absent)
        for b in beams:
            index = self._index(b) if (len(b.samples), b.samples.dtype) == self._want else None
            if index is None:
                self.stats["refused"] += 1
                continue
            if b.pose is not None and not _usable_pose(b.pose):
                self.stats["bad_poses"] += 1    # a CRC-valid packet whose pose is not a rigid transform
                continue
            newest = self._newest
            if newest is not None and b.frame < newest - KEPT_FRAMES:       # the radar restarted its count
                ready += self._release(lambda f: True)
                self._count_missing(list(self._seen))
                self._seen.clear()
                self._frame_poses.clear()
                newest = None
            if b.frame not in self._seen:
                if newest is not None and b.frame < newest:
                    self.stats["late"] += 1
                old = [f for f in self._seen if f < b.frame - KEPT_FRAMES]
                self._count_missing(old)
                for f in old:
                    self._seen.pop(f)
                    self._frame_poses.pop(f, None)
            self._newest = b.frame if newest is None else max(newest, b.frame)
            seen = self._seen.setdefault(b.frame, set())
            if index in seen:
                self.stats["duplicates"] += 1
                continue
            seen.add(index)
            if self._paired:
                pair, other = self._pair(b)
                key = (b.frame, pair)
                if key in self._held:                   # its pair waited for it
                    ready.append((b.frame, *self._held.pop(key), False))
                    ready.append((b.frame, index, b, False))
                elif other is None:
                    ready.append((b.frame, index, b, False))
                elif key in self._alone:                # its pair was fused without it
                    ready.append((b.frame, index, b, True))
                else:
                    self._held[key] = (index, b)
                ready += self._release(lambda f: f < self._newest)      # the radar moved on: pairs lost
            else:
                ready.append((b.frame, index, b, False))
        return self._fuse_ready(ready)

    def flush(self):
        """Fuse the beams still waiting for their pair (the stream ended). Returns the number fused."""
        return self._fuse_ready(self._release(lambda f: True)) if self.mapping is not None else 0

    def _release(self, older):
        out = []
        for key in [k for k in self._held if older(k[0])]:
            index, b = self._held.pop(key)
            self._alone.add(key)
            out.append((key[0], index, b, True))
        self._alone = {k for k in self._alone if k[0] in self._seen}
        return out

    def _count_missing(self, frames):
        """Beams of ``frames`` (about to be forgotten) that never arrived."""
        n = self.mapping.fusion.lattice.n_az * self.mapping.fusion.lattice.n_el
        self.stats["beams_missing"] += sum(n - len(self._seen[f]) for f in frames)

    def missing(self):
        """Beams missing from the frames seen so far (each frame's lattice minus what arrived)."""
        if self.mapping is None:
            return self.stats["beams_missing"]
        n = self.mapping.fusion.lattice.n_az * self.mapping.fusion.lattice.n_el
        return self.stats["beams_missing"] + sum(n - len(s) for s in self._seen.values())

    def _fuse_ready(self, ready):
        groups = {}
        for frame_id, index, b, alone in ready:
            # a beam whose pair was fused alone before goes into a second pass, so that the two
            # never share an FFT, however the stream was cut
            passes = groups.setdefault(frame_id, [[], []])
            late_pair = alone and any(o is not b and self._pair(o)[0] == self._pair(b)[0] for _, o in passes[0])
            passes[1 if late_pair else 0].append((index, b))
        fused = 0
        new = {f for f in groups if f not in self._frame_poses}
        for frame_id, passes in groups.items():
            for items in passes:
                if items:
                    fused += self._fuse(frame_id, items)
        self.runtime.queue.finish()
        done = time.perf_counter()
        for frame_id, passes in groups.items():
            for items in passes:
                self.latencies.extend(done - b.arrived for _, b in items)
                self.latency_times.extend(done for _ in items)
                if frame_id in new:
                    self.new_pose_latencies.extend(done - b.arrived for _, b in items)
        return fused

    def recent_latencies(self, now=None):
        """Latencies [s] of the beams fused in the last ``LATENCY_WINDOW_S`` seconds."""
        now = time.perf_counter() if now is None else now
        lo = bisect.bisect_left(self.latency_times, now - self.LATENCY_WINDOW_S)
        return self.latencies[lo:]

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


def _usable_pose(pose):
    try:
        check_pose(pose)
    except ConfigError:
        return False
    return True


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
