"""`radarcl export`: a map written for other tools (``maps.exports``), saying what the map says."""

import math
from pathlib import Path

from radarcl.commands.options import add_output, add_salvage, say_lost
from radarcl.errors import ConfigError
from radarcl.io import files
from radarcl.maps import disk, exports
from radarcl.maps.map import FREE_NATS, OCCUPIED_NATS, Map, check_thresholds

SUMMARY = "write a map for other tools: OctoMap, PLY, VTK, a ROS costmap or bag"
DESCRIPTION = ("Every format says what the map says: a voxel is occupied above --occupied-threshold, free below "
               "--free-threshold, unknown otherwise (or where no beam reached it). octomap: .bt (occupied/free) "
               "or .ot (their log-odds) on OctoMap's lattice, read by OctoMap and octovis; ply: the occupied "
               "voxels with colours, log_odds and probability; mesh: the isosurface at the occupied threshold as "
               "a PLY mesh; vti: the dense log-odds and an observed mask as VTK image data for ParaView; costmap: "
               "a ROS map_server PGM + YAML projected over --band (occupied, free, unknown); rosbag: a ROS 2 bag "
               "with the same grid on /map (latched) and the occupied voxels on /map/points.")
BAG_FILES = (".db3", ".mcap", ".db3-shm", ".db3-wal", ".db3-journal")


def add_arguments(parser):
    p = parser
    p.add_argument("map", help="a map (.npz) or map store")
    p.add_argument("--to", required=True, choices=list(exports.FORMATS))
    add_output(p, "--out", None, "file to write, with its format's extension (.bt/.ot, .ply, .vti, .pgm; a directory "
                                 "for rosbag)")
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
    p.add_argument("--frame-id", default="map", help="rosbag: the frame of the messages (default: %(default)s)")
    add_salvage(p)


def run(args):
    exports.check_suffix(args.to, args.out)
    check_thresholds(args.occupied, args.free)
    directory = ("ROS 2 bag", _only_a_bag) if args.to == "rosbag" else None
    out = files.check(args.out, args.force, inputs=[args.map], what="export", directory=directory)
    if args.to == "costmap":
        files.check(out.with_suffix(".yaml"), args.force, inputs=[args.map], what="costmap YAML")
    if args.band is not None and not all(math.isfinite(b) for b in args.band):
        raise ConfigError(f"--band must be two finite heights [m], got {args.band}")
    m = Map.open(args.map, salvage=args.salvage)
    say_lost(m.lost or [])
    thresholds = dict(occupied_nats=args.occupied, free_nats=args.free)
    if args.to == "octomap":
        result = exports.octomap(m, out, resample=args.resample, **thresholds)
    elif args.to == "ply":
        result = exports.ply_points(m, out, args.occupied, colour=args.colour)
    elif args.to == "mesh":
        result = exports.ply_mesh(m, out, args.occupied, band=args.band)
    elif args.to == "vti":
        result = exports.vti(m, out, band=args.band)
    elif args.to == "costmap":
        result = exports.costmap(m, out, band=args.band, **thresholds)
    else:
        result = exports.rosbag(m, out, band=args.band, frame_id=args.frame_id, stamp_ns=disk.saved_ns(args.map),
                                **thresholds)
    print(summary(args, result))
    return 0


def summary(args, result):
    """What was written, with labelled counts and the thresholds that made them."""
    written = ", ".join(f"{p} ({p.stat().st_size / 2**20:.2f} MiB)" for p in result["files"])
    counts = ", ".join(f"{v:,} {k.replace('_', ' ')}" for k, v in result.items() if k not in ("files", "lattice", "shape"))
    rule = (f"occupied above {args.occupied:g} nat, free below {args.free:g} nat" if args.to not in ("vti", "ply", "mesh")
            else f"occupied above {args.occupied:g} nat" if args.to != "vti" else "every voxel's log-odds")
    extra = f"; {result['lattice']}" if "lattice" in result else ""
    return f"wrote {written} ({args.to}: {counts}; {rule}{extra})"


def _only_a_bag(path):
    """A directory --force may replace with a bag: a ROS 2 bag (``exports.is_bag``) holding
    nothing but a bag's files; notes or data of anyone else's beside them keep it."""
    return exports.is_bag(path) and all(p.is_file() and (p.name == "metadata.yaml" or p.name.endswith(BAG_FILES))
                                        for p in Path(path).iterdir())
