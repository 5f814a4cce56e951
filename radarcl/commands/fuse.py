"""`radarcl fuse`: any sensor's frames fused into a map (``jobs.fuse``)."""

import sys
from pathlib import Path

from radarcl.commands.options import (
    add_config,
    add_foxglove_options,
    add_output,
    add_progress,
    add_trajectory_options,
    positive_int,
    foxglove_out,
    progress,
    resolve_config,
    runtime,
    say_notes,
)
from radarcl.errors import ConfigError
from radarcl.io import files, inputs
from radarcl.io.inputs import open_input
from radarcl.maps import disk
from radarcl.maps.rolling import WINDOW_RANGE_FACTOR

SUMMARY = "fuse any sensor's frames into a map file (rewritten every --every frames for radarcl view --live)"


def description():
    """The command's help text, with what each reader of ``io.inputs.READERS`` reads."""
    return ("Reads INPUT as the sensor's reader says (" + "; ".join(r.describes for r in inputs.READERS.values())
            + "), fuses every frame with the map configuration and writes the map file. Input without poses is "
            "fused only with --still (every frame at the origin).")


def input_help():
    """INPUT's help: what the readers of ``io.inputs.READERS`` read, in a few words each."""
    what = [r.what for r in inputs.READERS.values()]
    return what[0] if len(what) == 1 else ", ".join(what[:-1]) + ", or " + what[-1]


DESCRIPTION = description()


def add_arguments(parser):
    parser.description = description()              # with the readers registered by now
    parser.add_argument("input", help=input_help())
    add_output(parser, "--out", "map.rcmap", "map to write: a map store directory (zarr; saved fast, --every then "
                                             "writes only the changed bricks), or an .npz file")
    add_config(parser, by_layout=True)
    parser.add_argument("--odometry", default=None, help="polar scans: an Oxford radar_odometry.csv (= --poses FILE "
                                                          "--poses-format oxford)")
    add_trajectory_options(parser)
    add_bag_options(parser)
    parser.add_argument("--still", action="store_true",
                        help="fuse input that has no poses with every frame at the origin (a radar that does not move)")
    parser.add_argument("--every", type=positive_int, default=None, help="rewrite the map file every N frames")
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="the run's HTML page: numbers, the map from above, the viewer's render, the configuration "
                             "(default: the map's name with .html, e.g. map.html)")
    parser.add_argument("--no-report", action="store_true", help="write no HTML page")
    parser.add_argument("--window", nargs="?", const="default", default=None, metavar="R",
                        help="a rolling map for a drive of any length: the device keeps the bricks within R metres of "
                             "the sensor and writes the others into the map store (--out, a store) as they leave, "
                             "reading them back when the sensor returns; the grid spans the whole trajectory unless "
                             "[grid] origin_m and size_m are set. --window alone: "
                             f"{WINDOW_RANGE_FACTOR:g} x the sensor's mapped range (interpret.range_max_m)")
    add_foxglove_options(parser)
    add_progress(parser)


def add_bag_options(parser):
    """--topic, --pose-topic, --msg-dir: what a ROS 2 bag's reader takes (``io.rosbag``)."""
    parser.add_argument("--topic", default=None, help="a ROS 2 bag: the radar topic to fuse (default: its only radar "
                                                      "topic; radarcl info BAG lists them)")
    parser.add_argument("--pose-topic", default=None, metavar="TOPIC", help="a ROS 2 bag: the nav_msgs/Odometry or tf2_msgs/TFMessage "
                                                           "topic of the radar's poses (default: its one odometry "
                                                           "topic, else /tf); --poses FILE overrides the bag's poses")
    parser.add_argument("--msg-dir", default=None, metavar="FOLDER",
                        help="a ROS 2 bag: message definitions it does not carry, as FOLDER/<package>/msg/<Name>.msg")


def window_of(args, config):
    """(--window in metres or None, whether it is the default): a sentence for what is not a distance."""
    if args.window is None:
        return None, False
    if args.window == "default":
        from radarcl.jobs import fuse

        return fuse.default_window_m(config), True
    try:
        value = float(args.window)
    except ValueError:
        raise ConfigError(f"--window must be a distance in metres, got {args.window!r}") from None
    if not (0 < value < float("inf")):
        raise ConfigError(f"--window must be a positive distance in metres, got {args.window}")
    return value, False


def run(args):
    from radarcl.jobs import fuse

    config = resolve_config(args)
    out = disk.check_output(args.out, args.force, inputs=[args.input, args.config, args.odometry])
    page = None if args.no_report else files.check(args.report or Path(out).with_suffix(".html"), args.force,
                                                    inputs=[args.input, args.config, out], what="report")
    if page is not None and Path(page).resolve() == Path(out).resolve():
        raise ConfigError(f"the report and the map would both be {out}; give --report another name")
    if args.odometry and args.poses:
        raise ConfigError("give --odometry or --poses, not both")
    source = open_input(config.sensor, args.input, args.odometry, args.poses, args.poses_format, args.clock_offset,
                        args.max_speed, args.poses_times, report=lambda line: print(f"radarcl: {line}", file=sys.stderr),
                        progress=progress(args), topic=args.topic, pose_topic=args.pose_topic, msg_dir=args.msg_dir)
    if not source.posed and not args.still:
        raise ConfigError(f"{args.input}: no poses for these frames ({source.summary}); give --poses FILE "
                          "(--poses-format: oxford, tum, kitti, xyzrpy, radiate, boreas), put them beside the scans, "
                          "or pass --still to fuse every frame at the origin (a radar that does not move)")
    said = config.notes + source.notes
    say_notes(source.notes, config.notes)
    if source.sensor is not config.sensor:                   # the reader learnt the bin count
        config = config.for_sensor(source.sensor)
        say_notes(config.notes, said)
    window, default = window_of(args, config)
    fox = foxglove_out(args)
    try:
        fuse.run(runtime(), source, config, out, every=args.every, progress=progress(args), inputs=[args.input],
                 page=page, window_m=window, window_default=default, overwrite=args.force, foxglove=fox)
    finally:
        if fox is not None:
            fox.close()
    return 0
