"""Changed bricks from a running engine to viewers, over a local TCP socket (no file polling,
and the viewer never imports pyopencl).

Messages: ``b"RCVS"``, a kind (uint8), the payload's length (uint32), the payload:
    1 SPEC    JSON {"origin_m": [x, y, z], "voxel_m": v, "shape": [nx, ny, nz]}
    2 BRICKS  uint32 n, keys (n, 3) int32 (bx, by, bz), data (n, 8, 8, 8) int32 log-odds units
    3 POSES   (n, 4, 4) float64: the sensor's poses so far
A viewer that connects gets SPEC, every brick and the poses, then the bricks each fuse changed.
The subscriber checks every message (kind, sizes, keys inside the grid) and stops on the first
bad one with the reason, as any input from outside would be.
"""

import collections
import contextlib
import json
import socket
import struct
import threading

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.gridspec import GridSpec

MAGIC = b"RCVS"
HEAD = struct.Struct("<4sBI")
SPEC, BRICKS, POSES = 1, 2, 3
BRICK_INTS = 512
MAX_MESSAGE = 1 << 30


def _message(kind, payload):
    return HEAD.pack(MAGIC, kind, len(payload)) + payload


def bricks_message(keys, data):
    keys = np.ascontiguousarray(keys, "<i4").reshape(-1, 3)
    data = np.ascontiguousarray(data, "<i4").reshape(len(keys), BRICK_INTS)  # an empty map too (a viewer that comes first)
    return _message(BRICKS, struct.pack("<I", len(keys)) + keys.tobytes() + data.tobytes())


def parse_address(text, default_host="127.0.0.1"):
    """"HOST:PORT" or "PORT" -> (host, port)."""
    host, _, port = str(text).rpartition(":")
    try:
        number = int(port)
    except ValueError:
        raise ConfigError(f"expected HOST:PORT or PORT, got {text!r}") from None
    if not 0 <= number < 65536:
        raise ConfigError(f"port must lie in [0, 65535], got {number}")
    return host or default_host, number


class _Viewer:
    """One connected viewer: messages queue here and a thread of its own sends them, so a viewer
    that reads slowly, or not at all, never holds the engine. Past ``limit`` bytes waiting, or
    a send that takes longer than ``timeout_s``, it is dropped."""

    def __init__(self, conn, limit, timeout_s):
        self.conn, self.limit = conn, limit
        self.conn.settimeout(timeout_s)
        self.waiting, self.closed = 0, threading.Event()
        self._queue = collections.deque()
        self._ready = threading.Condition()
        threading.Thread(target=self._send, name="radarcl-view-sender", daemon=True).start()

    def put(self, message):
        """Queue ``message``; False (and the viewer closed) when too much already waits."""
        with self._ready:
            if self.closed.is_set():
                return False
            if self.waiting + len(message) > self.limit:
                self._close()
                return False
            self._queue.append(message)
            self.waiting += len(message)
            self._ready.notify()
        return True

    def _send(self):
        while True:
            with self._ready:
                while not self._queue and not self.closed.is_set():
                    self._ready.wait()
                if self.closed.is_set():
                    return
                message = self._queue.popleft()
            try:
                self.conn.sendall(message)
            except OSError:
                with self._ready:
                    self._close()
                return
            with self._ready:
                self.waiting -= len(message)

    def _close(self):
        self.closed.set()
        self._queue.clear()
        self._ready.notify_all()
        with contextlib.suppress(OSError):
            self.conn.shutdown(socket.SHUT_RDWR)
        self.conn.close()

    def close(self):
        with self._ready:
            self._close()


class BrickPublisher:
    """Serves viewers on ``address`` (port 0: a free one; ``address`` says which). ``publish``
    queues changed bricks for every viewer and returns at once (each viewer has a sender
    thread); a viewer that connects first gets the whole map from ``snapshot()`` -> (spec,
    keys, data, poses). A viewer that stops reading is dropped once ``limit_bytes`` wait for it
    or a send takes longer than ``timeout_s``: the engine's latency never depends on viewers."""

    def __init__(self, snapshot, address=("127.0.0.1", 0), timeout_s=2.0, limit_bytes=256 << 20):
        self.snapshot, self.timeout_s, self.limit = snapshot, timeout_s, limit_bytes
        try:
            self._server = socket.create_server(address)
        except (OSError, OverflowError, TypeError) as exc:
            raise ConfigError(f"cannot serve viewers on {address[0]}:{address[1]} ({exc})") from None
        self.address = self._server.getsockname()[:2]
        self._new, self._clients = [], []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        threading.Thread(target=self._accept, name="radarcl-view-server", daemon=True).start()

    def _accept(self):
        while not self._closed.is_set():
            try:
                conn, _ = self._server.accept()
            except OSError:
                return
            with self._lock:
                self._new.append(_Viewer(conn, self.limit, self.timeout_s))

    @property
    def viewers(self):
        with self._lock:
            self._clients = [c for c in self._clients if not c.closed.is_set()]
            return len(self._clients) + len(self._new)

    def publish(self, keys=None, data=None, poses=None):
        """Queue the changed bricks (and the poses) for the viewers; greet new ones with everything."""
        with self._lock:
            new, self._new = self._new, []
        if new:
            spec, all_keys, all_data, all_poses = self.snapshot()
            greeting = _message(SPEC, json.dumps(dict(origin_m=list(spec.origin_m), voxel_m=spec.voxel_m,
                                                      shape=list(spec.shape))).encode())
            greeting += bricks_message(all_keys, all_data)
            if all_poses is not None:
                greeting += _message(POSES, np.ascontiguousarray(all_poses, "<f8").tobytes())
            for c in new:
                c.put(greeting)
        message = b""
        if keys is not None and len(keys):
            message += bricks_message(keys, data)
        if poses is not None:
            message += _message(POSES, np.ascontiguousarray(poses, "<f8").tobytes())
        with self._lock:
            old = [c for c in self._clients if not c.closed.is_set()]
            self._clients = old + [c for c in new if not c.closed.is_set()]
        if message:
            for c in old:
                c.put(message)

    def close(self):
        self._closed.set()
        self._server.close()
        with self._lock:
            for c in self._clients + self._new:
                c.close()
            self._clients, self._new = [], []


class BrickSubscriber:
    """A viewer's end: connects to ``address`` and reads messages on a thread into ``updates``
    (a list taken with ``take()``): ("spec", GridSpec), ("bricks", keys, data), ("poses", P).
    ``error`` holds why it stopped (the engine went away, or a bad message)."""

    def __init__(self, address, timeout_s=10.0):
        host, port = parse_address(address) if isinstance(address, str) else address
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout_s)
        except OSError as exc:
            raise ConfigError(f"no radarcl engine at {host}:{port} ({exc}); start one with radarcl live --serve") from exc
        self._sock.settimeout(None)
        self.spec, self.error = None, None
        self._updates, self._lock = [], threading.Lock()
        self.arrived = threading.Event()
        self._thread = threading.Thread(target=self._read, name="radarcl-view-follow", daemon=True)
        self._thread.start()

    def take(self):
        with self._lock:
            out, self._updates = self._updates, []
        return out

    def _exact(self, n):
        buf = bytearray()
        while len(buf) < n:
            chunk = self._sock.recv(min(n - len(buf), 1 << 20))
            if not chunk:
                raise EOFError("the engine closed the stream")
            buf += chunk
        return bytes(buf)

    def _read(self):
        try:
            while True:
                magic, kind, length = HEAD.unpack(self._exact(HEAD.size))
                if magic != MAGIC or kind not in (SPEC, BRICKS, POSES) or length > MAX_MESSAGE:
                    raise FrameFormatError(f"not a radarcl brick stream (magic {magic!r}, kind {kind}, {length} bytes)")
                payload = self._exact(length)
                if kind == SPEC:
                    d = json.loads(payload)
                    self.spec = GridSpec(tuple(float(v) for v in d["origin_m"]), float(d["voxel_m"]),
                                         tuple(int(v) for v in d["shape"]))
                    item = ("spec", self.spec)
                elif kind == BRICKS:
                    item = ("bricks", *self._bricks(payload))
                else:
                    if length % 128:
                        raise FrameFormatError(f"poses of {length} bytes are not whole 4x4 float64 matrices")
                    poses = np.frombuffer(payload, "<f8").reshape(-1, 4, 4)
                    if not np.isfinite(poses).all():
                        raise FrameFormatError("poses with NaN or Inf")
                    item = ("poses", poses.copy())
                with self._lock:
                    self._updates.append(item)
                self.arrived.set()
        except (OSError, EOFError, ValueError, KeyError, TypeError, struct.error) as exc:
            self.error = str(exc) or type(exc).__name__
            self.arrived.set()

    def _bricks(self, payload):
        if self.spec is None:
            raise FrameFormatError("bricks before the grid's description")
        (n,) = struct.unpack_from("<I", payload)
        if len(payload) != 4 + n * 12 + n * BRICK_INTS * 4:
            raise FrameFormatError(f"{n} bricks need {4 + n * (12 + BRICK_INTS * 4)} bytes, got {len(payload)}")
        keys = np.frombuffer(payload, "<i4", n * 3, 4).reshape(n, 3).astype(np.int32)
        data = np.frombuffer(payload, "<i4", n * BRICK_INTS, 4 + n * 12).reshape(n, 8, 8, 8).astype(np.int32)
        if n and ((keys < 0).any() or (keys >= np.asarray(self.spec.brick_shape)).any()):
            raise FrameFormatError(f"brick keys outside the grid's {self.spec.brick_shape} bricks")
        return keys, data

    def close(self):
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
