"""`radarcl replay`: a recorded stream fused again through the same parser and mapper as
`radarcl live`."""

import sys

from radarcl.commands.live import add_pose_options, counts_text, make_mapper, summary
from radarcl.commands.options import add_config, add_output, resolve_config
from radarcl.errors import ConfigError
from radarcl.maps import disk

SUMMARY = "fuse a recorded stream (radarcl live --record) again: the same map, bit for bit"
DESCRIPTION = ("Feeds a stream file through the same parser and mapper as radarcl live, as fast as it parses or "
               "at the recorded pace, with the sensor, configuration and --mount/--poses the recording's header "
               "keeps (options given here take precedence); the map is bit-identical to the live one.")


def add_arguments(parser):
    parser.add_argument("stream", help="a stream file written by radarcl live --record")
    add_output(parser, "--out", "replay.rcmap", "map to write (a map store, or .npz)")
    add_config(parser)
    add_pose_options(parser)
    parser.add_argument("--speed", choices=["max", "recorded"], default="max", help="(default: %(default)s)")


def run(args):
    from radarcl.jobs import live

    out = disk.check_output(args.out, args.force, inputs=[args.stream])

    def factory(header):
        recorded = None
        if args.sensor is None and args.config is None:
            if not isinstance(header.get("sensor"), str) or not header["sensor"]:
                raise ConfigError(f"{args.stream} does not name its sensor; give --sensor")
            args.sensor = header["sensor"]
            recorded = header.get("config")          # what live used, below any --set given here
            if recorded is not None and not isinstance(recorded, dict):
                raise ConfigError(f"{args.stream}: its header's configuration is not a table")
        if args.mount is None and args.poses is None:
            args.mount = header.get("mount") if isinstance(header.get("mount"), str) else None
            args.poses = header.get("poses") if isinstance(header.get("poses"), str) else None
        config = resolve_config(args, program=recorded)
        return config.sensor, make_mapper(args, config, out, [args.stream])

    _, s, header = live.replay(args.stream, factory, args.speed, say=lambda line: print(line, file=sys.stderr))
    if not s["beams"]:
        raise ConfigError(f"no beam of {args.stream} could be fused ({counts_text(s)}); {out} was not written")
    print(summary(s, out))
    return 0
