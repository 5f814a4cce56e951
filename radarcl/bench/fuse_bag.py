"""`radarcl bench fuse-bag`: the 11 Oxford scans fused from a ROS 2 bag (sqlite3 and MCAP
storage, one sensor_msgs/Image per scan, written here with rosbags) against the same scans fused
from their PNG folder, interleaved in one run: open the input, fuse every frame, wait for the
device. The goal: a bag costs no more than 10 % over the files."""

import tempfile
from pathlib import Path

import numpy as np

from radarcl.bench.timing import interleaved_medians

PROFILE = "navtech-cts350x"


def write_bag(path, scan_dir, storage):
    """A rosbag2 at ``path`` holding each PNG of ``scan_dir`` as a mono8 sensor_msgs/Image on
    /radar/polar, stamped with its file name's time [us]."""
    from PIL import Image
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        c = w.add_connection("/radar/polar", "sensor_msgs/msg/Image", typestore=ts)
        for p in sorted(Path(scan_dir).glob("*.png")):
            px = np.asarray(Image.open(p))
            t = int(p.stem) * 1000
            header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=t // 10 ** 9,
                                                                                     nanosec=t % 10 ** 9),
                                              frame_id="radar")
            msg = T["sensor_msgs/msg/Image"](header=header, height=px.shape[0], width=px.shape[1], encoding="mono8",
                                             is_bigendian=0, step=px.shape[1], data=px.reshape(-1).copy())
            w.write(c, t, ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))
    return Path(path)


def run(runtime, data_root, repeat=6):
    """Scans per second of each input and its ratio to the files'; returns the --json dict."""
    from radarcl.config import mapconfig
    from radarcl.io.inputs import open_input
    from radarcl.pipeline import Mapping

    scans = data_root / "navtech_oxford" / "radar"
    odometry = data_root / "navtech_oxford" / "gt" / "radar_odometry.csv"
    config = mapconfig.resolve(PROFILE)
    with tempfile.TemporaryDirectory(prefix="radarcl-bench-") as tmp:
        inputs = {"files": scans, "bag_sqlite3": write_bag(Path(tmp) / "sqlite3", scans, "sqlite3"),
                  "bag_mcap": write_bag(Path(tmp) / "mcap", scans, "mcap")}
        counted = {}

        def fuse(path):
            def go():
                source = open_input(config.sensor, path, poses=odometry)
                cfg = config.for_sensor(source.sensor) if source.sensor is not config.sensor else config
                mapping = Mapping.from_config(runtime, config=cfg)
                mapping.fuse_source(source)
                runtime.queue.finish()
                counted[path] = len(source)
            return go

        load = {}
        t = interleaved_medians({k: fuse(v) for k, v in inputs.items()}, repeat, block=1, warmup=1, load=load)
    n = counted[scans]
    return dict(benchmark="fuse-bag", repeat=repeat, scans=n, device=runtime.name,
                scans_per_s={k: n / v for k, v in t.items()},
                seconds={k: v for k, v in t.items()},
                bag_vs_files={k: t[k] / t["files"] for k in t if k != "files"}, load=load,
                goal="bag_vs_files <= 1.10 (a bag fuses within 10 % of the files' time)")


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    lines = [f"{result['scans']} Oxford scans opened and fused on {result['device']}, median of {result['repeat']} "
             "interleaved runs per input",
             f"{'input':>12} {'s per run':>10} {'scans/s':>8} {'vs files':>9}"]
    for k, s in result["seconds"].items():
        ratio = "1.00" if k == "files" else f"{result['bag_vs_files'][k]:.2f}"
        lines.append(f"{k:>12} {s:>10.2f} {result['scans_per_s'][k]:>8.1f} {ratio:>9}")
    lines.append(f"goal: {result['goal']}")
    return lines


def add_arguments(parser):
    """`radarcl bench fuse-bag` options."""
    from radarcl.commands.options import positive_int

    parser.add_argument("--repeat", type=positive_int, default=6, help="timed runs per input (default: %(default)s)")
    parser.add_argument("--data", default=None, help="the shared data directory (default: $RADARCL_DATA or "
                                                     "../shared/data beside the source)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.commands.options import default_data

    root = Path(args.data) if args.data else default_data("")
    result = run(runtime(), root, repeat=args.repeat)
    return result, format_table(result)
