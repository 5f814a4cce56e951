"""`radarcl calibrate`: the interpreter's constants fitted by maximum likelihood on the training
scenes (``jobs.calibrate``); what both calibration commands write (``fit_outputs``, ``write_fit``)."""

import json

from radarcl import models
from radarcl.commands.options import bounded_int, positive_float, runtime
from radarcl.errors import ConfigError
from radarcl.io import files

SUMMARY = ("fit the interpreter's constants by maximum likelihood on the training scenes; --save writes them as "
           "a configuration file")
DESCRIPTION = ("Simulates the generated training scenes (radarcl/scene/generator.py), fits the eq. 12 constants "
               "(or the occlusion-aware interpreter's) by logistic regression of the visibility truth on the fused "
               "per-bin features, chooses the CFAR settings and the surface test by the log-likelihood on "
               "validation scenes, prints the constants with standard errors and writes a configuration file "
               "and a reliability diagram. The held-out scenes are never used (radarcl bench scenes reports on them).")


def add_fit_outputs(parser, models=("occlusion", "paper")):
    """--model, --save, --figure, --json, --force: the options both calibration commands share."""
    parser.add_argument("--model", choices=models, default="occlusion",
                        help="the interpreter to calibrate (default: %(default)s)")
    parser.add_argument("--save", default=None, metavar="FILE", help="write the calibrated configuration to FILE")
    parser.add_argument("--figure", default=None, metavar="PNG", help="write the before/after reliability diagram")
    parser.add_argument("--json", default=None, metavar="FILE", help="write the whole result as JSON")
    parser.add_argument("--force", action="store_true", help="replace existing output files")


def add_arguments(parser):
    parser.add_argument("--voxel", type=positive_float, default=None,
                        help="voxel edge [m] (default: 0.2; 0.4 for --model detstats, whose every candidate is a map)")
    parser.add_argument("--seeds", type=bounded_int(0, 2 ** 32 - 1), nargs="+", default=None,
                        help="training scene seeds (default: generator.TRAIN_SEEDS; the last third validates)")
    parser.add_argument("--unknown-behind", action="store_true",
                        help="hold E_l at 0: the map stays unknown behind the first surface (shadows are unknowable)")
    parser.add_argument("--radar", choices=("paper", "spinning"), default="paper",
                        help="--model detstats: the tilting stand's generated scenes, or the simulated spinning radar's "
                             "streets (default: %(default)s)")
    add_fit_outputs(parser, ("occlusion", "paper", "detstats"))


def fit_outputs(args):
    """The checked --save, --figure and --json paths of a calibration command (None where not
    asked), refused before any work when they exist without --force."""
    return tuple(files.check(path, args.force, what=what) if path else None
                 for path, what in ((args.save, "configuration file"), (args.figure, "figure"), (args.json, "JSON file")))


def write_fit(paths, config, header, figure, result):
    """Write a calibration's configuration, figure (a callable drawing it) and JSON to
    ``paths`` (from ``fit_outputs``)."""
    from radarcl.report import figures

    save, figure_path, json_out = paths
    if save:
        config.save(save, header=header, overwrite=True)
        print(f"wrote {save} (use it with --config)")
    if figure_path:
        figures.save(figure(), figure_path)
        print(f"wrote {figure_path}")
    if json_out:
        with files.atomic(json_out) as tmp:
            tmp.write_text(json.dumps(result, indent=1))
        print(f"wrote {json_out}")


def run(args):
    from radarcl.jobs import calibrate

    paths = fit_outputs(args)
    if args.seeds is not None and len(set(args.seeds)) != len(args.seeds):
        raise ConfigError(f"--seeds {' '.join(map(str, args.seeds))}: a scene seed appears twice (fitting and "
                          "validating on the same scene proves nothing)")
    if models.get(args.model).knowledge:      # its own fit: the detection statistics' parameters
        from radarcl.jobs import calibrate_detstats as calibrate

        config, result = calibrate.run(runtime(), args.voxel or 0.4, args.seeds, report=print, radar=args.radar)
    else:
        config, result = calibrate.run(runtime(), args.model, args.voxel or 0.2, args.seeds, report=print,
                                       unknown_behind=args.unknown_behind)
    print("\n".join(calibrate.format_lines(result)))
    write_fit(paths, config, ("radarcl map configuration fitted by `radarcl calibrate`",
                              f"{result['model']} model, training scenes {result['fit_seeds']} "
                              f"(validation {result['validation_seeds']}), {result['voxel_m']} m"),
              lambda: calibrate.reliability_figure(result), result)
    return 0
