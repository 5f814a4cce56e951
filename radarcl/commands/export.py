"""`radarcl export`: a map written for other tools (``maps.exports``), saying what the map says."""

import math

from radarcl.commands.options import add_output, add_salvage, say_lost
from radarcl.errors import ConfigError
from radarcl.io import files
from radarcl.maps import disk, exports
from radarcl.maps.map import FREE_NATS, OCCUPIED_NATS, Map, check_thresholds

SUMMARY = "write a map for other tools: OctoMap, PLY, VTK, a ROS costmap or bag"


def description():
    """The command's help text: the thresholds, then each format of ``exports.FORMATS`` and what it writes."""
    return ("Every format says what the map says: a voxel is occupied above --occupied-threshold, free below "
            "--free-threshold, unknown otherwise (or where no beam reached it). "
            + "; ".join(f"{f.name}: {f.describes}" for f in exports.FORMATS.values()) + ".")


def out_help():
    """--out's help: the extensions of ``exports.FORMATS``, and the formats that write a directory."""
    extensions = dict.fromkeys("/".join(f.suffixes) for f in exports.FORMATS.values() if f.suffixes != ("",))
    directories = [f.name for f in exports.FORMATS.values() if f.suffixes == ("",)]
    return (f"file to write, with its format's extension ({', '.join(extensions)}"
            + (f"; a directory for {' or '.join(directories)}" if directories else "") + ")")


DESCRIPTION = description()


def add_arguments(parser):
    p = parser
    p.description = description()              # with the formats registered by now
    p.add_argument("map", help="a map (.npz) or map store")
    p.add_argument("--to", required=True, choices=list(exports.FORMATS))
    add_output(p, "--out", None, out_help())
    p.add_argument("--occupied-threshold", "--threshold", dest="occupied", type=float, default=OCCUPIED_NATS,
                   metavar="NATS", help="occupied above this log-odds [nat] (default: %(default)s, p 0.73)")
    p.add_argument("--free-threshold", dest="free", type=float, default=FREE_NATS, metavar="NATS",
                   help="free below this log-odds [nat] (default: %(default)s, p 0.27)")
    p.add_argument("--band", type=float, nargs=2, default=None, metavar=("Z_MIN", "Z_MAX"),
                   help="height band [m] for costmap, rosbag's grid, mesh and vti (default: the whole grid)")
    p.add_argument("--resample", action="store_true",
                   help="octomap: interpolate a map whose origin is off OctoMap's lattice onto it (else refused)")
    p.add_argument("--colour", choices=exports.COLOURS, default="log-odds", help="ply: colour the points by (default: "
                                                                               "%(default)s)")
    p.add_argument("--frame-id", default="map",
                   help="the map's frame: rosbag's messages, PLY's and .vti's header (default: %(default)s)")
    add_salvage(p)


def run(args):
    exports.check_suffix(args.to, args.out)
    check_thresholds(args.occupied, args.free)
    fmt = exports.FORMATS[args.to]
    out = files.check(args.out, args.force, inputs=[args.map], what="export", directory=fmt.directory)
    for suffix, what in fmt.companions:
        files.check(out.with_suffix(suffix), args.force, inputs=[args.map], what=what)
    if args.band is not None and not all(math.isfinite(b) for b in args.band):
        raise ConfigError(f"--band must be two finite heights [m], got {args.band}")
    m = Map.open(args.map, salvage=args.salvage)
    say_lost(m.lost or [])
    result = fmt.write(m, out, **{name: option(args) for name, option in OPTIONS.items() if name in fmt.options})
    print(summary(args, result))
    return 0


OPTIONS = {                      # exports.OPTIONS from the command line: the exporter takes those it names
    "occupied_nats": lambda args: args.occupied,
    "free_nats": lambda args: args.free,
    "band": lambda args: args.band,
    "resample": lambda args: args.resample,
    "colour": lambda args: args.colour,
    "frame_id": lambda args: args.frame_id,
    "stamp_ns": lambda args: disk.saved_ns(args.map),
    "poses": lambda args: disk.read_poses(args.map),
    "times_ns": lambda args: disk.read_meta(args.map, "times_ns"),
}


def summary(args, result):
    """What was written, with labelled counts and the thresholds that made them."""
    written = ", ".join(f"{p} ({p.stat().st_size / 2**20:.2f} MiB)" for p in result["files"])
    counts = ", ".join(f"{v:,} {k.replace('_', ' ')}" for k, v in result.items() if k not in ("files", "lattice", "shape"))
    thresholds = exports.FORMATS[args.to].thresholds
    rule = (f"occupied above {args.occupied:g} nat, free below {args.free:g} nat" if "free" in thresholds
            else f"occupied above {args.occupied:g} nat" if thresholds else "every voxel's log-odds")
    extra = f"; {result['lattice']}" if "lattice" in result else ""
    return f"wrote {written} ({args.to}: {counts}; {rule}{extra})"

