"""Raw ADC captures of TI xWR 77 GHz radars as published by OpenRadar (PreSense).

Format trap: the real and imaginary parts hold raw UNSIGNED 16-bit ADC words stored as floats
(65375 means -161). ``words_to_int16`` converts each part by two's complement; a plain float to
int16 cast is undefined for values above 32767. The radar itself (chirp profile, beams, range)
is the sensor profile ``ti-xwr-openradar`` (radarcl/profiles/ti-xwr-openradar.toml).
"""

from pathlib import Path

import numpy as np

from radarcl.errors import FrameFormatError
from radarcl.io.files import declared_bytes, memory_budget, read_npy_header


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
        if path.suffix == ".npy":
            _check_npy_header(path)
            raw = np.load(path, allow_pickle=False)
        else:
            raw = np.loadtxt(path, dtype=complex)
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"cannot read TI capture {path}: {exc}") from exc
    if not np.iscomplexobj(raw):
        raise FrameFormatError(f"{path} holds {raw.dtype} values; expected complex ADC words")
    return complex_words_to_iq(raw)


def _check_npy_header(path):
    """Refuse a .npy whose header declares more than the memory budget, before reading it."""
    try:
        with open(path, "rb") as f:
            shape, dtype = read_npy_header(f)
    except (OSError, ValueError) as exc:
        raise FrameFormatError(f"cannot read TI capture {path}: {exc}") from exc
    if dtype.hasobject or declared_bytes(shape, dtype) > memory_budget():
        raise FrameFormatError(f"{path} declares {shape} {dtype}: objects or more than the memory budget")
