"""`radarcl fuse-many`: many recordings fused in parallel on a Dask cluster into one map.

Each input is fused on a worker into its own sparse grid (its own OpenCL context; PoCL limited to
one thread per worker, ``POCL_MAX_PTHREAD_COUNT=1``, so workers do not fight over cores), and
only its bricks travel back (keys and int32 values, never a dense grid: moving a dense 448 MB
grid between processes cost 1-4 s). The maps merge brick by brick with exact integer sums,
clamped at the grid's saturation (+-2^30), so the result is bit-identical to fusing every input
in one process, in any order and on any number of workers, as long as no voxel saturates on
the way (the single-process map clamps at every write, which at +-2^30 units, a million nats,
only a corrupted input reaches).

Cost model of the merge: the coordinator adds every worker's bricks, O(bricks x inputs); the
fusion itself scales with the workers until the inputs run out.
"""

import contextlib
import os
import tempfile
import time

import numpy as np

from radarcl.errors import ConfigError
from radarcl.grid import GRID_LIMIT
from radarcl.io.files import scratch
from radarcl.io.inputs import open_input

SCHEDULER_TIMEOUT_S = 10


def fuse_one(config_values, sensor_toml, path, spec_tuple):
    """On a worker: fuse every frame of ``path``; returns (keys, data, frames, seconds)."""
    os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", "1")
    if os.environ["POCL_MAX_PTHREAD_COUNT"] == "1":
        os.environ["POCL_AFFINITY"] = "0"       # one thread per worker: pinned, all would share CPU 0
    from pathlib import Path

    from radarcl.cl import Runtime
    from radarcl.config import mapconfig
    from radarcl.grid import EvidenceGrid, GridSpec
    from radarcl.pipeline import Mapping

    with tempfile.TemporaryDirectory() as tmp:
        profile = Path(tmp) / "sensor.toml"
        profile.write_text(sensor_toml)
        config = mapconfig.resolve(str(profile), program=config_values)
    runtime = Runtime()
    source = open_input(config.sensor, path)
    config = config.for_sensor(source.sensor) if source.sensor is not config.sensor else config
    grid = EvidenceGrid(runtime, GridSpec(*spec_tuple))
    mapping = Mapping.from_config(runtime, config=config, grid=grid)
    start = time.perf_counter()
    mapping.fuse_source(source)
    runtime.queue.finish()
    keys, data = grid.bricks()
    return keys, data, len(source), time.perf_counter() - start


def merge(parts):
    """Sum sparse maps [(keys, data), ...] brick by brick (int64), clamped at +-GRID_LIMIT:
    (keys sorted by (bz, by, bx), data int32)."""
    keys = np.concatenate([k for k, _ in parts]) if parts else np.zeros((0, 3), np.int32)
    if not len(keys):
        return keys.astype(np.int32), np.zeros((0, *(parts[0][1].shape[1:] if parts else (8, 8, 8))), np.int32)
    k = keys.astype(np.int64)
    ids = (k[:, 2] << 42) | (k[:, 1] << 21) | k[:, 0]
    unique, inverse = np.unique(ids, return_inverse=True)
    total = np.zeros((len(unique), *parts[0][1].shape[1:]), np.int64)
    start = 0
    for _, d in parts:                  # a part's keys are unique: a plain indexed add is exact
        rows = inverse[start:start + len(d)]
        if len(np.unique(rows)) != len(rows):
            raise ConfigError("a map to merge lists a brick twice")
        total[rows] += d
        start += len(d)
    mask = (1 << 21) - 1
    out_keys = np.stack([unique & mask, (unique >> 21) & mask, unique >> 42], axis=1).astype(np.int32)
    return out_keys, np.clip(total, -GRID_LIMIT, GRID_LIMIT).astype(np.int32)


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
    cluster of ``workers`` processes) into ``out`` (.npz or a map store); returns a dict of
    timings. The grid is the configuration's."""
    from radarcl.maps.disk import MapSaver

    if len(set(map(str, paths))) != len(paths):
        raise ConfigError("an input appears twice; each recording is fused once")
    if config["interpret.model"] == "detstats":
        raise ConfigError("fuse-many merges the maps' sums only: the detection-statistics model's knowledge channel "
                          "is not merged yet; fuse such a recording with `radarcl fuse`")
    shapes = check_inputs(config, paths)
    spec = config.grid_spec()
    report(f"fusing {len(paths)} inputs ({sum(n for _, n in shapes.values())} frames) of sensor {config.sensor.name} "
           f"into a {' x '.join(map(str, spec.shape))} grid of {spec.voxel_m:g} m")
    own, spill = None, contextlib.ExitStack()
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

            directory = str(spill.enter_context(scratch(out)))        # dask's scratch space, not the user's cwd
            dask.config.set({"temporary-directory": directory})
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                   local_directory=directory)
            client = own = Client(cluster)
    try:
        start = time.perf_counter()
        spec_tuple = (spec.origin_m, spec.voxel_m, spec.shape, spec.brick_z)
        futures = [client.submit(fuse_one, config.as_dict(), config.sensor.toml(), str(p), spec_tuple, pure=False)
                   for p in paths]
        results = client.gather(futures)
        fused = time.perf_counter() - start
        keys, data = merge([(k, d) for k, d, _, _ in results])
        merged = time.perf_counter() - start - fused
    finally:
        if own is not None:
            cluster = getattr(own, "cluster", None)
            own.close()
            if cluster is not None:
                cluster.close()
        spill.close()

    class _Snapshot:                                        # what MapSaver reads of a grid
        def __init__(self):
            self.spec = spec

        def bricks(self):
            return keys, data

        def save(self, path, poses=None):
            from radarcl.maps import npz

            npz.write(path, spec, keys, data, poses)

    MapSaver(out, config.sensor.toml(), config.as_dict(), paths)(_Snapshot())
    report(f"wrote {out}: {len(keys)} bricks; fused in {fused:.1f} s on the workers (busy "
           f"{sum(r[3] for r in results):.1f} s), merged in {merged:.2f} s")
    return dict(inputs=len(paths), bricks=len(keys), fuse_s=fused, merge_s=merged,
                worker_busy_s=[r[3] for r in results])
