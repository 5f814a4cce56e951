"""`radarcl fuse`: any sensor's frames fused into a map (``jobs.fuse``)."""

from pathlib import Path

from radarcl.commands.options import (
    add_config,
    add_output,
    add_progress,
    positive_int,
    progress,
    resolve_config,
    runtime,
)
from radarcl.errors import ConfigError
from radarcl.io import files
from radarcl.io.inputs import open_input
from radarcl.maps import disk

SUMMARY = "fuse any sensor's frames into a map file (rewritten every --every frames for radarcl view --live)"
DESCRIPTION = ("Reads INPUT as the sensor's reader says (a radarcl recording; a directory of polar PNG scans, "
               "with radar_odometry.csv beside them or in ../gt; a TI capture .npy/.txt), fuses every frame with "
               "the map configuration and writes the map file.")


def add_arguments(parser):
    parser.add_argument("input", help="a recording (.npz), a directory of polar scans, or a TI capture")
    add_output(parser, "--out", "map.rcmap", "map to write: a map store directory (zarr; saved fast, --every then "
                                             "writes only the changed bricks), or an .npz file")
    add_config(parser)
    parser.add_argument("--odometry", default=None, help="polar scans: the radar_odometry.csv (default: found beside them)")
    parser.add_argument("--every", type=positive_int, default=None, help="rewrite the map file every N frames")
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="the run's HTML page: numbers, the map from above, the viewer's render, the configuration "
                             "(default: the map's name with .html, e.g. map.html)")
    parser.add_argument("--no-report", action="store_true", help="write no HTML page")
    add_progress(parser)


def run(args):
    from radarcl.jobs import fuse

    config = resolve_config(args)
    out = disk.check_output(args.out, args.force, inputs=[args.input, args.config, args.odometry])
    page = None if args.no_report else files.check(args.report or Path(out).with_suffix(".html"), args.force,
                                                    inputs=[args.input, args.config, out], what="report")
    if page is not None and Path(page).resolve() == Path(out).resolve():
        raise ConfigError(f"the report and the map would both be {out}; give --report another name")
    source = open_input(config.sensor, args.input, args.odometry)
    if source.sensor is not config.sensor:                   # the reader learnt the bin count
        config = config.for_sensor(source.sensor)
    fuse.run(runtime(), source, config, out, every=args.every, progress=progress(args), inputs=[args.input], page=page)
    return 0
