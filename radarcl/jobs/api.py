"""The Python API at the top of the package (``import radarcl``): what a notebook needs.

``radarcl.fuse(path, sensor=...)`` maps a recording in one call and returns a ``radarcl.Map``;
``radarcl.open_input`` and ``radarcl.Mapping`` take a sensor by its name for a loop of one's
own. ``radarcl/__init__.py`` names these lazily (``API``), so ``import radarcl`` loads nothing
but itself; this module is where they come from.
"""

from pathlib import Path

from radarcl.config import mapconfig, sensors
from radarcl.errors import ConfigError
from radarcl.io import inputs, polar_layout
from radarcl.maps import disk
from radarcl.maps.map import Map


def sensor_of(path, sensor=None):
    """The ``SensorProfile`` to read ``path`` with: ``sensor`` (a ``SensorProfile``, a built-in
    name or a profile file), else the profile a directory's layout says (Oxford, RADIATE,
    Boreas, MulRan: ``io.polar_layout.recognise``), else the default (a radarcl recording)."""
    if isinstance(sensor, sensors.SensorProfile):
        return sensor
    if sensor is None:
        found = polar_layout.recognise(path)
        if found is None and Path(path).is_dir():
            raise ConfigError(f"{path} is a directory of no recording layout radarcl knows (Oxford, RADIATE, Boreas, "
                              f"MulRan); give sensor=: one of {', '.join(sensors.builtin_names())}, or a profile file")
        sensor = found[0] if found else sensors.DEFAULT_SENSOR
    return sensors.load(sensor)


def open_input(sensor, path, **options):
    """``io.inputs.open_input`` with ``sensor`` a built-in name (``"navtech-cts350x"``), a
    profile file or a ``SensorProfile``; ``options`` as there (poses=, poses_format=, ...)."""
    return inputs.open_input(sensor_of(path, sensor), path, **options)


def fuse(path, sensor=None, *, out=None, config=None, set=None, scans=None, poses=None, still=False, runtime=None,
         overwrite=False):
    """Fuse a recording into a map and return it as a ``Map``.

    path: what the sensor's reader opens (a recording's directory of polar scans, a radarcl
    recording ``.npz``, a TI capture); sensor: a built-in profile name, a profile file or a
    ``SensorProfile`` (default: the one the directory's layout says, see ``sensor_of``);
    config: a configuration file; set: {"section.key": value} on top of it (as ``--set``);
    scans: fuse only the first that many frames; poses: a trajectory file (default: found
    beside the scans); still: fuse input without poses with every frame at the origin;
    out: also write the map there (``.npz`` or a map store), with the sensor's poses and the
    trajectory beside it as ``<out>.tum`` where the input's frames have times, and where GPS
    placed them (RADIATE) the map frame's ``geo_anchor`` (latitude, longitude, altitude,
    heading; ``maps.disk.read_meta``) in both (an existing ``out`` only with ``overwrite``);
    runtime: a ``radarcl.cl.Runtime`` (default: a new one)."""
    from radarcl.pipeline import Mapping

    profile = sensor_of(path, sensor)
    resolved = mapconfig.resolve(profile, config, dict(set or {}))
    source = inputs.open_input(profile, path, poses=poses)
    if not source.posed and not still:
        raise ConfigError(f"{path}: no poses for these frames ({source.summary}); give poses= a trajectory file, "
                          "or still=True to fuse every frame at the origin")
    if scans is not None:
        if isinstance(scans, bool) or not isinstance(scans, int) or scans < 1:
            raise ConfigError(f"scans must be a positive whole number of frames, got {scans!r}")
        source = source.head(scans)
    if source.sensor is not resolved.sensor:                # the reader learnt the bin count
        resolved = resolved.for_sensor(source.sensor)
    if out is not None:
        out = disk.check_output(out, overwrite, inputs=[path, config, poses])
    if runtime is None:
        from radarcl.cl import Runtime

        runtime = Runtime()
    mapping = Mapping.from_config(runtime, config=resolved)
    trajectory, _ = mapping.fuse_source(source)
    result = Map.of_grid(mapping.grid)
    if out is not None:
        anchor = geo_anchor_of(source)
        result.save(out, poses=trajectory if len(trajectory) else None, overwrite=True,
                    meta=None if anchor is None else dict(geo_anchor=anchor))
        write_trajectory(source, trajectory, out)
    return result


def geo_anchor_of(source):
    """Where the map frame of ``source`` (a ``FrameSource``: its first scan's pose) lies on the
    Earth, a dict (``io.trajectory.geo_anchor``), for input placed by GPS (RADIATE); else None."""
    return None if source.trajectory is None else source.trajectory.anchor


def trajectory_path(out):
    """Where ``fuse`` writes the trajectory of the map at ``out``: ``<out>.tum`` beside it."""
    out = Path(out)
    return out.with_name(out.name + ".tum")


def write_trajectory(source, trajectory, out):
    """Write the sensor's ``trajectory`` (n, 4, 4) the map at ``out`` was fused with (each
    frame's pose, or its middle beam's), at the frames' times, in TUM form beside the map
    (``trajectory_path``); returns the path, or None for input whose frames have no times."""
    from radarcl.io import files
    from radarcl.io.trajectory import Trajectory

    if source.times_ns is None or not len(trajectory):
        return None
    path = trajectory_path(out)
    track = Trajectory(source.times_ns, trajectory, source=f"the frames fused into {Path(out).name}",
                       anchor=geo_anchor_of(source))
    with files.atomic(path) as tmp:
        tmp.write_text(track.tum_text())
    return path
