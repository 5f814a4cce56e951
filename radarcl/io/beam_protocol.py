"""The radarcl beam protocol: one raw beam per packet, so a radar streams beam by beam.

At 921600 baud one 64 x 4 x 256 int16 frame takes about 1.4 s, so nothing may wait for a whole
frame. Byte by byte (little-endian; docs/beam_protocol.md has an example hex dump):

    offset size  field
    0      4     magic "RCBM" (52 43 42 4D)
    4      1     version (1)
    5      1     header size in bytes (48; a later version at most 64)
    6      2     flags: bit 0 = a float32 pose follows the header, bit 1 = a float64 pose does
    8      4     sequence number (per packet, wraps at 2^32)
    12     4     frame id
    16     2     azimuth index of the beam
    18     2     elevation index of the beam
    20     8     timestamp [ns] (the radar's clock)
    28     4     sample count
    32     1     sample type: 1 int16, 2 complex int16 (I, Q interleaved), 3 float32 power profile
    33     3     reserved (0)
    36     4     payload size in bytes (pose + samples)
    40     4     reserved (0)
    44     4     CRC-32 of bytes 0-43 (the header's own check)
    48     48|96 pose (flags bit 0 or 1): the beam's sensor-to-world 3 x 4 [R | t], row-major,
                 float32 (48 bytes) or float64 (96 bytes)
    ...          samples
    end    4     CRC-32 (zlib's) of everything before it

The header carries its own CRC so that a magic word met inside samples is refused at once; the
trailing CRC covers the whole packet. The parser (``BeamParser``) resynchronises on the next
magic word after any damage and never loses a packet whose bytes arrived intact.
"""

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from radarcl.errors import ConfigError
from radarcl.geometry import check_pose
from radarcl.io.stream import BAD, BAD_CRC, NEED_MORE, ScanningParser

MAGIC = b"RCBM"
VERSION = 1
HEADER = struct.Struct("<4sBBHIIHHQIB3xII")          # everything before the header CRC
HEADER_SIZE = HEADER.size + 4                         # 48
MAX_HEADER_SIZE = 64                                  # what a later version may grow the header to
POSE_SIZE = 48                                        # 12 float32
POSE64_SIZE = 96                                      # 12 float64
FLAG_POSE = 1
FLAG_POSE64 = 2
SAMPLE_TYPES = {1: np.dtype("<i2"), 2: np.dtype([("i", "<i2"), ("q", "<i2")]), 3: np.dtype("<f4")}
SAMPLE_NAMES = {1: "int16", 2: "complex int16", 3: "float32 power profile"}
MAX_SAMPLES = 1 << 20                                 # a packet of at most 4 MiB of samples


@dataclass(frozen=True)
class BeamPacket:
    """One beam: where it sits in the frame, when, its samples and (optionally) its pose.
    ``samples`` is int16, complex64 (from complex int16) or float32; ``pose`` (4, 4) or None."""

    sequence: int
    frame: int
    azimuth: int
    elevation: int
    timestamp_ns: int
    sample_type: int
    samples: np.ndarray
    pose: np.ndarray = None

    @property
    def shape_text(self):
        return f"{len(self.samples)} {SAMPLE_NAMES[self.sample_type]} samples"


def sample_type_of(dtype):
    """The protocol's sample type for a frame dtype (int16, complex64, float32)."""
    dtype = np.dtype(dtype)
    if dtype == np.int16:
        return 1
    if dtype == np.complex64:
        return 2
    if dtype == np.float32:
        return 3
    raise ConfigError(f"the beam protocol carries int16, complex int16 or float32 samples, not {dtype}")


def encode(sequence, frame, azimuth, elevation, timestamp_ns, samples, pose=None, pose_bits=64):
    """The bytes of one beam packet. ``samples`` int16, complex64 (sent as complex int16: its
    parts must be whole numbers within int16) or float32; ``pose`` (4, 4) or None, sent as
    float64 (``pose_bits`` 64: the map equals the offline one bit for bit) or float32 (32: what
    a radar with a float32 navigation solution sends; the map then differs, see docs/guide/live.md)."""
    samples = np.asarray(samples)
    kind = sample_type_of(samples.dtype)
    for name, value, bits in (("sequence", sequence, None), ("frame", frame, None), ("azimuth", azimuth, 16),
                              ("elevation", elevation, 16), ("timestamp_ns", timestamp_ns, None)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0 or \
                (bits is not None and value >= 1 << bits):
            raise ConfigError(f"{name} must be an integer >= 0{f' below 2^{bits}' if bits else ''}, got {value!r}")
    if samples.ndim != 1 or not 0 < len(samples) <= MAX_SAMPLES:
        raise ConfigError(f"a beam is 1 to {MAX_SAMPLES} samples, got shape {samples.shape}")
    if kind == 2:
        parts = np.stack([samples.real, samples.imag], axis=-1)
        if not (np.isfinite(parts).all() and (parts == np.round(parts)).all() and np.abs(parts).max() <= 32767):
            raise ConfigError("complex samples go out as complex int16: whole numbers within +-32767")
        body = parts.astype("<i2").tobytes()
    else:
        body = samples.astype(SAMPLE_TYPES[kind]).tobytes()
    flags = 0
    if pose is not None:
        if pose_bits not in (32, 64):
            raise ConfigError(f"a pose goes out as float32 or float64 (pose_bits 32 or 64), got {pose_bits!r}")
        flags |= FLAG_POSE64 if pose_bits == 64 else FLAG_POSE
        body = check_pose(pose, "the beam's pose")[:3, :4].astype("<f8" if pose_bits == 64 else "<f4").tobytes() + body
    head = HEADER.pack(MAGIC, VERSION, HEADER_SIZE, flags, int(sequence) & 0xFFFFFFFF, int(frame) & 0xFFFFFFFF,
                       int(azimuth), int(elevation), int(timestamp_ns) & 0xFFFFFFFFFFFFFFFF, len(samples), kind,
                       len(body), 0)
    head += struct.pack("<I", zlib.crc32(head))
    packet = head + body
    return packet + struct.pack("<I", zlib.crc32(packet))


def encode_frame(frame, frame_id, first_sequence, timestamp_ns=0, pose=None, beam_ns=0):
    """A whole frame (n_az, n_el, n_samples) as beam packets, azimuth-major (the order a
    scanning radar sends them); each beam carries ``pose`` when given. Returns a list of bytes."""
    frame = np.asarray(frame)
    n_az, n_el = frame.shape[:2]
    out = []
    for i in range(n_az):
        for k in range(n_el):
            b = i * n_el + k
            out.append(encode(first_sequence + b, frame_id, i, k, timestamp_ns + b * beam_ns, frame[i, k], pose))
    return out


class BeamParser(ScanningParser):
    """The beam protocol as a pure protocol: ``data_received(chunk)`` -> ``BeamPacket``s."""

    MAGIC = MAGIC

    def __init__(self, on_packet=None):
        super().__init__(on_packet)
        self._last_sequence = None

    def _examine(self, view):
        if len(view) < HEADER_SIZE:
            return NEED_MORE, None
        version, header_size = view[4], view[5]
        # A fake magic word (inside samples, or noise) with a large header-size byte would make
        # the parser wait for bytes the next good packet may not send soon; bounding the header
        # bounds that wait to MAX_HEADER_SIZE bytes (the long fuzz run found 8 in 10^6 streams
        # whose last good packet waited behind a claimed header of 221-255 bytes).
        if header_size != HEADER_SIZE if version == VERSION else not HEADER_SIZE <= header_size <= MAX_HEADER_SIZE:
            return BAD, None
        if len(view) < header_size:
            return NEED_MORE, None
        (crc,) = struct.unpack_from("<I", view, header_size - 4)
        if zlib.crc32(view[:header_size - 4]) != crc:
            return BAD, None
        flags, n, kind, payload = view[6] | view[7] << 8, *struct.unpack_from("<IB3xI", view, 28)
        if version == VERSION:          # a later version keeps these offsets and is skipped whole
            if flags & FLAG_POSE and flags & FLAG_POSE64:
                return BAD, None
            pose = POSE_SIZE if flags & FLAG_POSE else POSE64_SIZE if flags & FLAG_POSE64 else 0
            if kind not in SAMPLE_TYPES or not 0 < n <= MAX_SAMPLES or payload != pose + n * SAMPLE_TYPES[kind].itemsize:
                return BAD, None
        elif payload > POSE_SIZE + 8 * MAX_SAMPLES:
            return BAD, None
        size = header_size + payload + 4
        if len(view) < size:
            return NEED_MORE, None
        (crc,) = struct.unpack_from("<I", view, size - 4)
        if zlib.crc32(view[:size - 4]) != crc:
            return BAD_CRC, None
        return "ok", size

    def _decode(self, data):
        if data[4] != VERSION:
            return None
        fields = HEADER.unpack_from(data)
        _, _, _, flags, seq, frame, az, el, t, n, kind, _, _ = fields
        at = HEADER_SIZE
        pose = None
        if flags & (FLAG_POSE | FLAG_POSE64):
            wide = flags & FLAG_POSE64
            pose = np.eye(4)
            pose[:3, :4] = np.frombuffer(data, "<f8" if wide else "<f4", 12, at).reshape(3, 4)
            at += POSE64_SIZE if wide else POSE_SIZE
        raw = np.frombuffer(data, SAMPLE_TYPES[kind], n, at)
        if kind == 1:
            samples = raw.astype(np.int16)
        elif kind == 2:
            samples = (raw["i"] + 1j * raw["q"].astype(np.float32)).astype(np.complex64)
        else:
            samples = raw.astype(np.float32)
        return BeamPacket(seq, frame, az, el, t, kind, samples, pose)

    def _is_new(self, packet):
        """False for a packet repeated (the sequence number just delivered); counts gaps."""
        last = self._last_sequence
        step = None if last is None else (packet.sequence - last) & 0xFFFFFFFF
        if step == 0:
            self.counters.duplicates += 1
            return False
        self._last_sequence = packet.sequence
        if step is not None and step < 1 << 31:
            self.counters.sequence_gaps += step - 1
        return True
