"""`radarcl evaluate-lidar`: radar maps scored against the lidar of the same recording
(``jobs.evaluate_lidar``)."""

import argparse
from pathlib import Path

from radarcl.commands.options import (
    DATA_ENV,
    add_progress,
    add_trajectory_options,
    default_data,
    positive_float,
    progress,
    runtime,
    say_notes,
)
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.io import files

SUMMARY = "score radar maps against the lidar of the same recording, per range band, beside no-radar controls"
DESCRIPTION = ("Fuses the recording's scans with each --model (paper, tuned, calibrated, or any configuration "
               "file) on one plane grid, builds the truth from its lidar frames ray-cast with the same poses "
               "(occupied at hits above the ground, free along the rays, unknown elsewhere and beyond the range "
               "each frame reaches), and prints per band of range from the radar's path the ROC area of every "
               "map, of the raw intensity and of two controls that use no radar data (samples counted, range), "
               "the IoU of every map at log-odds 0, and whether each annotated vehicle box is occupied. Each map is "
               "also read at the costmap's thresholds (those of `radarcl export --to costmap`): per band its recall, "
               "phantom rate (lidar-free cells called occupied), miss rate (lidar-occupied cells called free), the "
               "cells it leaves unknown and its ECE against the lidar, beside the raw intensity's phantom rate at the "
               "same recall. --scans scores a part of the recording (e.g. the part a model was not fitted on) "
               "against the lidar frames taken meanwhile; the first line names the scans scored.")


def scan_range(text):
    """argparse type: "A:B" as a Python slice of the recording's scans (either side may be
    empty, negatives count from the end) -> (A or None, B or None); the bounds are checked
    against the recording (``jobs.evaluate_lidar.select_scans``)."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        return tuple(int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:STOP of the recording's scans in order (e.g. 6:12, 6:, "
                                         f":-3), got {text!r}") from None


def add_arguments(parser):
    parser.add_argument("data", nargs="?", default=None,
                        help=f"a recording with radar scans, lidar and poses (default: RADIATE's fog sequence in "
                             f"${DATA_ENV} or ../shared/data)")
    parser.add_argument("--sensor", default="radiate-cts350x", metavar="NAME|FILE",
                        help="sensor profile of the scans (default: %(default)s)")
    parser.add_argument("--model", action="append", default=None, metavar="NAME|FILE",
                        help="a map to score: paper, tuned, calibrated, detstats, or a configuration file (repeatable; "
                             "default: paper and detstats, eq. 12 and radarcl's default model)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="set one configuration value for every model")
    parser.add_argument("--force-sensor", action="store_true", help="use configuration files made for another sensor")
    parser.add_argument("--voxel", type=positive_float, default=0.3, help="cell edge of the plane grid [m] "
                                                                         "(default: %(default)s)")
    parser.add_argument("--scans", type=scan_range, default=None, metavar="START:STOP",
                        help="score only these of the recording's scans, in order, as a Python slice (0:6 the first "
                             "six, 6: the rest, --scans=-4: the last four) against the lidar frames taken meanwhile "
                             "(default: all)")
    add_trajectory_options(parser)
    parser.add_argument("--json", default=None, metavar="FILE", help="also write the figures to this JSON file")
    parser.add_argument("--out", default=None, metavar="DIR", help="write lidar_truth.png, lidar_map.png (the best "
                                                                  "map), lidar_beside_map.png (the two side by side) "
                                                                  "and evaluate_lidar.json there")
    parser.add_argument("--force", action="store_true", help="replace existing files in --out and --json")
    add_progress(parser)


def run(args):
    from radarcl.jobs import evaluate_lidar as job

    data = Path(args.data) if args.data else default_data("radiate_fog")
    if not data.is_dir():
        raise ConfigError(f"no recording directory {data}; give DATA or set {DATA_ENV}")
    outputs = None
    if args.out:
        outputs = [files.check(Path(args.out) / name, args.force, inputs=[data], what="output")
                   for name in ("lidar_truth.png", "lidar_map.png", "evaluate_lidar.json", "lidar_beside_map.png")]
    json_out = files.check(args.json, args.force, inputs=[data], what="output") if args.json else None
    flags = dict(mapconfig.parse_flag(text) for text in args.set)
    models = job.resolve_models(args.sensor, args.model or ["paper", "detstats"], flags, args.force_sensor)
    for _, c in models:
        say_notes(c.notes)
    result, arrays = job.run(runtime(), models, data, voxel_m=args.voxel, poses=args.poses,
                             poses_format=args.poses_format, clock_offset_s=args.clock_offset, report=print,
                             progress=progress(args), scan_slice=args.scans)
    say_notes(result["notes"])
    print("\n".join(job.table(result)))
    if outputs:
        best = max(arrays["maps"], key=lambda m: sum(r["auc"][m] for r in result["bands"]))
        Path(args.out).mkdir(parents=True, exist_ok=True)
        job.plot(arrays, args.out, best)
        with files.atomic(outputs[2]) as tmp:
            job.write_json(result, tmp)
        print(f"wrote {', '.join(str(o) for o in outputs)}")
    if json_out:
        with files.atomic(json_out) as tmp:
            job.write_json(result, tmp)
        print(f"wrote {json_out}")
    return 0
