"""TI's mmWave SDK demo output on the data UART: frames of TLVs after a magic word.

Layout (little-endian), as the SDK's ``mmw_output.h`` declares it:

    magic word 02 01 04 03 06 05 08 07
    header: version, totalPacketLen, platform, frameNumber, timeCpuCycles, numDetectedObj,
            numTLVs (uint32 each), and subFrameNumber (uint32) from SDK 2.0 on
    numTLVs x (type uint32, length uint32 = payload bytes, payload)
    padding to a multiple of 32 bytes (totalPacketLen counts it)

Supported header layouts: SDK 1.x (xWR14xx, 36 bytes with the magic word) and SDK 2.x / 3.x
(xWR14xx/16xx/18xx/64xx/68xx, 40 bytes); ``version`` is major << 24 | minor << 16 | ..., and
frames of other majors are skipped whole and counted (``unsupported``). TLV type 2 is the range
profile: one uint16 per range bin at zero Doppler, a fixed-point sum of log2 of the FFT
magnitude over the virtual antennas whose scale depends on the device and SDK (see
``profile_power``). It enters the pipeline at CFAR as power; other TLV types are kept as bytes
and ignored.

The protocol has no checksum: a bit flipped inside a payload cannot be seen. The parser checks
what it can (the sizes add up, the TLVs fit, no magic word inside the frame, which means the
frame was cut short and the next one began) and resynchronises on the next magic word.
"""

import struct
from dataclasses import dataclass, field

import numpy as np

from radarcl.io.stream import BAD, NEED_MORE, ScanningParser

MAGIC = bytes([2, 1, 4, 3, 6, 5, 8, 7])
TLV = struct.Struct("<II")
RANGE_PROFILE, NOISE_PROFILE, DETECTED_POINTS, STATS = 2, 3, 1, 6
SEGMENT = 32                           # frames are padded to this many bytes
MAX_FRAME = 4 << 20                    # a range-Doppler heat map of 512 x 1024 bins fits
MAX_TLVS = 64
SUPPORTED_MAJORS = (1, 2, 3)


def header_size(major):
    """Bytes of the header with the magic word: 36 for SDK 1.x, 40 from SDK 2.0 on."""
    return 36 if major == 1 else 40


@dataclass(frozen=True)
class TiFrame:
    """One frame of the demo's output: header fields and its TLVs {type: payload bytes}."""

    version: int
    platform: int
    frame_number: int
    time_cpu_cycles: int
    detected_objects: int
    subframe: int
    tlvs: dict = field(default_factory=dict)

    @property
    def sdk(self):
        """The SDK version as text, e.g. "3.5.0.4"."""
        v = self.version
        return f"{v >> 24 & 0xFF}.{v >> 16 & 0xFF}.{v >> 8 & 0xFF}.{v & 0xFF}"

    @property
    def range_profile(self):
        """The range profile TLV as uint16 (n_bins,) in Q log2 units, or None."""
        data = self.tlvs.get(RANGE_PROFILE)
        return None if data is None else np.frombuffer(data, "<u2", len(data) // 2).copy()


def profile_power(values, antennas, q_bits=9):
    """The range profile (uint16: ``antennas`` x the mean log2 |X| over the virtual antennas, in
    Q``q_bits``) as the mean power of one antenna, float32: 2 ** (2 v / (2^q_bits antennas)).
    CFAR's thresholds assume square-law power of one channel; the sum of logs is the log of a
    product, so the mean gives the geometric mean magnitude. TI's scales (its Doppler DPU docs
    and its visualizer's log2linScale), for N virtual antennas, N' = 2^ceil(log2 N): xWR14xx a
    Q9 mean (antennas 1, Q9); xWR16xx with SDK 1.x/2.x a Q8 sum (antennas N, Q8); xWR18xx/68xx
    with SDK 3.0/3.1 2^9 / N' x the sum, from 3.2 on 2^8 / N' x the sum (N a power of two:
    antennas 1, Q9 or Q8; N = 12: 192 x the mean, antennas 3, Q6). The sensor profile's [stream]
    keys say which (tests/test_ti_uart.py checks them against TI's worked values)."""
    exponent = np.asarray(values, np.float64) * (2.0 / ((1 << q_bits) * antennas))
    return np.exp2(np.minimum(exponent, 126.0)).astype(np.float32)      # float32 holds up to 2^128


def encode_frame(frame_number, tlvs, version=0x03050004, platform=0xA1843, time_cpu_cycles=0, detected_objects=0,
                 subframe=0):
    """The bytes of one frame: ``tlvs`` a list of (type, payload bytes); padded as the SDK pads."""
    major = version >> 24 & 0xFF
    body = b"".join(TLV.pack(t, len(p)) + bytes(p) for t, p in tlvs)
    size = header_size(major) + len(body)
    total = -(-size // SEGMENT) * SEGMENT
    fields = [version, total, platform, frame_number, time_cpu_cycles, detected_objects, len(tlvs)]
    if major != 1:
        fields.append(subframe)
    head = MAGIC + struct.pack(f"<{len(fields)}I", *fields)
    return head + body + bytes(total - size)


class TiParser(ScanningParser):
    """The demo's UART output as a pure protocol: ``data_received(chunk)`` -> ``TiFrame``s."""

    MAGIC = MAGIC

    def __init__(self, on_packet=None):
        super().__init__(on_packet)
        self._last_frame = None
        self._searched_at, self._searched = -1, 0

    def _examine(self, view):
        if len(view) < 16:
            return NEED_MORE, None
        version, total = struct.unpack_from("<II", view, 8)
        major = version >> 24 & 0xFF
        head = header_size(major)
        if not head <= total <= MAX_FRAME:
            return BAD, None
        if len(view) < head:
            return NEED_MORE, None
        n_tlv = struct.unpack_from("<I", view, 32)[0]
        if n_tlv > MAX_TLVS:
            return BAD, None
        # A magic word inside the frame: this one was cut short and the next one began there.
        # Searched once per byte (a frame may arrive in many chunks): from where the last look ended.
        first = self._searched if self._searched_at == self._start else len(MAGIC)
        end = min(total, len(view))
        if bytes(view[max(len(MAGIC), first - len(MAGIC) + 1):end]).find(MAGIC) >= 0:
            return BAD, None
        self._searched_at, self._searched = self._start, end
        if len(view) < total:
            return NEED_MORE, None
        if major in SUPPORTED_MAJORS:
            at = head
            for _ in range(n_tlv):
                if at + TLV.size > total:
                    return BAD, None
                _, length = TLV.unpack_from(view, at)
                at += TLV.size + length
                if at > total:
                    return BAD, None
            if total - at >= SEGMENT:                 # more than padding left over
                return BAD, None
        return "ok", total

    def _decode(self, data):
        version = struct.unpack_from("<I", data, 8)[0]
        major = version >> 24 & 0xFF
        if major not in SUPPORTED_MAJORS:
            return None
        fields = struct.unpack_from("<7I", data, 8)
        subframe = struct.unpack_from("<I", data, 36)[0] if major != 1 else 0
        at, tlvs = header_size(major), {}
        for _ in range(fields[6]):
            kind, length = TLV.unpack_from(data, at)
            tlvs[kind] = data[at + TLV.size:at + TLV.size + length]
            at += TLV.size + length
        return TiFrame(version, fields[2], fields[3], fields[4], fields[5], subframe, tlvs)

    def _is_new(self, packet):
        last = self._last_frame
        if last is not None and packet.frame_number == last:
            self.counters.duplicates += 1
            return False
        self._last_frame = packet.frame_number
        if last is not None and 0 < packet.frame_number - last < 1 << 31:
            self.counters.sequence_gaps += packet.frame_number - last - 1
        return True
