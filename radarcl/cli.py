"""The `radarcl` command: argument parsing only; each subcommand is a small function that calls a
library or job module. Subcommands, and the benchmarks under `radarcl bench`, own their options.

Exit status: 0 done, 2 a radarcl error or a bad argument (one sentence on stderr), 130 Ctrl-C,
143 SIGTERM, 70 an unexpected error (a bug: one sentence, and the traceback with --debug or
RADARCL_DEBUG=1).
"""

import argparse
import logging
import os
import signal
import sys

from radarcl import commands
from radarcl.commands import DATA_ENV
from radarcl.errors import RadarclError


# -- argument types and shared option groups ------------------------------------------------------------
def positive_int(text):
    """argparse type: an integer >= 1."""
    return bounded_int(1, None)(text)


def bounded_int(lo, hi):
    """argparse type: an integer in [lo, hi] (hi None: no upper bound)."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must lie in [{lo}, {hi if hi is not None else 'inf'}], got {value}")
        return value
    return parse


def positive_float(text):
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return value


def add_output(p, flag, default, what):
    """``flag`` (an output file; required when ``default`` is None) and --force."""
    if default is None:
        p.add_argument(flag, required=True, help=f"{what}; an existing file is kept unless --force")
    else:
        p.add_argument(flag, default=default, help=f"{what} (default: %(default)s); an existing file is kept unless "
                                                   "--force")
    if not any(a.dest == "force" for a in p._actions):
        p.add_argument("--force", action="store_true", help="replace existing output files")


def add_config(p, sensor_default=None):
    """--sensor, --config, --set, --voxel: the map configuration (radarcl.mapconfig)."""
    from radarcl import sensors

    default = sensor_default or sensors.DEFAULT_SENSOR
    p.add_argument("--sensor", default=None, metavar="NAME|FILE",
                   help=f"sensor profile: {', '.join(sensors.builtin_names())} or a TOML file "
                        f"(default: the --config file's sensor, else {default}; `radarcl sensors` lists them)")
    p.add_argument("--config", default=None, metavar="FILE", help="map configuration file (TOML), e.g. from "
                                                                  "`radarcl tune --save`")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="set one configuration value, e.g. --set cfar.guard_m=0.6 (repeatable; "
                        "`radarcl config show` lists the keys)")
    p.add_argument("--voxel", type=positive_float, default=None, help="voxel edge [m] (= --set grid.voxel_m=...)")
    p.set_defaults(sensor_default=default)


# -- the parser ----------------------------------------------------------------------------------------------
def _view_options(p, follow=False):
    from radarcl.viewer.modes import COLORMAPS, MODES

    p.add_argument("map", nargs="?" if follow else None,
                   help="a map file or store (radarcl demo's map.npz)" + (" (or --follow)" if follow else ""))
    p.add_argument("--mode", choices=list(MODES), default="occupancy",
                   help="; ".join(f"{m.name}: {m.description}" for m in MODES.values()) + " (default: %(default)s)")
    p.add_argument("--camera", default="iso",
                   help="iso, top, front, side or AZ,EL[,DIST[,X,Y,Z]] in degrees and metres (default: %(default)s)")
    p.add_argument("--size", type=bounded_int(1, 16384), nargs=2, default=[1024, 768], metavar=("W", "H"),
                   help="pixels, 1-16384 (default: %(default)s)")
    p.add_argument("--threshold", type=float, default=1.0,
                   help="occupancy threshold [nat]: the isosurface and the low end of the colours (default: %(default)s)")
    p.add_argument("--lo", type=float, default=None, help="low end of the transfer function [nat] (default: --threshold)")
    p.add_argument("--hi", type=float, default=None,
                   help="high end [nat] (default: the 99.9th percentile of the values above --lo)")
    p.add_argument("--gamma", type=positive_float, default=1.0, help="transfer-function gamma (default: %(default)s)")
    p.add_argument("--colormap", choices=COLORMAPS, default="inferno", help="(default: %(default)s)")
    p.add_argument("--step", type=positive_float, default=1.0, help="ray-march step [voxels] (default: %(default)s)")


BENCHES = {
    "range-fft": ("radarcl.bench.range_fft", "window + FFT + magnitude of a paper frame vs scipy.fft, same run"),
    "cfar": ("radarcl.bench.cfar", "CFAR + eq. 12 of a paper frame vs vectorised numpy, same run"),
    "fusion": ("radarcl.bench.fusion", "one paper frame into the 0.1 m grid vs the float64 oracle and the "
                                       "memory floor, same run"),
    "quality": ("radarcl.bench.quality", "map error against run time on the reference scene (zero padding, beam "
                                         "model, voxel, CFAR kind) on one fixed voxel set, with three baselines"),
    "heldout-scans": ("radarcl.bench.heldout_scans", "real data without lidar: a map of the even Navtech scans "
                                                     "predicts the CFAR detections of the odd ones, vs raw intensity"),
    "scenes": ("radarcl.bench.scenes", "the maps of generated scenes (held-out or training split) scored on their "
                                       "visibility truth, beside the three baselines"),
    "store": ("radarcl.bench.store", "saving and loading the paper's 0.1 m map as .npz vs the map store, with an "
                                     "incremental save, same run"),
    "live": ("radarcl.bench.live", "the reference scene streamed beam by beam over a pty into the live engine: "
                                   "throughput, latency, faults, vs waiting for whole frames"),
    "viewer": ("radarcl.bench.viewer", "the paper's full grid rendered at 512 x 512 through EGL vs a plain ray "
                                       "march, same run"),
}


def build_parser():
    """The argparse parser of the `radarcl` command."""
    import importlib

    parser = argparse.ArgumentParser(
        prog="radarcl",
        description="FMCW radar to 3D evidence grids (Foessel-Bunting sensor model) with OpenCL kernels. "
                    "The device comes from RADARCL_DEVICE (P:D or a name substring); PoCL's CPU is the fallback.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages (kernel builds...)")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error (or RADARCL_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, func, summary, description=None):
        p = sub.add_parser(name, help=summary, description=description or summary[0].upper() + summary[1:] + ".")
        p.set_defaults(func=func)
        return p

    command("info", commands.cmd_info, "list OpenCL platforms and devices and what the kernels need")

    p = command("sensors", commands.cmd_sensors, "list the built-in sensor profiles, or print one",
                "Lists the built-in sensor profiles (radarcl/profiles/*.toml), or prints one as TOML: copy it to "
                "describe your own radar and pass the file to --sensor.")
    p.add_argument("name", nargs="?", help="a profile name or file to print")

    p = command("config", commands.cmd_config, "show or save the effective map configuration",
                "`config show` prints every configuration key with its value and where it came from (radarcl "
                "default, the sensor's geometry, its profile, the --config file, a flag), and how the windows in "
                "metres become bins. `config save FILE` writes it as a file for --config.")
    p.add_argument("action", choices=["show", "save"])
    p.add_argument("file", nargs="?", help="config save: the file to write")
    p.add_argument("--force", action="store_true", help="config save: replace an existing file")
    add_config(p)

    p = command("demo", commands.cmd_demo, "the main job: the paper's reference scene simulated, fused at 0.1 m, scored "
                                  "on its visibility truth beside three baselines, plotted",
                "Simulates the outdoor scene of the paper's §4.3 (3,840 observations), fuses it with the paper's "
                "constants, the tuned ones and the calibrated occlusion-aware interpreter (radarcl calibrate), prints "
                "metrics and timings and writes the recording, one of the maps (--show), plots, summary.json and "
                "report.html to --out.")
    p.add_argument("--show", choices=("tuned", "calibrated", "paper constants"), default="tuned",
                   help="the map written, rendered and plotted (default: %(default)s; all three are scored)")
    p.add_argument("--out", default="out/demo", help="output directory (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="simulation seed (default: %(default)s, the evaluation seed)")
    p.add_argument("--quick", action="store_true", help="0.4 m voxels instead of the paper's 0.1 m (CI-sized)")
    p.add_argument("--replay", default=None, help="replay a recording (reference_scene.npz) instead of simulating")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")

    p = command("tune", commands.cmd_tune, "the documented search for the CFAR settings and the eq. 12 constants on the "
                                  "reference scene; --save writes the choice as a configuration file",
                "Runs the coordinate search of radarcl/evaluation/tuning.py (CFAR kind and P_fa, wide-pulse width, "
                "E_h and E_l, common scale) on the reference scene simulated with the tuning seed, and with --save "
                "writes the chosen configuration for --config.")
    p.add_argument("--seed", type=int, default=2, help="simulation seed (default: %(default)s, the tuning seed)")
    p.add_argument("--replay", default=None, help="tune on a recording of the reference scene instead of simulating")
    p.add_argument("--voxel", type=positive_float, default=0.2, help="voxel edge [m] (default: %(default)s)")
    p.add_argument("--save", default=None, metavar="FILE", help="write the chosen configuration to FILE")
    p.add_argument("--force", action="store_true", help="replace an existing --save file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")

    p = command("calibrate", commands.cmd_calibrate, "fit the interpreter's constants by maximum likelihood on the "
                                                   "training scenes; --save writes them as a configuration file",
                "Simulates the generated training scenes (radarcl/scene/generator.py), fits the eq. 12 constants "
                "(or the occlusion-aware interpreter's) by logistic regression of the visibility truth on the fused "
                "per-bin features, chooses the CFAR settings and the surface test by the log-likelihood on "
                "validation scenes, prints the constants with standard errors and writes a configuration file "
                "and a reliability diagram. The held-out scenes are never used (radarcl bench scenes reports on them).")
    p.add_argument("--model", choices=("occlusion", "paper"), default="occlusion",
                   help="the interpreter to calibrate (default: %(default)s)")
    p.add_argument("--voxel", type=positive_float, default=0.2, help="voxel edge [m] (default: %(default)s)")
    p.add_argument("--seeds", type=int, nargs="+", default=None,
                   help="training scene seeds (default: generator.TRAIN_SEEDS; the last third validates)")
    p.add_argument("--unknown-behind", action="store_true",
                   help="hold E_l at 0: the map stays unknown behind the first surface (shadows are unknowable)")
    p.add_argument("--save", default=None, metavar="FILE", help="write the calibrated configuration to FILE")
    p.add_argument("--figure", default=None, metavar="PNG", help="write the before/after reliability diagram")
    p.add_argument("--json", default=None, metavar="FILE", help="write the whole result as JSON")
    p.add_argument("--force", action="store_true", help="replace existing output files")

    p = command("calibrate-scans", commands.cmd_calibrate_scans,
                "fit the interpreter's constants on a real radar's own polar scans: a map of some scans predicts "
                "the detections of the others",
                "Splits the sequence in time. On the first part, a map of the even scans (each interpreter feature "
                "fused as its own channel) predicts the CFAR detections of the odd scans (the sensor profile's own "
                "detector); a logistic fit of those detections gives the constants, and the map's CFAR and surface "
                "test are chosen by its likelihood. On the last part, never seen by the fit, it compares the profile's "
                "constants, the calibrated ones and the baselines on the same held-out bins, and writes a "
                "configuration file for --config.")
    p.add_argument("data", nargs="?", default=None,
                   help="a directory of radar/*.png and gt/radar_odometry.csv (default: the shared Oxford sequence)")
    add_config(p, "navtech-cts350x")
    p.add_argument("--model", choices=("occlusion", "paper"), default="occlusion",
                   help="the interpreter to calibrate (default: %(default)s)")
    p.add_argument("--save", default=None, metavar="FILE", help="write the calibrated configuration to FILE")
    p.add_argument("--figure", default=None, metavar="PNG", help="write the before/after reliability diagram")
    p.add_argument("--json", default=None, metavar="FILE", help="write the whole result as JSON")
    p.add_argument("--force", action="store_true", help="replace existing output files")

    p = command("fuse", commands.cmd_fuse, "fuse any sensor's frames into a map file (rewritten every --every frames for "
                                  "radarcl view --live)",
                "Reads INPUT as the sensor's reader says (a radarcl recording; a directory of polar PNG scans, "
                "with radar_odometry.csv beside them or in ../gt; a TI capture .npy/.txt), fuses every frame with "
                "the map configuration and writes the map file.")
    p.add_argument("input", help="a recording (.npz), a directory of polar scans, or a TI capture")
    add_output(p, "--out", "map.npz", "map to write: an .npz file, or any other name for a map store directory "
                                      "(zarr; --every then writes only the changed bricks)")
    add_config(p)
    p.add_argument("--odometry", default=None, help="polar scans: the radar_odometry.csv (default: found beside them)")
    p.add_argument("--every", type=positive_int, default=None, help="rewrite the map file every N frames")
    p.add_argument("--report", default=None, metavar="FILE",
                   help="the run's HTML page: numbers, the map from above, the viewer's render, the configuration "
                        "(default: the map's name with .html, e.g. map.html)")
    p.add_argument("--no-report", action="store_true", help="write no HTML page")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")

    p = command("fuse-many", commands.cmd_fuse_many, "fuse many recordings in parallel on a Dask cluster into one map",
                "Fuses each input on a Dask worker (a LocalCluster by default, any scheduler address for a real "
                "cluster), each worker with its own OpenCL context, and merges the maps brick by brick with exact "
                "integer sums: the same map as fusing every input in one process, in any order.")
    p.add_argument("inputs", nargs="+", help="recordings (or anything fuse reads) of one sensor")
    add_output(p, "--out", "map.rcmap", "map to write (.npz, or a map store)")
    add_config(p)
    p.add_argument("--scheduler", default=None, help="a Dask scheduler address (default: a local cluster)")
    p.add_argument("--workers", type=positive_int, default=2, help="local cluster workers (default: %(default)s)")

    p = command("convert", commands.cmd_convert, "copy a map between the .npz file and the map store",
                "Reads an .npz map or a map store (a directory: zarr v3, versioned, incremental saves) and writes "
                "the other: the target's name decides (.npz, or anything else for a store).")
    p.add_argument("source", help="a map (.npz) or map store")
    p.add_argument("target", help="the map to write")
    p.add_argument("--force", action="store_true", help="replace an existing target")

    p = command("export", commands.cmd_export, "write a map for other tools: OctoMap, PLY, VTK, a ROS costmap or bag",
                "octomap: .bt (occupied/free) or .ot (log-odds) read by OctoMap and octovis; ply: the voxels above "
                "--threshold with log_odds and probability; mesh: the isosurface at --threshold as a PLY mesh; "
                "vti: the dense log-odds as VTK image data for ParaView; costmap: a ROS map_server PGM + YAML "
                "projected over --band; rosbag: a ROS 2 bag with a PointCloud2 and an OccupancyGrid.")
    p.add_argument("map", help="a map (.npz) or map store")
    p.add_argument("--to", required=True, choices=["octomap", "ply", "mesh", "vti", "costmap", "rosbag"])
    add_output(p, "--out", None, "file to write (a directory for rosbag)")
    p.add_argument("--threshold", type=float, default=None,
                   help="[nat]: occupied above it (default 1; octomap: voxels with |log-odds| >= it, default 0)")
    p.add_argument("--band", type=float, nargs=2, default=None, metavar=("Z_MIN", "Z_MAX"),
                   help="height band [m] for costmap, rosbag's grid, mesh and vti (default: the whole grid)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")

    p = command("navtech", commands.cmd_navtech, "CFAR and the eq. 12 interpreter on one polar scan; plot one azimuth "
                                        "like the paper's Fig. 10",
                "Reads a polar PNG scan (1 dB per level), runs CFAR and eq. 12 on every azimuth with the kernels, "
                "prints what was found and writes a Fig. 10 style PNG of one azimuth.")
    p.add_argument("scan", help="a <unix_us>.png scan")
    p.add_argument("--azimuth", type=int, default=0, help="azimuth index to plot (default: %(default)s)")
    add_output(p, "--out", "navtech_fig10.png", "PNG to write")
    add_config(p, "navtech-cts350x")

    p = command("navtech-map", commands.cmd_navtech_map, "fuse polar scans with their odometry into a map; check the "
                                                "geometry by half-map consistency",
                "Fuses the first and second half of the scans into two maps and prints how well they agree with "
                "the true poses and with the second half moved 1 m, turned 2 deg, without motion within a scan, "
                "with the azimuths or the odometry reversed; prints the detector's pulse statistics; fuses all "
                "scans into a top-down PNG and, with --map, a map file.")
    p.add_argument("data", nargs="?", default=None,
                   help=f"directory with radar/*.png and gt/radar_odometry.csv (default: the Oxford scans in "
                        f"${DATA_ENV} or ../shared/data beside the source)")
    add_output(p, "--out", "navtech_map.png", "PNG to write")
    p.add_argument("--map", default=None, help="also write the fused map file (npz)")
    p.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    add_config(p, "navtech-cts350x")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")

    from radarcl import stream_commands

    stream_commands.add_parsers(command, add_output, add_config, positive_float, positive_int)

    p = command("render", commands.cmd_render, "render a map file to a PNG through EGL (no display needed)",
                "Ray-marches the map as a 3D texture (or draws the Fig. 11 spheres) offscreen through EGL and "
                "writes a PNG with a colour bar.")
    _view_options(p)
    add_output(p, "--out", "view.png", "PNG to write")
    p.add_argument("--no-colorbar", action="store_true", help="leave the colour bar out")
    p.add_argument("--no-guides", action="store_true", help="leave the ground grid, axes and sensor poses out")

    p = command("view", commands.cmd_view, "the interactive volume viewer (press h in the window for the keys)",
                "Opens a window on the map: drag to orbit, right-drag or shift-drag to pan, wheel to zoom; 1-5 "
                "modes (5: free space too), t/T threshold, x/y/z slices, c colormap, a guides, s screenshot, "
                "h help. --live follows a map file that a running fusion rewrites.")
    _view_options(p, follow=True)
    p.add_argument("--live", action="store_true", help="watch MAP and upload the bricks that changed whenever it is "
                                                       "rewritten")
    p.add_argument("--follow", default=None, metavar="HOST:PORT",
                   help="show the map a running `radarcl live --serve` fuses, brick by brick as it changes")
    p.add_argument("--window", default="pyglet", help="moderngl-window backend: pyglet, glfw, headless "
                                                      "(default: %(default)s)")
    p.add_argument("--screenshot", default=None, help="save the last frame to this PNG when the window closes")
    p.add_argument("--force", action="store_true", help="replace an existing screenshot")
    p.add_argument("--frames", type=positive_int, default=None, help="close after this many frames (scripts, tests)")
    p.add_argument("--keys", default="", help="keys pressed one per frame at the start, e.g. '2t' (scripts, tests)")

    p = command("bench", commands.cmd_bench, "benchmarks, each against a baseline measured in the same run",
                "Each benchmark prints its figures and their ratio to a baseline measured in the same run "
                "(interleaved, medians). `radarcl bench NAME --help` for its options.")
    benches = p.add_subparsers(dest="bench", required=True, metavar="NAME")
    for name, (module_name, summary) in BENCHES.items():
        module = importlib.import_module(module_name)
        b = benches.add_parser(name, help=summary, description=summary[0].upper() + summary[1:] + ".")
        b.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
        module.add_arguments(b)
        b.set_defaults(module=module)
    return parser


def main(argv=None):
    """Entry point; returns the exit status (see the module docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = args.debug or os.environ.get("RADARCL_DEBUG", "") not in ("", "0")
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    previous = signal.getsignal(signal.SIGTERM)

    def terminated(signum, frame):
        raise SystemExit(143)                         # unwinds: temporary files are removed

    if threading_main():
        signal.signal(signal.SIGTERM, terminated)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("radarcl: interrupted", file=sys.stderr)
        return 130
    except RadarclError as exc:
        if debug:
            raise
        print(f"radarcl: error: {exc}", file=sys.stderr)
        return 2
    except (OSError, MemoryError) as exc:
        if debug:
            raise
        what = exc.strerror if isinstance(exc, OSError) and exc.strerror else (str(exc) or type(exc).__name__)
        where = f" ({exc.filename})" if isinstance(exc, OSError) and exc.filename else ""
        print(f"radarcl: error: {what}{where}", file=sys.stderr)
        return 2
    except Exception as exc:                          # a bug: say so in one line
        if debug:
            raise
        print(f"radarcl: unexpected error (a bug, please report it with --debug's traceback): "
              f"{type(exc).__name__}: {exc}", file=sys.stderr)
        return 70
    finally:
        if threading_main():
            signal.signal(signal.SIGTERM, previous)


def threading_main():
    """True in the main thread (only there may signal handlers be set)."""
    import threading

    return threading.current_thread() is threading.main_thread()
