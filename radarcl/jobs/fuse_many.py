"""`radarcl fuse-many`: many recordings fused in parallel on a Dask cluster into one map.

Each input is fused on a worker into its own sparse grid (its own OpenCL context; PoCL limited to
one thread per worker, ``POCL_MAX_PTHREAD_COUNT=1``, so workers do not fight over cores), and
written beside the output as a partial map store, its bricks in key order (never a dense grid:
moving a dense 448 MB grid between processes cost 1-4 s). The partial maps are then merged on
the same workers (``jobs.merge_maps``): a Dask reduction partitioned by brick key, exact integer
sums clamped at the grid's saturation (+-2^30), the merged store's chunks written by the
workers. The result is bit-identical to fusing every input in one process, in any order and on
any number of workers, as long as no voxel saturates on the way (the single-process map clamps
at every write, which at +-2^30 units, a million nats, only a corrupted input reaches). A map of
the detection-statistics model merges its knowledge channel the same way (knowledge and looks
are sums too), with its reading.

With ``--scheduler``, the output's directory must be one the workers see under the same path (a
shared filesystem): they write the partial maps and the merged store there; that is checked
before any fusion.
"""

import contextlib
import os
import tempfile
import time

import numpy as np

from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.io.files import scratch
from radarcl.io.inputs import open_input
from radarcl.jobs.merge_maps import key_ids, merge_stores

SCHEDULER_TIMEOUT_S = 10


def fuse_one(config_values, sensor_toml, path, spec_tuple, partial):
    """On a worker: fuse every frame of ``path`` and write its map, bricks in key order, as the
    map store ``partial``; returns (bricks, frames, seconds)."""
    os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", "1")
    if os.environ["POCL_MAX_PTHREAD_COUNT"] == "1":
        os.environ["POCL_AFFINITY"] = "0"       # one thread per worker: pinned, all would share CPU 0
    from pathlib import Path

    from radarcl import self_test
    from radarcl.cl import Runtime
    from radarcl.config import mapconfig
    from radarcl.gridspec import GridSpec
    from radarcl.maps.store import StoreWriter
    from radarcl.pipeline import Mapping, new_grid

    with tempfile.TemporaryDirectory() as tmp:
        profile = Path(tmp) / "sensor.toml"
        profile.write_text(sensor_toml)
        config = mapconfig.resolve(str(profile), program=config_values)
    self_test.register()                        # as the parent checked the device: its cached verdict answers
    runtime = Runtime()
    source = open_input(config.sensor, path)
    config = config.for_sensor(source.sensor) if source.sensor is not config.sensor else config
    grid = new_grid(runtime, config, GridSpec(*spec_tuple))
    mapping = Mapping.from_config(runtime, config=config, grid=grid)
    start = time.perf_counter()
    mapping.fuse_source(source)
    runtime.queue.finish()
    keys, data = grid.bricks()
    order = np.argsort(key_ids(keys), kind="stable")          # key order: a partition reads contiguous chunks
    if grid.has_knowledge:                                    # the knowledge channel, in the same order
        StoreWriter(partial, grid.spec, reading=config.reading()).save(
            keys[order], data[order], knowledge=grid.knowledge_bricks()[order],
            looks=grid.knowledge_bricks("looks")[order])
    else:
        StoreWriter(partial, grid.spec).save(keys[order], data[order])
    return len(keys), len(source), time.perf_counter() - start


def check_inputs(config, paths):
    """Open every input with the configuration's sensor before any work: a mismatch (another
    sensor's frames, another frame shape) is refused naming the input and both shapes."""
    shapes = {}
    for p in paths:
        source = open_input(config.sensor, p)            # raises naming both shapes
        shapes[str(p)] = (tuple(source.sensor.frame_shape()), len(source))
    if len({s for s, _ in shapes.values()}) > 1:
        raise ConfigError("the inputs have different frame shapes: " + "; ".join(f"{p}: {s}" for p, (s, _) in shapes.items()))
    return shapes


def run(config, paths, out, scheduler=None, workers=2, report=print, client=None):
    """Fuse ``paths`` on a Dask cluster (``client``, a ``scheduler`` address, or a local
    cluster of ``workers`` processes) into ``out`` (.npz or a map store), merged on the same
    workers; returns a dict of timings. The grid is the configuration's."""
    config = mapconfig.as_resolved(config)              # a sensor's name takes its defaults
    if len(set(map(str, paths))) != len(paths):
        raise ConfigError("an input appears twice; each recording is fused once")
    shapes = check_inputs(config, paths)
    spec = config.grid_spec()
    report(f"fusing {len(paths)} inputs ({sum(n for _, n in shapes.values())} frames) of sensor {config.sensor.name} "
           f"into a {' x '.join(map(str, spec.shape))} grid of {spec.voxel_m:g} m")
    own, spill = None, contextlib.ExitStack()
    try:
        # the partial maps and dask's scratch, not the user's cwd; absolute, for workers and later runs alike
        directory = os.path.abspath(spill.enter_context(scratch(out)))
        if client is None:
            import logging

            from dask.distributed import Client, LocalCluster

            for name in ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.worker"):
                logging.getLogger(name).setLevel(logging.ERROR)      # its INFO lines are not ours to show

            os.environ["POCL_MAX_PTHREAD_COUNT"] = "1"          # the workers inherit it
            os.environ["POCL_AFFINITY"] = "0"                   # and each its one thread unpinned
            if scheduler:
                try:
                    client = own = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
                except (ValueError, OSError, TimeoutError, TypeError) as exc:
                    raise ConfigError(f"cannot reach the Dask scheduler {scheduler!r} ({exc}); give its address as "
                                      "tcp://HOST:PORT, or leave --scheduler out for a local cluster") from None
            else:
                import dask

                from radarcl.cl import choose_device

                choose_device()               # the device check once, here, not in every worker at once

                spill.enter_context(dask.config.set({"temporary-directory": directory}))    # for this run only
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                       local_directory=directory)
                client = own = Client(cluster)
        blind = sorted(w for w, seen in client.run(os.path.isdir, directory).items() if not seen)
        if blind:
            raise ConfigError(f"the Dask workers {', '.join(blind)} do not see {directory}: they write the partial "
                              "maps and the merged map beside the output, on a filesystem every worker shares under "
                              "the same path; choose such an --out")
        start = time.perf_counter()
        spec_tuple = (spec.origin_m, spec.voxel_m, spec.shape, spec.brick_z)
        partials = [os.path.join(directory, f"partial_{i}.rcmap") for i in range(len(paths))]
        futures = [client.submit(fuse_one, config.as_dict(), config.sensor.toml(), str(p), spec_tuple, partial,
                                 pure=False) for p, partial in zip(paths, partials)]
        results = client.gather(futures)
        fused = time.perf_counter() - start
        merged = merge_stores(client, partials, out, config.sensor.toml(), config.as_dict(), provenance=paths)
    finally:
        if own is not None:
            cluster = getattr(own, "cluster", None)
            own.close()
            if cluster is not None:
                cluster.close()
        spill.close()
    report(f"wrote {out}: {merged['bricks']} bricks; fused in {fused:.1f} s on the workers (busy "
           f"{sum(r[2] for r in results):.1f} s), merged in {merged['seconds']:.2f} s on "
           f"{len(merged['workers_used'])} workers ({merged['partitions']} partitions by brick key)")
    return dict(inputs=len(paths), bricks=merged["bricks"], fuse_s=fused, merge_s=merged["seconds"],
                worker_busy_s=[r[2] for r in results], partitions=merged["partitions"])
