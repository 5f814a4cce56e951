"""`radarcl fuse-many`: many recordings fused in parallel on a Dask cluster (``jobs.fuse_many``)."""

from radarcl.commands.options import add_config, add_output, positive_int, resolve_config
from radarcl.maps import disk

SUMMARY = "fuse many recordings in parallel on a Dask cluster into one map"
DESCRIPTION = ("Fuses each input on a Dask worker (a LocalCluster by default, any scheduler address for a real "
               "cluster), each worker with its own OpenCL context, and merges the maps brick by brick with exact "
               "integer sums: the same map as fusing every input in one process, in any order.")


def add_arguments(parser):
    parser.add_argument("inputs", nargs="+", help="recordings (or anything fuse reads) of one sensor")
    add_output(parser, "--out", "map.rcmap", "map to write: a map store, or an .npz file")
    add_config(parser)
    parser.add_argument("--scheduler", default=None, help="a Dask scheduler address (default: a local cluster)")
    parser.add_argument("--workers", type=positive_int, default=2, help="local cluster workers (default: %(default)s)")


def run(args):
    from radarcl.jobs import fuse_many

    config = resolve_config(args)
    out = disk.check_output(args.out, args.force, inputs=list(args.inputs) + [args.config])
    fuse_many.run(config, args.inputs, out, scheduler=args.scheduler, workers=args.workers, report=print)
    return 0
