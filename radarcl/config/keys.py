"""The keys of a map configuration: each key's check, unit and help, and radarcl's defaults.

Below both ``sensors`` (a profile's ``[defaults.*]`` tables are checked here) and ``mapconfig``
(which resolves the keys for a sensor).
"""

from dataclasses import dataclass

from radarcl import sensor_model
from radarcl.cfar_theory import CFAR_KINDS
from radarcl.config import tomlfile
from radarcl.config.stage_config import INTERPRETERS, is_power_of_two
from radarcl.errors import ConfigError
from radarcl.geometry import BEAM_MODELS
from radarcl.oracle import WINDOWS

_N = tomlfile.number


def _pow2(v):
    v = tomlfile.integer(v, 4, 1 << 16)
    if not is_power_of_two(v):
        raise ConfigError(f"must be a power of two, got {v}")
    return v


@dataclass(frozen=True)
class Key:
    """One configuration key: its check (value -> value, or ConfigError(reason)), unit, help."""

    check: object
    unit: str
    help: str


KEYS = {
    "range_fft.n_fft": Key(_pow2, "", "FFT length after zero padding (eq. 11); raw-sample sensors"),
    "range_fft.window": Key(lambda v: tomlfile.choice(v, WINDOWS), "", "window on the samples (§3.2)"),
    "cfar.kind": Key(lambda v: tomlfile.choice(v, CFAR_KINDS), "", "CA (the paper's), GO, SO or OS"),
    "cfar.pfa": Key(lambda v: _N(v, 0, 0.5, lo_open=True), "", "design false-alarm probability"),
    "cfar.guard_m": Key(lambda v: _N(v, 0, 1e4, unit="m"), "m", "guard band per side"),
    "cfar.train_m": Key(lambda v: _N(v, 0, 1e4, lo_open=True, unit="m"), "m", "training window per side"),
    "cfar.os_rank": Key(lambda v: _N(v, 0, 1, lo_open=True), "", "OS-CFAR: rank as a fraction of the training cells"),
    "cfar.noise_floor": Key(lambda v: _N(v, 1e-37, 1e37), "", "lower bound of the noise estimate [power]"),
    "interpret.k_occ": Key(lambda v: _N(v, 0, 1e3), "nat/decade", "eq. 12 gain on log10(r/n)"),
    "interpret.e_high": Key(lambda v: _N(v, -16, 0, unit="nat"), "nat", "E_h: noise before the first wide pulse"),
    "interpret.e_low": Key(lambda v: _N(v, -16, 0, unit="nat"), "nat", "E_l: noise after it"),
    "interpret.wide_pulse_m": Key(lambda v: _N(v, 0, 1e4, lo_open=True, unit="m"), "m", "a pulse this wide is wide"),
    "interpret.range_min_m": Key(lambda v: _N(v, 0, 1e5, unit="m"), "m", "no evidence nearer"),
    "interpret.range_max_m": Key(lambda v: _N(v, 0, 1e5, lo_open=True, unit="m"), "m", "no evidence farther"),
    "interpret.max_pulses": Key(lambda v: tomlfile.integer(v, 1, 1 << 16), "", "pulse rows kept per beam"),
    "interpret.model": Key(lambda v: tomlfile.choice(v, INTERPRETERS), "",
                           "paper: eq. 12; occlusion: free evidence only up to the first surface"),
    "interpret.surface_db": Key(lambda v: _N(v, -100, 100, unit="dB"), "dB",
                                "occlusion: a pulse whose peak r/n reaches this is a surface"),
    "interpret.e_high_far": Key(lambda v: _N(v, -16, 0, unit="nat"), "nat",
                                "occlusion: E_h at the far end of the range (e_high at the near end)"),
    **{f"sensor_model.{name}": Key(lambda v, lo=lo, hi=hi, unit=unit: _N(v, lo, hi, unit=unit), unit, f"detstats: {why}")
       for name, (lo, hi, unit, why) in sensor_model.RANGES.items()},
    "sensor_model.evidence": Key(lambda v: tomlfile.choice(v, sensor_model.EVIDENCE_KINDS), "",
                                 "detstats: snr, the likelihood ratio of the measured power over the beam's noise "
                                 "floor; detection, the CFAR's outcome alone"),
    "sensor_model.evidence_bound": Key(lambda v: tomlfile.choice(v, sensor_model.EVIDENCE_BOUNDS), "",
                                       "detstats: detection, a look says no more than a CFAR detection would at its "
                                       "opportunity, either way; none, the measured power's likelihood ratio as it is"),
    "sensor_model.ground_below_m": Key(lambda v: _N(v, *sensor_model.GROUND_RANGE[:2], unit="m"), "m",
                                       "detstats: the sensor's height above the ground plane (0: no terrain class)"),
    "beam.model": Key(lambda v: tomlfile.choice(v, BEAM_MODELS), "", "beam volume (§3.4, Fig. 7c)"),
    "grid.voxel_m": Key(lambda v: _N(v, 1e-4, 1e3, unit="m"), "m", "voxel edge"),
    "grid.origin_m": Key(lambda v: tomlfile.vector(v, unit="m"), "m", "low corner (x, y, z), world frame"),
    "grid.size_m": Key(lambda v: tomlfile.vector(v, lo=0, lo_open=True, unit="m"), "m", "extent (x, y, z)"),
}
SECTIONS = tuple(dict.fromkeys(k.split(".")[0] for k in KEYS))

BUILTIN = {
    "range_fft.window": "hann", "cfar.kind": "ca", "cfar.pfa": 1e-3, "cfar.os_rank": 0.75,
    "cfar.noise_floor": 1e-30, "interpret.k_occ": 1.0, "interpret.e_high": -1.0, "interpret.e_low": -0.1,
    "interpret.max_pulses": 32, "beam.model": "cylindrical-conical", "grid.voxel_m": 0.1,
    "interpret.model": "detstats", "interpret.surface_db": 10.0,
    **{f"sensor_model.{name}": value for name, value in sensor_model.DEFAULTS.items()},
}
"""radarcl's own defaults: the paper's CFAR (CA, P_fa 1e-3, Fig. 6), its eq. 12 constants
(k_occ 1, E_h -1 from Fig. 10; E_l -0.1 ours, the paper gives none), Rohling's OS rank 3/4,
the paper's beam (Fig. 7c) and voxel (0.1 m); the interpreter: the detection-statistics model
(the instrument shows it better than eq. 12 on both simulated radars and against RADIATE's lidar:
docs/guide/sensor-models.md), with its parameters (``sensor_model.DEFAULTS``); eq. 12 is interpret.model = "paper"."""


def check_value(name, value):
    """``value`` for key ``name`` ("section.key"), checked; ConfigError names what is allowed."""
    if name not in KEYS:
        raise ConfigError(f"unknown configuration key {name!r}; keys: {', '.join(KEYS)}")
    try:
        return KEYS[name].check(value)
    except ConfigError as exc:
        raise ConfigError(f"{name} {exc}") from None
