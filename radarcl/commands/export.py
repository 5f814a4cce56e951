"""`radarcl export`: a map written for other tools (``maps.exports``)."""

import math
from pathlib import Path

from radarcl.commands.options import add_output, add_progress, add_salvage, progress, say_lost
from radarcl.errors import ConfigError
from radarcl.io import files
from radarcl.maps import exports
from radarcl.maps.map import Map

SUMMARY = "write a map for other tools: OctoMap, PLY, VTK, a ROS costmap or bag"
DESCRIPTION = ("octomap: .bt (occupied/free) or .ot (log-odds) read by OctoMap and octovis; ply: the voxels above "
               "--threshold with log_odds and probability; mesh: the isosurface at --threshold as a PLY mesh; "
               "vti: the dense log-odds as VTK image data for ParaView; costmap: a ROS map_server PGM + YAML "
               "projected over --band; rosbag: a ROS 2 bag with a PointCloud2 and an OccupancyGrid.")


def add_arguments(parser):
    parser.add_argument("map", help="a map (.npz) or map store")
    parser.add_argument("--to", required=True, choices=["octomap", "ply", "mesh", "vti", "costmap", "rosbag"])
    add_output(parser, "--out", None, "file to write (a directory for rosbag)")
    parser.add_argument("--threshold", type=float, default=None,
                        help="[nat]: occupied above it (default 1; octomap: voxels with |log-odds| >= it, default 0)")
    parser.add_argument("--band", type=float, nargs=2, default=None, metavar=("Z_MIN", "Z_MAX"),
                        help="height band [m] for costmap, rosbag's grid, mesh and vti (default: the whole grid)")
    add_progress(parser)
    add_salvage(parser)


def run(args):
    directory = ("ROS 2 bag", _only_a_bag) if args.to == "rosbag" else None
    out = files.check(args.out, args.force, inputs=[args.map], what="export", directory=directory)
    if args.to == "costmap":
        # the exporter writes the PGM to --out and its YAML beside it, named by the suffix:
        # --out cm.yaml would write the PGM, then the YAML over it
        if out.suffix.lower() in (".yaml", ".yml"):
            raise ConfigError(f"a costmap is a PGM image and a YAML file beside it: give --out "
                              f"{out.with_suffix('.pgm')} (its YAML {out.with_suffix('.yaml')} is written beside it)")
        files.check(out.with_suffix(".yaml"), args.force, inputs=[args.map], what="costmap YAML")
    if args.threshold is not None and not math.isfinite(args.threshold):
        raise ConfigError(f"--threshold must be a finite number of nats, got {args.threshold}")
    if args.band is not None and not all(math.isfinite(b) for b in args.band):
        raise ConfigError(f"--band must be two finite heights [m], got {args.band}")
    m = Map.open(args.map, salvage=args.salvage)
    say_lost(m.lost or [])
    fn = exports.FORMATS[args.to]
    options = {}
    if args.to in ("mesh", "vti", "costmap", "rosbag"):
        options["band"] = args.band
    if args.to == "octomap":
        options["threshold_nats"] = 0.0 if args.threshold is None else args.threshold
        options["progress"] = progress(args)
    elif args.to != "vti":
        options["threshold_nats"] = 1.0 if args.threshold is None else args.threshold
    result = fn(m, out, **options)
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) if out.is_dir() else out.stat().st_size
    print(f"wrote {out} ({args.to}, {size / 2**20:.2f} MiB): {result}")
    return 0


BAG_FILES = (".db3", ".mcap", ".db3-shm", ".db3-wal", ".db3-journal")


def _only_a_bag(path):
    """A directory --force may replace with a bag: a ROS 2 bag (``exports.is_bag``) holding
    nothing but a bag's files; notes or data of anyone else's beside them keep it."""
    return exports.is_bag(path) and all(p.is_file() and (p.name == "metadata.yaml" or p.name.endswith(BAG_FILES))
                                        for p in Path(path).iterdir())
