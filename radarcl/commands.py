"""What each `radarcl` subcommand does: a small function per command, taking the parsed
arguments and calling a library or job module (``radarcl.cli`` builds the parser). Returns the
exit status; errors are raised as ``RadarclError`` and turned into one sentence by the CLI."""

import json
import os
import sys
from pathlib import Path

DATA_ENV = "RADARCL_DATA"


def resolve_config(args, program=None):
    """The ``mapconfig.Resolved`` the options of ``add_config`` describe."""
    from radarcl import mapconfig

    flags = dict(mapconfig.parse_flag(text) for text in args.set)
    if args.voxel is not None:
        flags["grid.voxel_m"] = args.voxel
    sensor = args.sensor if args.sensor is not None or args.config is not None else args.sensor_default
    return mapconfig.resolve(sensor, args.config, flags, program)


def default_data(name):
    """The shared data set ``name``: under $RADARCL_DATA, else ../shared/data beside the source
    checkout (never relative to the current directory)."""
    root = Path(os.environ[DATA_ENV]) if os.environ.get(DATA_ENV) else Path(__file__).resolve().parents[2] / "shared" / "data"
    return root / name


class ProgressBar:
    """A one-line progress bar on stderr: ``bar(done, total, what)``; a new ``what`` starts a new line."""

    def __init__(self, stream=sys.stderr, width=30):
        self.stream, self.width, self.what = stream, width, None

    def __call__(self, done, total, what):
        if not self.stream.isatty() and done < total:
            return                                # a log file gets the finished line only
        if what != self.what and self.what is not None:
            self.stream.write("\n")
        self.what = what
        filled = int(self.width * done / max(1, total))
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} {what}")
        if done >= total:
            self.stream.write("\n")
            self.what = None
        self.stream.flush()


def _progress(args):
    return None if getattr(args, "no_progress", False) else ProgressBar()


def _runtime():
    from radarcl.cl import Runtime

    return Runtime()


def cmd_info(args):
    from radarcl.cl import choose_device, device_report

    print("\n".join(device_report()))
    choose_device()  # after the listing: no usable device, or a RADARCL_DEVICE that fits none, is an error
    return 0


def cmd_sensors(args):
    from radarcl import sensors

    if args.name:
        print(sensors.load(args.name).toml(), end="")
        return 0
    for name in sensors.builtin_names():
        s = sensors.load(name)
        print(f"{name:20s} {s.input:8s} {s.description}")
    print("(radarcl sensors NAME prints a profile; --sensor takes a name or a TOML file)")
    return 0


def cmd_config(args):
    from radarcl import mapconfig, outputs

    if args.action == "save" and not args.file:
        from radarcl.errors import ConfigError

        raise ConfigError("config save needs the FILE to write")
    config = resolve_config(args)
    if args.action == "save":
        path = outputs.check(args.file, args.force, inputs=[args.config], what="configuration file")
        config.save(path, header=("radarcl map configuration", "written by radarcl config save"), overwrite=True)
        print(f"wrote {path}")
        return 0
    print("\n".join(mapconfig.show(config)))
    return 0


def cmd_demo(args):
    from radarcl.jobs import demo

    demo.run(_runtime(), args.out, seed=args.seed, quick=args.quick, replay=args.replay, report=print,
             progress=_progress(args), shown=args.show)
    return 0


def cmd_tune(args):
    from radarcl import outputs
    from radarcl.evaluation import tuning
    from radarcl.evaluation.evaluate import paper_config
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_grid, paper_scene

    save = outputs.check(args.save, args.force, inputs=[args.replay], what="configuration file") if args.save else None
    if args.replay:
        obs = recording.load_observations(args.replay)
    else:
        print(f"simulating the reference scene, seed {args.seed} ...")
        obs = observe(paper_scene(), PAPER_TILTS_DEG, seed=args.seed)
    base = paper_config(args.voxel)
    truth = paper_scene().truth(paper_grid(args.voxel))
    best, _ = tuning.tune(_runtime(), obs, truth, base, report=print, progress=_progress(args))
    print(f"chosen: {best.label(base)}")
    if save:
        best.save(save, header=("radarcl map configuration chosen by `radarcl tune`",
                                f"reference scene, seed {obs.seed}, {args.voxel} m; the search of radarcl/evaluation/tuning.py"),
                  overwrite=True)
        print(f"wrote {save} (use it with --config)")
    return 0


def _fit_outputs(args):
    """The checked --save, --figure and --json paths of a calibration command (None where not
    asked), refused before any work when they exist without --force."""
    from radarcl import outputs

    return tuple(outputs.check(path, args.force, what=what) if path else None
                 for path, what in ((args.save, "configuration file"), (args.figure, "figure"), (args.json, "JSON file")))


def _write_fit(paths, config, header, figure, result):
    """Write a calibration's configuration, figure (a callable drawing it) and JSON to
    ``paths`` (from ``_fit_outputs``)."""
    from radarcl import outputs
    from radarcl.jobs import plots

    save, figure_path, json_out = paths
    if save:
        config.save(save, header=header, overwrite=True)
        print(f"wrote {save} (use it with --config)")
    if figure_path:
        plots.save(figure(), figure_path)
        print(f"wrote {figure_path}")
    if json_out:
        with outputs.atomic(json_out) as tmp:
            tmp.write_text(json.dumps(result, indent=1))
        print(f"wrote {json_out}")


def cmd_calibrate(args):
    from radarcl.jobs import calibrate

    paths = _fit_outputs(args)
    config, result = calibrate.run(_runtime(), args.model, args.voxel, args.seeds, report=print,
                                   unknown_behind=args.unknown_behind)
    print("\n".join(calibrate.format_lines(result)))
    _write_fit(paths, config, ("radarcl map configuration fitted by `radarcl calibrate`",
                               f"{result['model']} interpreter, training scenes {result['fit_seeds']} "
                               f"(validation {result['validation_seeds']}), {result['voxel_m']} m"),
               lambda: calibrate.reliability_figure(result), result)
    return 0


def cmd_calibrate_scans(args):
    from radarcl.errors import ConfigError
    from radarcl.jobs import calibrate_scans

    paths = _fit_outputs(args)
    data = args.data or default_data("navtech_oxford")
    if not Path(data).is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (radar/*.png and gt/radar_odometry.csv)")
    config, result = calibrate_scans.run(_runtime(), resolve_config(args), data, args.model, report=print)
    print("\n".join(calibrate_scans.format_lines(result)))
    _write_fit(paths, config, ("radarcl map configuration fitted by `radarcl calibrate-scans`",
                               f"{result['model']} interpreter, {result['sensor']} scans {result['fit_scans']} of {data}"),
               lambda: calibrate_scans.reliability_figure(result), result)
    return 0


def cmd_fuse(args):
    from radarcl import outputs
    from radarcl.jobs import fuse_recording

    config = resolve_config(args)
    out = outputs.check(args.out, args.force, inputs=[args.input, args.config, args.odometry], what="map",
                        store=not str(args.out).endswith(".npz"))
    page = None if args.no_report else outputs.check(args.report or Path(out).with_suffix(".html"), args.force,
                                                      inputs=[args.input, args.config, out], what="report")
    if page is not None and Path(page).resolve() == Path(out).resolve():
        from radarcl.errors import ConfigError

        raise ConfigError(f"the report and the map would both be {out}; give --report another name")
    source = fuse_recording.open_source(config.sensor, args.input, args.odometry)
    if source.sensor is not config.sensor:                   # the reader learnt the bin count
        config = config.for_sensor(source.sensor)
    fuse_recording.run(_runtime(), source, config, out, every=args.every, progress=_progress(args),
                       inputs=[args.input], page=page)
    return 0


def cmd_navtech(args):
    from radarcl import outputs
    from radarcl.jobs.navtech_report import report

    out = outputs.check(args.out, args.force, inputs=[args.scan], what="figure")
    report(_runtime(), resolve_config(args), args.scan, args.azimuth, out, print)
    return 0


def cmd_navtech_map(args):
    from radarcl import outputs
    from radarcl.jobs import navtech_map

    data = Path(args.data) if args.data else default_data("navtech_oxford")
    if not data.is_dir():
        from radarcl.errors import ConfigError

        raise ConfigError(f"no data directory {data}; give DATA (radar/*.png and gt/radar_odometry.csv) or set "
                          f"{DATA_ENV}")
    out = outputs.check(args.out, args.force, what="figure")
    map_out = outputs.check(args.map, args.force, what="map file") if args.map else None
    json_out = outputs.check(args.json, args.force, what="JSON file") if args.json else None
    config = resolve_config(args)
    results, grid, poses, pulses = navtech_map.run(_runtime(), config, data, report=print, progress=_progress(args))
    print(f"detector: {pulses['cfar']['kind'].upper()}-CFAR guard {pulses['cfar']['guard_bins']} train "
          f"{pulses['cfar']['train_bins']} bins; {pulses['detections_per_scan']:.0f} detections and "
          f"{pulses['pulses_per_scan']:.0f} pulses per scan, pulse width median {pulses['pulse_width_median_m']:.3f} m "
          f"(90 % below {pulses['pulse_width_p90_m']:.3f} m), {100 * pulses['wide_fraction']:.1f} % wide")
    navtech_map.plot_map(grid, poses, out, results, title=config.sensor.name)
    mem = grid.memory()
    print(f"map: {mem['bricks']} bricks, {mem['sparse_bytes'] / 2**20:.1f} MiB allocated "
          f"({mem['dense_bytes'] / 2**20:.1f} MiB dense); wrote {out}")
    if map_out:
        grid.save(map_out, poses=poses)
        print(f"wrote {map_out} (radarcl render / view open it)")
    if json_out:
        with outputs.atomic(json_out) as tmp:
            tmp.write_text(json.dumps(dict(consistency=results, detector=pulses, config=config.as_dict()), indent=1))
    return 0


def cmd_convert(args):
    from radarcl import outputs, store

    target = outputs.check(args.target, args.force, inputs=[args.source], what="map",
                           store=not str(args.target).endswith(".npz"))
    spec, n = store.convert(args.source, target)
    print(f"wrote {target}: {n} bricks of a {' x '.join(map(str, spec.shape))} grid at {spec.voxel_m:g} m")
    return 0


def cmd_export(args):
    from radarcl import exports, outputs
    from radarcl.maps import Map

    out = outputs.check(args.out, args.force, inputs=[args.map], what="export", bag=args.to == "rosbag")
    if args.to == "costmap":
        outputs.check(out.with_suffix(".yaml"), args.force, inputs=[args.map], what="costmap YAML")
    m = Map.open(args.map)
    fn = exports.FORMATS[args.to]
    options = {}
    if args.to in ("mesh", "vti", "costmap", "rosbag"):
        options["band"] = args.band
    if args.to == "octomap":
        options["threshold_nats"] = 0.0 if args.threshold is None else args.threshold
        options["progress"] = _progress(args)
    elif args.to != "vti":
        options["threshold_nats"] = 1.0 if args.threshold is None else args.threshold
    result = fn(m, out, **options)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) if out.is_dir() else out.stat().st_size
    print(f"wrote {out} ({args.to}, {size / 2**20:.2f} MiB): {result}")
    return 0


def cmd_fuse_many(args):
    from radarcl import outputs
    from radarcl.jobs import fuse_many

    config = resolve_config(args)
    out = outputs.check(args.out, args.force, inputs=list(args.inputs) + [args.config], what="map",
                        store=not str(args.out).endswith(".npz"))
    fuse_many.run(config, args.inputs, out, scheduler=args.scheduler, workers=args.workers, report=print)
    return 0


def _settings(args):
    from radarcl.viewer.modes import Settings

    return Settings(threshold=args.threshold, lo=args.lo, hi=args.hi, gamma=args.gamma, colormap=args.colormap,
                    step=args.step)


def cmd_render(args):
    from radarcl import outputs
    from radarcl.viewer.headless import render_map

    out = outputs.check(args.out, args.force, inputs=[args.map], what="image")
    with outputs.atomic(out) as tmp:
        render_map(args.map, tmp, args.mode, args.camera, tuple(args.size), _settings(args),
                   colorbar=not args.no_colorbar, report=lambda line: print(line.replace(str(tmp), str(out))),
                   guides=not args.no_guides)
    return 0


def cmd_view(args):
    from radarcl import outputs
    from radarcl.viewer.app import run

    if (args.map is None) == (args.follow is None):
        from radarcl.errors import ConfigError

        raise ConfigError("give a MAP file to view, or --follow HOST:PORT of a running radarcl live --serve (not both)")
    shot = outputs.check(args.screenshot, args.force, inputs=[args.map], what="screenshot") if args.screenshot else None
    status = run(args.map, mode_name=args.mode, camera=args.camera, size=tuple(args.size), settings=_settings(args),
                 live=args.live, frames=args.frames, screenshot=shot, keys=args.keys, window=args.window,
                 follow=args.follow)
    if shot:
        print(f"saved {shot}")
    return status


def cmd_bench(args):
    say = (lambda line: None) if args.json else (lambda line: print(line, file=sys.stderr))
    say(f"measuring {args.bench} ...")
    result, lines = args.module.command(args, _runtime, say)
    print(json.dumps(result) if args.json else "\n".join(lines))
    return 0


