"""Sensor profiles: a radar described once, as data (a TOML file), and the pipeline defaults
that follow from its own resolution and geometry.

A profile gives what the pipeline needs to know of a sensor: whether it delivers raw beat
samples (``input = "samples"``: the range FFT runs first) or range profiles (``"profiles"``:
they enter at CFAR); its waveform or its range bins; its beams and scan lattice; its mounting;
how its files are read (``[reader]``); and, optionally, its own choices for the map
configuration (``[defaults.<section>]``, the sections of a configuration file, see
``config.mapconfig``). ``extends = "name"`` starts from another profile. Built-in profiles live
in ``radarcl/profiles/*.toml``; ``radarcl sensors`` lists them and ``--sensor`` takes a name or
a path.

Defaults derived from the sensor (``derived_defaults``), each with the reason it reports:
- the CFAR guard holds a point target's whole pulse at the threshold, the Hann mainlobe of
  ``MAINLOBE_CELLS`` resolution cells, and, where the mounting makes wide ground echoes (a
  beam pointing down at ``ground_elevation_deg`` from ``height_m``), half of such an echo as
  the paper's wide-pulse rule measures it (its half-power ground extent plus a point pulse);
- the training window spans ``TRAIN_CELLS`` resolution cells per side (the paper's 16 bins of
  its x4 zero-padded FFT);
- a pulse is wide from the paper's rule where the mounting defines it (the ground extent at the
  lowest elevation, §3.3), else from twice a point target's mainlobe;
- the FFT pads x4 (the paper's 1024 points for 256 samples, §4.1); the range interval is the
  sensor's; the grid is the field of view's bounding box (one voxel thick for a spinning radar
  with one elevation: it maps a plane);
- the detection-statistics model (``radarcl.sensor_model``) takes the sensor's sensitivity from
  ``[sensitivity] snr_1m2_at_10m_db`` (a profile without it gets a sentence saying so and the
  default used, ``missing_sensitivity``) and its ground plane from ``[mounting] height_m``
  (stacked beams only: a spinning radar's one elevation maps a plane and has no terrain class).
"""

import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from radarcl import physics, sensor_model
from radarcl.config import tomlfile
from radarcl.config.keys import check_value
from radarcl.config.stage_config import RadarConfig
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice, beam_model
from radarcl.gridspec import lattice_box
from radarcl.io import inputs
from radarcl.io.polar_layout import FILE_NAME_UNITS, ORIENTATIONS, TIMESTAMP_AT, TIMESTAMPS
from radarcl.io.stream import PROTOCOLS

PROFILE_DIR = Path(__file__).resolve().parents[1] / "profiles"
DEFAULT_SENSOR = "paper"
INPUTS = ("samples", "profiles")
SAMPLE_TYPES = {"int16": np.int16, "float32": np.float32, "complex64": np.complex64}
MAINLOBE_CELLS = 4.0       # Hann mainlobe, null to null, in resolution cells (Harris 1978)
TRAIN_CELLS = 4.0          # training window per side, in resolution cells
_NEEDS = {"samples": ("waveform", "beams", "range"), "profiles": ("beams", "range")}
PADDING = 4                # n_fft = PADDING x the next power of two >= n_samples (a power of two itself)
MAX_EXTENDS = 16           # profiles chained by ``extends``: deeper is a mistake, not a sensor

_N = tomlfile.number
_SCHEMA = {                # section -> key -> check (value -> value, or ConfigError(reason))
    "": {"name": tomlfile.text, "description": tomlfile.text, "extends": tomlfile.text,
         "input": lambda v: tomlfile.choice(v, INPUTS)},
    # Bounds: what any radar has, with room; beyond them a derived quantity (c / 2B, the bin
    # spacing, the wavelength) overflows or vanishes and the map would be silently wrong.
    "waveform": {"carrier_hz": lambda v: _N(v, 1e6, 1e13, unit="Hz"),
                 "bandwidth_hz": lambda v: _N(v, 1e3, 1e12, unit="Hz"),
                 "sweep_time_s": lambda v: _N(v, 1e-9, 10.0, unit="s"),
                 "sample_rate_hz": lambda v: _N(v, 1.0, 1e12, unit="Hz"),
                 "n_samples": lambda v: tomlfile.integer(v, 2, 1 << 20),
                 "sample_type": lambda v: tomlfile.choice(v, tuple(SAMPLE_TYPES))},
    "range": {"range_min_m": lambda v: _N(v, 0, 1e5, unit="m"), "range_max_m": lambda v: _N(v, 1e-3, 1e5, unit="m"),
              "bin_spacing_m": lambda v: _N(v, 0, 1e3, lo_open=True, unit="m"),
              "n_bins": lambda v: tomlfile.integer(v, 1, 1 << 20),
              "resolution_m": lambda v: _N(v, 0, 1e3, lo_open=True, unit="m"),
              "carrier_hz": lambda v: _N(v, 1e6, 1e13, unit="Hz")},
    "beams": {"n_azimuth": lambda v: tomlfile.integer(v, 1, 1 << 16), "n_elevation": lambda v: tomlfile.integer(v, 1, 1 << 10),
              "azimuth_step_deg": lambda v: _N(v, 0, 360, unit="deg"), "elevation_step_deg": lambda v: _N(v, 0, 180, unit="deg"),
              "beamwidth_az_deg": lambda v: _N(v, 1e-3, 179, unit="deg"),
              "beamwidth_el_deg": lambda v: _N(v, 1e-3, 179, unit="deg"),
              "spinning": tomlfile.boolean},
    "sensitivity": {"snr_1m2_at_10m_db": lambda v: _N(v, *sensor_model.RANGES["snr_1m2_at_10m_db"][:2], unit="dB")},
    "mounting": {"height_m": lambda v: _N(v, 1e-3, 1e4, unit="m"),
                 "lowest_elevation_deg": lambda v: _N(v, -89, 0, lo_open=True, unit="deg"),
                 "ground_elevation_deg": lambda v: _N(v, -89, 0, lo_open=True, unit="deg")},
    "stream": {"protocol": lambda v: tomlfile.choice(v, PROTOCOLS),
               "range_profile_antennas": lambda v: tomlfile.integer(v, 1, 256),
               "range_profile_q": lambda v: tomlfile.integer(v, 0, 15)},
    "reader": {"format": lambda v: tomlfile.choice(v, tuple(inputs.READERS)),
               "orientation": lambda v: tomlfile.choice(v, ORIENTATIONS),
               "meta_columns": lambda v: tomlfile.integer(v, 0, 1 << 16),
               "timestamp_column": lambda v: tomlfile.integer(v, -1, 1 << 16),
               "encoder_column": lambda v: tomlfile.integer(v, -1, 1 << 16),
               "encoder_counts": lambda v: tomlfile.integer(v, 1, 1 << 31),
               "valid_column": lambda v: tomlfile.integer(v, -1, 1 << 16),
               "timestamps": lambda v: tomlfile.choice(v, TIMESTAMPS),
               "timestamp_file": tomlfile.text,
               "file_name_unit": lambda v: tomlfile.choice(v, ("auto", *FILE_NAME_UNITS)),
               "timestamp_at": lambda v: tomlfile.choice(v, TIMESTAMP_AT),
               "timestamp_offset_s": lambda v: _N(v, -3600, 3600, unit="s"),
               "scan_period_s": lambda v: _N(v, 0, 3600, lo_open=True, unit="s"),
               "azimuth_start_deg": lambda v: _N(v, -360, 360, unit="deg"),
               "range_offset_m": lambda v: _N(v, -1e3, 1e3, unit="m"),
               "scan_directory": tomlfile.text,
               "db_per_level": lambda v: _N(v, 0, 1.4, lo_open=True, unit="dB"),
               "clockwise": tomlfile.boolean},
}


@dataclass(frozen=True)
class SensorProfile:
    """A sensor as its profile describes it (see the module docstring); build with ``load``."""

    name: str
    description: str
    input: str
    source: str                          # the file it was read from, or "built-in <name>"
    tables: dict = field(repr=False)     # the merged TOML tables (after ``extends``)
    defaults: dict = field(repr=False)   # {"section.key": value} from [defaults.*]
    radar: RadarConfig = None            # input = "samples": waveform, beams and range as a RadarConfig
    notes: tuple = ()                    # what was adjusted when the profile was read (a clipped range)

    def __post_init__(self):
        self._validate()

    # -- what the pipeline asks ---------------------------------------------------------------------
    def get(self, section, key, default=None):
        """A raw value of the profile, or ``default``."""
        return self.tables.get(section, {}).get(key, default)

    @property
    def protocol(self):
        """How the sensor streams over a serial line (``radarcl live``): "beams" (the radarcl
        beam protocol) unless its [stream] protocol says "ti" (TI's mmWave demo UART)."""
        return self.get("stream", "protocol", "beams")

    @property
    def raw(self):
        """True when frames are raw beat samples (range FFT first)."""
        return self.input == "samples"

    @property
    def n_azimuth(self):
        return int(self.get("beams", "n_azimuth"))

    @property
    def n_elevation(self):
        return int(self.get("beams", "n_elevation", 1))

    @property
    def spinning(self):
        """A full turn of azimuths per frame (a spinning radar, e.g. Navtech)."""
        return bool(self.get("beams", "spinning", False))

    @property
    def range_interval_m(self):
        """(range_min_m, range_max_m) the sensor measures."""
        return float(self.get("range", "range_min_m", 0.0)), float(self.get("range", "range_max_m"))

    @property
    def range_resolution_m(self):
        """c / 2B of the sweep (eq. 7); for profiles, [range] resolution_m or the bin spacing."""
        if self.raw:
            return self.radar.range_resolution_m
        return float(self.get("range", "resolution_m", self.get("range", "bin_spacing_m")))

    @property
    def wavelength_m(self):
        carrier = self.radar.carrier_hz if self.raw else self.get("range", "carrier_hz")
        return float(physics.wavelength(carrier))

    @property
    def sample_dtype(self):
        """dtype of a frame: the samples' for raw sensors, float32 power for profiles."""
        return np.dtype(SAMPLE_TYPES[self.get("waveform", "sample_type", "int16")] if self.raw else np.float32)

    def n_bins(self, n_fft=None):
        """Range bins per beam: after an n_fft FFT for raw sensors; the profile's for profiles
        (None when the reader learns it from the data: see ``with_bins``)."""
        if self.raw:
            return self.radar.n_bins(n_fft)
        n = self.get("range", "n_bins")
        return None if n is None else int(n)

    def bin_spacing_m(self, n_fft=None):
        """Range between bins [m] (bin j at j x spacing)."""
        return self.radar.bin_spacing_m(n_fft) if self.raw else float(self.get("range", "bin_spacing_m"))

    def frame_shape(self, n_fft=None):
        """Shape of one frame: (n_az, n_el, n_samples) raw; (*lattice.batch, n_bins) profiles."""
        if self.raw:
            return self.radar.frame_shape
        return (*self.lattice().batch, self.n_bins(n_fft))

    def with_bins(self, n_bins):
        """This profile with ``n_bins`` range bins (a reader that learns them from the data); a
        range beyond the last bin is clipped to it, with a note (``notes``)."""
        tables = {k: dict(v) for k, v in self.tables.items()}
        tables.setdefault("range", {})["n_bins"] = int(n_bins)
        tables, notes = clip_range(tables, self.source)
        return SensorProfile(self.name, self.description, self.input, self.source, tables, self.defaults, self.radar,
                             self.notes + notes)

    def lattice(self):
        """The frame's ``BeamLattice`` in the head frame (x forward, y left, z up): a full
        counter-clockwise turn for a spinning radar, else centred on the boresight."""
        n_az, n_el = self.n_azimuth, self.n_elevation
        el_step = math.radians(self.get("beams", "elevation_step_deg", 0.0))
        el0 = -0.5 * (n_el - 1) * el_step
        if self.spinning:
            return BeamLattice(n_az, n_el, 0.0, 2 * math.pi / n_az, el0, el_step)
        az_step = math.radians(self.get("beams", "azimuth_step_deg", 0.0))
        return BeamLattice(n_az, n_el, -0.5 * (n_az - 1) * az_step, az_step, el0, el_step)

    def beam_model(self, name, voxel_m):
        """The ``BeamModel`` called ``name`` (``geometry.BEAM_MODELS``) for this sensor."""
        return beam_model(name, math.radians(self.get("beams", "beamwidth_az_deg")),
                          math.radians(self.get("beams", "beamwidth_el_deg")), self.wavelength_m, voxel_m)

    def toml(self):
        """The profile as TOML text (merged, as used)."""
        tables = {k: v for k, v in self.tables.items() if k and k != "defaults"}
        defaults = {f"defaults.{k.split('.')[0]}": {} for k in self.defaults}
        for k, v in self.defaults.items():
            section, key = k.split(".")
            defaults[f"defaults.{section}"][key] = v
        top = {k: v for k, v in self.tables.get("", {}).items() if k != "extends"}
        return tomlfile.dumps({**tables, **defaults}, header=(f"sensor profile {self.name} ({self.source})",),
                              top=top)

    # -- checks -----------------------------------------------------------------------------------------------
    def _validate(self):
        where = self.source
        for section in _NEEDS[self.input]:
            if section not in self.tables:
                raise ConfigError(f"{where}: a sensor with input = {self.input!r} needs a [{section}] table")
        required = [("beams", "n_azimuth"), ("beams", "beamwidth_az_deg"), ("beams", "beamwidth_el_deg"),
                    ("range", "range_max_m")]
        required += ([("range", "bin_spacing_m"), ("range", "carrier_hz")] if not self.raw else
                     [("waveform", k) for k in ("carrier_hz", "bandwidth_hz", "sweep_time_s", "sample_rate_hz",
                                                "n_samples")])
        for section, key in required:
            if self.get(section, key) is None:
                raise ConfigError(f"{where}: [{section}] {key} is required for a sensor with input = {self.input!r}")
        if not self.raw and "waveform" in self.tables:
            raise ConfigError(f"{where}: [waveform] applies to input = 'samples' only")
        lo, hi = self.range_interval_m
        if lo >= hi:
            raise ConfigError(f"{where}: need range_min_m < range_max_m, got {lo} and {hi}")
        reader = inputs.READERS.get(self.get("reader", "format"))
        if reader is not None and reader.check_profile is not None:
            try:
                reader.check_profile(self)
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
        if self.spinning and self.get("beams", "azimuth_step_deg") is not None:
            step = self.get("beams", "azimuth_step_deg")
            if abs(step * self.n_azimuth - 360.0) > 1e-6 * 360:
                raise ConfigError(f"{where}: a spinning sensor's {self.n_azimuth} azimuths of {step} deg "
                                  "do not make a full turn (leave azimuth_step_deg out)")
        try:
            self.lattice()
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None


# -- loading -----------------------------------------------------------------------------------------------------
def clip_range(tables, source):
    """(tables, notes): a profile's range_max_m beyond its last range bin clipped to that bin
    (a generic profile's 100 m on RADIATE's 576 bins of 0.173611 m: 99.83 m), with a note."""
    rng = tables.get("range", {})
    n, spacing, hi = rng.get("n_bins"), rng.get("bin_spacing_m"), rng.get("range_max_m")
    if n is None or spacing is None or hi is None:
        return tables, ()
    last = round((n - 1) * spacing, 6)
    if hi <= last * (1 + 1e-9):
        return tables, ()
    tables = {k: dict(v) for k, v in tables.items()}
    tables["range"]["range_max_m"] = last
    return tables, (f"{source}: range_max_m = {hi:g} m lies beyond the last of {n} bins of {spacing:g} m; "
                    f"clipped to {last:g} m",)


def builtin_names():
    """Names of the built-in profiles."""
    return sorted(p.stem for p in PROFILE_DIR.glob("*.toml"))


def _read(spec, seen=()):
    """(tables, Source) of a profile name or path, ``extends`` resolved."""
    path = Path(spec)
    if spec in builtin_names() and not path.exists():
        path = PROFILE_DIR / f"{spec}.toml"
    elif not path.is_file():
        close = difflib.get_close_matches(str(spec), builtin_names(), n=1)
        raise ConfigError(f"no sensor profile {spec!r}: not a built-in ({', '.join(builtin_names())}) "
                          "and no such file" + (f"; did you mean {close[0]}?" if close else ""))
    data, source = tomlfile.load(path)
    tables = {"": {k: v for k, v in data.items() if not isinstance(v, dict)}}
    for key, value in data.items():
        if isinstance(value, dict):
            if key == "defaults":
                for section, table in value.items():
                    if not isinstance(table, dict):
                        raise ConfigError(f"{source.where('defaults', section)}: [defaults] holds tables "
                                          f"[defaults.<section>] of configuration keys, got {section} = {table!r}")
                    tables[f"defaults.{section}"] = table
            else:
                tables[key] = value
    for section, table in tables.items():
        if section.startswith("defaults."):
            continue
        if section not in _SCHEMA:
            raise ConfigError(f"{source.where(section)}: unknown table; allowed: "
                              f"{', '.join('[' + s + ']' for s in _SCHEMA if s)}, [defaults.<section>]")
        tomlfile.check_keys(table, _SCHEMA[section], source, section)
        for key, value in table.items():
            try:
                table[key] = _SCHEMA[section][key](value)
            except ConfigError as exc:
                raise ConfigError(f"{source.where(section, key)} {exc}") from None
    base = tables[""].get("extends")
    if base is not None:
        if len(seen) >= MAX_EXTENDS:
            raise ConfigError(f"{source.name}: profiles extend each other more than {MAX_EXTENDS} deep "
                              f"({' -> '.join(seen[:3])} -> ... -> {base})")
        if base in seen:
            raise ConfigError(f"{source.name}: profiles extend each other in a circle: {' -> '.join(seen + (base,))}")
        parent, _ = _read(base, seen + (base,))
        merged = {k: dict(v) for k, v in parent.items()}
        for section, table in tables.items():
            merged.setdefault(section, {}).update(table)
        merged[""].pop("extends", None)
        tables = merged
    return tables, source


def load(spec=DEFAULT_SENSOR):
    """The ``SensorProfile`` of a built-in name or a TOML file; ConfigError with file, line,
    key, value and what is allowed for anything wrong in it."""
    if isinstance(spec, SensorProfile):
        return spec
    tables, source = _read(str(spec))
    top = tables[""]
    for key in ("name", "input"):
        if key not in top:
            raise ConfigError(f"{source.name}: the profile needs a top-level {key} = ...")
    defaults = {}
    for section, table in tables.items():
        if section.startswith("defaults."):
            for key, value in table.items():
                name = f"{section[len('defaults.'):]}.{key}"
                try:
                    defaults[name] = check_value(name, value)
                except ConfigError as exc:
                    raise ConfigError(f"{source.where(section, key)} {exc}") from None
    for section in _NEEDS[top["input"]]:
        if section not in tables:
            raise ConfigError(f"{source.name}: a sensor with input = {top['input']!r} needs a [{section}] table")
    radar = None
    if top["input"] == "samples":
        w, b, r = tables.get("waveform", {}), tables.get("beams", {}), tables.get("range", {})
        try:
            radar = RadarConfig(
                carrier_hz=w.get("carrier_hz"), bandwidth_hz=w.get("bandwidth_hz"), sweep_time_s=w.get("sweep_time_s"),
                sample_rate_hz=w.get("sample_rate_hz"), n_samples=w.get("n_samples"),
                complex_samples=w.get("sample_type", "int16") == "complex64",
                beamwidth_az_deg=b.get("beamwidth_az_deg"), beamwidth_el_deg=b.get("beamwidth_el_deg"),
                n_azimuth=b.get("n_azimuth"), n_elevation=b.get("n_elevation", 1),
                azimuth_step_deg=b.get("azimuth_step_deg", 1.0) or 1.0,
                elevation_step_deg=b.get("elevation_step_deg", 1.0) or 1.0,
                range_min_m=r.get("range_min_m", 0.0), range_max_m=r.get("range_max_m"))
        except (ConfigError, TypeError) as exc:
            raise ConfigError(f"{source.name}: {exc}") from None
    label = source.name if Path(str(spec)).exists() else f"built-in {top['name']}"
    tables, notes = clip_range(tables, label) if top["input"] == "profiles" else (tables, ())
    return SensorProfile(top["name"], top.get("description", ""), top["input"], label, tables, defaults, radar, notes)


# -- defaults that follow from the sensor ------------------------------------------------------------------------
def ground_pulse_m(sensor, elevation_deg):
    """Width [m] at the CFAR threshold of the ground echo of a beam at ``elevation_deg`` (the
    paper's wide-pulse construction, physics.wide_pulse_width), or None without a mounting."""
    height = sensor.get("mounting", "height_m")
    if height is None or elevation_deg is None:
        return None
    return float(physics.wide_pulse_width(height, math.radians(elevation_deg),
                                          math.radians(sensor.get("beams", "beamwidth_el_deg")),
                                          sensor.range_resolution_m))


def derived_defaults(sensor):
    """{"section.key": (value, reason)}: the configuration this sensor's own geometry gives
    (see the module docstring)."""
    res = sensor.range_resolution_m
    mainlobe = MAINLOBE_CELLS * res
    out = {}
    guard, why = mainlobe, f"a point target's pulse: {MAINLOBE_CELLS:g} resolution cells of {res:.4g} m"
    ground = ground_pulse_m(sensor, sensor.get("mounting", "ground_elevation_deg"))
    if ground is not None and ground / 2 > guard:
        guard, why = ground / 2, (f"half the {ground:.3g} m ground echo at "
                                  f"{sensor.get('mounting', 'ground_elevation_deg'):g} deg")
    out["cfar.guard_m"] = (guard, why)
    out["cfar.train_m"] = (TRAIN_CELLS * res, f"{TRAIN_CELLS:g} resolution cells of {res:.4g} m per side")
    wide = ground_pulse_m(sensor, sensor.get("mounting", "lowest_elevation_deg"))
    if wide is not None:
        out["interpret.wide_pulse_m"] = (wide, f"the paper's rule: ground echo at the lowest elevation "
                                               f"{sensor.get('mounting', 'lowest_elevation_deg'):g} deg")
    else:
        out["interpret.wide_pulse_m"] = (2 * mainlobe, "twice a point target's pulse (no ground geometry)")
    lo, hi = sensor.range_interval_m
    out["interpret.range_min_m"] = (lo, "the sensor's range")
    out["interpret.range_max_m"] = (hi, "the sensor's range")
    if sensor.raw:
        n = sensor.radar.n_samples
        n_fft = PADDING * (1 << max(0, math.ceil(math.log2(n))))
        out["range_fft.n_fft"] = (n_fft, f"x{PADDING} zero padding of {n} samples (§4.1)")
    n_bins = sensor.n_bins(out.get("range_fft.n_fft", (None,))[0])
    if n_bins is not None:
        out["interpret.max_pulses"] = (max(32, n_bins // 32), f"one per 32 of {n_bins} bins, at least 32")
    snr = sensor.get("sensitivity", "snr_1m2_at_10m_db")
    if snr is not None:
        out["sensor_model.snr_1m2_at_10m_db"] = (snr, "the sensor's [sensitivity]")
    else:
        out["sensor_model.snr_1m2_at_10m_db"] = (sensor_model.DEFAULT_SNR_DB, missing_sensitivity(sensor))
    height = sensor.get("mounting", "height_m")
    if height is not None and sensor.n_elevation > 1:
        out["sensor_model.ground_below_m"] = (height, "the sensor's [mounting] height_m: the ground plane below it")
    return out


def missing_sensitivity(sensor):
    """The sentence for a profile without the figure the detection-statistics model needs."""
    return (f"sensor {sensor.name} has no [sensitivity] snr_1m2_at_10m_db (the SNR of a 1 m^2 target at 10 m on "
            f"the beam's axis); using {sensor_model.DEFAULT_SNR_DB:g} dB; give it in the profile or with "
            f"--set sensor_model.snr_1m2_at_10m_db=DB")


def brick_depth(sensor):
    """Voxels per grid brick along z for ``sensor``'s maps: 1 for a spinning radar with one
    elevation (it maps a plane one voxel thick, so 8 x 8 x 1 bricks: an 8^3 brick would leave
    7/8 of its memory unwritten), else 8 (8^3 bricks)."""
    return 1 if sensor.spinning and sensor.n_elevation == 1 else 8


def field_of_view_box(sensor, voxel_m, range_max_m):
    """(origin_m, size_m) of the grid that holds the field of view around a sensor at the
    origin: the bounding box of its beams out to ``range_max_m``, its origin on the voxel
    lattice that starts at 0 (``gridspec.lattice_box``: OctoMap's); one voxel thick in z,
    centred on the sensor's plane, for a spinning radar with one elevation."""
    r = float(range_max_m)
    if sensor.spinning and sensor.n_elevation == 1:       # the plane's one layer stays centred on the sensor
        return lattice_box((-r, -r, -0.5 * voxel_m), (r, r, 0.5 * voxel_m), voxel_m, axes=2)
    lat = sensor.lattice()
    half_az = math.radians(sensor.get("beams", "beamwidth_az_deg")) / 2
    half_el = math.radians(sensor.get("beams", "beamwidth_el_deg")) / 2
    az = np.concatenate([lat.azimuths - half_az, lat.azimuths + half_az, lat.azimuths])
    el = np.concatenate([lat.elevations - half_el, lat.elevations + half_el, lat.elevations])
    a, e = (x.ravel() for x in np.meshgrid(az, np.clip(el, -math.pi / 2, math.pi / 2)))
    d = r * np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=1)
    d = np.vstack([d, np.zeros(3)])
    lo, hi = d.min(axis=0), d.max(axis=0)
    return lattice_box(lo, np.maximum(hi, lo + voxel_m), voxel_m)


def frame_volume_m3(sensor, range_min_m, range_max_m, voxel_m):
    """Volume [m^3] one frame's beams sweep between the two ranges: the solid angle of the
    lattice (its azimuth span times the band of its elevations, each widened by a beamwidth)
    times the shell (r_max^3 - r_min^3) / 3; a spinning radar with one elevation sweeps the
    annulus of its plane, one voxel thick. What a frame allocates in the grid is at least about
    this (fewer where the grid cuts the frustum)."""
    lo, hi = float(range_min_m), float(range_max_m)
    if sensor.spinning and sensor.n_elevation == 1:
        return math.pi * (hi ** 2 - lo ** 2) * voxel_m
    lat = sensor.lattice()
    bw_az = math.radians(sensor.get("beams", "beamwidth_az_deg"))
    bw_el = math.radians(sensor.get("beams", "beamwidth_el_deg"))
    span_az = min(2 * math.pi, abs(lat.azimuths[-1] - lat.azimuths[0]) + bw_az)
    el_lo = max(-math.pi / 2, float(lat.elevations.min()) - bw_el / 2)
    el_hi = min(math.pi / 2, float(lat.elevations.max()) + bw_el / 2)
    return span_az * (math.sin(el_hi) - math.sin(el_lo)) * (hi ** 3 - lo ** 3) / 3
