"""TI's mmWave demo UART (radarcl/io/ti_uart.py): both header layouts, TLVs we skip, frames
cut short, other SDK majors, damage, and the range profile's conversion to power."""

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarcl.io import emulator
from radarcl.io import ti_uart as tu


def frames(n=5, version=0x03050004, bins=64):
    rng = np.random.default_rng(n)
    profiles = rng.integers(2000, 30000, (n, bins)).astype(np.uint16)
    return emulator.ti_packets(profiles, version=version), profiles


def parse(data, cuts=()):
    p = tu.TiParser()
    prev = 0
    for c in sorted(cuts) + [len(data)]:
        p.data_received(data[prev:c])
        prev = c
    return p, p.take()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(0, 5000), max_size=30), st.sampled_from([0x01020000, 0x02010004, 0x03050004]))
def test_both_header_layouts_in_chunks_split_anywhere(cuts, version):
    packets, profiles = frames(version=version)
    data = b"".join(packets)
    p, got = parse(data, [c % (len(data) + 1) for c in cuts])
    assert [f.frame_number for f in got] == list(range(5))
    assert all(np.array_equal(f.range_profile, q) for f, q in zip(got, profiles))
    assert all(sorted(f.tlvs) == [tu.DETECTED_POINTS, tu.RANGE_PROFILE, tu.STATS] for f in got)
    assert got[0].sdk == f"{version >> 24}.{version >> 16 & 255}.{version >> 8 & 255}.{version & 255}"
    assert p.counters.bytes_dropped == 0 and all(len(x) % tu.SEGMENT == 0 for x in packets)


def test_sdk1_header_is_36_bytes_and_later_ones_40():
    one = tu.encode_frame(1, [], version=0x01000000)
    three = tu.encode_frame(1, [], version=0x03050004)
    assert struct.unpack_from("<I", one, 12)[0] == 64 and one[36:] == bytes(28)        # padding after 36
    assert struct.unpack_from("<I", three, 32)[0] == 0 and len(three) == 64


def test_a_frame_cut_short_does_not_swallow_the_next():
    packets, _ = frames()
    p, got = parse(packets[0] + packets[1][:200] + packets[2] + packets[3])
    assert [f.frame_number for f in got] == [0, 2, 3]
    assert p.counters.header_failures == 1 and p.counters.sequence_gaps == 1
    c = p.counters
    assert c.bytes_in == c.bytes_in_packets + c.bytes_dropped + c.bytes_pending


def test_another_sdk_major_is_skipped_whole():
    packets, _ = frames(2)
    future = tu.encode_frame(9, [(2, b"\x00" * 8)], version=0x04000000)
    p, got = parse(packets[0] + future + packets[1])
    assert [f.frame_number for f in got] == [0, 1] and p.counters.unsupported == 1


def test_sizes_that_do_not_add_up_are_refused():
    good = tu.encode_frame(1, [(2, b"\x01\x00" * 8)])
    bad = bytearray(good)
    struct.pack_into("<I", bad, 44, 4000)                    # the TLV claims more than the frame holds
    p, got = parse(bytes(bad) + good)
    assert [f.frame_number for f in got] == [1] and p.counters.header_failures == 1


@settings(max_examples=100, deadline=None)
@given(st.data())
def test_damage_never_raises_and_untouched_frames_arrive(data):
    packets, profiles = frames(6)
    bounds = np.cumsum([0] + [len(x) for x in packets])
    buf = bytearray(b"".join(packets))
    touched = set()
    for kind, pos, value in sorted(data.draw(st.lists(st.tuples(st.sampled_from(["flip", "delete", "insert"]),
                                                               st.integers(0, len(buf) - 1), st.integers(0, 255)),
                                                     max_size=4)), key=lambda e: -e[1]):
        if pos >= len(buf):                                   # an earlier edit at the end took it
            continue
        touched.add(int(np.searchsorted(bounds, pos, side="right") - 1))
        if kind == "flip":
            buf[pos] ^= 1 << (value % 8)
        elif kind == "delete":
            del buf[pos]
        else:
            buf[pos:pos] = bytes([value])
    p, got = parse(bytes(buf), data.draw(st.lists(st.integers(0, len(buf)), max_size=8)))
    numbers = [f.frame_number for f in got]
    for i in range(6):
        # an untouched frame arrives, unless damage to the one before claimed its bytes (TI has no CRC)
        if i not in touched and i - 1 not in touched:
            assert i in numbers, (i, touched, numbers)
    c = p.counters
    assert c.bytes_in == c.bytes_in_packets + c.bytes_dropped + c.bytes_pending


def test_profile_power_inverts_the_emulators_q9():
    for antennas in (1, 4, 12):
        top = min(2.0 ** (2 * 65535 / (512 * antennas)), 2.0 ** 120)     # what uint16 Q9 and float32 hold
        power = np.array([1.0, 10.0, 1e4, 0.99 * top])
        q9 = emulator.q9_of_power(power, antennas)
        back = tu.profile_power(q9, antennas)
        assert np.allclose(back, power, rtol=np.log(2) / (256 * antennas) * 1.01)   # half a Q9 step
    assert np.isfinite(tu.profile_power(np.array([65535], np.uint16), 1)).all()       # no float32 overflow


def test_range_profile_scaling_follows_tis_documentation():
    """The ti-xwr18xx-uart profile's scaling against what TI documents, not against our emulator.

    - The mmw demo (SDK 3.x, xWR18xx/68xx) sends as its range profile TLV (type 2, Range FFT size
      x uint16) the 0th Doppler bin of its detection matrix (mss_main.c: ``detMatrix[i *
      numDopplerBins]``).
    - The Doppler DPU's documentation (ti/datapath/dpu/dopplerproc/dopplerproc.h, "Summation")
      defines that matrix: the HWA's log2|X| in Q11, summed over the N virtual antennas by an
      FFT whose output is 1/N' of the sum (N' = 2^ceil(log2 N)), 8 bits dropped: Q8, so a value
      is 2^8 / N' x sum_a log2|X_a|; and its worked threshold: TdB dB above the noise is
      T = 256 x TdB / 6 x N / N' units.
    - TI's mmWave Demo Visualizer 3.6.0 (app/input_validations.js) turns a value into dB as
      value x log2linScale x 20 log10(2), log2linScale = (1 / 256) x N' / N from SDK 3.2 on
      (1 / 512 x N' / N before), 1 / (256 N) on xWR16xx with SDK 1.x/2.x (a Q8 sum), 1 / 512 on
      xWR14xx (a Q9 mean). (The demo's doxygen still says "sum of log2 magnitudes ... in Q9
      format": SDK 2.x's words.)
    The profile's demo: SDK 3.5, 1 TX x 4 RX, so N = N' = 4."""
    from radarcl.config import sensors
    from radarcl.livemap import ti_scaling

    antennas, q_bits = ti_scaling(sensors.load("ti-xwr18xx-uart"))
    n = n_pow2 = 4
    log2lin = (1 / 256) * n_pow2 / n                                   # the visualizer, SDK >= 3.2
    # one antenna magnitude 2^10 on each of the 4: the value is 2^8 / 4 x 4 x 10 = 2560, and the
    # power of one antenna 2^20 (profile_power's promise: the mean power of one antenna)
    value = round(2 ** 8 / n_pow2 * n * 10)
    assert value == 2560 and tu.profile_power(np.array([value], np.uint16), antennas, q_bits)[0] == 2.0 ** 20
    # TI's worked threshold: 15 dB above the noise is 256 x 15 / 6 x N / N' = 640 units; in power
    # the profile says 640 x log2lin x 20 log10(2) = 15.05 dB (TI's 6 is 20 log10(2) = 6.02, rounded)
    t = round(256 * 15 / 6 * n / n_pow2)
    v = np.array([3000, 3000 + t], np.uint16)
    p = tu.profile_power(v, antennas, q_bits).astype(np.float64)
    step_db = 10 * np.log10(p[1] / p[0])
    assert t == 640 and step_db == pytest.approx(t * log2lin * 20 * np.log10(2), rel=1e-6)
    assert step_db == pytest.approx(15.0, rel=0.004)
    # and the visualizer's dB of any value, up to its constant FFT-scaling offset (to 2^8 x 62,
    # past any log2 |X| of the HWA's 32-bit magnitudes; beyond, float32 power saturates at 2^126)
    values = np.arange(0, 256 * 62, 97, dtype=np.uint16)
    db = 10 * np.log10(tu.profile_power(values, antennas, q_bits).astype(np.float64))
    np.testing.assert_allclose(db - db[0], (values - values[0]) * log2lin * 20 * np.log10(2), rtol=1e-6, atol=1e-4)
