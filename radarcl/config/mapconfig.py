"""The map configuration: how a map is made, in physical units, in one file.

A configuration file (TOML) has these tables; every key is optional:

  [range_fft]  n_fft (raw-sample sensors), window
  [cfar]       kind, pfa, guard_m, train_m (windows in metres), os_rank, noise_floor
  [interpret]  k_occ, e_high, e_low (eq. 12 [nat]), wide_pulse_m, range_min_m, range_max_m, max_pulses
  [beam]       model
  [grid]       voxel_m, origin_m, size_m
  [sensor_model]  the detection-statistics model's parameters (interpret.model = "detstats";
               ``radarcl.sensor_model``): each refused outside its physical range

``resolve(sensor, file, flags)`` fills each key from, in increasing priority: radarcl's default
(``BUILTIN``), the sensor's geometry (``sensors.derived_defaults``), the sensor profile's own
``[defaults.*]`` tables, the file, and command-line flags; it remembers where each value came
from (``radarcl config show`` prints it).

A saved configuration records the sensor it was made for (``sensor = "NAME"``). Used with
another sensor it is refused, naming both; with ``force_sensor`` it is used with a note, its
constants kept and its metre-valued keys that follow from a sensor's bins and range
(``SENSOR_KEYS``: CFAR guard and training windows, wide pulse, range interval, grid extent)
derived again for the new sensor, each change listed in the notes. The result, a ``Resolved``, is the only way a pipeline
is built (``pipeline.Mapping.from_config``): it converts the windows in metres to bins of the
sensor at hand, saying how it rounded.
"""

import math
from dataclasses import dataclass
from pathlib import Path

from radarcl import models, sensor_model
from radarcl.config import sensors, tomlfile
from radarcl.config.keys import BUILTIN, KEYS, SECTIONS, check_value
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.gridspec import GridSpec

FIELD_OF_VIEW = "field of view"     # the origin of a [grid] box derived from the sensor (``grid_follows_sensor``)

# Metre-valued keys that follow from the sensor a configuration was made for (its resolution,
# range and field of view): derived again when a configuration is forced onto another sensor.
# grid.voxel_m is the map's resolution, a choice of the user, and is kept.
SENSOR_KEYS = ("cfar.guard_m", "cfar.train_m", "interpret.wide_pulse_m", "interpret.range_min_m",
               "interpret.range_max_m", "grid.origin_m", "grid.size_m")


def read(path):
    """{"section.key": (value, "file PATH:LINE")} of a configuration file; ConfigError names
    the file, line, key, value and what is allowed for an unknown key or a bad value."""
    data, source = tomlfile.load(path)
    out = {}
    for section, table in data.items():
        if section == "sensor" and isinstance(table, str):
            out["sensor"] = (table, f"file {source.where('', 'sensor').split(': ')[0]}")
            continue
        if section not in SECTIONS or not isinstance(table, dict):
            raise ConfigError(f"{source.where('', section)}: unknown entry; a configuration has sensor = "
                              f"\"NAME\" and the tables {', '.join('[' + s + ']' for s in SECTIONS)}")
        tomlfile.check_keys(table, {k.split(".")[1] for k in KEYS if k.startswith(section + ".")}, source, section)
        for key, value in table.items():
            where = source.where(section, key)
            try:
                out[f"{section}.{key}"] = (KEYS[f"{section}.{key}"].check(value), "file " + where.split(": ")[0])
            except ConfigError as exc:
                raise ConfigError(f"{where} = {value!r}: {exc}") from None
    return out


def parse_flag(text):
    """A ``--set section.key=value`` flag as (key, value): the value is read as TOML
    (0.5, "so", [1, 2, 3]), or taken as a bare string."""
    if "=" not in text:
        raise ConfigError(f"--set takes section.key=value, got {text!r}")
    name, raw = (s.strip() for s in text.split("=", 1))
    try:
        value = tomlfile.loads(f"v = {raw}")["v"]
    except ConfigError:
        value = raw
    return name, check_value(name, value)


@dataclass(frozen=True)
class Resolved:
    """A complete configuration for one sensor: ``values`` {"section.key": value} and
    ``origins`` {"section.key": where it came from}."""

    sensor: object
    values: dict
    origins: dict
    notes: tuple = ()      # sentences about what was adjusted (a forced sensor, a clipped range)

    def __getitem__(self, name):
        return self.values[name]

    def replaced(self, **changes):
        """A copy with some values changed (keyword names use __ for the dot:
        cfar__kind="so"), marked as set by the program."""
        values, origins = dict(self.values), dict(self.origins)
        for name in ("grid.origin_m", "grid.size_m"):     # a field-of-view box follows the new values
            if origins[name].endswith(FIELD_OF_VIEW):
                del values[name], origins[name]
        for key, value in changes.items():
            name = key.replace("__", ".")
            values[name] = check_value(name, value)
            origins[name] = "set by the program"
        return _checked(self.sensor, values, origins, self.notes)

    def for_sensor(self, sensor):
        """The same values for a variant of the sensor (e.g. with its bin count learnt from the
        data), checked again; a range beyond the variant's (its last bin) is clipped with a note,
        and a field-of-view grid follows it."""
        values, origins = dict(self.values), dict(self.origins)
        notes = self.notes + tuple(n for n in getattr(sensor, "notes", ()) if n not in self.notes)
        hi = sensor.range_interval_m[1]
        if values["interpret.range_max_m"] > hi + 1e-9:
            notes += (f"interpret.range_max_m = {values['interpret.range_max_m']:g} m (from "
                      f"{origins['interpret.range_max_m']}) lies beyond sensor {sensor.name}'s last bin; "
                      f"clipped to {hi:g} m",)
            values["interpret.range_max_m"] = hi
            origins["interpret.range_max_m"] += ", clipped to the last bin"
            for name in ("grid.origin_m", "grid.size_m"):
                if origins[name].endswith(FIELD_OF_VIEW):
                    del values[name], origins[name]
        return _checked(sensor, values, origins, notes)

    @property
    def n_fft(self):
        """FFT length (raw sensors) or None."""
        return self.values.get("range_fft.n_fft")

    @property
    def bin_spacing_m(self):
        return self.sensor.bin_spacing_m(self.n_fft)

    def cfar_config(self):
        """The ``CfarConfig`` in bins of this sensor: the guard rounded up (it must cover at least
        guard_m), the training window to the nearest bin (at least one)."""
        spacing = self.bin_spacing_m
        guard = math.ceil(self["cfar.guard_m"] / spacing - 1e-9)
        train = max(1, round(self["cfar.train_m"] / spacing))
        rank = max(1, round(self["cfar.os_rank"] * 2 * train)) if self["cfar.kind"] == "os" else None
        return CfarConfig(kind=self["cfar.kind"], guard=guard, train=train, pfa=self["cfar.pfa"], rank=rank,
                          noise_floor=self["cfar.noise_floor"])

    def interpret_config(self):
        """The ``InterpretConfig`` (eq. 12 constants, wide-pulse width, range interval)."""
        return InterpretConfig(k_occ=self["interpret.k_occ"], e_high=self["interpret.e_high"],
                               e_low=self["interpret.e_low"], range_min_m=self["interpret.range_min_m"],
                               range_max_m=self["interpret.range_max_m"], wide_pulse_m=self["interpret.wide_pulse_m"],
                               max_pulses=self["interpret.max_pulses"], model=self["interpret.model"],
                               surface_db=self["interpret.surface_db"],
                               e_high_far=self.values.get("interpret.e_high_far"))   # unset: E_h (no ramp)

    def evidence_model(self):
        """The evidence model in force (``radarcl.models``): what differs between models is asked of it."""
        return models.get(self["interpret.model"])

    def reading(self):
        """What a map of this configuration keeps to be read (``EvidenceModel.reading``), or None."""
        return self.evidence_model().reading(self.model_params())

    def grid_follows_sensor(self):
        """True when neither [grid] origin nor size was given: both are the field of view's box."""
        return all(self.origins.get(k, "").endswith(FIELD_OF_VIEW) for k in ("grid.origin_m", "grid.size_m"))

    def derived_from_sensor(self, name):
        """True when key ``name`` holds what radarcl derived from the sensor's description (its
        mounting, range, resolution or field of view): nobody gave it."""
        return self.origins.get(name, "").startswith(f"sensor {self.sensor.name}: ")

    def sensitivity_missing(self):
        """True when the sensor's profile gives no sensitivity and the default stands in
        (``sensors.missing_sensitivity`` says so)."""
        return self.origins.get("sensor_model.snr_1m2_at_10m_db", "").endswith(sensors.missing_sensitivity(self.sensor))

    def model_params(self):
        """The detection-statistics model's ``sensor_model.ModelParams`` of [sensor_model]."""
        return sensor_model.ModelParams.of(self.values)

    def grid_spec(self):
        """The ``GridSpec`` of [grid]: origin_m, ceil(size_m / voxel_m) voxels, bricks shaped
        to the sensor (``sensors.brick_depth``)."""
        voxel = self["grid.voxel_m"]
        shape = tuple(max(1, math.ceil(s / voxel - 1e-9)) for s in self["grid.size_m"])
        return GridSpec(self["grid.origin_m"], voxel, shape, sensors.brick_depth(self.sensor))

    def rounding(self):
        """Sentences saying how the windows in metres became bins."""
        c, spacing = self.cfar_config(), self.bin_spacing_m
        return [f"CFAR guard {self['cfar.guard_m']:.4g} m -> {c.guard} bins of {spacing:.4g} m "
                f"({c.guard * spacing:.4g} m, rounded up)",
                f"CFAR training {self['cfar.train_m']:.4g} m -> {c.train} bins ({c.train * spacing:.4g} m, nearest)",
                f"wide pulse {self['interpret.wide_pulse_m']:.4g} m -> "
                f"{self.interpret_config().wide_bins(spacing)} bins (rounded up)"]

    def label(self, base=None):
        """Short text naming the values that differ from ``base`` (a Resolved), or all the
        CFAR and interpreter choices: eq. 12's constants, or the detection-statistics model's evidence."""
        keys = [k for k in self.values if base is None or base.values.get(k) != self.values[k]]
        if base is None:
            own = self.evidence_model().label_keys
            keys = [k for k in keys if k.startswith(("cfar.kind", "cfar.pfa", "interpret.model", *own, "grid.voxel"))]
        return ", ".join(f"{k.split('.')[1]}={_short(self.values[k])}" for k in keys) or "the same"

    def as_dict(self):
        """JSON-ready {"section.key": value}."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.values.items()}

    def to_toml(self, header=()):
        """The configuration as a file ``read`` accepts (every key, with its origin as a comment;
        but a default prior, which follows the grid's voxel, is left out and said so: written, it
        would hold the base rate of this voxel at every other)."""
        tables = {s: {} for s in SECTIONS}
        comments = {}
        for name, value in self.values.items():
            section, key = name.split(".")
            tables[section][key] = value
            comments[(section, key)] = self.origins.get(name)
        prior = "sensor_model.prior_nats"
        if PRIOR_SCALED_MARK in self.origins.get(prior, ""):
            tables["sensor_model"]["prior_nats"] = None
            header = (*header, f"[sensor_model] prior_nats is left out: the default prior follows the grid's voxel "
                               f"({_short(self.values[prior])} nat here; {self.origins[prior]})")
        return tomlfile.dumps(tables, header=header, top={"sensor": self.sensor.name}, comments=comments)

    def save(self, path, header=(), overwrite=False):
        """Write ``to_toml`` to ``path`` (refusing an existing file unless ``overwrite``)."""
        path = Path(path)
        if path.exists() and not overwrite:
            raise ConfigError(f"{path} exists; choose another name or pass --force")
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(self.to_toml(header))
        tmp.replace(path)


def _short(v):
    return f"{v:g}" if isinstance(v, float) else str(list(v) if isinstance(v, tuple) else v)


def as_resolved(config):
    """``config`` as a ``Resolved``: itself, or for a sensor (a built-in name, a profile file or
    a ``SensorProfile``) its default configuration (``resolve``): what a function that takes a
    configuration takes."""
    return config if isinstance(config, Resolved) else resolve(config)


def resolve(sensor=None, path=None, flags=None, program=None, force_sensor=False):
    """The ``Resolved`` configuration of ``sensor`` (a SensorProfile, a name or a path; default
    the file's ``sensor = ...`` or the paper's radar) with the file at ``path``, ``flags``
    {"section.key": value} from the command line, and ``program`` {"section.key": value} set
    by the calling program (a job's own choice, below the user's file and flags). A file made
    for another sensor is refused, or with ``force_sensor`` used with its ``SENSOR_KEYS``
    derived again (see the module)."""
    if path is not None and not isinstance(path, (str, Path)):
        raise ConfigError(f"a configuration file is a path, got {path!r}")
    for what, given in (("flags", flags), ("program", program)):
        if given is not None and not isinstance(given, dict):
            raise ConfigError(f"{what} must be a dict {{'section.key': value}}, got {given!r}")
    from_file, notes = {}, ()
    if path is not None:
        from_file = read(path)
        file_sensor = from_file.pop("sensor", (None, None))[0]
        if sensor is None and file_sensor is not None:
            sensor = file_sensor
    sensor = sensors.load(sensor if sensor is not None else sensors.DEFAULT_SENSOR)
    if path is not None and file_sensor is not None and file_sensor != sensor.name:
        if not force_sensor:
            raise ConfigError(f"{path} is a configuration for sensor {file_sensor!r}, not {sensor.name!r}: its "
                              f"windows, range and grid follow that sensor's bins; use a configuration made for "
                              f"{sensor.name!r} (radarcl config save --sensor {sensor.name}), or --force-sensor to "
                              f"keep its constants and derive the rest for {sensor.name!r}")
        dropped = {k: from_file.pop(k)[0] for k in SENSOR_KEYS if k in from_file}
        notes += (f"{path} was made for sensor {file_sensor!r}; used with {sensor.name!r} (--force-sensor): its "
                  f"constants are kept, its {', '.join(dropped) or 'no sensor-derived keys'} derived again for "
                  f"{sensor.name!r}",)
    values = dict(BUILTIN)
    origins = {k: "radarcl default" for k in BUILTIN}
    for name, (value, why) in sensors.derived_defaults(sensor).items():
        values[name], origins[name] = value, f"sensor {sensor.name}: {why}"
    for name, value in sensor.defaults.items():
        values[name], origins[name] = value, f"sensor {sensor.name} ({sensor.source})"
    for name, value in (program or {}).items():
        values[name], origins[name] = check_value(name, value), "the command's own choice"
    for name, (value, where) in from_file.items():
        values[name], origins[name] = value, where
    for name, value in (flags or {}).items():
        values[name], origins[name] = check_value(name, value), "flag"
    resolved = _checked(sensor, values, origins, notes + tuple(getattr(sensor, "notes", ())))
    if path is not None and file_sensor is not None and file_sensor != sensor.name:
        changes = [f"{k} {_short(dropped[k])} -> {_short(resolved.values[k])}" for k in dropped
                   if k in resolved.values and resolved.values[k] != dropped[k]]
        if changes:
            resolved = Resolved(resolved.sensor, resolved.values, resolved.origins,
                                resolved.notes + (f"re-derived for {sensor.name!r}: {'; '.join(changes)}",))
    return resolved


def _checked(sensor, values, origins, notes=()):
    """Fill the grid extent, drop what the sensor does not use, and check the keys together."""
    if not sensor.raw:
        values.pop("range_fft.n_fft", None)
        values.pop("range_fft.window", None)
    if "grid.size_m" not in values or "grid.origin_m" not in values:
        origin, size = sensors.field_of_view_box(sensor, values["grid.voxel_m"], values["interpret.range_max_m"])
        if "grid.origin_m" not in values:
            values["grid.origin_m"], origins["grid.origin_m"] = origin, f"sensor {sensor.name}: {FIELD_OF_VIEW}"
        if "grid.size_m" not in values:
            values["grid.size_m"], origins["grid.size_m"] = size, f"sensor {sensor.name}: {FIELD_OF_VIEW}"
    _scale_default_prior(sensor, values, origins)
    order = {k: i for i, k in enumerate(KEYS)}
    values = dict(sorted(values.items(), key=lambda kv: order[kv[0]]))
    resolved = Resolved(sensor, values, origins, tuple(notes))

    def fail(keys, reason):
        raise ConfigError("; ".join(f"{k} = {_short(values[k])} (from {origins[k]})" for k in keys) + f": {reason}")

    lo, hi = values["interpret.range_min_m"], values["interpret.range_max_m"]
    if lo >= hi:
        fail(["interpret.range_min_m", "interpret.range_max_m"], "need range_min_m < range_max_m")
    s_lo, s_hi = sensor.range_interval_m
    if lo < s_lo - 1e-9 or hi > s_hi + 1e-9:
        fail(["interpret.range_min_m", "interpret.range_max_m"],
             f"outside the range sensor {sensor.name} measures, [{s_lo:g}, {s_hi:g}] m")
    if sensor.raw and values["range_fft.n_fft"] < sensor.radar.n_samples:
        fail(["range_fft.n_fft"], f"shorter than the {sensor.radar.n_samples} samples per ramp (eq. 11 pads, "
                                  "never truncates)")
    n_bins = sensor.n_bins(values.get("range_fft.n_fft"))
    try:
        cfar = resolved.cfar_config()
    except ConfigError as exc:
        fail(["cfar.kind", "cfar.pfa", "cfar.guard_m", "cfar.train_m"], str(exc))
    if n_bins is not None and cfar.window > n_bins:
        fail(["cfar.guard_m", "cfar.train_m"], f"the CFAR window needs {cfar.window} bins of "
                                               f"{resolved.bin_spacing_m:.4g} m; the sensor's profiles have {n_bins}")
    try:
        resolved.grid_spec().check_brick_table()
    except ConfigError as exc:
        fail(["grid.voxel_m", "grid.size_m"], str(exc))
    return resolved


PRIOR_SCALED_MARK = "the base rate at "
PRIOR_SCALED = PRIOR_SCALED_MARK + "{voxel:g} m: {base:g} nat at {ref:g} m + ln({voxel:g} / {ref:g})"


def _scale_default_prior(sensor, values, origins):
    """A default prior (radarcl's or the profile's, fitted at ``sensor_model.PRIOR_VOXEL_M``) as the
    base rate at the grid's voxel (``sensor_model.prior_for_voxel``); one the user gave stays."""
    key = "sensor_model.prior_nats"
    origin = origins.get(key, "")
    if origin.startswith("radarcl default"):
        base, source = sensor_model.DEFAULTS["prior_nats"], "radarcl default"
    elif origin.startswith(f"sensor {sensor.name} (") and key in sensor.defaults:
        base, source = sensor.defaults[key], f"sensor {sensor.name} ({sensor.source})"
    else:
        return
    voxel, ref = values["grid.voxel_m"], sensor_model.PRIOR_VOXEL_M
    values[key] = check_value(key, max(-10.0, min(0.0, sensor_model.prior_for_voxel(base, voxel))))
    origins[key] = f"{source}: " + PRIOR_SCALED.format(voxel=voxel, base=base, ref=ref)


def show(resolved):
    """Lines for ``radarcl config show``: each key, its value and unit, where it came from."""
    s = resolved.sensor
    lines = [f"sensor {s.name} ({s.source}): {s.description}"]
    width = max(len(k) for k in resolved.values)
    for name, value in resolved.values.items():
        unit = KEYS[name].unit
        lines.append(f"  {name:<{width}} = {_short(value):<24} {unit:<10} {resolved.origins[name]}")
    lines += ["  " + r for r in resolved.rounding()]
    lines += [f"  note: {n}" for n in resolved.notes]
    return lines
