"""`radarcl fuse`: any sensor's frames fused into a map file.

The input is whatever the sensor's reader opens (``radarcl.io.inputs.open_input``): a radarcl recording
(the demo's ``reference_scene.npz``, or frames of any sensor), a directory of polar PNG scans
with their odometry, a TI raw ADC capture. The map configuration comes from
``mapconfig.resolve`` (sensor defaults, ``--config`` file, ``--set`` flags). With ``every`` the
map file is rewritten every that many frames (atomically), so ``radarcl view --live`` shows the
map growing; a store output makes each rewrite cost the changed bricks only.

With ``window_m`` the map rolls (``maps.rolling``): the device keeps the bricks within that
distance of the sensor, the others go into the map store as they leave and come back when the
sensor returns, so a drive of any length maps in bounded memory; the grid then spans the
whole trajectory plus the sensor's range (unless [grid] origin and size were given).
"""

import contextlib
import time
from pathlib import Path

import numpy as np

from radarcl.config import mapconfig
from radarcl.errors import ConfigError, FrameFormatError, ShapeError
from radarcl.gridspec import GridSpec, lattice_box
from radarcl.io.files import scratch
from radarcl.maps.foxglove_out import snapshot
from radarcl.maps.disk import MapSaver, output_format, reading_of
from radarcl.maps.map import Map
from radarcl.maps.rolling import WINDOW_RANGE_FACTOR, RollingStore, RollingWindow
from radarcl.pipeline import Mapping, new_grid


def default_window_m(config):
    """The window a rolling map keeps on the device by default [m]: ``WINDOW_RANGE_FACTOR``
    times the range the configuration maps to (interpret.range_max_m)."""
    return WINDOW_RANGE_FACTOR * float(config["interpret.range_max_m"])


def drive_spec(config, positions):
    """The grid of a drive: [grid] as configured when its origin or size was given, else the
    configured box widened in x and y to every sensor position (n, 3) plus the mapped range
    (bricks shaped to the sensor as ``grid_spec`` says)."""
    spec = config.grid_spec()
    if not config.grid_follows_sensor():
        return spec
    reach = float(config["interpret.range_max_m"])
    v = spec.voxel_m
    lo, size = lattice_box(np.minimum(positions[:, :2].min(axis=0) - reach, spec.origin_m[:2]),
                           positions[:, :2].max(axis=0) + reach, v)           # on OctoMap's lattice
    shape = tuple(max(1, round(x / v)) for x in size) + (spec.shape[2],)
    return GridSpec((lo[0], lo[1], spec.origin_m[2]), v, shape, spec.brick_z)


def frame_positions(source):
    """Each frame's sensor position (n, 3) [m] (its middle beam's with one pose per beam)."""
    if hasattr(source.poses, "positions"):          # polar scans' poses, made a scan at a time: one azimuth each
        return source.poses.positions(source.poses.n_az // 2)
    out = np.zeros((len(source), 3))
    for j in range(len(source)):
        p = np.asarray(source.poses[j])
        out[j] = (p if p.ndim == 2 else p[len(p) // 2])[:3, 3]
    return out
from radarcl.report import figures, html
from radarcl.report.summary import map_summary


class Tally:
    """What a fuse run counts beside the map: ``save_s``, the seconds spent saving (timed apart
    from fusion), and ``device_bytes``, the most device memory ``grid`` held when asked (a
    rolling map's high-water mark)."""

    def __init__(self, grid):
        self.grid = grid
        self.save_s = 0.0
        self.device_bytes = 0

    @contextlib.contextmanager
    def saving(self):
        """Count the time the block takes as saving."""
        t0 = time.perf_counter()
        yield
        self.save_s += time.perf_counter() - t0

    def device_memory(self):
        """Note the device memory the grid holds now."""
        self.device_bytes = max(self.device_bytes, self.grid.memory()["device_bytes"])


def frame_time_ns(source, j):
    """Frame j's time [UNIX ns] where the source knows it, else None: its middle beam's, the time
    of the pose the map keeps for it (``Mapping.fuse_source``'s trajectory, the TUM file's times),
    so an export places each pose at the moment the sensor was there."""
    if source.times_ns is not None:
        return int(source.times_ns[j])
    scans = getattr(source.frames, "scans", None)         # a still radar's scans: no trajectory placed them
    return scans[j].middle_ns if scans is not None and scans[j].timed else None


def run(runtime, source, config, out, every=None, progress=None, report=print, inputs=(), page=None, window_m=None,
        window_default=False, overwrite=False, foxglove=None):
    """Fuse every frame of ``source`` (an ``io.inputs.FrameSource``) with ``config`` (a
    ``mapconfig.Resolved``, or a sensor's name for its defaults) and write the map to ``out``: an ``.npz`` file, or a map store
    (``maps.store``, any other name: only changed bricks are written after the first save).
    ``inputs`` go into the store's provenance; ``page`` names the HTML report to write
    (``write_report``). ``window_m``: a rolling map (see the module docstring; ``out`` must be
    a store, replaced when ``overwrite``; ``window_default`` says the window was the default).
    Returns a dict with the frame count, milliseconds per frame of fusion (the device's work
    included) and seconds of saving, timed apart (and, rolling, the device's high-water mark
    and the bricks that left and came back). ``foxglove``: a ``maps.foxglove_out.FoxgloveOut`` offered
    the map as it grows (at its rate) and once at the end, stamped with the frames' own times."""
    config = mapconfig.as_resolved(config)              # a sensor's name takes its defaults
    rolling = None
    if window_m is not None and foxglove is not None:
        raise ConfigError("--window and --foxglove/--mcap: a rolling map keeps only the window on the device; send "
                          "the finished store to Foxglove with radarcl export, or leave out --window")
    if window_m is not None:
        if output_format(out) == "npz":
            raise ConfigError(f"--window writes the map into a map store as the sensor drives; {out} is an .npz "
                              "file: give --out a store name (e.g. drive.rcmap)")
        if every:
            raise ConfigError("--every and --window: a rolling map is written as it drives (each segment of "
                              "bricks that leave the window); leave out --every")
        spec = drive_spec(config, frame_positions(source))
        # before the drive: a window a frame does not fit, a store that cannot be written
        mapping = Mapping.from_config(runtime, config=config, grid=new_grid(runtime, config, spec))
        rolling = RollingWindow(mapping.grid, None, window_m)
        rolling.check_reach(mapping.fusion.r_hi)
        backing = RollingStore(out, spec, config.sensor.toml(), config.as_dict(), inputs, overwrite=overwrite,
                               reading=config.reading())
        rolling.backing = mapping.grid.backing = backing
    else:
        saver = MapSaver(out, config.sensor.toml(), config.as_dict(), inputs)
        mapping = Mapping.from_config(runtime, config=config)
    spec = mapping.grid.spec
    report(f"fusing {source.summary} with sensor {config.sensor.name} ({config.label()}) into a "
           f"{' x '.join(map(str, spec.shape))} grid of {spec.voxel_m:g} m -> {out}"
           + (f"; a rolling map: the device keeps the bricks within {rolling.window_m:g} m of the sensor"
              + (" (the default, {:g} x the mapped range)".format(WINDOW_RANGE_FACTOR) if window_default else "")
              + ", the others go to the store as they leave" if rolling else ""))
    start = time.perf_counter()
    n = len(source)
    tally = Tally(mapping.grid)

    from radarcl.jobs.api import geo_anchor_of, write_trajectory

    anchor = geo_anchor_of(source)
    extra = {} if anchor is None else dict(geo_anchor=anchor)     # where the map frame lies on the Earth

    def save(poses):
        mapping.runtime.queue.finish()                  # the device's work counts as fusion, not saving
        times = [frame_time_ns(source, j) for j in range(0 if poses is None else len(poses))]
        with tally.saving():
            # the frames' own times, where known: exports stamp with the recording's time
            stamped = {"times_ns": times} if times and None not in times else {}
            saver(mapping.grid, poses, **extra, **stamped)

    def before_frame(j, position):
        rolling.update(position)
        tally.device_memory()

    fused = dict(trajectory=[])                  # the frames fused so far: a map kept when a frame fails

    reading = reading_of(config) if mapping.grid.has_knowledge else None

    def show(j, trajectory):
        foxglove.offer(snapshot(mapping, trajectory, source.poses[j], frame_time_ns(source, j), reading))

    def after_frame(j, trajectory):
        fused["trajectory"] = trajectory
        if every and (j + 1) % every == 0 and j + 1 < n:
            save(np.array(trajectory))
        if foxglove is not None and (foxglove.due() or j + 1 == n):
            show(j, trajectory)
        if progress is not None:
            progress(j + 1, n, "frames fused")

    def say_kept():
        """A frame that could not be read or fused: the map of the frames before it is kept."""
        report(f"kept the map of the {len(fused['trajectory'])} frames fused before the error in {out}")

    if rolling is None:
        try:
            trajectory, outside = mapping.fuse_source(source, after_frame)
        except (FrameFormatError, ShapeError) as exc:
            done = fused["trajectory"]
            save(np.array(done) if done else None)
            say_kept()
            raise
        save(trajectory if len(trajectory) else None)
        mem = mapping.grid.memory()
        bricks, mib = mem["bricks"], mem["sparse_bytes"] / 2 ** 20
    else:
        try:
            trajectory, outside = mapping.fuse_source(source, after_frame, before_frame)
            mapping.runtime.queue.finish()
        except ConfigError as exc:               # the store failed mid-drive: it holds the map up to there
            backing.close()
            raise ConfigError(f"the drive stopped: {exc}") from None
        except (FrameFormatError, ShapeError) as exc:
            mapping.runtime.queue.finish()
            rolling.finish(dict(poses=np.asarray(fused["trajectory"]).reshape(-1, 16).tolist(), **extra))
            say_kept()
            raise
        tally.device_memory()
        with tally.saving():
            bricks = rolling.finish(dict(poses=np.asarray(trajectory).reshape(-1, 16).tolist(), **extra))
        mib = bricks * spec.brick_bytes / 2 ** 20
    with tally.saving():
        track = write_trajectory(source, np.asarray(trajectory), out)
    if track is not None:
        report(f"wrote {track}: the sensor's trajectory in TUM form (evo, SLAM tools)")
    if anchor is not None:
        report("the map frame (the first scan's pose) lies at latitude {latitude_deg:.7f}, longitude "
               "{longitude_deg:.7f} deg, altitude {altitude_m:.1f} m, its x axis {heading_deg:.1f} deg counter-clockwise "
               "from east (from GPS; kept in the map as geo_anchor)".format(**anchor))
    save_s = tally.save_s
    ms = ((time.perf_counter() - start) - save_s) * 1e3 / n
    report(f"wrote {out}: {bricks} bricks ({mib:.0f} MiB); fusion {ms:.0f} ms per "
           f"frame, saving {save_s:.2f} s" + (f" ({-(-n // every)} saves, one every {every} frames)" if every else "")
           + (f"; {outside} beam(s) reached no voxel of the grid" if outside else ""))
    result = dict(frames=n, ms_per_frame=ms, save_s=save_s, bricks=bricks, beams_outside=outside,
                  memory_mib=mib, every=every, device=runtime.name)
    if rolling is not None:
        st = backing.stats
        result.update(window_m=rolling.window_m, device_mib_max=tally.device_bytes / 2 ** 20, evicted=rolling.evicted,
                      restored=st["restored"], restored_from_disk=st["restored_from_disk"], segments=st["segments"])
        report(f"rolling map: the device held at most {result['device_mib_max']:.0f} MiB; {rolling.evicted} bricks "
               f"left the window, {st['restored']} came back ({st['restored_from_disk']} read from the store)")
    if page is not None:
        map_ = Map.of_grid(mapping.grid, reading) if rolling is None else Map.open(out)
        write_report(page, out, source, config, result, map_, trajectory)
        report(f"wrote {page}")
    return result


def write_report(page, out, source, config, result, map_, trajectory):
    """The run as one HTML page: what was fused and how fast, the map from above (each column's
    most telling voxel, ``Map.column_extremes``) with the sensor's path, the viewer's render
    (when EGL is there), and the configuration with where each value came from."""
    run = {"input": source.summary, "sensor": config.sensor.name, "map": str(out), "frames": result["frames"],
           "device": result["device"], "fusion [ms per frame]": round(result["ms_per_frame"], 1),
           "saving the map [s]": round(result["save_s"], 2),
           "bricks": result["bricks"], "memory [MiB]": round(result["memory_mib"], 1),
           "beams that reached no voxel": result["beams_outside"]}
    if result["every"]:
        run["saved every"] = f"{result['every']} frames"
    spec = map_.spec
    title = f"{config.sensor.name}: {result['frames']} frames fused at {spec.voxel_m:g} m, seen from above"
    with scratch(page) as tmp:                   # beside the page: a killed run's is removed by the next
        top = Path(tmp) / "top.png"
        unknown = ~map_.known_columns() if map_.has_knowledge else None
        figures.save(figures.plane_map_figure(map_.column_extremes(), spec, trajectory, title, "sensor path",
                                          "most telling log-odds of the column [nat]", unknown=unknown), top)
        shown = [html.Figure(top.read_bytes(), "Each column's largest log-odds where positive, else its "
                                                 "smallest: red occupied, blue free, white unseen"
                                                 + ("; grey: never observed (unknown)" if unknown is not None else ""))]
        if spec.shape[2] == 1:                   # a planar map: its classes, as `radarcl render` draws it
            classes = Path(tmp) / "classes.png"
            figures.save(figures.classes_figure(map_.classes_from_above(), spec, trajectory,
                                                f"{config.sensor.name}: {Path(str(out)).name}"), classes)
            shown.append(html.Figure(classes.read_bytes(), "Each cell's class: occupied, free, observed but "
                                                           "undecided, or never observed (radarcl render)"))
        else:
            shown.append(_render(out, Path(tmp) / "view.png"))
    html.write(page, f"radarcl fuse: {Path(str(out)).name}", [
        ("Summary", map_summary(map_, out)), ("Run", [html.Pairs(run)]), ("Map", shown),
        ("Configuration", [html.configuration(config)])],
        f"{source.summary}, sensor {config.sensor.name}.")


def _render(map_path, png):
    """The viewer's isosurface of the map as a report figure, or a sentence when it cannot render."""
    try:
        from radarcl.viewer.headless import render_map
        from radarcl.viewer.renderer import ViewerError

        render_map(map_path, png, "iso", size=(800, 500), report=lambda _: None)
    except (ImportError, ViewerError) as exc:
        return html.Text(f"No render: {exc}")
    return html.Figure(png.read_bytes(), "The viewer's isosurface at 1 nat (radarcl render --mode iso); its colour "
                                         "bar says what the colours are")

