"""Raw ADC captures of TI xWR 77 GHz radars as published by OpenRadar (PreSense).

Format trap: the real and imaginary parts hold raw UNSIGNED 16-bit ADC words stored as floats
(65375 means -161). ``words_to_int16`` converts each part by two's complement; a plain float to
int16 cast is undefined for values above 32767.
"""

from pathlib import Path

import numpy as np

from radarcl.config import RadarConfig
from radarcl.errors import FrameFormatError

# Chirp profile of the OpenRadar tutorials: 2.5 Msps, 60 MHz/us slope, 128 complex samples,
# f0 = 77.4201 GHz -> B = 3.072 GHz over the sampled 51.2 us. Beamwidths are nominal: the
# capture is one virtual antenna at a time (the TI patch antennas are wide, ~60 x 30 deg).
TI_OPENRADAR = RadarConfig(
    carrier_hz=77.4201e9, bandwidth_hz=60e12 * 51.2e-6, sweep_time_s=51.2e-6,
    sample_rate_hz=2.5e6, n_samples=128, complex_samples=True,
    beamwidth_az_deg=60.0, beamwidth_el_deg=30.0, n_azimuth=1, n_elevation=1,
    range_min_m=0.2, range_max_m=6.0)   # below 0.2 m: transmitter-to-receiver coupling


def words_to_int16(values):
    """Raw unsigned 16-bit words (any real dtype, integral values in 0..65535) -> int16 by two's
    complement. Raises FrameFormatError for non-integral, non-finite or out-of-range values."""
    v = np.asarray(values)
    if not np.isfinite(v).all():
        raise FrameFormatError("ADC words must be finite; found NaN or Inf")
    if (v != np.round(v)).any() or (v < 0).any() or (v > 0xFFFF).any():
        raise FrameFormatError(f"ADC words must be integers in 0..65535, found values in "
                               f"[{v.min()}, {v.max()}]")
    return v.astype(np.int64).astype(np.uint16).view(np.int16)


def complex_words_to_iq(values):
    """Complex array of raw unsigned words -> complex64 I/Q in signed ADC codes."""
    v = np.asarray(values)
    return (words_to_int16(v.real).astype(np.float32)
            + 1j * words_to_int16(v.imag).astype(np.float32)).astype(np.complex64)


def load_capture(path):
    """Load an OpenRadar capture (.txt of complex numbers, or .npy) as complex64 signed codes,
    the original shape kept (the last axis is the samples of one chirp)."""
    path = Path(path)
    try:
        raw = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, dtype=complex)
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"cannot read TI capture {path}: {exc}") from exc
    if not np.iscomplexobj(raw):
        raise FrameFormatError(f"{path} holds {raw.dtype} values; expected complex ADC words")
    return complex_words_to_iq(raw)
