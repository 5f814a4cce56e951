"""`radarcl live`: a radar's stream fused into a map as it arrives (``jobs.live``,
``livemap``); what `radarcl replay` shares with it (``add_pose_options``, ``make_mapper``,
``summary``)."""

import argparse
import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from radarcl.commands.options import (
    add_config,
    add_foxglove_options,
    add_output,
    add_trajectory_options,
    foxglove_out,
    positive_float,
    positive_int,
    read_trajectory,
    resolve_config,
    runtime,
)
from radarcl.errors import ConfigError
from radarcl.geometry import pose_from_xyz_rpy
from radarcl.io import files
from radarcl.io.brick_stream import BrickPublisher, parse_address
from radarcl.io.stream import PortReader, StreamRecorder, open_port
from radarcl.livemap import LiveMapper, PoseSource, Session
from radarcl.maps import disk
from radarcl.maps.map import Map

SUMMARY = "fuse a radar's stream from a serial port (or any pyserial URL) as it arrives"
DESCRIPTION = ("Reads the radar on PORT (/dev/ttyUSB0, socket://host:port, rfc2217://..., a pty from radarcl "
               "emulate) in its sensor's protocol (the radarcl beam protocol, or TI's mmWave demo UART), fuses "
               "the beams as they arrive, checkpoints the map every --checkpoint seconds and, with --record, "
               "keeps the raw bytes for radarcl replay. Ctrl-C saves and ends with a summary.")


def add_arguments(parser):
    p = parser
    p.add_argument("port", nargs="?", default=None, help="the radar's port: a device (/dev/ttyUSB0) or any pyserial URL")
    p.add_argument("--port", dest="port_option", default=None, metavar="PORT", help=argparse.SUPPRESS)   # the old spelling
    p.add_argument("--baud", type=positive_int, default=921600, help="baud rate (default: %(default)s)")
    add_output(p, "--out", "live.rcmap", "map to write: a map store (only changed bricks per checkpoint), or .npz")
    add_config(p)
    add_pose_options(p)
    p.add_argument("--checkpoint", type=positive_float, default=5.0, help="seconds between saves (default: %(default)s)")
    p.add_argument("--record", default=None, metavar="FILE", help="keep the raw byte stream with receive times")
    p.add_argument("--json-status", default=None, metavar="FILE", help="write the status as JSON every second")
    p.add_argument("--serve", default=None, metavar="[HOST:]PORT",
                   help="send changed bricks to viewers (radarcl view --follow HOST:PORT); 0 picks a free port")
    p.add_argument("--view", action="store_true", help="open the viewer on the growing map (implies --serve 0)")
    add_foxglove_options(p)
    p.add_argument("--retry", type=positive_float, default=None, metavar="S",
                   help="when the port goes away, try to reopen it every S seconds (default: save and stop)")
    p.add_argument("--duration", type=positive_float, default=None, help="stop after this many seconds")
    p.add_argument("--quiet", action="store_true", help="no status line on stderr")


def add_pose_options(p):
    """--poses (``options.add_trajectory_options``) and --mount: where a frame's pose comes from
    when the packets carry none."""
    add_trajectory_options(p, "the frames, when the packets carry none")
    p.add_argument("--mount", default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                   help="a fixed sensor pose [m, deg] (when neither the packets nor --poses give one; default: "
                        "the origin)")


def pose_source(args):
    """The ``livemap.PoseSource`` of --poses and --mount."""
    mount = None
    if args.mount:
        try:
            values = [float(v) for v in args.mount.split(",")]
        except ValueError:
            values = []
        if len(values) != 6 or not np.isfinite(values).all():
            raise ConfigError(f"--mount {args.mount!r}: expected X,Y,Z,ROLL,PITCH,YAW (metres, degrees)")
        mount = pose_from_xyz_rpy(*values[:3], *np.radians(values[3:]))
    track = read_trajectory(args)
    return PoseSource(mount, None if track is None else (track.times_ns, track.poses))


def make_mapper(args, config, out, inputs, on_fused=None, poses=None):
    """The ``livemap.LiveMapper`` saving to ``out`` (poses: a ``PoseSource``, default --poses/--mount's)."""
    saver = disk.MapSaver(out, config.sensor.toml(), config.as_dict(), inputs)
    return LiveMapper(runtime(), config, saver, poses or pose_source(args), on_fused)


def run(args):
    from radarcl.jobs import live

    if (args.port is None) == (args.port_option is None):
        raise ConfigError("give the radar's PORT once: radarcl live /dev/ttyUSB0 (or any pyserial URL, or the pty "
                          "radarcl emulate printed)")
    args.port = args.port or args.port_option
    config = resolve_config(args)
    out = disk.check_output(args.out, args.force)
    json_status = check_status_file(args.json_status, args.force) if args.json_status else None
    poses = pose_source(args)                        # every argument checked before a file is made
    view = _ViewServer(args) if (args.serve is not None or args.view) else None
    fox = foxglove_out(args)
    port = open_port(args.port, args.baud)
    # the header keeps what made the map, so that a replay makes the same one without being told
    recorder = StreamRecorder(args.record, dict(protocol=config.sensor.protocol, sensor=config.sensor.name,
                                                baud=args.baud, port=args.port, config=config.as_dict(),
                                                mount=args.mount, poses=args.poses)) if args.record else None
    reader = None
    try:
        session = Session(config.sensor, recorder)
        mapper = make_mapper(args, config, out, [], view.changed if view else None, poses)
        mapper.prepare()                             # compile before the radar streams
        if view:
            view.start(mapper)
        after_fuse = _after_fuse(view, fox, mapper)
        say = None if args.quiet else (lambda line: print("\r" + line, end="", file=sys.stderr, flush=True))
        started = time.monotonic()
        stop = threading.Event()
        reader = PortReader(port, session.feed).start()
        print(f"radarcl live: reading {args.port} at {args.baud} baud as sensor {config.sensor.name} "
              f"({config.sensor.protocol} protocol) into {out}; Ctrl-C saves and stops", file=sys.stderr, flush=True)
        while True:
            watch = threading.Thread(target=_watch, args=(reader, stop, args.duration, started), daemon=True)
            watch.start()
            s = live.run(session, mapper, checkpoint_s=args.checkpoint, say=say, json_status=json_status, stop=stop,
                         after_fuse=after_fuse, stop_feeding=reader.stop)
            if reader.lost is None or args.retry is None or s["interrupted"]:
                break
            print(f"\nradarcl: the port {args.port} went away ({reader.lost}); the map is saved ({s['saved_beams']} "
                  f"beams); reopening every {args.retry:g} s (Ctrl-C stops)", file=sys.stderr)
            port = _reopen(args, stop)
            stop.clear()
            reader = PortReader(port, session.feed).start()
        if fox is not None and mapper.mapping is not None and mapper.trajectory:
            from radarcl.maps.foxglove_out import snapshot

            fox.offer(snapshot(mapper.mapping, mapper.trajectory, mapper.trajectory[-1], reading=mapper.config))
    finally:
        if reader is not None:
            reader.stop()
        else:
            port.close()
        if recorder is not None:
            recorder.close()
            if recorder.bytes == 0:                  # a header and no byte: nothing to replay, and it
                with contextlib.suppress(OSError):   # would block the next run's --record
                    os.unlink(args.record)
        if view:
            view.close()
        if fox is not None:
            fox.close()
    if say:
        print(file=sys.stderr)
    if reader.ended is not None and not s["interrupted"]:
        print(f"radarcl live: the stream on {args.port} ended ({reader.ended})", file=sys.stderr)
    if recorder is not None and recorder.bytes == 0:
        print(f"radarcl live: no byte arrived; {args.record} was not kept", file=sys.stderr)
    if not s["beams"]:
        raise ConfigError(f"no beam was fused ({counts_text(s)}); {out} was not written")
    print(summary(s, out))
    if reader.lost is not None and not s["interrupted"] and args.retry is None:
        raise ConfigError(f"the radar's port {args.port} went away ({reader.lost}); the map is saved in {out} "
                          f"({s['saved_beams']} beams); --retry S waits for it to come back")
    return 0


def _after_fuse(view, fox, mapper):
    """What runs after each pass of the live loop: the view stream's publish and Foxglove's
    (the map offered at the Foxglove rate, and always after the last pass, which saves)."""
    if fox is None:
        return view.publish if view else None
    from radarcl.maps.foxglove_out import snapshot

    def after():
        if view:
            view.publish()
        beams = mapper.stats["beams"]
        if mapper.mapping is not None and mapper.trajectory and beams != getattr(after, "shown", None) and fox.due():
            fox.offer(snapshot(mapper.mapping, mapper.trajectory, mapper.trajectory[-1], reading=mapper.config))
            after.shown = beams
    return after


def check_status_file(path, force):
    """--json-status FILE: a path that may be written; an existing file is replaced only when it
    is a status file radarcl wrote (a JSON object with its counts) or with --force."""
    path = Path(path)
    if path.is_file() and not force:
        try:
            ours = {"beams", "frames", "bytes_in"} <= set(json.loads(path.read_text()))
        except (OSError, ValueError, TypeError, UnicodeDecodeError):
            ours = False
        if not ours:
            raise ConfigError(f"status file {path} exists and is not a radarcl status file; pass --force to replace it")
        force = True
    return files.check(path, force, what="status file")


def _watch(reader, stop, duration, started):
    """Sets ``stop`` when the port goes away or the duration is up."""
    while not stop.is_set():
        if reader.closed.wait(0.2) or (duration is not None and time.monotonic() - started >= duration):
            stop.set()


def _reopen(args, stop):
    while True:
        try:
            return open_port(args.port, args.baud)
        except ConfigError:
            time.sleep(args.retry)                   # a person is plugging the radar back in


def summary(s, out):
    """The line a live or replayed stream ends with."""
    lat = "" if s["latency_p50_ms"] is None else f", latency p50 {s['latency_p50_ms']:.0f} ms p99 {s['latency_p99_ms']:.0f} ms"
    return (f"{'interrupted: ' if s.get('interrupted') else ''}fused {s['beams']} beams of {s['frames']} frames in "
            f"{s['wall_s']:.1f} s ({s['beams_per_s']:.0f}/s{lat}); {counts_text(s)}; wrote {out}")


def counts_text(s):
    """What arrived and what did not, in words."""
    bad = f", {s['bad_poses']} with a pose that is not a rigid transform" if s.get("bad_poses") else ""
    return (f"{s['bytes_in']} bytes in, {s['bytes_dropped']} dropped, {s['crc_failures']} CRC failures, "
            f"{s['sequence_gaps']} packets missing between those that arrived, {s['beams_missing']} beams missing "
            f"from the frames seen, {s['duplicates']} duplicates, {s['refused']} refused{bad}")


def shown(grid, keys, channels, config):
    """The bricks a viewer is sent of a grid with the knowledge channel (``channels``: evidence,
    knowledge and looks bricks of ``keys``): as the map reads them where it knows, 0 where it
    does not (``Map.shown_units``), not the raw sums."""
    return Map(grid.spec, keys, channels["evidence"], channels["knowledge"], channels["looks"],
               config.reading()).shown_units()


class _ViewServer:
    """--serve / --view: a BrickPublisher fed with the bricks each fuse changed (at most 5 times
    a second), and with --view a `radarcl view --follow` process."""

    def __init__(self, args):
        self.address = parse_address(args.serve if args.serve is not None else "0")
        self.open_viewer = args.view
        self._slots, self._last, self.publisher, self.process = [], 0.0, None, None

    def start(self, mapper):
        self.mapper = mapper

        def snapshot():
            grid = mapper.mapping.grid
            keys, data = grid.read_slots(grid.live_slots(), channels=grid.channels)
            data = shown(grid, keys, data, mapper.mapping.config) if grid.has_knowledge else data["evidence"]
            return grid.spec, keys, data, np.array(mapper.trajectory) if mapper.trajectory else None

        self.publisher = BrickPublisher(snapshot, self.address)
        host, port = self.publisher.address
        print(f"serving the map to viewers on {host}:{port} (radarcl view --follow {host}:{port})", file=sys.stderr)
        self.pending_viewer = self.open_viewer

    def changed(self, bricks):
        self._slots.append(np.asarray(bricks))

    def publish(self):
        if self.publisher is None or self.mapper.mapping is None:
            return
        if self.pending_viewer:                      # the map exists now: the viewer can be given it
            host, port = self.publisher.address
            self.process = subprocess.Popen([sys.executable, "-m", "radarcl", "view", "--follow", f"{host}:{port}"])
            self.pending_viewer = False
        now = time.monotonic()
        if now - self._last < 0.2 or not (self._slots or self.publisher.viewers):
            return
        self._last = now
        grid = self.mapper.mapping.grid
        slots = np.concatenate(self._slots)[:, 3] if self._slots else np.empty(0, np.int64)
        self._slots = []
        keys, data = (None, None)
        if len(slots):
            keys, data = grid.read_slots(slots, channels=grid.channels)
            data = shown(grid, keys, data, self.mapper.mapping.config) if grid.has_knowledge else data["evidence"]
        poses = np.array(self.mapper.trajectory) if self.mapper.trajectory else None
        self.publisher.publish(keys, data, poses)

    def close(self):
        if self.publisher is not None:
            self.publisher.close()
