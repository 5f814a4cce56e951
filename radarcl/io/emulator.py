"""A radar on a serial line, for tests and demos: packets from a recording, faults injected
at given rates with a seed, written to a pseudo-terminal or any pyserial port at a baud rate.

``packets_of(...)`` turns frames into protocol packets (the beam protocol, or TI's demo UART
for a sensor of range profiles); ``Faults`` damages a packet stream reproducibly and says which
packets went out intact; ``Emulator`` paces bytes onto a port (8N1: baud / 10 bytes per second).
No pyopencl imports here.
"""

import contextlib
import math
import os
import threading
import time
from dataclasses import dataclass, fields

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io import beam_protocol, ti_uart


@dataclass(frozen=True)
class Faults:
    """Fault rates: ``ber`` per bit flipped, ``drop`` / ``dup`` per byte removed / sent twice,
    ``truncate`` per packet cut short at a random point, ``noise`` per packet preceded by a
    burst of 1-64 random bytes; ``pause`` seconds of silence every ``pause_every`` packets;
    ``disconnect`` after that many packets (0: never); ``seed`` for the generator."""

    ber: float = 0.0
    drop: float = 0.0
    dup: float = 0.0
    truncate: float = 0.0
    noise: float = 0.0
    pause: float = 0.0
    pause_every: int = 0
    disconnect: int = 0
    seed: int = 0

    MAX_PAUSE_S = 3600.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            whole = f.type in (int, "int")
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer) if whole else
                                                                  (int, float, np.integer, np.floating)) \
                    or not math.isfinite(float(v) if abs(v) < 1e300 else math.inf) or v < 0:
                raise ConfigError(f"fault {f.name} must be a finite {'whole ' if whole else ''}number >= 0, got {v!r}")
        for name in ("ber", "drop", "dup", "truncate", "noise"):
            if getattr(self, name) > 1:
                raise ConfigError(f"fault rate {name} is a probability in [0, 1], got {getattr(self, name)}")
        if self.pause > self.MAX_PAUSE_S:
            raise ConfigError(f"fault pause is at most {self.MAX_PAUSE_S:g} s, got {self.pause!r}")
        for name in ("seed", "pause_every", "disconnect"):
            if getattr(self, name) >= 1 << 63:
                raise ConfigError(f"fault {name} must lie in [0, 2^63), got {getattr(self, name)!r}")

    @classmethod
    def parse(cls, text):
        """From the command line: ``ber=1e-4,drop=1e-5,pause=2,pause_every=100,seed=3``."""
        if not text:
            return cls()
        names = {f.name: f.type for f in fields(cls)}
        values = {}
        for part in text.split(","):
            key, _, value = part.partition("=")
            key = key.strip()
            if key not in names or not value:
                raise ConfigError(f"--faults {text!r}: expected NAME=VALUE pairs with names {', '.join(names)}")
            try:
                values[key] = int(value) if names[key] in (int, "int") else float(value)
            except (ValueError, OverflowError):
                raise ConfigError(f"--faults: {key} needs a {'whole ' if names[key] in (int, 'int') else ''}number, "
                                  f"got {value!r}") from None
        return cls(**values)

    @property
    def any(self):
        return any(getattr(self, n) for n in ("ber", "drop", "dup", "truncate", "noise"))

    def apply(self, packets, rng=None):
        """Damage ``packets`` (a list of bytes). Returns (the bytes to send, one per packet with
        any burst in front of it, and a bool per packet: its own bytes went out unchanged)."""
        rng = np.random.default_rng(self.seed) if rng is None else rng
        out, intact = [], []
        for p in packets:
            burst = rng.integers(0, 256, int(rng.integers(1, 65)), np.uint8).tobytes() \
                if self.noise and rng.random() < self.noise else b""
            data = np.frombuffer(p, np.uint8).copy()
            ok = True
            if self.truncate and rng.random() < self.truncate:
                data, ok = data[:int(rng.integers(0, len(data)))], False
            if self.ber:
                flips = rng.binomial(len(data) * 8, self.ber)
                if flips:
                    at = rng.integers(0, len(data) * 8, flips)
                    np.bitwise_xor.at(data, at // 8, (1 << (at % 8)).astype(np.uint8))
                    ok = False
            for rate, repeat in ((self.drop, 0), (self.dup, 2)):
                if rate:
                    hit = rng.random(len(data)) < rate
                    if hit.any():
                        data, ok = np.repeat(data, np.where(hit, repeat, 1)), False
            out.append(burst + data.tobytes())
            intact.append(ok)
        return out, intact


def beam_packets(frames, poses=None, frame_period_ns=100_000_000, first_frame=0):
    """A recording's frames (n, n_az, n_el, n_samples) as beam-protocol packets, each with its
    frame's pose ((n, 4, 4); per-beam poses (n, n_beams, 4, 4) go beam by beam). Returns a list
    of bytes, azimuth-major within each frame."""
    out, seq = [], 0
    for j, frame in enumerate(frames):
        n_az, n_el = frame.shape[:2]
        beam_ns = frame_period_ns // max(1, n_az * n_el)
        for i in range(n_az):
            for k in range(n_el):
                pose = None if poses is None else (poses[j] if poses[j].ndim == 2 else poses[j][i * n_el + k])
                out.append(beam_protocol.encode(seq, first_frame + j, i, k, (first_frame + j) * frame_period_ns
                                                + seq % (n_az * n_el) * beam_ns, frame[i, k], pose))
                seq += 1
    return out


def ti_packets(profiles_q9, first_frame=0, version=0x03050004):
    """Range profiles (n, n_bins) uint16 in Q9 as TI demo frames, each with a detected-points
    TLV and a stats TLV beside the profile (the parser must skip what it does not use)."""
    out = []
    for j, q9 in enumerate(np.asarray(profiles_q9, np.uint16)):
        points = np.zeros((2, 4), "<f4").tobytes()                # two empty (x, y, z, v) points
        stats = np.arange(6, dtype="<u4").tobytes()
        out.append(ti_uart.encode_frame(first_frame + j, [(ti_uart.DETECTED_POINTS, points),
                                                          (ti_uart.RANGE_PROFILE, q9.astype("<u2").tobytes()),
                                                          (ti_uart.STATS, stats)], version=version,
                                        detected_objects=2))
    return out


MAX_GAP_S = 10.0     # a longer silence in a recorded stream is a clock that jumped: skipped


def due_times(times_ns, max_gap_s=MAX_GAP_S):
    """Seconds from the start at which recorded chunks go out: the recorded gaps, none negative,
    and a gap longer than ``max_gap_s`` skipped (a clock that jumps must not hold the stream
    for years)."""
    gaps = np.diff(np.asarray(times_ns, np.float64)) / 1e9
    gaps = np.where(gaps > max_gap_s, 0.0, np.maximum(gaps, 0.0))
    return np.concatenate([[0.0], np.cumsum(gaps)]).tolist() if len(times_ns) else None


def q9_of_power(power, antennas, q_bits=9):
    """Power profiles as TI's range profile carries them (the inverse of
    ``ti_uart.profile_power``): round(2^q_bits antennas log2 sqrt(power)), within uint16."""
    log2_mag = 0.5 * np.log2(np.maximum(np.asarray(power, np.float64), 1e-30))
    return np.clip(np.rint((1 << q_bits) * antennas * log2_mag), 0, 65535).astype(np.uint16)


def is_pty_link(path):
    """True for a symbolic link to a pseudo-terminal (what ``open_pty`` makes, perhaps left by
    an emulator that was killed): the only thing ``--link`` may replace."""
    return os.path.islink(path) and os.readlink(path).startswith("/dev/pts/")


def check_link(link):
    """ConfigError unless ``link`` may become the pty's link: nothing there yet, or a link to a
    pseudo-terminal (an earlier emulator's). A file, a directory or any other link is the user's."""
    if link is None:
        return None
    if os.path.lexists(link) and not is_pty_link(link):
        what = "a symbolic link to " + os.readlink(link) if os.path.islink(link) else \
            "a directory" if os.path.isdir(link) else "a file"
        raise ConfigError(f"--link {link} is {what}; it would be replaced: give a new name (only a link to a "
                          "pseudo-terminal, an earlier emulator's, is replaced)")
    parent = os.path.dirname(os.path.abspath(link))
    if not os.path.isdir(parent) or not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"--link {link}: {parent} is not a writable directory")
    return link


def remove_link(link, name):
    """Remove ``link`` if it still points at the pty ``name`` (ours, not one a later run made)."""
    try:
        if link and os.path.islink(link) and os.readlink(link) == name:
            os.unlink(link)
    except OSError:
        pass


def open_pty(link=None):
    """A pseudo-terminal in raw mode: (master fd, slave path, slave fd). The emulator keeps the
    slave open, so bytes written before a reader opens it wait in the pty instead of being
    lost; ``link`` makes a symbolic link to the slave (a stable name for scripts; see
    ``check_link``: only an earlier emulator's link is replaced, atomically)."""
    import tty

    check_link(link)
    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    if link:
        tmp = f"{link}.{os.getpid()}.tmp"
        try:
            os.symlink(name, tmp)
            check_link(link)                        # still nothing of the user's there
            os.replace(tmp, link)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            os.close(master)
            os.close(slave)
            raise
    return master, name, slave


def pty_writer(master, halt):
    """``write(bytes)`` onto a pty's master that never blocks past ``halt`` (an Event): a pty
    nobody reads fills up, and a plain write would hold Ctrl-C until the kernel took the bytes."""
    import fcntl
    import select

    fcntl.fcntl(master, fcntl.F_SETFL, fcntl.fcntl(master, fcntl.F_GETFL) | os.O_NONBLOCK)

    def write(data):
        view = memoryview(data)
        while len(view) and not halt.is_set():
            try:
                view = view[os.write(master, view):]
            except BlockingIOError:
                select.select([], [master], [], 0.05)
    return write


def pending(fd):
    """Bytes waiting to be read on a tty ``fd`` (FIONREAD)."""
    import fcntl
    import struct
    import termios

    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]


def close_pty(master, slave, timeout_s=10.0, drain=True):
    """Close a pty once its reader has taken what was sent (closing the master discards what
    still waits on the slave), or after ``timeout_s``; returns the bytes left unread (0 when the
    reader took everything; with ``drain`` False it closes at once). The slave's count does not
    see bytes still in the kernel's buffer between the two ends, so it must read 0 for
    ``QUIET_S`` in a row before the pty is taken as drained."""
    deadline = time.monotonic() + timeout_s
    left = 0
    try:
        quiet_since = None
        while drain and time.monotonic() < deadline:
            left = pending(slave)
            if left:
                quiet_since = None
            elif quiet_since is None:
                quiet_since = time.monotonic()
            elif time.monotonic() - quiet_since >= QUIET_S:
                break
            time.sleep(0.01)                     # the reader is another process: poll its progress
    except OSError:
        pass
    finally:
        os.close(master)
        os.close(slave)
    return left


QUIET_S = 0.3


class Emulator:
    """Writes ``chunks`` (a list of bytes, e.g. damaged packets) to ``write`` (a callable taking
    bytes) at ``baud`` (None: as fast as the port takes them), from a thread; chunk j not before
    ``due_s[j]`` seconds from the start when given (a radar's frame rate). ``faults`` pauses and
    disconnects (``disconnected`` is then set). ``sent`` counts bytes, ``done`` is set at the
    end, ``stop()`` ends it early; nothing is sent for the first ``delay_s`` seconds."""

    MIN_BAUD, MAX_BAUD = 50, 1e9

    def __init__(self, chunks, write, baud=921600, faults=Faults(), close=None, loop=False, due_s=None, delay_s=0.0):
        if baud is not None and (isinstance(baud, (bool, np.bool_)) or not isinstance(baud, (int, float, np.number))
                                 or not self.MIN_BAUD <= baud <= self.MAX_BAUD):
            raise ConfigError(f"baud must lie in [{self.MIN_BAUD}, {self.MAX_BAUD:g}], got {baud!r}")
        if not (isinstance(delay_s, (int, float, np.number)) and 0 <= delay_s < 3600):
            raise ConfigError(f"delay_s must lie in [0, 3600) seconds, got {delay_s!r}")
        self.chunks, self.write, self.baud, self.faults = chunks, write, baud, faults
        self.close, self.loop, self.due_s, self.delay_s = close, loop, due_s, delay_s
        self.sent, self.packets_sent = 0, 0
        self.error = None                          # what ended the thread, if not the end or stop()
        self.done, self.disconnected = threading.Event(), threading.Event()
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="radarcl-emulator", daemon=True)

    def start(self):
        self.thread.start()
        return self

    def stop(self):
        self._stop.set()
        self.thread.join(5)

    def _run(self):
        rate = None if self.baud is None else self.baud / 10.0              # 8N1: 10 bits per byte
        if self.delay_s and self._stop.wait(self.delay_s):
            self.done.set()
            return
        start = time.perf_counter()
        f = self.faults
        try:
            while not self._stop.is_set():
                lap = time.perf_counter()
                for j, chunk in enumerate(self.chunks):
                    if self._stop.is_set():
                        return
                    if self.due_s is not None:
                        wait = lap + self.due_s[j] - time.perf_counter()
                        if wait > 0:
                            if self._stop.wait(wait):
                                return
                            start += wait          # silence does not count against the baud rate
                    if f.disconnect and self.packets_sent >= f.disconnect:
                        self.disconnected.set()
                        return
                    if f.pause and f.pause_every and self.packets_sent and self.packets_sent % f.pause_every == 0:
                        if self._stop.wait(f.pause):
                            return
                        start += f.pause
                    for at in range(0, len(chunk), 4096):
                        piece = chunk[at:at + 4096]
                        if rate is not None:
                            due = start + (self.sent + len(piece)) / rate - time.perf_counter()
                            if due > 0 and self._stop.wait(due):
                                return
                        self.write(piece)
                        self.sent += len(piece)
                    self.packets_sent += 1
                if not self.loop:
                    return
        except OSError:                           # the reader went away
            self.disconnected.set()
        except Exception as exc:                  # noqa: BLE001 - told to the main thread (``error``)
            self.error = exc
        finally:
            if self.close is not None:
                self.close()
            self.done.set()
