"""What every byte-stream protocol shares: the counters a parser keeps, the resynchronising
scanner both protocols build on, and the adapter that feeds a pyserial port into a parser.

Parsing is a pure protocol (pyserial's ``serial.threaded.Protocol``): a parser takes byte
chunks of any size through ``data_received`` and hands whole packets to ``on_packet``; it never
blocks, never sleeps and never raises into its caller. The port is an adapter: pyserial's
``ReaderThread`` moves bytes from any ``serial_for_url`` URL (``/dev/ttyUSB0``,
``socket://host:port``, ``rfc2217://``, a pty) into the parser. No pyopencl imports here.
"""

import errno
import json
import logging
import os
import struct
import threading
import time
from dataclasses import asdict, dataclass

from radarcl.errors import ConfigError, FrameFormatError
from radarcl.io.files import check_readable

log = logging.getLogger(__name__)

PROTOCOLS = ("beams", "ti")        # radarcl.io.beam_protocol, radarcl.io.ti_uart
NEED_MORE, BAD, BAD_CRC = "need more", "bad header", "bad crc"


@dataclass
class StreamCounters:
    """What a parser saw. ``bytes_in`` always equals ``bytes_in_packets + bytes_dropped +
    bytes_pending`` (the bytes held while a packet is incomplete)."""

    bytes_in: int = 0
    bytes_in_packets: int = 0
    bytes_dropped: int = 0
    bytes_pending: int = 0
    packets: int = 0              # delivered
    header_failures: int = 0      # a magic word whose header did not check out
    crc_failures: int = 0         # a whole packet whose CRC-32 did not match
    sequence_gaps: int = 0        # packets missing between two delivered ones
    duplicates: int = 0           # a packet delivered again (same sequence number)
    handler_errors: int = 0       # exceptions raised by on_packet (logged, never re-raised)
    unsupported: int = 0          # well-formed packets of a version or kind this parser does not read

    def as_dict(self):
        return asdict(self)


class ScanningParser:
    """Finds packets in a byte stream that starts each with ``MAGIC``; subclasses say how long
    a packet is and whether it checks out (``_examine``) and what it decodes to (``_decode``).

    On anything wrong it drops the first byte of the magic word and searches again from the
    next byte, so a good packet after a damaged one is never lost, and it counts every dropped
    byte. ``on_packet(packet)`` receives each packet; without it, packets collect in
    ``self.packets`` (``take()`` empties it)."""

    MAGIC = b""
    COMPACT = 1 << 16                 # drop consumed bytes from the buffer's front past this

    def __init__(self, on_packet=None):
        self.on_packet = on_packet
        self.counters = StreamCounters()
        self.packets = []
        self._buf = bytearray()
        self._start = 0
        self._lock = threading.Lock()

    # -- the pure protocol ----------------------------------------------------------------------
    def data_received(self, data):
        """Feed a chunk of bytes (any size, split anywhere)."""
        if not data:
            return
        with self._lock:
            self.counters.bytes_in += len(data)
            self._buf += data
            self._scan()
            self.counters.bytes_pending = len(self._buf) - self._start

    def take(self):
        """The packets collected since the last call (when there is no ``on_packet``)."""
        with self._lock:
            out, self.packets = self.packets, []
        return out

    def _scan(self):
        buf, magic = self._buf, self.MAGIC
        while True:
            i = buf.find(magic, self._start)
            if i < 0:
                keep = max(self._start, len(buf) - (len(magic) - 1))     # a magic word split by the chunk
                self._drop(keep - self._start)
                break
            self._drop(i - self._start)
            status, size = self._examine(memoryview(buf)[i:])
            if status == NEED_MORE:
                break
            if status in (BAD, BAD_CRC):
                if status == BAD:
                    self.counters.header_failures += 1
                else:
                    self.counters.crc_failures += 1
                self._drop(1)
                continue
            packet = self._decode(bytes(buf[i:i + size]))
            self._start = i + size
            self.counters.bytes_in_packets += size
            if packet is None:                       # well-formed, but not for us: skipped whole
                self.counters.unsupported += 1
                continue
            self._deliver(packet)
        if self._start > self.COMPACT:
            del buf[:self._start]
            self._start = 0

    def _drop(self, n):
        if n > 0:
            self._start += n
            self.counters.bytes_dropped += n

    def _deliver(self, packet):
        if not self._is_new(packet):
            return
        self.counters.packets += 1
        if self.on_packet is None:
            self.packets.append(packet)
            return
        try:
            self.on_packet(packet)
        except Exception:                            # never into the reader thread: count and log
            self.counters.handler_errors += 1
            log.exception("the packet handler failed; the stream goes on")

    def _is_new(self, packet):
        """False for a repeated packet (not delivered again); counts sequence gaps."""
        return True

    def _examine(self, view):
        """(NEED_MORE, None), (BAD or BAD_CRC, None) or ("ok", size) for the bytes at a magic word."""
        raise NotImplementedError

    def _decode(self, data):
        """The packet object of ``data`` (one whole, checked packet), or None to skip it."""
        raise NotImplementedError


def open_port(url, baud=921600, timeout=0.2):
    """A pyserial port for ``url`` (a device, ``socket://``, ``rfc2217://``, ``loop://``);
    ConfigError with pyserial's reason when it cannot be opened."""
    try:
        import serial
    except ImportError as exc:
        raise ConfigError("reading a radar needs pyserial: pip install 'radarcl[serial]'") from exc
    try:
        return serial.serial_for_url(url, baudrate=baud, timeout=timeout)
    except (serial.SerialException, ValueError, OSError) as exc:
        raise ConfigError(f"cannot open the radar's port {url}: {exc}") from exc


class PortReader:
    """Moves bytes from a pyserial port to ``sink(receive_time_ns, chunk)`` (a ``Session.feed``:
    recorder and parser) on a thread of its own. When the port goes away, ``closed`` is set and
    either ``ended`` (the far end of a pseudo-terminal or a socket closed: the stream is over,
    as when ``radarcl emulate`` finishes) or ``lost`` (a device that went away, e.g. a USB radar
    unplugged) holds the reason.

    Written here rather than with pyserial's ``serial.threaded.ReaderThread``: that one catches
    only ``SerialException``, and a pty whose far end closes raises ``OSError`` (EIO) from
    ``in_waiting``, which ends its thread with a traceback and tells nobody. A socket's
    ``in_waiting`` says 1 whenever anything waits, so a socket is read by whole receive buffers,
    not byte by byte."""

    CHUNK = 1 << 16

    def __init__(self, port, sink):
        self.port, self.sink = port, sink
        self.lost, self.ended = None, None
        self.closed = threading.Event()
        self._stop = threading.Event()
        self._socket = type(port).__module__.rsplit(".", 1)[-1] in ("protocol_socket", "protocol_rfc2217")
        self._pty = isinstance(getattr(port, "port", None), str) and os.path.realpath(port.port).startswith("/dev/pts/")
        self.thread = threading.Thread(target=self._run, name="radarcl-port-reader", daemon=True)

    def start(self):
        self.thread.start()
        return self

    def _read(self):
        if not self._socket:
            return self.port.read(self.port.in_waiting or 1)
        data = self.port.read(1)                          # waits up to the port's timeout
        if data:
            timeout, self.port.timeout = self.port.timeout, 0
            try:
                data += self.port.read(self.CHUNK)        # and whatever else waits, at once
            finally:
                self.port.timeout = timeout
        return data

    def _run(self):
        try:
            while not self._stop.is_set():
                data = self._read()
                if data:
                    self.sink(time.time_ns(), data)
        except Exception as exc:                          # noqa: BLE001 - a port that went away, in any form
            # (pyserial's socket port closed under a read raises AttributeError): said, not a traceback
            if not self._stop.is_set():                   # not our own close
                reason = str(exc) or type(exc).__name__
                eio = getattr(exc, "errno", None) == errno.EIO or f"[Errno {errno.EIO}]" in reason
                hangup = eio or "returned no data" in reason        # a pty's far end closed: EIO, or an empty read
                if self._socket and "disconnected" in reason or self._pty and hangup:
                    self.ended = reason
                else:
                    self.lost = reason
        finally:
            self.closed.set()

    def stop(self):
        """Stop reading and close the port; after it returns, ``sink`` is not called again."""
        if self._stop.is_set():
            self.thread.join(2)
            return
        self._stop.set()
        try:
            if hasattr(self.port, "cancel_read") and self.port.is_open:
                self.port.cancel_read()
        except (OSError, ValueError):
            pass
        finally:
            self.port.close()
        self.thread.join(2)
        self.closed.set()


# -- record and replay ------------------------------------------------------------------------------
STREAM_MAGIC = b"RCSTREAM1\n"
RECORD = struct.Struct("<QI")          # receive time [ns since the epoch], byte count


class StreamRecorder:
    """``--record FILE``: the raw bytes as they arrived, each chunk with its receive time.

    The file is ``STREAM_MAGIC``, one JSON line (protocol, sensor, baud, what else the caller
    gives), then records of (time uint64, length uint32, bytes). Append-only and flushed at
    least every ``flush_s`` seconds, so a killed process leaves every record but the last few;
    ``read_stream`` stops at a torn last record and says so. Refuses an existing file."""

    def __init__(self, path, header, flush_s=0.5):
        try:
            self._f = open(path, "xb")
        except FileExistsError:
            raise ConfigError(f"recording {path} exists; choose another name (a stream is never overwritten)") from None
        except OSError as exc:
            raise ConfigError(f"cannot write the recording {path}: {exc}") from exc
        self.path, self.flush_s = path, flush_s
        self._f.write(STREAM_MAGIC + json.dumps(header).encode() + b"\n")
        self._f.flush()
        self._last = time.monotonic()
        self._time = time.monotonic
        self._lock = threading.Lock()
        self.bytes = 0

    def __call__(self, t_ns, data):
        with self._lock:
            if self._f.closed:
                return
            self._f.write(RECORD.pack(t_ns, len(data)))
            self._f.write(data)
            self.bytes += len(data)
            if self._time() - self._last >= self.flush_s:
                self._f.flush()
                self._last = self._time()

    def close(self):
        with self._lock:
            if not self._f.closed:
                self._f.close()


def read_stream(path):
    """(header dict, iterator of (time_ns, bytes)) of a ``StreamRecorder`` file. A file that is
    not one is refused; a torn last record (the writer was killed) ends the iteration, and the
    iterator's ``torn`` attribute says how many bytes were left over."""
    check_readable(path, "radarcl stream recording")
    f = open(path, "rb")
    try:
        if f.read(len(STREAM_MAGIC)) != STREAM_MAGIC:
            raise FrameFormatError(f"{path} is not a radarcl stream recording (no {STREAM_MAGIC!r} at its start)")
        line = f.readline(1 << 16)
        try:
            header = json.loads(line)
            if not isinstance(header, dict):
                raise ValueError("not an object")
        except (ValueError, RecursionError) as exc:
            raise FrameFormatError(f"{path}: the stream header is not a JSON object ({exc})") from exc
    except BaseException:
        f.close()
        raise
    return header, _Records(f)


class _Records:
    """Iterates a stream file's records; ``torn`` is set to the bytes of an incomplete last one."""

    LIMIT = 1 << 26                                   # one chunk of at most 64 MiB

    def __init__(self, f):
        self._f, self.torn = f, 0

    def __iter__(self):
        with self._f as f:
            while True:
                head = f.read(RECORD.size)
                if not head:
                    return
                if len(head) < RECORD.size:
                    self.torn = len(head)
                    return
                t, n = RECORD.unpack(head)
                if n > self.LIMIT:
                    raise FrameFormatError(f"{f.name}: a record claims {n} bytes; the recorder writes at most "
                                           f"{self.LIMIT} (the file is damaged)")
                data = f.read(n)
                if len(data) < n:
                    self.torn = RECORD.size + len(data)
                    return
                yield t, data
