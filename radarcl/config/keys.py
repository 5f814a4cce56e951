"""The keys of a map configuration: each key's check, unit and help, and radarcl's defaults.

Below both ``sensors`` (a profile's ``[defaults.*]`` tables are checked here) and ``mapconfig``
(which resolves the keys for a sensor).
"""

from dataclasses import dataclass

from radarcl import models, sensor_model
from radarcl.cfar_theory import CFAR_KINDS
from radarcl.config import tomlfile
from radarcl.config.stage_config import is_power_of_two
from radarcl.errors import ConfigError
from radarcl.geometry import BEAM_MODELS
from radarcl.oracle import WINDOWS

_N = tomlfile.number


def _pow2(v):
    v = tomlfile.integer(v, 4, 1 << 16)
    if not is_power_of_two(v):
        raise ConfigError(f"must be a power of two, got {v}")
    return v


def _model_key(spec):
    """The ``Key`` of a key an evidence model declares (``models.Number`` or ``models.Choice``)."""
    if isinstance(spec, models.Choice):
        return Key(lambda v: tomlfile.choice(v, spec.choices), "", spec.help)
    return Key(lambda v: _N(v, spec.lo, spec.hi, lo_open=spec.lo_open, unit=spec.unit), spec.unit, spec.help)


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
    "interpret.model": Key(lambda v: tomlfile.choice(v, models.names()), "",
                           "; ".join(f"{m.name}: {m.summary}" for m in models.MODELS.values())),
    **{name: _model_key(spec) for model in models.MODELS.values() for name, spec in model.keys.items()},
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
