"""What the commands share: argument types, the map configuration's options and its
resolution, output options, the shared data, the progress bar and the device."""

import argparse
import os
import sys
from pathlib import Path

from radarcl.config import mapconfig, sensors
from radarcl.errors import ConfigError

DATA_ENV = "RADARCL_DATA"


# -- argument types ------------------------------------------------------------------------------------
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


# -- option groups -------------------------------------------------------------------------------------
def add_output(p, flag, default, what):
    """``flag`` (an output file; required when ``default`` is None) and --force."""
    if default is None:
        p.add_argument(flag, required=True, help=f"{what}; an existing file is kept unless --force")
    else:
        p.add_argument(flag, default=default, help=f"{what} (default: %(default)s); an existing file is kept unless "
                                                   "--force")
    if not any(a.dest == "force" for a in p._actions):
        p.add_argument("--force", action="store_true", help="replace existing output files")


def add_config(p, sensor_default=None, by_layout=False):
    """--sensor, --config, --set, --voxel: the map configuration (``config.mapconfig``);
    ``by_layout``: a directory INPUT picks the sensor its layout says (``default_sensor``)."""
    default = sensor_default or sensors.DEFAULT_SENSOR
    layout = "for a recording's directory (Oxford, RADIATE, Boreas, MulRan) the profile its layout says, " if by_layout else ""
    p.add_argument("--sensor", default=None, metavar="NAME|FILE",
                   help=f"sensor profile: {', '.join(sensors.builtin_names())} or a TOML file "
                        f"(default: the --config file's sensor, else {layout}else {default}; `radarcl sensors` lists "
                        "them)")
    p.add_argument("--config", default=None, metavar="FILE", help="map configuration file (TOML), e.g. from "
                                                                  "`radarcl tune --save`")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="set one configuration value, e.g. --set cfar.guard_m=0.6 (repeatable; "
                        "`radarcl config show` lists the keys)")
    p.add_argument("--voxel", type=positive_float, default=None, help="voxel edge [m] (= --set grid.voxel_m=...)")
    p.add_argument("--force-sensor", action="store_true",
                   help="use a --config made for another sensor: keep its constants, derive its windows, range and "
                        "grid for this sensor (with a warning)")
    p.set_defaults(sensor_default=default, sensor_by_layout=by_layout)


def resolve_config(args, program=None):
    """The ``mapconfig.Resolved`` the options of ``add_config`` describe; its notes (a forced
    sensor, a clipped range) go to stderr."""
    flags = dict(mapconfig.parse_flag(text) for text in args.set)
    if args.voxel is not None:
        flags["grid.voxel_m"] = args.voxel
    sensor = args.sensor if args.sensor is not None or args.config is not None else default_sensor(args)
    config = mapconfig.resolve(sensor, args.config, flags, program, force_sensor=getattr(args, "force_sensor", False))
    say_notes(config.notes)
    return config


def default_sensor(args):
    """The sensor when neither --sensor nor --config names one: the one a directory INPUT's
    layout says (``io.polar_layout.recognise``), said on stderr; the command's default for a
    file; for a directory of no known layout, a ConfigError naming the profiles to try."""
    from radarcl.io import polar_layout

    path = getattr(args, "input", None)
    if not getattr(args, "sensor_by_layout", False) or not isinstance(path, str) or not Path(path).is_dir():
        return args.sensor_default
    found = polar_layout.recognise(path)
    if found is None:
        raise ConfigError(f"{path} is a directory of no recording layout radarcl knows (Oxford, RADIATE, Boreas, "
                          f"MulRan); give --sensor: one of {', '.join(sensors.builtin_names())} (polar-png for other "
                          "polar PNG scans), or a profile file")
    print(f"radarcl: {path} is laid out as {found[1]}: --sensor {found[0]}", file=sys.stderr)
    return found[0]


def say_notes(notes, said=()):
    """Print each note (not in ``said``) to stderr as a warning line."""
    for note in notes:
        if note not in said:
            print(f"radarcl: note: {note}", file=sys.stderr)


def add_trajectory_options(p, what="the scans"):
    """--poses, --poses-format, --poses-times, --clock-offset, --max-speed: one trajectory reader
    (``io.poses``) for every command that places a radar."""
    from radarcl.io.poses import FORMATS
    from radarcl.io.trajectory import DEFAULT_MAX_SPEED_M_S

    p.add_argument("--poses", default=None, metavar="FILE",
                   help=f"the sensor's trajectory for {what} (default: the poses found beside them); interpolated at "
                        "each azimuth's time")
    p.add_argument("--poses-format", default=None, choices=FORMATS,
                   help="the pose file's format (default: told from its name and first line): Oxford radar "
                        "odometry, TUM, KITTI, 't x y z roll pitch yaw', RADIATE GPS/IMU, Boreas applanix CSV")
    p.add_argument("--poses-times", default=None, metavar="FILE", help="KITTI: the poses' times, one [s] per line "
                                                                       "(default: times.txt beside them)")
    p.add_argument("--clock-offset", type=float, default=None, metavar="S",
                   help="seconds the pose file's clock runs ahead of the radar's (RADIATE GPS/IMU: found from the "
                        "lidar when not given)")
    p.add_argument("--max-speed", type=positive_float, default=DEFAULT_MAX_SPEED_M_S, metavar="M_S",
                   help="a trajectory faster than this between two poses is refused as a jump (default: %(default)s)")


def read_trajectory(args):
    """The ``Trajectory`` of --poses (None without it), its notes said on stderr."""
    if not args.poses:
        return None
    from radarcl.io.poses import read_trajectory as read

    track = read(args.poses, args.poses_format, args.clock_offset, args.poses_times,
                 report=lambda line: print(f"radarcl: {line}", file=sys.stderr))
    track.check_motion(args.max_speed)
    say_notes(track.notes)
    return track


def add_salvage(p):
    """--salvage: read a damaged map store's intact bricks and list the lost ones."""
    p.add_argument("--salvage", action="store_true",
                   help="read a damaged map store anyway: its damaged bricks are left out and each lost brick is "
                        "listed (without it a damaged store is refused)")


def say_lost(lost):
    """Print what ``--salvage`` left out (every lost brick's key) on stderr."""
    from radarcl.maps.disk import lost_lines

    for line in lost_lines(lost):
        print(f"radarcl: salvage: {line}", file=sys.stderr)


def add_progress(p):
    """--no-progress."""
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


# -- what commands use -----------------------------------------------------------------------------------
def default_data(name):
    """The shared data set ``name``: under $RADARCL_DATA, else ../shared/data beside the source
    checkout (never relative to the current directory)."""
    root = Path(os.environ[DATA_ENV]) if os.environ.get(DATA_ENV) else Path(__file__).resolve().parents[3] / "shared" / "data"
    return root / name


class ProgressBar:
    """A one-line progress bar on stderr: ``bar(done, total, what)``; a new ``what`` starts a new line."""

    def __init__(self, stream=sys.stderr, width=30):
        self.stream, self.width, self.what = stream, width, None

    def __call__(self, done, total, what):
        if not self.stream.isatty() and done < total:
            return                                # a log file gets the finished line only
        if what != self.what and self.what is not None:
            self.stream.write("\n")
        self.what = what
        filled = int(self.width * done / max(1, total))
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} {what}")
        if done >= total:
            self.stream.write("\n")
            self.what = None
        self.stream.flush()


def progress(args):
    """The progress bar a command reports to, or None with --no-progress."""
    return None if getattr(args, "no_progress", False) else ProgressBar()


def runtime():
    """The OpenCL runtime of the chosen device (RADARCL_DEVICE, else PoCL's CPU)."""
    from radarcl.cl import Runtime  # pyopencl is loaded only by commands that run kernels

    return Runtime()


def add_foxglove_options(p):
    """--foxglove [PORT], --mcap FILE, --foxglove-rate HZ: the map out to Foxglove (``maps.foxglove_out``)."""
    p.add_argument("--foxglove", nargs="?", const=8765, default=None, type=bounded_int(0, 65535), metavar="PORT",
                   help="serve the growing map, the latest scan, the trajectory and TF to Foxglove (WebSocket on "
                        "127.0.0.1 only; PORT default 8765, 0 picks a free one)")
    p.add_argument("--mcap", default=None, metavar="FILE", help="record the same channels to an MCAP file Foxglove "
                                                                "opens (--force replaces it)")
    p.add_argument("--foxglove-rate", type=positive_float, default=2.0, metavar="HZ",
                   help="at most this many map updates a second to Foxglove and the MCAP file (default: %(default)s)")


def foxglove_out(args):
    """The ``maps.foxglove_out.FoxgloveOut`` that --foxglove / --mcap ask for, or None."""
    if args.foxglove is None and args.mcap is None:
        return None
    from radarcl.io import files
    from radarcl.maps.foxglove_out import FoxgloveOut

    read = [getattr(args, k, None) for k in ("input", "config", "poses", "odometry", "record")]
    mcap = files.check(args.mcap, args.force, inputs=[r for r in read if r], what="MCAP file") if args.mcap else None
    return FoxgloveOut(args.foxglove, mcap, args.foxglove_rate, overwrite=args.force,
                       say=lambda line: print(f"radarcl: {line}", file=sys.stderr, flush=True))
