"""`radarcl fit-sensor`: a real radar's background law and sensitivity from its own scans
(``jobs.fit_sensor``)."""

import json
from pathlib import Path

from radarcl.commands.options import add_config, default_data, resolve_config, runtime
from radarcl.errors import ConfigError

SUMMARY = "fit a real radar's clutter law and sensitivity from its own polar scans, with intervals"
DESCRIPTION = ("Reads the scans' powers over each beam's noise floor and fits, by maximum likelihood per band of "
               "range, the background the detection-statistics model weighs an echo against (noise, or with a "
               "share of bins clutter of a log-normal power) and the sensitivity that makes a typical target's "
               "echo fall as r^-4; approximate intervals (1.96 jackknife SEs over scans). Without a lidar it writes "
               "the values the scans bound; with --lidar it also chooses the map's sensitivity, look limit and "
               "background by what the lidar's cells say. The configuration (for --config) says where every value "
               "came from. Fit on one part of a recording (--scans) and score on another (evaluate-lidar --scans).")


def add_arguments(parser):
    parser.add_argument("data", nargs="?", default=None,
                        help="a directory of polar scans (default: the shared Oxford sequence)")
    add_config(parser, "navtech-cts350x")
    parser.add_argument("--scans", default="all", metavar="A:B[:S]",
                        help="the scans to fit on, a Python slice in time order (e.g. 0::2, the even ones; "
                             "default: all)")
    parser.add_argument("--lidar", action="store_true",
                        help="use the recording's lidar (RADIATE's layout): the background from the bins of cells it "
                             "calls free, the sensitivity from those it calls occupied, then the map's sensitivity, "
                             "look limit and background: the best ROC area of the lidar's cells among the maps "
                             "calling at most 0.10 of its free cells occupied in every band to 30 m; --scans must be "
                             "a run A:B")
    parser.add_argument("--save", metavar="FILE", help="write the fitted configuration (TOML, for --config); an "
                                                       "existing file is kept unless --force")
    parser.add_argument("--force", action="store_true", help="replace existing output files")
    parser.add_argument("--json", metavar="PATH", help="also write the fit as JSON")


def run(args):
    from radarcl.jobs import fit_sensor

    data = args.data or default_data("navtech_oxford")
    if not Path(data).is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (a directory of polar scans)")
    for path in (args.save, args.json):
        if path and Path(path).exists() and not args.force:
            raise ConfigError(f"{path} exists; choose another name or pass --force")
    config, out = fit_sensor.run(resolve_config(args), data, args.scans, args.lidar,
                                 runtime() if args.lidar else None, report=print)
    print("\n".join(fit_sensor.format_lines(out)))
    if args.save:
        config.save(args.save, header=("radarcl map configuration fitted by `radarcl fit-sensor`",
                                       f"{out['sensor']} scans {fit_sensor.span(out['scans'])} of {out['data']}"),
                    overwrite=args.force)
        print(f"wrote {args.save} (give it to --config, or to evaluate-lidar as --model {args.save})")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0
