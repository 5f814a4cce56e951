"""`radarcl calibrate-scans`: the interpreter's constants fitted on a real radar's own scans
(``jobs.calibrate_scans``)."""

from pathlib import Path

from radarcl.commands.calibrate import add_fit_outputs, fit_outputs, write_fit
from radarcl.commands.options import add_config, default_data, resolve_config, runtime
from radarcl.errors import ConfigError

SUMMARY = ("fit the interpreter's constants on a real radar's own polar scans: a map of some scans predicts the "
           "detections of the others")
DESCRIPTION = ("Splits the sequence in time. On the first part, a map of the even scans (each interpreter feature "
               "fused as its own channel) predicts the CFAR detections of the odd scans (the sensor profile's own "
               "detector); a logistic fit of those detections gives the constants, and the map's CFAR and surface "
               "test are chosen by its likelihood. On the last part, never seen by the fit, it compares the profile's "
               "constants, the calibrated ones and the baselines on the same held-out bins, and writes a "
               "configuration file for --config.")


def add_arguments(parser):
    parser.add_argument("data", nargs="?", default=None,
                        help="a directory of radar/*.png and gt/radar_odometry.csv (default: the shared Oxford sequence)")
    add_config(parser, "navtech-cts350x")
    add_fit_outputs(parser)


def run(args):
    from radarcl.jobs import calibrate_scans

    paths = fit_outputs(args)
    data = args.data or default_data("navtech_oxford")
    if not Path(data).is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (radar/*.png and gt/radar_odometry.csv)")
    config, result = calibrate_scans.run(runtime(), resolve_config(args), data, args.model, report=print)
    print("\n".join(calibrate_scans.format_lines(result)))
    write_fit(paths, config, ("radarcl map configuration fitted by `radarcl calibrate-scans`",
                              f"{result['model']} interpreter, {result['sensor']} scans {result['fit_scans']} of {data}"),
              lambda: calibrate_scans.reliability_figure(result), result)
    return 0
