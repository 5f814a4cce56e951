"""Radar configuration: frozen dataclasses, validated on construction.

The defaults are the radar of Foessel-Bunting §2.3: a bistatic 77 GHz FMCW unit sweeping
300 MHz in 256 us, sampled at 1 MHz (256 real samples per ramp), beam 1 deg (az) x 2 deg (el),
64 azimuths 1 deg apart x 4 stacked beams 2 deg apart, range 1-64 m.
"""

import functools
import math
import numbers
from dataclasses import dataclass

import numpy as np

from radarcl import cfar_theory, models, physics
from radarcl.errors import ConfigError

# The paper states 64 m at exactly the Nyquist frequency using c = 3e8 m/s. With the exact
# speed of light that beat frequency is 0.07 % above Nyquist; we accept that much and no more.
NYQUIST_SLACK = 1e-3


def _is_real(value):
    """A real number, numpy's scalars included (np.float32(0.01) is a valid pfa); never a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _is_int(value):
    """An integer, numpy's included; never a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def _require(condition, message):
    if not condition:
        raise ConfigError(message)


def _positive_finite(name, value):
    _require(_is_real(value)
             and math.isfinite(value) and value > 0,
             f"{name} must be a positive finite number, got {value!r}")


def _positive_int(name, value):
    _require(_is_int(value) and value > 0,
             f"{name} must be a positive integer, got {value!r}")


def is_power_of_two(n):
    """True for 1, 2, 4, 8, ... (integers only)."""
    return _is_int(n) and n > 0 and (n & (n - 1)) == 0


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
        _require(isinstance(self.complex_samples, (bool, np.bool_)),
                 f"complex_samples must be True or False, got {self.complex_samples!r}")
        with np.errstate(all="ignore"):
            derived = {"range resolution c / 2B [m]": self.range_resolution_m, "wavelength [m]": self.wavelength_m,
                       "beat frequency at range_max_m [Hz] (eq. 10)": self.max_beat_frequency_hz}
        for what, value in derived.items():
            _require(math.isfinite(value) and value > 0,
                     f"the {what} comes out as {value:g}: carrier_hz {self.carrier_hz:g}, bandwidth_hz "
                     f"{self.bandwidth_hz:g}, sweep_time_s {self.sweep_time_s:g} describe no radar")
        _require(self.range_resolution_m < self.range_max_m,
                 f"the range resolution c / 2B = {self.range_resolution_m:.3g} m (bandwidth_hz {self.bandwidth_hz:g}) "
                 f"is not below range_max_m = {self.range_max_m:g} m: the sweep resolves nothing in its range")
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
        _require(_is_real(self.range_min_m) and math.isfinite(self.range_min_m)
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


MAX_TRAIN = 4096        # CA/GO/SO: 2 x 4096 cells of at most oracle.PROFILE_LIMIT sum to a finite float32
MAX_TRAIN_OS = 128      # OS ranks 2 x train cells against each other per bin: O(train^2)
MAX_GUARD = 1 << 20


@dataclass(frozen=True)
class CfarConfig:
    """A CFAR detector (paper §3.3, Fig. 6) on power profiles; see ``radarcl.cfar_theory``.

    kind: "ca" (cell averaging, the paper's), "go" (greatest of), "so" (smallest of), "os"
        (ordered statistic).
    guard, train: guard and training cells per side of the cell under test.
    pfa: design false-alarm probability; the threshold factor ``alpha`` follows from it.
    rank: OS only, the k-th smallest of the 2 x train cells (default round(3/4 n), Rohling).
    noise_floor: the noise estimate is max(estimate, noise_floor), so an all-zero training
        window gives a finite ratio and log. 1e-30 keeps alpha x floor a normal float32.

    Defaults: the paper's cell averaging at P_fa 1e-3, sized for its 512 bins of 0.125 m. The
    guard band must hold half of the widest pulse: a ground echo at -9 deg spans some 35 bins
    at the threshold, and with a narrower guard its own bins raise the noise estimate until it
    is no longer detected in full (measured on scene.echoes.fig10_ground_beam: guard 4 and
    8 lose it or cut it below the wide-pulse width, 16 keeps it wide).

    Edge rule "shift": every cell uses exactly 2 x train training cells inside the profile.
    Near an end, the cells the missing side cannot give are taken further out on the other
    side, outside the guard band. The estimate then has the same statistics at every bin, so
    one alpha gives the design P_fa everywhere (zero padding would bias it low, wrap-around
    would mix the two ends). The oracle is ``radarcl.oracle.cfar``.
    """

    kind: str = "ca"
    guard: int = 16         # covers half of a wide ground echo, so it does not mask itself
    train: int = 16
    pfa: float = 1e-3
    rank: int | None = None
    noise_floor: float = 1e-30

    def __post_init__(self):
        _require(self.kind in cfar_theory.CFAR_KINDS,
                 f"CFAR kind must be one of {cfar_theory.CFAR_KINDS}, got {self.kind!r}")
        _require(_is_int(self.guard)
                 and self.guard >= 0, f"guard must be an integer >= 0, got {self.guard!r}")
        _positive_int("train", self.train)
        most = MAX_TRAIN_OS if self.kind == "os" else MAX_TRAIN
        _require(self.train <= most, f"train must be at most {most} cells per side for {self.kind.upper()}-CFAR "
                                     f"(got {self.train}): " + ("OS sorts 2 x train cells per bin"
                                                                if self.kind == "os" else
                                                                "its float32 sums must stay finite"))
        _require(self.guard <= MAX_GUARD, f"guard must be at most {MAX_GUARD} cells per side, got {self.guard}")
        _require(_is_real(self.pfa) and 0 < self.pfa < 1,
                 f"pfa must lie strictly between 0 and 1, got {self.pfa!r}")
        if self.kind == "os":
            if self.rank is None:
                object.__setattr__(self, "rank", cfar_theory.default_rank(self.n_train))
            _require(_is_int(self.rank) and 1 <= self.rank <= self.n_train,
                     f"OS-CFAR rank must be in [1, {self.n_train}] (2 x train cells), got {self.rank!r}")
        else:
            _require(self.rank is None, f"rank applies to OS-CFAR only, got rank={self.rank!r} "
                                        f"for kind {self.kind!r}")
        _require(_is_real(self.noise_floor) and 1e-37 <= self.noise_floor < 1e37,
                 f"noise_floor must lie in [1e-37, 1e37] (a normal float32), got {self.noise_floor!r}")
        _require(self.alpha * self.noise_floor >= 1.2e-38,
                 f"alpha x noise_floor = {self.alpha * self.noise_floor:.3g} is below the smallest normal "
                 f"float32; raise noise_floor or lower pfa")

    @property
    def n_train(self):
        """Training cells in all: 2 x train."""
        return 2 * int(self.train)

    @property
    def window(self):
        """Cells a profile needs at least: the cell under test, 2 x guard and 2 x train."""
        return 1 + 2 * int(self.guard) + 2 * int(self.train)

    @functools.cached_property
    def alpha(self):
        """Threshold factor on the noise estimate for the design pfa (``cfar_theory.threshold_factor``;
        solved once per config: GO, SO and OS need a bisection)."""
        return cfar_theory.threshold_factor(self.kind, float(self.pfa), self.n_train,
                                          int(self.rank) if self.rank is not None else None)

    def check_profile_length(self, n_bins):
        """Refuse profiles shorter than the CFAR window."""
        _require(n_bins >= self.window,
                 f"a {self.kind.upper()}-CFAR with {self.guard} guard and {self.train} training cells per "
                 f"side needs profiles of at least {self.window} bins, got {n_bins}")
        return int(n_bins)


@dataclass(frozen=True)
class InterpretConfig:
    """The down-range interpreter, eq. 12, with the paper's defaults.

    Evidence per bin, in natural log-odds (``radarcl.logodds``):
      pulse bins (r/n > alpha):                 k_occ * log10(r / n), never below 0
      noise bins before the first wide pulse:   e_high  (E_h)
      noise bins after its end:                 e_low   (E_l)
      bins outside [range_min_m, range_max_m]:  0 (no evidence)
    k_occ = 1, E_h = -1 are read off the paper's Fig. 10: "a value of -1 providing strong
    evidence that the cells are empty", and "close to +2" on a ground pulse some 20 dB above the
    noise (log10 of the power ratio = 2). The paper gives no number for E_l, only "a weaker
    level"; -0.1 is our choice (its empirical rule says noise behind a surface implies little).
    wide_pulse_m: the wide-pulse rule (physics.wide_pulse_width); default: the paper's stand
        (sensor 1.5 m above flat ground - our assumption, the paper does not say), lowest
        elevation -14 deg, 2 deg beam, 0.5 m resolution: 1.87 m.
    max_pulses: pulses kept per beam (more are counted, and still give evidence).
    model: the registered evidence model (``radarcl.models.MODELS``; docs/design/models.md): "paper"
        (eq. 12 as above), "occlusion" (radarcl's, beyond the paper: noise bins before the first
        surface get E_h interpolated in range from e_high (first bin) to e_high_far (last bin),
        noise bins after it E_l; a pulse is a surface when it is wide or its peak 10 log10(r / n)
        reaches surface_db; kernels/interpret.cl says why) or "detstats" (``radarcl.sensor_model``:
        evidence from the CFAR's own detection statistics; eq. 12's constants are unused, its own
        parameters are the ``sensor_model`` keys).
    """

    k_occ: float = 1.0
    e_high: float = -1.0
    e_low: float = -0.1
    range_min_m: float = 1.0
    range_max_m: float = 64.0
    wide_pulse_m: float = None
    max_pulses: int = 32
    model: str = "paper"
    surface_db: float = 10.0
    e_high_far: float = None

    def __post_init__(self):
        if self.wide_pulse_m is None:
            object.__setattr__(self, "wide_pulse_m", PAPER_WIDE_PULSE_M)
        if self.e_high_far is None:
            object.__setattr__(self, "e_high_far", self.e_high)
        for name in ("k_occ", "e_high", "e_low", "range_min_m", "range_max_m", "wide_pulse_m"):
            value = getattr(self, name)
            _require(_is_real(value) and math.isfinite(value),
                     f"{name} must be a finite number, got {value!r}")
        _require(self.k_occ >= 0, f"k_occ must be >= 0 (a stronger echo is more evidence), got {self.k_occ}")
        _require(self.e_high <= 0 and self.e_low <= 0,
                 f"E_h and E_l are evidence of emptiness and must be <= 0 (eq. 12), got "
                 f"{self.e_high} and {self.e_low}")
        _require(0 <= self.range_min_m < self.range_max_m,
                 f"need 0 <= range_min_m < range_max_m, got {self.range_min_m} and {self.range_max_m}")
        _require(self.wide_pulse_m > 0, f"wide_pulse_m must be positive, got {self.wide_pulse_m}")
        _positive_int("max_pulses", self.max_pulses)
        _require(self.model in models.MODELS, f"model must be one of {models.names()}, got {self.model!r}")
        _require(_is_real(self.surface_db) and math.isfinite(self.surface_db),
                 f"surface_db must be a finite number, got {self.surface_db!r}")
        _require(_is_real(self.e_high_far) and math.isfinite(self.e_high_far) and self.e_high_far <= 0,
                 f"e_high_far is evidence of emptiness and must be a finite number <= 0, got {self.e_high_far!r}")

    @property
    def evidence_model(self):
        """The ``models.EvidenceModel`` registered as ``model``."""
        return models.get(self.model)

    @property
    def occludes(self):
        """The first surface ends the free evidence and E_h ramps to e_high_far (``EvidenceModel.occludes``)."""
        return self.evidence_model.occludes

    def bin_interval(self, bin_spacing_m, n_bins):
        """[first, last] bins (inclusive) whose range lies in [range_min_m, range_max_m]:
        bin j sits at j x bin_spacing_m. Empty (first > last) when none does."""
        _require(bin_spacing_m > 0, f"bin spacing must be positive, got {bin_spacing_m}")
        first = max(0, math.ceil(self.range_min_m / bin_spacing_m - 1e-9))
        last = min(int(n_bins) - 1, math.floor(self.range_max_m / bin_spacing_m + 1e-9))
        return first, last

    def wide_bins(self, bin_spacing_m):
        """A pulse of at least this many bins is wide."""
        return max(1, math.ceil(self.wide_pulse_m / bin_spacing_m - 1e-9))


PAPER_SENSOR_HEIGHT_M = 1.5
PAPER_LOWEST_ELEVATION_DEG = -14.0
PAPER_WIDE_PULSE_M = float(physics.wide_pulse_width(
    PAPER_SENSOR_HEIGHT_M, math.radians(PAPER_LOWEST_ELEVATION_DEG),
    math.radians(PAPER_RADAR.beamwidth_el_deg), PAPER_RADAR.range_resolution_m))
