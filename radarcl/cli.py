"""The `radarcl` command: a table of subcommands (``COMMANDS``), each a module of
``radarcl.commands`` (or ``radarcl.bench``) that owns its options and its run.

Exit status: 0 done, 1 a command that ran but found something wrong (`bench all`: a bench
failed), 2 a radarcl error or a bad argument (one sentence on stderr), 130 Ctrl-C,
143 SIGTERM, 70 an unexpected error (a bug: one sentence, and the traceback with --debug or
RADARCL_DEBUG=1).
"""

import argparse
import logging
import os
import signal
import sys
import threading

from radarcl import bench, self_test
from radarcl.commands import (
    calibrate,
    calibrate_scans,
    config,
    convert,
    demo,
    emulate,
    evaluate_lidar,
    export,
    fit_sensor,
    fuse,
    fuse_many,
    info,
    live,
    navtech,
    navtech_map,
    poses,
    render,
    replay,
    sensors,
    tune,
    view,
)
from radarcl.errors import RadarclError, Terminated

COMMANDS = {
    "info": info, "sensors": sensors, "config": config, "demo": demo, "tune": tune, "calibrate": calibrate,
    "calibrate-scans": calibrate_scans, "fit-sensor": fit_sensor, "fuse": fuse, "fuse-many": fuse_many, "convert": convert, "export": export,
    "navtech": navtech, "navtech-map": navtech_map, "poses": poses, "evaluate-lidar": evaluate_lidar, "live": live, "emulate": emulate, "replay": replay,
    "render": render, "view": view, "bench": bench,
}


def build_parser():
    """The argparse parser of the `radarcl` command: one subparser per entry of ``COMMANDS``."""
    parser = argparse.ArgumentParser(
        prog="radarcl",
        description="FMCW radar to 3D evidence grids (Foessel-Bunting sensor model) with OpenCL kernels. "
                    "The device comes from RADARCL_DEVICE (P:D or a name substring); PoCL's CPU is the fallback.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages (kernel builds...)")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error (or RADARCL_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module in COMMANDS.items():
        p = sub.add_parser(name, help=module.SUMMARY, description=module.DESCRIPTION)
        module.add_arguments(p)
        p.set_defaults(module=module)
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
        raise Terminated()                            # unwinds: temporary files are removed

    if threading_main():
        signal.signal(signal.SIGTERM, terminated)
    self_test.register()            # a device is used only once the pipeline's kernels ran right on it
    try:
        return args.module.run(args)
    except KeyboardInterrupt:
        print("radarcl: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("radarcl: terminated (SIGTERM)", file=sys.stderr)
        return 143
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
    return threading.current_thread() is threading.main_thread()
