"""`radarcl bench store`: saving and loading a map as ``.npz`` against the map store, in the same
run, on the paper's 0.1 m map (the reference scene fused with the tuned configuration, or
``--map``).

Measured, median of ``repeat`` interleaved rounds: a full save and a load of each format, their
sizes, and an incremental save of the store after ``changed`` bricks changed (what a running
fusion rewrites), which an ``.npz`` can only do as a full save.
"""

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from radarcl.maps import store
from radarcl.maps.disk import read


def reference_map(voxel_m=0.1, report=None):
    """(spec, keys, data) of the reference scene fused at ``voxel_m`` with the tuned constants."""
    from radarcl.cl import Runtime
    from radarcl.config.presets import paper_config
    from radarcl.config.presets import EVALUATION_SEED
    from radarcl.evaluation.tuning import TUNED
    from radarcl.pipeline import Mapping
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_scene

    (report or (lambda _: None))(f"simulating and fusing the reference scene at {voxel_m} m ...")
    obs = observe(paper_scene(), PAPER_TILTS_DEG, seed=EVALUATION_SEED)
    mapping = Mapping.from_config(Runtime(), config=paper_config(voxel_m, TUNED))
    for frame, pose in zip(obs.samples, obs.poses):
        mapping.fuse(frame, pose)
    keys, data = mapping.grid.bricks()
    return mapping.grid.spec, keys, data


def _size(path):
    path = Path(path)
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) if path.is_dir() else path.stat().st_size


def run(map_path=None, repeat=3, changed=4096, report=None):
    """Measure; returns the --json dict."""
    spec, keys, data = read(map_path) if map_path else reference_map(report=report)
    rng = np.random.default_rng(0)
    rows = rng.choice(len(keys), min(changed, len(keys)), replace=False)
    work = Path(tempfile.mkdtemp(prefix="radarcl-bench-store-"))
    try:
        npz, st = work / "map.npz", work / "map.rcmap"
        times = {k: [] for k in ("npz_save", "npz_load", "store_save", "store_load", "store_incremental")}
        for _ in range(repeat):
            start = time.perf_counter()
            with open(npz, "wb") as f:
                np.savez_compressed(f, version=1, origin_m=np.asarray(spec.origin_m), voxel_m=spec.voxel_m,
                                    shape=np.asarray(spec.shape), keys=keys, data=data)
            times["npz_save"].append(time.perf_counter() - start)
            start = time.perf_counter()
            read(npz)
            times["npz_load"].append(time.perf_counter() - start)
            shutil.rmtree(st, ignore_errors=True)
            start = time.perf_counter()
            writer = store.StoreWriter(st, spec)
            writer.save(keys, data)
            times["store_save"].append(time.perf_counter() - start)
            start = time.perf_counter()
            read(st)
            times["store_load"].append(time.perf_counter() - start)
            changed_data = data.copy()
            changed_data[rows, 0, 0, 0] += 1
            start = time.perf_counter()
            written = writer.save(keys, changed_data)
            times["store_incremental"].append(time.perf_counter() - start)
        med = {k: float(np.median(v)) for k, v in times.items()}
        return dict(benchmark="store", bricks=int(len(keys)), voxel_m=spec.voxel_m, grid=list(spec.shape),
                    raw_mib=data.nbytes / 2 ** 20, repeat=repeat, changed_bricks=int(written),
                    npz_mib=_size(npz) / 2 ** 20, store_mib=_size(st) / 2 ** 20,
                    **{f"{k}_s": v for k, v in med.items()},
                    save_ratio=med["npz_save"] / med["store_save"], load_ratio=med["npz_load"] / med["store_load"],
                    incremental_ratio=med["npz_save"] / med["store_incremental"])
    finally:
        shutil.rmtree(work, ignore_errors=True)


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    return [f"map: {r['bricks']} bricks ({r['raw_mib']:.0f} MiB of int32), {r['grid']} at {r['voxel_m']} m; "
            f"median of {r['repeat']} interleaved rounds",
            f"  npz   save {r['npz_save_s']:7.2f} s  load {r['npz_load_s']:6.2f} s  size {r['npz_mib']:7.1f} MiB",
            f"  store save {r['store_save_s']:7.2f} s  load {r['store_load_s']:6.2f} s  size {r['store_mib']:7.1f} MiB",
            f"  store, {r['changed_bricks']} changed bricks: {r['store_incremental_s']:.3f} s "
            f"(npz can only save whole: {r['npz_save_s']:.2f} s)",
            f"  ratios npz / store: save {r['save_ratio']:.1f}x, load {r['load_ratio']:.1f}x, "
            f"incremental save {r['incremental_ratio']:.1f}x"]


def add_arguments(parser):
    """`radarcl bench store` options."""
    from radarcl.commands.options import bounded_int

    parser.add_argument("--map", default=None, help="time this map instead of the reference scene's at 0.1 m")
    parser.add_argument("--repeat", type=bounded_int(1, 50), default=3, help="rounds (default: %(default)s)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(args.map, repeat=args.repeat, report=say)
    return result, format_table(result)
