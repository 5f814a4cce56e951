"""The streaming subcommands: `radarcl live`, `radarcl emulate`, `radarcl replay` (their
options and the small functions the CLI calls). The work is in ``radarcl.jobs.live`` and
``radarcl.io.emulator``."""

import sys
import threading
import time
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError


def add_parsers(command, add_output, add_config, positive_float, positive_int):
    """Register the three subcommands with the CLI's ``command`` helper."""
    p = command("live", cmd_live, "fuse a radar's stream from a serial port (or any pyserial URL) as it arrives",
                "Reads the radar on PORT (/dev/ttyUSB0, socket://host:port, rfc2217://..., a pty from radarcl "
                "emulate) in its sensor's protocol (the radarcl beam protocol, or TI's mmWave demo UART), fuses "
                "the beams as they arrive, checkpoints the map every --checkpoint seconds and, with --record, "
                "keeps the raw bytes for radarcl replay. Ctrl-C saves and ends with a summary.")
    p.add_argument("--port", required=True, help="the radar's port: a device or any pyserial URL")
    p.add_argument("--baud", type=positive_int, default=921600, help="baud rate (default: %(default)s)")
    add_output(p, "--out", "live.rcmap", "map to write: a map store (only changed bricks per checkpoint), or .npz")
    add_config(p)
    _pose_options(p)
    p.add_argument("--checkpoint", type=positive_float, default=5.0, help="seconds between saves (default: %(default)s)")
    p.add_argument("--record", default=None, metavar="FILE", help="keep the raw byte stream with receive times")
    p.add_argument("--json-status", default=None, metavar="FILE", help="write the status as JSON every second")
    p.add_argument("--serve", default=None, metavar="[HOST:]PORT",
                   help="send changed bricks to viewers (radarcl view --follow HOST:PORT); 0 picks a free port")
    p.add_argument("--view", action="store_true", help="open the viewer on the growing map (implies --serve 0)")
    p.add_argument("--retry", type=positive_float, default=None, metavar="S",
                   help="when the port goes away, try to reopen it every S seconds (default: save and stop)")
    p.add_argument("--duration", type=positive_float, default=None, help="stop after this many seconds")
    p.add_argument("--quiet", action="store_true", help="no status line on stderr")

    p = command("emulate", cmd_emulate, "play a recording onto a pseudo-terminal (or a port) as a radar would, with faults",
                "Sends a recording's frames beam by beam in the beam protocol (or, for a sensor of range profiles, "
                "as TI demo frames) at --baud, onto a new pseudo-terminal (--pty; its path is printed) or --port, "
                "with faults injected at the given rates and seed. A recorded stream (radarcl live --record) is "
                "played byte for byte. The test port and the demo port of radarcl live.")
    p.add_argument("source", help="a recording (.npz), a TI capture, or a stream file from --record")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--pty", action="store_true", help="create a pseudo-terminal and print its path")
    target.add_argument("--port", default=None, help="write to this port (any pyserial URL)")
    p.add_argument("--link", default=None, metavar="PATH", help="with --pty: a symbolic link to it at PATH")
    p.add_argument("--sensor", default=None, help="the recording's sensor (default: the recording's own)")
    p.add_argument("--protocol", choices=["beams", "ti"], default=None,
                   help="beams: the radarcl beam protocol; ti: TI's demo UART (range profiles of a one-beam sensor, "
                        "computed from raw chirps as the demo does); default: the sensor's")
    p.add_argument("--ti-sensor", default="ti-xwr18xx-uart",
                   help="with --protocol ti from raw chirps: the TI demo profile whose range-profile scaling "
                        "([stream] antennas, Q bits) the frames use (default: %(default)s)")
    p.add_argument("--baud", default="921600", help="bytes go out at baud / 10 per second; 'max' for no pacing "
                                                   "(default: %(default)s)")
    p.add_argument("--faults", default="", help="e.g. ber=1e-4,drop=1e-5,dup=1e-5,truncate=1e-3,noise=1e-3,"
                                                "pause=2,pause_every=100,disconnect=500,seed=1")
    p.add_argument("--frames", type=positive_int, default=None, help="only the first N frames")
    p.add_argument("--loop", action="store_true", help="play the recording again and again (frame ids restart: "
                                                        "recordings of more than 8 frames)")
    p.add_argument("--delay", type=float, default=0.0, help="seconds to wait before the first byte (time to start "
                                                          "radarcl live: bytes sent before a reader opens the port "
                                                          "are dropped when it does)")
    p.add_argument("--frame-period", type=positive_float, default=0.1, help="seconds between frame timestamps")

    p = command("replay", cmd_replay, "fuse a recorded stream (radarcl live --record) again: the same map, bit for bit",
                "Feeds a stream file through the same parser and mapper as radarcl live, as fast as it parses or "
                "at the recorded pace; the map is bit-identical to the live one.")
    p.add_argument("stream", help="a stream file written by radarcl live --record")
    add_output(p, "--out", "replay.rcmap", "map to write (a map store, or .npz)")
    add_config(p)
    _pose_options(p)
    p.add_argument("--speed", choices=["max", "recorded"], default="max", help="(default: %(default)s)")


def _pose_options(p):
    p.add_argument("--poses", default=None, metavar="FILE",
                   help="poses 't_s x y z roll pitch yaw' per row, interpolated at each frame's time (when the "
                        "packets carry none)")
    p.add_argument("--mount", default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                   help="a fixed sensor pose [m, deg] (when neither the packets nor --poses give one; default: "
                        "the origin)")


def _poses(args):
    from radarcl.jobs import live

    mount = None
    if args.mount:
        try:
            values = [float(v) for v in args.mount.split(",")]
        except ValueError:
            values = []
        if len(values) != 6 or not np.isfinite(values).all():
            raise ConfigError(f"--mount {args.mount!r}: expected X,Y,Z,ROLL,PITCH,YAW (metres, degrees)")
        mount = live.pose_matrix(values[:3] + list(np.radians(values[3:])))
    track = live.read_pose_file(args.poses) if args.poses else None
    return live.PoseSource(mount, track)


def _mapper(args, config, out, inputs, on_fused=None):
    from radarcl.cl import Runtime
    from radarcl.jobs import live
    from radarcl.store import MapSaver

    saver = MapSaver(out, config.sensor.toml(), config.as_dict(), inputs)
    return live.LiveMapper(Runtime(), config, saver, _poses(args), on_fused)


def cmd_live(args):
    from radarcl import outputs
    from radarcl.commands import resolve_config
    from radarcl.io.stream import PortReader, StreamRecorder, open_port
    from radarcl.jobs import live

    config = resolve_config(args)
    out = outputs.check(args.out, args.force, what="map", store=not str(args.out).endswith(".npz"))
    json_status = outputs.check(args.json_status, True, what="status file") if args.json_status else None
    port = open_port(args.port, args.baud)
    recorder = StreamRecorder(args.record, dict(protocol=config.sensor.protocol, sensor=config.sensor.name,
                                                baud=args.baud, port=args.port)) if args.record else None
    session = live.Session(config.sensor, recorder)
    view = _ViewServer(args) if (args.serve is not None or args.view) else None
    mapper = _mapper(args, config, out, [], view.changed if view else None)
    mapper.prepare()                                 # compile before the radar streams
    if view:
        view.start(mapper)
    say = None if args.quiet else (lambda line: print("\r" + line, end="", file=sys.stderr, flush=True))
    started = time.monotonic()
    stop = threading.Event()
    reader = PortReader(port, session.feed).start()
    print(f"radarcl live: reading {args.port} at {args.baud} baud as sensor {config.sensor.name} "
          f"({config.sensor.protocol} protocol) into {out}; Ctrl-C saves and stops", file=sys.stderr, flush=True)
    try:
        while True:
            watch = threading.Thread(target=_watch, args=(reader, stop, args.duration, started), daemon=True)
            watch.start()
            s = live.run(session, mapper, checkpoint_s=args.checkpoint, say=say, json_status=json_status, stop=stop,
                         after_fuse=view.publish if view else None)
            if reader.lost is None or args.retry is None or s["interrupted"]:
                break
            print(f"\nradarcl: the port {args.port} went away ({reader.lost}); the map is saved ({s['saved_beams']} "
                  f"beams); reopening every {args.retry:g} s (Ctrl-C stops)", file=sys.stderr)
            port = _reopen(args, stop)
            stop.clear()
            reader = PortReader(port, session.feed).start()
    finally:
        reader.stop()
        if recorder is not None:
            recorder.close()
        if view:
            view.close()
    if say:
        print(file=sys.stderr)
    print(_summary(s, out))
    if reader.lost is not None and not s["interrupted"] and args.retry is None:
        raise ConfigError(f"the radar's port {args.port} went away ({reader.lost}); the map is saved in {out} "
                          f"({s['saved_beams']} beams); --retry S waits for it to come back")
    return 0


def _watch(reader, stop, duration, started):
    """Sets ``stop`` when the port goes away or the duration is up."""
    while not stop.is_set():
        if reader.closed.wait(0.2) or (duration is not None and time.monotonic() - started >= duration):
            stop.set()


def _reopen(args, stop):
    from radarcl.io.stream import open_port

    while True:
        try:
            return open_port(args.port, args.baud)
        except ConfigError:
            time.sleep(args.retry)                   # a person is plugging the radar back in


def _summary(s, out):
    lat = "" if s["latency_p50_ms"] is None else f", latency p50 {s['latency_p50_ms']:.0f} ms p99 {s['latency_p99_ms']:.0f} ms"
    return (f"{'interrupted: ' if s.get('interrupted') else ''}fused {s['beams']} beams of {s['frames']} frames in "
            f"{s['wall_s']:.1f} s ({s['beams_per_s']:.0f}/s{lat}); {s['bytes_in']} bytes in, {s['bytes_dropped']} "
            f"dropped, {s['crc_failures']} CRC failures, {s['sequence_gaps']} packets missing, {s['duplicates']} "
            f"duplicates; wrote {out}")


class _ViewServer:
    """--serve / --view: a BrickPublisher fed with the bricks each fuse changed (at most 5 times
    a second), and with --view a `radarcl view --follow` process."""

    def __init__(self, args):
        from radarcl.io.brick_stream import parse_address

        self.address = parse_address(args.serve if args.serve is not None else "0")
        self.open_viewer = args.view
        self._slots, self._last, self.publisher, self.process = [], 0.0, None, None

    def start(self, mapper):
        from radarcl.io.brick_stream import BrickPublisher

        self.mapper = mapper

        def snapshot():
            grid = mapper.mapping.grid
            keys, data = grid.bricks()
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
            import subprocess

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
        keys, data = grid.read_slots(slots) if len(slots) else (None, None)
        poses = np.array(self.mapper.trajectory) if self.mapper.trajectory else None
        self.publisher.publish(keys, data, poses)

    def close(self):
        if self.publisher is not None:
            self.publisher.close()


def cmd_emulate(args):
    from radarcl.io import emulator
    from radarcl.io.stream import open_port

    faults = emulator.Faults.parse(args.faults)
    baud = None if args.baud == "max" else _baud(args.baud)
    chunks, due = _emulated_chunks(args)
    damaged, intact = faults.apply(chunks)
    if args.pty:
        import os

        master, name, slave = emulator.open_pty(args.link)
        write, close = (lambda b: os.write(master, b)), (lambda: emulator.close_pty(master, slave))
        print(f"emulating on {name}" + (f" (link {args.link})" if args.link else "") + f": {len(chunks)} packets, "
              f"{sum(map(len, damaged))} bytes at {args.baud} baud; radarcl live --port {args.link or name}", flush=True)
    else:
        port = open_port(args.port, baud or 921600)
        write, close = port.write, port.close
        print(f"emulating on {args.port}: {len(chunks)} packets", flush=True)
    if not 0 <= args.delay < 3600:
        raise ConfigError(f"--delay must lie in [0, 3600) seconds, got {args.delay}")
    emu = emulator.Emulator(damaged, write, baud, faults, close, loop=args.loop, due_s=due, delay_s=args.delay).start()
    try:
        while not emu.done.wait(0.5):
            pass
    except KeyboardInterrupt:
        emu.stop()
    print(f"sent {emu.sent} bytes in {emu.packets_sent} packets ({sum(intact)} intact)"
          + ("; disconnected as asked" if emu.disconnected.is_set() else ""))
    return 0


def _baud(text):
    try:
        value = float(text)
    except ValueError:
        value = -1
    if not 0 < value <= 1e9:
        raise ConfigError(f"--baud must be a positive number or 'max', got {text!r}")
    return value


def _emulated_chunks(args):
    """(packets (list of bytes), seconds from the start each may go out, or None) to play: a
    stream file's chunks at their recorded times, or a recording in its sensor's protocol at
    --frame-period."""
    from radarcl import sensors
    from radarcl.io import emulator, open_input
    from radarcl.io.stream import STREAM_MAGIC, read_stream

    path = Path(args.source)
    if path.is_file():
        with open(path, "rb") as f:
            if f.read(len(STREAM_MAGIC)) == STREAM_MAGIC:
                _, records = read_stream(path)
                timed = list(records)                   # played at the pace it was recorded
                return [d for _, d in timed], [(t - timed[0][0]) / 1e9 for t, _ in timed] if timed else None
    sensor = sensors.load(args.sensor or _recording_sensor(path))
    source = open_input(sensor, path)
    n = len(source) if args.frames is None else min(args.frames, len(source))
    frames = np.stack([source.frames[j] for j in range(n)])
    protocol = args.protocol or sensor.protocol
    if protocol == "ti":
        if sensor.n_azimuth * sensor.n_elevation != 1:
            raise ConfigError(f"TI's demo UART carries one range profile per frame; sensor {sensor.name} has "
                              f"{sensor.n_azimuth} x {sensor.n_elevation} beams")
        power = frames.reshape(n, -1)
        if sensor.raw:                                  # the demo's range FFT: Hann window, |X|^2
            power = np.abs(np.fft.fft(power * np.hanning(power.shape[1]), axis=1)) ** 2
        from radarcl.jobs.live import ti_scaling

        antennas, q_bits = ti_scaling(sensor if sensor.protocol == "ti" else sensors.load(args.ti_sensor))
        values = emulator.q9_of_power(power, antennas, q_bits)
        return emulator.ti_packets(values), [j * args.frame_period for j in range(n)]
    if not sensor.raw:
        raise ConfigError(f"sensor {sensor.name} delivers range profiles: the beam protocol carries raw beams; "
                          "use --protocol ti for a one-beam profile sensor")
    poses = np.stack([source.poses[j] for j in range(n)])
    beams = frames.shape[1] * frames.shape[2]
    due = [b // beams * args.frame_period for b in range(n * beams)]        # a frame starts no sooner than its time
    return emulator.beam_packets(frames, poses, int(args.frame_period * 1e9)), due


def _recording_sensor(path):
    from radarcl.io import recording

    if path.suffix != ".npz":
        raise ConfigError(f"{path}: give --sensor (only a radarcl recording names its sensor)")
    return recording.load(path).sensor


def cmd_replay(args):
    from radarcl import outputs
    from radarcl.commands import resolve_config
    from radarcl.jobs import live

    out = outputs.check(args.out, args.force, inputs=[args.stream], what="map", store=not str(args.out).endswith(".npz"))

    def factory(header):
        if args.sensor is None and args.config is None:
            if not isinstance(header.get("sensor"), str):
                raise ConfigError(f"{args.stream} does not name its sensor; give --sensor")
            args.sensor = header["sensor"]
        config = resolve_config(args)
        return config.sensor, _mapper(args, config, out, [args.stream])

    _, s, header = live.replay(args.stream, factory, args.speed, say=lambda line: print(line, file=sys.stderr))
    print(_summary(s, out))
    return 0

