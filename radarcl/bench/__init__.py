"""`radarcl bench NAME`: benchmarks, each printing its figures and their ratio to a baseline
measured in the same run (interleaved, medians: ``timing``). Each benchmark module has
``add_arguments(parser)`` and ``command(args, runtime, say)`` -> (result dict, table lines).
With --json the result carries a ``context``: the bench, its options, the date, the versions,
the CPU, the load average before and after and the wall time.
`radarcl bench all` (``suite``) runs those that tell a device apart, at sizes for a lent GPU, into
one JSON and one table; it exits 1 when one of them failed."""

import json
import os
import sys
import time

from radarcl.bench import (cfar, drive, foxglove, frames, fuse_bag, fusion, heldout_scans, live, merge, polar_read,
                           quality, range_fft, scenes, store, suite, viewer)
from radarcl.commands.options import runtime

SUMMARY = "benchmarks, each against a baseline measured in the same run"
DESCRIPTION = ("Each benchmark prints its figures and their ratio to a baseline measured in the same run "
               "(interleaved, medians). `radarcl bench NAME --help` for its options.")

BENCHES = {
    "range-fft": (range_fft, "window + FFT + magnitude of a paper frame vs scipy.fft, same run"),
    "cfar": (cfar, "CFAR + eq. 12 of a paper frame vs vectorised numpy, same run"),
    "fusion": (fusion, "one paper frame into the 0.1 m grid vs the float64 oracle and the memory floor, a spinning "
                       "radar's scan, eq. 12 beside the default model, same run"),
    "quality": (quality, "map error against run time on the reference scene: eq. 12's configurations (zero padding, "
                         "beam model, voxel, CFAR kind) and the default model's (evidence, blocker gap, zero padding, "
                         "voxel, the detection evidence stacked on each, look limit, knowledge channel) on one fixed "
                         "voxel set, with three baselines and the Pareto fronts"),
    "heldout-scans": (heldout_scans, "real data without lidar: a map of the even Navtech scans predicts the CFAR "
                                     "detections of the odd ones, vs raw intensity"),
    "scenes": (scenes, "the maps of generated scenes (held-out or training split) scored on their visibility truth, "
                       "beside the three baselines"),
    "frames": (frames, "do probabilities hold at any number of scans: maps of 1, 10 and 100 frames of a still and a "
                       "moving radar on generated scenes, scored on their visibility truth"),
    "store": (store, "saving and loading the paper's 0.1 m map as .npz vs the map store, with an incremental save, "
                     "same run"),
    "live": (live, "the reference scene streamed beam by beam over a pty into the live engine: throughput, latency, "
                   "faults, vs waiting for whole frames"),
    "viewer": (viewer, "the paper's full grid rendered at 512 x 512 through EGL vs a plain ray march, same run"),
    "drive": (drive, "the 11 Oxford scans replayed cyclically along the 37-minute odometry into a rolling map: "
                     "scans/s vs real time, memory high-water marks, latency, vs today's unbounded grid; decoding on "
                     "a reader thread: end-to-end vs decode-alone and fuse-alone rates, same run"),
    "merge": (merge, "fuse-many's merge partitioned by brick key on 1, 2 and 3 Dask workers, many overlapping partial "
                     "maps, vs the one-process merge, same run"),
    "polar-read": (polar_read, "reading polar scans (RADIATE, Oxford) with their layout vs decoding the PNG with PIL "
                               "alone, same run"),
    "foxglove": (foxglove, "the Oxford scans fused without Foxglove, served, and served to a client that stalls, "
                           "same run"),
    "fuse-bag": (fuse_bag, "the Oxford scans fused from a ROS 2 bag (sqlite3, MCAP) vs from their PNG folder, same run"),
}


def add_arguments(parser):
    """One sub-command per benchmark, each with --json and its own options."""
    benches = parser.add_subparsers(dest="bench", required=True, metavar="NAME")
    for name, (module, summary) in BENCHES.items():
        b = benches.add_parser(name, help=summary, description=summary[0].upper() + summary[1:] + ".")
        b.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
        module.add_arguments(b)
        b.set_defaults(bench_module=module, bench_options=[a.dest for a in b._actions if a.dest not in ("help", "json")])
    b = benches.add_parser("all", help=suite.SUMMARY, description=suite.DESCRIPTION)
    suite.add_arguments(b)
    b.set_defaults(bench_module=suite)


def run(args):
    if args.bench_module is suite:
        return suite.main(args, runtime)
    say = (lambda line: None) if args.json else (lambda line: print(line, file=sys.stderr))
    say(f"measuring {args.bench} ...")
    context = dict(bench=args.bench, options={dest: getattr(args, dest) for dest in args.bench_options},
                   **suite.context())
    start = time.perf_counter()
    result, lines = args.bench_module.command(args, runtime, say)
    if args.json:                 # where and when it ran, for whoever reads the figures later
        context.update(load_after=list(os.getloadavg()), wall_s=time.perf_counter() - start)
        print(json.dumps({**result, "context": context}))
    else:
        print("\n".join(lines))
    return 0
