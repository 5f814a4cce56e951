"""FMCW beat-signal simulator (paper §2.2, eq. 3-6): the source of truth for tests and the demo.

A target at range r delays the echo by t' = 2 r / c. After the mixer and the low-pass filter
only the first series of eq. 5 remains: per target a tone

    a cos(2 pi (B t' / T) t + (2 pi F0 t' - pi (B / T) t'^2 - phi))

at the beat frequency B t' / T (eq. 6a). ``amplitude`` here is the tone's amplitude a
(A A'_i / 2 in eq. 5) in ADC volts. I/Q receivers give a exp(i (...)) instead of the cosine.
Noise is white Gaussian receiver noise; the ADC rounds to integer codes and clips at its rails.
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl.config.stage_config import RadarConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.physics import SPEED_OF_LIGHT


CHUNK_BYTES = 1 << 27        # beat_signal's temporaries per block of beams (128 MiB)


@dataclass(frozen=True)
class Adc:
    """A signed ADC of ``bits`` bits (2-16) whose code 2^(bits-1) corresponds to ``full_scale`` volts."""

    bits: int = 16
    full_scale: float = 1.0

    def __post_init__(self):
        if not (isinstance(self.bits, int) and 2 <= self.bits <= 16):
            raise ConfigError(f"Adc.bits must be an integer in 2..16 (codes are stored as int16), got {self.bits!r}")
        if not (np.isfinite(self.full_scale) and self.full_scale > 0):
            raise ConfigError(f"Adc.full_scale must be a positive finite voltage, got {self.full_scale!r}")

    @property
    def max_code(self):
        """Largest code, 2^(bits-1) - 1; the smallest is -2^(bits-1)."""
        return 2 ** (self.bits - 1) - 1

    @property
    def clip_level(self):
        """|code| at or above which a sample counts as clipped (pass to RangeFFT)."""
        return float(self.max_code)

    def quantise(self, volts):
        """Round volts to codes, clipping at the rails. Returns (codes, n_clipped): int16 codes for
        real input, complex64 with integer parts for complex input."""
        v = np.asarray(volts)
        lsb = self.full_scale / 2 ** (self.bits - 1)

        def one(part):
            codes = np.round(part / lsb)
            clipped = (codes > self.max_code) | (codes < -self.max_code - 1)
            return np.clip(codes, -self.max_code - 1, self.max_code), int(np.count_nonzero(clipped))

        if np.iscomplexobj(v):
            (re, n_re), (im, n_im) = one(v.real), one(v.imag)
            return (re + 1j * im).astype(np.complex64), n_re + n_im
        codes, n = one(v)
        return codes.astype(np.int16), n


@dataclass(frozen=True)
class SimulatedFrame:
    """Samples (..., n_samples) and how many samples the ADC clipped."""

    samples: np.ndarray
    n_clipped: int


@dataclass(frozen=True)
class PointTarget:
    """One point target seen by beam (az_index, el_index) of a frame."""

    az_index: int
    el_index: int
    range_m: float
    amplitude: float
    phase_rad: float = 0.0


def beat_signal(config: RadarConfig, amplitude, range_m, phase_rad=0.0):
    """Noise-free beat signal, eq. 5 (first series), float64 or complex128.

    amplitude, range_m, phase_rad: broadcastable arrays whose LAST axis lists the targets of a
    beam (amplitude 0 pads beams with fewer targets). Returns shape (..., n_samples): the sum over
    the last axis. Complex (I/Q) when ``config.complex_samples``.
    """
    amplitude, range_m, phase_rad = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (amplitude, range_m, phase_rad)))
    if not (np.isfinite(amplitude).all() and np.isfinite(range_m).all() and np.isfinite(phase_rad).all()):
        raise ConfigError("target amplitudes, ranges and phases must be finite")
    if (range_m < 0).any():
        raise ConfigError(f"target ranges must be >= 0 m, got a minimum of {range_m.min()} m")
    t = np.arange(config.n_samples) / config.sample_rate_hz
    delay = 2.0 * range_m / SPEED_OF_LIGHT                               # t', paper §2.2
    slope = config.bandwidth_hz / config.sweep_time_s                    # B_s / T_s
    f_beat = slope * delay                                               # eq. 6a
    phase0 = 2 * np.pi * config.carrier_hz * delay - np.pi * slope * delay ** 2 - phase_rad
    # a block of beams at a time, so that the (beams, K, n_samples) tones stay near CHUNK_BYTES;
    # each beam's sum runs over its own targets in order, so blocks change no bit of it
    lead, k = amplitude.shape[:-1], amplitude.shape[-1]
    amplitude, f_beat, phase0 = (a.reshape(math.prod(lead), k) for a in (amplitude, f_beat, phase0))
    out = np.empty((len(amplitude), config.n_samples), np.complex128 if config.complex_samples else np.float64)
    rows = max(1, CHUNK_BYTES // (16 * max(k, 1) * config.n_samples))
    for i in range(0, len(amplitude), rows):
        block = slice(i, i + rows)
        arg = 2 * np.pi * f_beat[block, :, None] * t + phase0[block, :, None]       # (beams, K, n_samples)
        tone = np.exp(1j * arg) if config.complex_samples else np.cos(arg)
        out[block] = np.sum(amplitude[block, :, None] * tone, axis=-2)
    return out.reshape(lead + (config.n_samples,))


def simulate_beams(config: RadarConfig, amplitude, range_m, phase_rad=0.0, *, noise_rms=0.0,
                   adc=None, seed=None):
    """Beat signal plus receiver noise, optionally quantised by ``adc``; seeded and reproducible.

    noise_rms: standard deviation [V] of white Gaussian noise per sample (for I/Q: total, split
    equally between I and Q). adc: an ``Adc`` to return integer codes (int16, or complex64 for I/Q);
    None returns volts (float64 / complex128). Returns a ``SimulatedFrame``.
    """
    if not (np.isfinite(noise_rms) and noise_rms >= 0):
        raise ConfigError(f"noise_rms must be finite and >= 0, got {noise_rms!r}")
    signal = beat_signal(config, amplitude, range_m, phase_rad)
    rng = np.random.default_rng(seed)
    if noise_rms > 0:
        if config.complex_samples:
            signal = signal + (noise_rms / np.sqrt(2)) * (rng.standard_normal(signal.shape)
                                                         + 1j * rng.standard_normal(signal.shape))
        else:
            signal = signal + noise_rms * rng.standard_normal(signal.shape)
    if adc is None:
        return SimulatedFrame(signal, 0)
    codes, n_clipped = adc.quantise(signal)
    return SimulatedFrame(codes, n_clipped)


def simulate_frame(config: RadarConfig, targets, *, noise_rms=0.0, adc=None, seed=None):
    """A whole frame (n_az, n_el, n_samples) from a list of ``PointTarget``; beams without
    targets hold noise only. See ``simulate_beams`` for noise and ADC."""
    targets = list(targets)
    per_beam = {}
    for tgt in targets:
        if not (0 <= tgt.az_index < config.n_azimuth and 0 <= tgt.el_index < config.n_elevation):
            raise ShapeError(f"target beam ({tgt.az_index}, {tgt.el_index}) is outside the "
                             f"{config.n_azimuth} x {config.n_elevation} beam lattice")
        per_beam.setdefault((tgt.az_index, tgt.el_index), []).append(tgt)
    k = max([len(v) for v in per_beam.values()], default=1)
    shape = (config.n_azimuth, config.n_elevation, k)
    amplitude, range_m, phase = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    for (az, el), beam_targets in per_beam.items():
        for i, tgt in enumerate(beam_targets):
            amplitude[az, el, i], range_m[az, el, i], phase[az, el, i] = tgt.amplitude, tgt.range_m, tgt.phase_rad
    return simulate_beams(config, amplitude, range_m, phase, noise_rms=noise_rms, adc=adc, seed=seed)
