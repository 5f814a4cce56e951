"""float64 numpy oracle of every stage: the semantics, written plainly.

Kernels are tested against these functions at named tolerances; benchmarks report kernel error
against them. Nothing here is fast, and nothing here needs OpenCL.
"""

import numpy as np

from radarcl.errors import ConfigError, ShapeError

WINDOWS = ("hann", "rect")
OUTPUTS = ("magnitude", "power")

# Per-beam flags set while loading samples (range_fft kernel and oracle alike).
FLAG_NONFINITE = 1   # a NaN or Inf sample: the beam is invalid and gives no evidence
FLAG_CLIPPED = 2     # a sample at or beyond the clip level: the ADC saturated


def window_coefficients(kind, n):
    """Window of length n, float64.

    ``"hann"`` is the periodic (DFT-even) Hann window 0.5 - 0.5 cos(2 pi j / n), the same as
    ``scipy.signal.get_window("hann", n)``: -31 dB sidelobes and a mainlobe 1.5x wider than the
    rectangular window's (paper §3.2, Fig. 3). ``"rect"`` is all ones (no window).
    """
    if kind == "hann":
        return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)
    if kind == "rect":
        return np.ones(n)
    raise ConfigError(f"window must be one of {WINDOWS}, got {kind!r}")


def range_gain(n_bins, bin_spacing_m, exponent):
    """Range-attenuation compensation r^k per bin (paper §2: "a filter generally corrects for
    attenuation due to distance"): (j * bin_spacing_m) ** exponent, float64, shape (n_bins,).

    Use k = 2 on magnitudes or k = 4 on powers to undo the radar equation's 1/r^4 in power.
    Bin 0 (zero range) gets gain 0 for k > 0.
    """
    if not np.isfinite(exponent) or not np.isfinite(bin_spacing_m) or bin_spacing_m <= 0:
        raise ConfigError(f"range gain needs a finite exponent and a positive bin spacing, "
                          f"got exponent {exponent!r}, spacing {bin_spacing_m!r}")
    return (np.arange(n_bins) * float(bin_spacing_m)) ** float(exponent)


def beam_flags(samples, clip_level=np.inf):
    """Per-beam flags (uint8, shape samples.shape[:-1]): FLAG_NONFINITE if any sample is NaN or
    Inf, FLAG_CLIPPED if any |sample| (either of I and Q) >= clip_level."""
    x = np.asarray(samples)
    parts = (x.real, x.imag) if np.iscomplexobj(x) else (x,)
    nonfinite = np.zeros(x.shape[:-1], bool)
    clipped = np.zeros(x.shape[:-1], bool)
    for part in parts:
        part = part.astype(np.float64)
        nonfinite |= ~np.isfinite(part).all(axis=-1)
        with np.errstate(invalid="ignore"):
            clipped |= (np.abs(np.where(np.isfinite(part), part, 0.0)) >= clip_level).any(axis=-1)
    return (nonfinite * FLAG_NONFINITE + clipped * FLAG_CLIPPED).astype(np.uint8)


def range_profile(samples, n_fft, *, window="hann", output="magnitude", gain=None):
    """Range processing of beat-signal samples (paper §3.2, eq. 11), in float64.

    samples: (..., n) real or complex. Each beam is windowed, zero padded to ``n_fft`` (a power
    of two >= n), transformed, and its bins are calibrated by the window's coherent gain so that
    a complex tone of amplitude A on a bin centre reads A (a real one A/2) at any padding.
    Kept bins: all n_fft for complex input, the n_fft/2 below Nyquist for real input (the
    paper's "512 range bins" for n_fft = 1024). ``output`` is the magnitude or its square;
    ``gain`` (n_bins,) multiplies the result, e.g. ``range_gain``. Beams with a non-finite
    sample come out all NaN (see ``beam_flags``): they are invalid and must give no evidence.
    """
    x = np.asarray(samples)
    if x.ndim < 1 or x.shape[-1] < 1:
        raise ShapeError(f"samples must be (..., n_samples) with n_samples >= 1, got shape {x.shape}")
    n = x.shape[-1]
    if not (isinstance(n_fft, (int, np.integer)) and n_fft >= n and n_fft & (n_fft - 1) == 0):
        raise ConfigError(f"n_fft must be a power of two >= n_samples = {n}, got {n_fft!r}")
    if output not in OUTPUTS:
        raise ConfigError(f"output must be one of {OUTPUTS}, got {output!r}")
    is_complex = np.iscomplexobj(x)
    x = x.astype(np.complex128 if is_complex else np.float64)
    invalid = ~np.isfinite(x).all(axis=-1)
    w = window_coefficients(window, n)
    spectrum = np.fft.fft(np.where(np.isfinite(x), x, 0) * w, n=int(n_fft), axis=-1)
    n_bins = n_fft if is_complex else n_fft // 2
    result = np.abs(spectrum[..., :n_bins]) / w.sum()
    if output == "power":
        result = result ** 2
    if gain is not None:
        gain = np.asarray(gain, dtype=np.float64)
        if gain.shape != (n_bins,):
            raise ShapeError(f"gain must have shape ({n_bins},), got {gain.shape}")
        result = result * gain
    result[invalid] = np.nan
    return result
