"""`radarcl bench merge`: fuse-many's merge (``jobs.merge_maps``) on a merge-dominated input, with
1, 2 and 3 Dask workers (local processes, one thread each) in the same run.

The input: ``inputs`` partial map stores of ``bricks`` random 8^3 bricks each, drawn from a pool of
``pool`` brick keys so that they overlap (a fleet driving the same streets), stored in key order
as fuse-many's partials are; 70 % of the voxels zero, the rest random log-odds. The merges take
turns, round after round (interleaved), each worker count on a cluster started for it before the
clock starts and closed after, and the median of ``repeat`` rounds is kept, beside the one-process merge of the
same inputs (every store read whole, ``merge``, one ``StoreWriter`` save: fuse-many's merge before
it was partitioned). Every output is checked to be the one-process map, bit for bit.
"""

import contextlib
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from radarcl.bench.timing import OtherLoad
from radarcl.gridspec import GridSpec
from radarcl.jobs import merge_maps
from radarcl.maps import store


def add_arguments(parser):
    parser.add_argument("--inputs", type=int, default=12, help="partial maps to merge (default: %(default)s)")
    parser.add_argument("--bricks", type=int, default=12000, help="bricks in each (default: %(default)s)")
    parser.add_argument("--pool", type=int, default=24000,
                        help="distinct brick keys they are drawn from (default: %(default)s)")
    parser.add_argument("--workers", default="1,2,3", help="worker counts, comma separated (default: %(default)s)")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved rounds (default: %(default)s)")


def synthesise(root, inputs, bricks, pool, seed=0):
    """``inputs`` map stores of random bricks (see the module docstring); returns their paths."""
    side = int(np.ceil(pool ** (1 / 3)))
    spec = GridSpec((0.0, 0.0, 0.0), 0.2, (8 * side, 8 * side, 8 * side))
    rng = np.random.default_rng(seed)
    grid = np.stack(np.unravel_index(np.arange(side ** 3), (side,) * 3), 1)[:pool].astype(np.int32)
    paths = []
    for i in range(inputs):
        keys = grid[np.sort(rng.choice(pool, min(bricks, pool), replace=False))]
        keys = keys[np.argsort(merge_maps.key_ids(keys), kind="stable")]
        data = rng.integers(-3000, 3000, (len(keys), 8, 8, 8), dtype=np.int32)
        data[rng.random(data.shape) < 0.7] = 0
        paths.append(Path(root) / f"partial_{i}.rcmap")
        store.StoreWriter(paths[-1], spec).save(keys, data)
    return spec, paths


def one_process(paths, out):
    """The merge before it was partitioned: every store read whole, summed, saved once."""
    parts = [store.read(p)[1:3] for p in paths]
    spec = store.read_manifest(paths[0])["spec"]
    keys, data = merge_maps.merge(parts)
    store.StoreWriter(out, spec).save(keys, data)


def cpu_seconds(pids):
    """CPU seconds (user + system) each of ``pids`` ("self" for this process) has used; NaN without /proc."""
    hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    out = []
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            out.append((int(fields[11]) + int(fields[12])) / hz)
        except (OSError, ValueError, IndexError):
            out.append(float("nan"))
    return np.array(out)


def _uptime():
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


@contextlib.contextmanager
def _cluster(workers, directory, warm):
    """A LocalCluster of ``workers`` processes (one thread each), warmed by merging the map store
    ``warm`` alone (imports, zarr's first use), alive only for one timed merge: an idle cluster's
    scheduler costs the coordinator about 5 % of a core, which would fall on every other
    measurement. None for the one-process merge."""
    if workers is None:
        yield None
        return
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      local_directory=str(directory)) as cluster, Client(cluster) as client:
        merge_maps.merge_stores(client, [warm], Path(directory) / "warm.rcmap", partitions=3 * workers)
        shutil.rmtree(Path(directory) / "warm.rcmap")
        yield client


def command(args, runtime, say):
    import logging

    import distributed  # noqa: F401  (its loggers exist once it is imported)

    for name in [n for n in logging.root.manager.loggerDict if n.startswith("distributed")] + ["distributed"]:
        logging.getLogger(name).setLevel(logging.CRITICAL)      # a closing cluster's INFO lines and comm errors
    counts = [int(w) for w in args.workers.split(",")]
    work = Path(tempfile.mkdtemp(prefix="radarcl-bench-merge-"))
    try:
        start = time.perf_counter()
        spec, paths = synthesise(work, args.inputs, args.bricks, args.pool)
        say(f"synthesised {args.inputs} partial maps of {args.bricks} bricks in {time.perf_counter() - start:.1f} s")
        names = ["one process", *(f"{n} workers" for n in counts)]
        load_before = _uptime()
        times, others, cpus = ({name: [] for name in names} for _ in range(3))   # cpus: [this process, each worker]
        want = None
        for r in range(args.repeat + 1):                       # round 0 warms the page cache
            for name in names:
                out = work / f"out_{name.replace(' ', '_')}.rcmap"
                shutil.rmtree(out, ignore_errors=True)
                with _cluster(None if name == "one process" else int(name.split()[0]), work, paths[0]) as client:
                    pids = list(client.run(os.getpid).values()) if client else []
                    meter, cpu0, t0 = OtherLoad(pids), cpu_seconds(["self", *pids]), time.perf_counter()
                    if client:
                        merge_maps.merge_stores(client, paths, out)
                    else:
                        one_process(paths, out)
                    if r:
                        times[name].append(time.perf_counter() - t0)
                        others[name].append(meter.cores())
                        cpus[name].append((cpu_seconds(["self", *pids]) - cpu0).tolist())
                got = store.read(out)[1:3]
                if want is None:
                    want = got
                if not (np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])):
                    raise AssertionError(f"{name} merged another map than the one-process merge")
            say(f"round {r}: " + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in times.items() if v and r))
        load_after = _uptime()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med = {k: float(np.median(v)) for k, v in times.items()}
    base = med[f"{counts[0]} workers"]
    cores = os.cpu_count() or 1
    result = dict(benchmark="merge", inputs=args.inputs, bricks_per_input=args.bricks, pool=args.pool,
                  merged_bricks=int(len(want[0])), input_mib=args.inputs * args.bricks * 2048 / 2 ** 20,
                  repeat=args.repeat, nproc=cores, load_before=load_before, load_after=load_after,
                  seconds={k: v for k, v in med.items()}, runs={k: v for k, v in times.items()},
                  other_cores={k: float(np.nanmean(v)) for k, v in others.items()},
                  cpu_s={k: v for k, v in cpus.items()},
                  speedup={f"{n} workers": base / med[f"{n} workers"] for n in counts},
                  ideal={f"{n} workers": float(min(n, cores)) / min(counts[0], cores) for n in counts},
                  bit_identical=True)
    lines = [f"merge of {args.inputs} partial maps x {args.bricks} bricks of 8^3 ({result['input_mib']:.0f} MiB) "
             f"into {result['merged_bricks']} bricks; nproc {cores}; load {load_before} before, {load_after} after; "
             f"median of {args.repeat} interleaved rounds",
             f"{'':14s} {'seconds':>8s} {'vs ' + str(counts[0]) + ' worker':>12s} {'ideal':>6s} {'others (cores)':>15s} "
             f"{'CPU s: coordinator':>19s} {'workers':>8s} {'busiest':>8s}"]
    for name, t in med.items():
        ratio = base / t
        ideal = f"{result['ideal'][name]:.2f}" if name in result["ideal"] else ""
        cpu = np.median(np.array(cpus[name]), axis=0)
        lines.append(f"{name:14s} {t:8.2f} {ratio:11.2f}x {ideal:>6s} {result['other_cores'][name]:15.2f} "
                     f"{cpu[0]:19.2f} {cpu[1:].sum():8.2f} {cpu[1:].max() if len(cpu) > 1 else 0:8.2f}")
    lines += ["every output is the one-process map, bit for bit; 'ideal' is min(workers, nproc): the cores there are;",
              "'others': cores other processes used meanwhile; CPU s: medians, this process and the workers (all, busiest)"]
    return result, lines
