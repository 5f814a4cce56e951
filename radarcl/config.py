"""Radar configuration: frozen dataclasses, validated on construction.

The defaults are the radar of Foessel-Bunting §2.3: a bistatic 77 GHz FMCW unit sweeping
300 MHz in 256 us, sampled at 1 MHz (256 real samples per ramp), beam 1 deg (az) x 2 deg (el),
64 azimuths 1 deg apart x 4 stacked beams 2 deg apart, range 1-64 m.
"""

import math
from dataclasses import dataclass

import numpy as np

from radarcl import physics
from radarcl.errors import ConfigError

# The paper states 64 m at exactly the Nyquist frequency using c = 3e8 m/s. With the exact
# speed of light that beat frequency is 0.07 % above Nyquist; we accept that much and no more.
NYQUIST_SLACK = 1e-3


def _require(condition, message):
    if not condition:
        raise ConfigError(message)


def _positive_finite(name, value):
    _require(isinstance(value, (int, float)) and not isinstance(value, bool)
             and math.isfinite(value) and value > 0,
             f"{name} must be a positive finite number, got {value!r}")


def _positive_int(name, value):
    _require(isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value > 0,
             f"{name} must be a positive integer, got {value!r}")


def is_power_of_two(n):
    """True for 1, 2, 4, 8, ... (integers only)."""
    return isinstance(n, (int, np.integer)) and n > 0 and (n & (n - 1)) == 0


@dataclass(frozen=True)
class RadarConfig:
    """One FMCW radar: its sweep, sampling, beam and scan lattice. All SI units.

    Raises ``ConfigError`` with the reason for any impossible combination (samples that do
    not fit in the sweep, a range of interest beyond Nyquist, an inverted range interval...).
    """

    carrier_hz: float = 77e9              # F0, eq. 3
    bandwidth_hz: float = 300e6           # B_s, swept in sweep_time_s
    sweep_time_s: float = 256e-6          # T_s: duration of the sampled ramp
    sample_rate_hz: float = 1e6           # ADC rate
    n_samples: int = 256                  # samples per ramp
    complex_samples: bool = False         # True: I/Q baseband; False: real ADC
    beamwidth_az_deg: float = 1.0         # half-power, one way
    beamwidth_el_deg: float = 2.0
    n_azimuth: int = 64                   # beams per frame in azimuth
    n_elevation: int = 4                  # stacked beams
    azimuth_step_deg: float = 1.0
    elevation_step_deg: float = 2.0
    range_min_m: float = 1.0              # range of operation (paper §2.3)
    range_max_m: float = 64.0

    def __post_init__(self):
        for name in ("carrier_hz", "bandwidth_hz", "sweep_time_s", "sample_rate_hz",
                     "beamwidth_az_deg", "beamwidth_el_deg", "azimuth_step_deg",
                     "elevation_step_deg", "range_max_m"):
            _positive_finite(name, getattr(self, name))
        for name in ("n_samples", "n_azimuth", "n_elevation"):
            _positive_int(name, getattr(self, name))
        _require(isinstance(self.complex_samples, bool),
                 f"complex_samples must be True or False, got {self.complex_samples!r}")
        _require(self.n_samples >= 2, f"n_samples must be at least 2, got {self.n_samples}")
        _require(self.beamwidth_az_deg < 180 and self.beamwidth_el_deg < 180,
                 "beamwidths must be below 180 deg, got "
                 f"{self.beamwidth_az_deg} x {self.beamwidth_el_deg} deg")
        _require(self.bandwidth_hz < self.carrier_hz,
                 f"bandwidth_hz ({self.bandwidth_hz:g}) must be below carrier_hz ({self.carrier_hz:g})")
        sampled = self.n_samples / self.sample_rate_hz
        _require(sampled <= self.sweep_time_s * (1 + 1e-9),
                 f"{self.n_samples} samples at {self.sample_rate_hz:g} Hz last {sampled * 1e6:.1f} us, "
                 f"longer than the {self.sweep_time_s * 1e6:.1f} us sweep")
        _require(isinstance(self.range_min_m, (int, float)) and math.isfinite(self.range_min_m)
                 and 0 <= self.range_min_m < self.range_max_m,
                 f"need 0 <= range_min_m < range_max_m, got {self.range_min_m!r} and {self.range_max_m!r}")
        f_max = float(self.max_beat_frequency_hz)
        _require(f_max <= self.nyquist_hz * (1 + NYQUIST_SLACK),
                 f"range_max_m = {self.range_max_m} m beats at {f_max / 1e3:.1f} kHz (eq. 10), above the "
                 f"Nyquist limit {self.nyquist_hz / 1e3:.1f} kHz of a {'complex' if self.complex_samples else 'real'} "
                 f"ADC at {self.sample_rate_hz / 1e6:g} MHz; the largest unambiguous range is "
                 f"{float(self.unambiguous_range_m):.2f} m")

    # -- derived quantities, each from its equation in radarcl.physics ------------------------
    @property
    def wavelength_m(self):
        """Carrier wavelength [m]."""
        return float(physics.wavelength(self.carrier_hz))

    @property
    def range_resolution_m(self):
        """c / 2B, eq. 7."""
        return float(physics.range_resolution(self.bandwidth_hz))

    @property
    def max_beat_frequency_hz(self):
        """Beat frequency at range_max_m, eq. 10."""
        return float(physics.max_beat_frequency(self.range_max_m, self.bandwidth_hz, self.sweep_time_s))

    @property
    def nyquist_hz(self):
        """Highest unambiguous beat frequency: fs/2 for a real ADC, fs for complex I/Q."""
        return self.sample_rate_hz if self.complex_samples else self.sample_rate_hz / 2

    @property
    def unambiguous_range_m(self):
        """Range whose beat frequency is the Nyquist frequency."""
        return float(physics.range_of_beat_frequency(self.nyquist_hz, self.bandwidth_hz, self.sweep_time_s))

    @property
    def aperture_az_m(self):
        """Antenna aperture implied by the azimuth beamwidth, eq. 1."""
        return float(physics.aperture_for_beamwidth(self.wavelength_m, math.radians(self.beamwidth_az_deg)))

    @property
    def aperture_el_m(self):
        """Antenna aperture implied by the elevation beamwidth, eq. 1."""
        return float(physics.aperture_for_beamwidth(self.wavelength_m, math.radians(self.beamwidth_el_deg)))

    @property
    def far_field_m(self):
        """Far-field distance of the larger aperture, eq. 2."""
        return float(physics.far_field_distance(max(self.aperture_az_m, self.aperture_el_m), self.wavelength_m))

    @property
    def n_beams(self):
        """Beams per frame: n_azimuth x n_elevation."""
        return self.n_azimuth * self.n_elevation

    @property
    def frame_shape(self):
        """Shape of one frame of raw samples: (n_azimuth, n_elevation, n_samples)."""
        return (self.n_azimuth, self.n_elevation, self.n_samples)

    def check_n_fft(self, n_fft):
        """Refuse an FFT length that is not a power of two or is shorter than the ramp."""
        _require(is_power_of_two(n_fft),
                 f"n_fft must be a power of two, got {n_fft!r}")
        _require(n_fft >= self.n_samples,
                 f"n_fft = {n_fft} is shorter than the {self.n_samples} samples per ramp; "
                 f"zero padding (eq. 11) needs n_fft >= n_samples")
        return int(n_fft)

    def n_bins(self, n_fft):
        """Range bins kept from an n_fft FFT: all n_fft for I/Q, the n_fft/2 below Nyquist for real."""
        n_fft = self.check_n_fft(n_fft)
        return n_fft if self.complex_samples else n_fft // 2

    def bin_spacing_m(self, n_fft):
        """Range between bins after zero padding to n_fft (§4.1)."""
        return float(physics.bin_spacing(self.bandwidth_hz, self.sweep_time_s, self.sample_rate_hz,
                                         self.check_n_fft(n_fft)))

    def bin_ranges_m(self, n_fft):
        """Range [m] of every kept bin, float64, shape (n_bins,)."""
        return np.arange(self.n_bins(n_fft)) * self.bin_spacing_m(n_fft)


PAPER_RADAR = RadarConfig()
"""The radar of Foessel-Bunting §2.3, the default everywhere."""
