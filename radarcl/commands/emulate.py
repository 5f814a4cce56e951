"""`radarcl emulate`: a recording played onto a pseudo-terminal (or a port) as a radar would
send it, with faults (``io.emulator``)."""

import threading
import time
from pathlib import Path

import numpy as np

from radarcl.commands.options import positive_float, positive_int
from radarcl.config import sensors
from radarcl.errors import ConfigError, Terminated
from radarcl.io import emulator, recording
from radarcl.io.inputs import open_input
from radarcl.io.stream import PROTOCOLS, STREAM_MAGIC, open_port, read_stream
from radarcl.livemap import ti_scaling

SUMMARY = "play a recording onto a pseudo-terminal (or a port) as a radar would, with faults"
DESCRIPTION = ("Sends a recording's frames beam by beam in the beam protocol (or, for a sensor of range profiles, "
               "as TI demo frames) at --baud, onto a new pseudo-terminal (--pty; its path is printed) or --port, "
               "with faults injected at the given rates and seed. A recorded stream (radarcl live --record) is "
               "played byte for byte. The test port and the demo port of radarcl live.")


def add_arguments(parser):
    p = parser
    p.add_argument("source", help="a recording (.npz), a TI capture, or a stream file from --record")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--pty", action="store_true", help="create a pseudo-terminal and print its path")
    target.add_argument("--port", default=None, help="write to this port (any pyserial URL)")
    p.add_argument("--link", default=None, metavar="PATH", help="with --pty: a symbolic link to it at PATH")
    p.add_argument("--sensor", default=None, help="the recording's sensor (default: the recording's own)")
    p.add_argument("--protocol", choices=PROTOCOLS, default=None,
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
    p.add_argument("--wait-for", default=None, metavar="PATH",
                   help="send nothing until PATH exists: the reader says it is ready (radarcl live's --json-status "
                        "file appears once it reads the port; or touch PATH after opening it), where --delay guesses")
    p.add_argument("--frame-period", type=positive_float, default=0.1, help="seconds between frame timestamps")


def run(args):
    faults = emulator.Faults.parse(args.faults)
    baud = None if args.baud == "max" else _baud(args.baud)
    if not 0 <= args.delay < 3600:
        raise ConfigError(f"--delay must lie in [0, 3600) seconds, got {args.delay}")
    if not args.frame_period <= MAX_FRAME_PERIOD_S:
        raise ConfigError(f"--frame-period must lie in (0, {MAX_FRAME_PERIOD_S:g}] seconds, got {args.frame_period:g}")
    if args.link and not args.pty:
        raise ConfigError("--link names the pseudo-terminal of --pty; with --port there is none")
    emulator.check_link(args.link)
    chunks, due = _emulated_chunks(args)
    damaged, intact = faults.apply(chunks)
    name = None
    halt = threading.Event()
    if args.pty:
        master, name, slave = emulator.open_pty(args.link)
        write = emulator.pty_writer(master, halt)
        print(f"emulating on {name}" + (f" (link {args.link})" if args.link else "") + f": {len(chunks)} packets, "
              f"{sum(map(len, damaged))} bytes at {args.baud} baud; radarcl live {args.link or name}", flush=True)
    else:
        port = open_port(args.port, baud or 921600)
        write = port.write
        print(f"emulating on {args.port}: {len(chunks)} packets", flush=True)
    emu = emulator.Emulator(damaged, write, baud, faults, None, loop=args.loop, due_s=due, delay_s=args.delay)
    interrupted, unread = None, 0
    try:
        if args.wait_for is not None:
            _wait_for(Path(args.wait_for))
        emu.start()
        while not emu.done.wait(0.05):
            pass
    except (KeyboardInterrupt, Terminated) as exc:
        interrupted = exc
        halt.set()                                    # a write blocked on a full pty gives up at once
        emu.stop()
    finally:
        halt.set()
        if args.pty:                                  # the last bytes still reach a reader, unless stopped
            try:
                unread = emulator.close_pty(master, slave, drain=interrupted is None)
            finally:
                emulator.remove_link(args.link, name)
        else:
            port.close()
    if emu.error is not None:
        raise ConfigError(f"the emulator stopped: {emu.error}") from emu.error
    print(f"sent {emu.sent} bytes in {emu.packets_sent} packets ({sum(intact)} intact)"
          + ("; disconnected as asked" if emu.disconnected.is_set() else "")
          + (f"; {unread} bytes were never read (no reader took them before the pty closed)" if unread else ""),
          flush=True)
    if interrupted is not None:
        raise interrupted
    return 0


MAX_FRAME_PERIOD_S = 3600.0


def _wait_for(path, poll_s=0.02):
    """Return once ``path`` exists (Ctrl-C stops the wait as it stops the emulator)."""
    if not path.parent.is_dir():
        raise ConfigError(f"--wait-for {path}: its directory {path.parent} does not exist, so it never will")
    while not path.exists():
        time.sleep(poll_s)


def _baud(text):
    try:
        value = float(text)
    except ValueError:
        value = -1
    lo, hi = emulator.Emulator.MIN_BAUD, emulator.Emulator.MAX_BAUD
    if not lo <= value <= hi:
        raise ConfigError(f"--baud must be a number in [{lo}, {hi:g}] or 'max', got {text!r}")
    return value


def _emulated_chunks(args):
    """(packets (list of bytes), seconds from the start each may go out, or None) to play: a
    stream file's chunks at their recorded times, or a recording in its sensor's protocol at
    --frame-period."""
    path = Path(args.source)
    if path.is_file():
        with open(path, "rb") as f:
            if f.read(len(STREAM_MAGIC)) == STREAM_MAGIC:
                _, records = read_stream(path)
                timed = list(records)                   # played at the pace it was recorded
                return [d for _, d in timed], emulator.due_times([t for t, _ in timed])
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
    if path.suffix != ".npz":
        raise ConfigError(f"{path}: give --sensor (only a radarcl recording names its sensor)")
    return recording.load(path).sensor
