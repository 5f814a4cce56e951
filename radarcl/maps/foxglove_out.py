"""The growing map out to Foxglove: the Foxglove WebSocket protocol served on 127.0.0.1 (the
foxglove-sdk package) and the same channels recorded to an MCAP file, for ``radarcl live`` and
``radarcl fuse`` (``--foxglove``, ``--mcap``).

Channels (foxglove schemas, protobuf-encoded by the SDK), all in the frame ``map``:
  /map           foxglove.Grid: the map's trinary projection (``Map.projection``), one int8 cell
                 each (100 occupied, 0 free, -1 unknown, as nav_msgs/OccupancyGrid), origin at
                 the lower-left cell's corner
  /map/voxels    foxglove.PointCloud: the occupied voxels' centres (x, y, z float32 [m]) and their
                 log-odds (float32 [nat]) (``Map.occupied``)
  /scan          foxglove.PointCloud: the latest frame's CFAR detections, each at its bin's range
                 along its beam, in the map frame (at most ``MAX_SCAN_POINTS``)
  /trajectory    foxglove.PosesInFrame: the sensor's pose of every frame so far
  /tf            foxglove.FrameTransforms: map -> radar (the latest pose)

Rate and isolation: the map's loop offers a snapshot at most ``rate_hz`` times a second
(``due``/``offer``: copying the map off the device is the only work it does for this); a
thread of its own encodes and logs the newest snapshot, an older one not yet sent is replaced,
never queued. The SDK keeps a bounded queue per client and drops its oldest messages when a
client does not read, so no client, stalled or gone, holds up the map.
"""

import threading
import time

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io.trajectory import quaternions
from radarcl.maps.map import FREE_NATS, OCCUPIED_NATS, Map

HOST = "127.0.0.1"               # loopback only: the map is never served to another address
MAX_SCAN_POINTS = 200_000        # a frame's detections beyond this are left out of /scan
FRAME, SENSOR_FRAME = "map", "radar"
STOP_WAIT_S = 2.0                # how long closing waits for clients to take what is queued for them


def scan_points(mapping, poses):
    """(n, 3) float32 map-frame points of the latest frame's CFAR detections (``mapping``: a
    ``pipeline.Mapping``; ``poses``: the frame's 4x4 or per-beam poses): each at its bin's range
    along its beam's direction of the sensor's lattice."""
    mask = mapping.detection.cfar.arrays["mask"].get(mapping.runtime.queue)
    lattice = mapping.fusion.lattice
    beam, b = np.nonzero(mask.reshape(lattice.n_beams, -1))
    if len(beam) > MAX_SCAN_POINTS:
        keep = np.linspace(0, len(beam) - 1, MAX_SCAN_POINTS).astype(np.int64)
        beam, b = beam[keep], b[keep]
    axis = lattice.beam_rotations()[beam, :, 0]                      # each beam's unit direction (stand frame)
    head = np.concatenate([axis * (b * mapping.detection.interpreter.bin_spacing_m)[:, None],
                           np.ones((len(b), 1))], axis=1)
    poses = np.asarray(poses)
    if poses.ndim == 2:
        world = head @ poses.T
    else:                                       # one pose per azimuth (or per beam)
        per_beam = poses.reshape(-1, 4, 4)
        per_beam = per_beam[beam // lattice.n_el] if len(per_beam) == lattice.n_az else per_beam[beam]
        world = np.einsum("nij,nj->ni", per_beam, head)
    return world[:, :3].astype(np.float32)


class FoxgloveOut:
    """Serves (``port``: an int, 0 picks a free one; None: no server) and records (``mcap``: a
    path, or None) the map's channels (see the module docstring). ``offer(snapshot)`` hands over
    the newest state: a dict with ``map`` (a ``maps.map.Map``), ``trajectory`` (n, 4, 4),
    ``scan`` ((m, 3) points or None) and ``time_ns`` (the data's time). ``close()`` sends the
    last one offered, then stops. ``published`` counts the snapshots logged."""

    def __init__(self, port=None, mcap=None, rate_hz=2.0, band=None, occupied_nats=OCCUPIED_NATS,
                 free_nats=FREE_NATS, overwrite=False, say=None):
        try:
            import foxglove
            from foxglove import channels
        except ImportError:
            raise ConfigError("--foxglove and --mcap need the foxglove-sdk package: pip install 'radarcl[ros]'") from None
        if not (rate_hz > 0):
            raise ConfigError(f"the Foxglove rate must be a positive number of updates per second, got {rate_hz}")
        self.period_s, self.band, self.occupied_nats, self.free_nats = 1.0 / rate_hz, band, occupied_nats, free_nats
        self.context = foxglove.Context()
        self.server = self.writer = None
        try:
            if port is not None:
                self.server = foxglove.start_server(name="radarcl", host=HOST, port=int(port), context=self.context)
            if mcap is not None:
                self.writer = foxglove.open_mcap(str(mcap), allow_overwrite=overwrite, context=self.context)
        except Exception as exc:            # noqa: BLE001 - the SDK raises its own FoxgloveError and OSError
            self._stop_outputs()
            what = f"port {port} on {HOST}" if self.writer is None and mcap is None or port is not None else str(mcap)
            raise ConfigError(f"cannot open the Foxglove output ({what}): {exc}") from None
        ctx = self.context
        self.channels = dict(map=channels.GridChannel("/map", context=ctx),
                             voxels=channels.PointCloudChannel("/map/voxels", context=ctx),
                             scan=channels.PointCloudChannel("/scan", context=ctx),
                             trajectory=channels.PosesInFrameChannel("/trajectory", context=ctx),
                             tf=channels.FrameTransformsChannel("/tf", context=ctx))
        self.published, self._last, self._slot = 0, -float("inf"), None
        self._wake, self._closing, self._lock = threading.Event(), False, threading.Lock()
        self._thread = threading.Thread(target=self._run, name="radarcl-foxglove", daemon=True)
        self._thread.start()
        if self.server is not None and say is not None:
            say(f"serving the map to Foxglove on ws://{HOST}:{self.server.port} (Foxglove: Open connection, "
                "Foxglove WebSocket)")

    @property
    def port(self):
        """The server's port (None without a server)."""
        return None if self.server is None else self.server.port

    def due(self, now=None):
        """True when a snapshot may be offered (``rate_hz`` since the last)."""
        now = time.monotonic() if now is None else now
        return now - self._last >= self.period_s

    def offer(self, snapshot, now=None):
        """Hand over the newest state (see the class docstring); returns at once."""
        self._last = time.monotonic() if now is None else now
        with self._lock:
            self._slot = snapshot
        self._wake.set()

    def _run(self):
        while True:
            self._wake.wait()
            self._wake.clear()
            with self._lock:
                snapshot, self._slot = self._slot, None
            if snapshot is not None:
                self._log(snapshot)
            if self._closing:
                with self._lock:
                    if self._slot is None:
                        return

    def _log(self, s):
        from foxglove import messages as fm

        t = int(s["time_ns"])
        stamp = fm.Timestamp(t // 10 ** 9, t % 10 ** 9)
        m = s["map"]
        grid = m.projection(self.band, self.occupied_nats, self.free_nats)
        x0, y0, _ = m.spec.origin_m
        origin = fm.Pose(position=fm.Vector3(x=float(x0), y=float(y0), z=0.0),
                         orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
        int8 = fm.PackedElementFieldNumericType.Int8
        self.channels["map"].log(fm.Grid(
            timestamp=stamp, frame_id=FRAME, pose=origin, column_count=grid.shape[1],
            cell_size=fm.Vector2(x=float(m.spec.voxel_m), y=float(m.spec.voxel_m)), row_stride=grid.shape[1],
            cell_stride=1, fields=[fm.PackedElementField(name="occupancy", offset=0, type=int8)],
            data=np.ascontiguousarray(grid, np.int8).tobytes()), log_time=t)
        centres, nats = m.occupied(self.occupied_nats)
        cloud = np.empty(len(centres), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("log_odds", "<f4")])
        cloud["x"], cloud["y"], cloud["z"] = centres.T
        cloud["log_odds"] = nats
        self.channels["voxels"].log(_cloud(fm, stamp, cloud), log_time=t)
        if s.get("scan") is not None:
            pts = np.asarray(s["scan"], np.float32)
            scan = np.empty(len(pts), [("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
            scan["x"], scan["y"], scan["z"] = pts.T if len(pts) else (np.empty(0),) * 3
            self.channels["scan"].log(_cloud(fm, stamp, scan), log_time=t)
        track = np.asarray(s["trajectory"]).reshape(-1, 4, 4)
        if len(track):
            q = quaternions(track[:, :3, :3])
            self.channels["trajectory"].log(fm.PosesInFrame(timestamp=stamp, frame_id=FRAME, poses=[
                fm.Pose(position=fm.Vector3(x=float(p[0, 3]), y=float(p[1, 3]), z=float(p[2, 3])),
                        orientation=fm.Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))
                for p, (w, x, y, z) in zip(track, q)]), log_time=t)
            p, (w, x, y, z) = track[-1], q[-1]
            self.channels["tf"].log(fm.FrameTransforms(transforms=[fm.FrameTransform(
                timestamp=stamp, parent_frame_id=FRAME, child_frame_id=SENSOR_FRAME,
                translation=fm.Vector3(x=float(p[0, 3]), y=float(p[1, 3]), z=float(p[2, 3])),
                rotation=fm.Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))]), log_time=t)
        self.published += 1

    def close(self):
        """Log the last snapshot offered, close the MCAP file and stop the server."""
        self._closing = True
        self._wake.set()
        self._thread.join()
        self._stop_outputs()

    def _stop_outputs(self):
        if self.writer is not None:
            self.writer.close()
        if self.server is not None:
            # the SDK's stop waits for every client to take what is queued for it: a client that
            # does not read would hold radarcl here for as long as it stalls, so it is given
            # STOP_WAIT_S and then left to the process's end
            done = threading.Thread(target=self.server.stop, name="radarcl-foxglove-stop", daemon=True)
            done.start()
            done.join(STOP_WAIT_S)
            self.server = None


def _cloud(fm, stamp, cloud):
    f32 = fm.PackedElementFieldNumericType.Float32
    return fm.PointCloud(timestamp=stamp, frame_id=FRAME,
                         pose=fm.Pose(position=fm.Vector3(x=0.0, y=0.0, z=0.0),
                                      orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                         point_stride=cloud.dtype.itemsize,
                         fields=[fm.PackedElementField(name=n, offset=cloud.dtype.fields[n][1], type=f32)
                                 for n in cloud.dtype.names], data=cloud.tobytes())


def snapshot(mapping, trajectory, frame_poses=None, time_ns=None, reading=None):
    """The state ``FoxgloveOut.offer`` takes, copied off the device now: the map of
    ``mapping.grid`` (``reading``: what its knowledge channel needs), the ``trajectory``, the
    latest frame's detections at ``frame_poses`` (None: no /scan), at ``time_ns`` (default: now)."""
    mapping.runtime.queue.finish()
    m = Map.of_grid(mapping.grid, reading) if mapping.grid.has_knowledge else Map.of_grid(mapping.grid)
    scan = scan_points(mapping, frame_poses) if frame_poses is not None else None
    return dict(map=m, trajectory=np.asarray(trajectory).reshape(-1, 4, 4), scan=scan,
                time_ns=time.time_ns() if time_ns is None else int(time_ns))
