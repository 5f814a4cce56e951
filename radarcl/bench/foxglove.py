"""`radarcl bench foxglove`: what serving the map to Foxglove costs the map. The 11 Oxford scans
fused into a map file (``jobs.fuse.run``) without Foxglove, with the server and no client, and
with the server and a client that subscribed to every channel and then stopped reading,
interleaved in one run; each variant's time against the plain fuse's. The goal: a stalled client
costs the map nothing beyond the snapshots the rate asks for."""

import base64
import json
import os
import socket
import struct
import tempfile
import time
from pathlib import Path

from radarcl.bench.timing import interleaved_medians

PROFILE = "navtech-cts350x"


def stalled_client(port, timeout_s=60.0):
    """A socket that completed the Foxglove WebSocket handshake on 127.0.0.1:``port`` and
    subscribed to every channel advertised, and will never read again (its receive buffer kept
    small, so the server's writes to it block at once). Written by hand: a WebSocket library
    would keep reading in the background."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            s = socket.create_connection(("127.0.0.1", port), timeout=30)
            break
        except ConnectionRefusedError:                 # the server is not up yet
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               "Sec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n\r\n").encode())
    buf = b""
    while b"\r\n\r\n" not in buf:
        buf += s.recv(4096)
    status = buf.split(b"\r\n")[0]
    if b" 101 " not in status:
        raise ConnectionError(f"the server refused the handshake: {status!r}")
    buf = buf.split(b"\r\n\r\n", 1)[1]
    while True:                                        # server frames are unmasked: opcode, length, body
        while len(buf) < 10:
            buf += s.recv(65536)
        n, at = buf[1] & 0x7F, 2
        if n == 126:
            n, at = struct.unpack(">H", buf[2:4])[0], 4
        elif n == 127:
            n, at = struct.unpack(">Q", buf[2:10])[0], 10
        while len(buf) < at + n:
            buf += s.recv(65536)
        op, body, buf = buf[0] & 0x0F, buf[at:at + n], buf[at + n:]
        if op == 1 and json.loads(body).get("op") == "advertise":
            channels = json.loads(body)["channels"]
            break
    text = json.dumps({"op": "subscribe", "subscriptions": [{"id": i + 1, "channelId": c["id"]}
                                                            for i, c in enumerate(channels)]}).encode()
    mask = os.urandom(4)
    size = bytes([0x80 | 126]) + struct.pack(">H", len(text)) if len(text) >= 126 else bytes([0x80 | len(text)])
    s.sendall(bytes([0x81]) + size + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(text)))
    return s, len(channels)


def run(runtime, data_root, repeat=6, rate_hz=2.0):
    """Seconds per fuse of each variant and its ratio to the plain fuse; returns the --json dict."""
    from radarcl.config import mapconfig
    from radarcl.io.inputs import open_input
    from radarcl.jobs import fuse
    from radarcl.maps.foxglove_out import FoxgloveOut

    scans = data_root / "navtech_oxford" / "radar"
    config = mapconfig.resolve(PROFILE)
    source = open_input(config.sensor, scans, poses=data_root / "navtech_oxford" / "gt" / "radar_odometry.csv")
    config = config.for_sensor(source.sensor) if source.sensor is not config.sensor else config
    served, stalled = FoxgloveOut(0, rate_hz=rate_hz), FoxgloveOut(0, rate_hz=rate_hz)
    client, subscribed = stalled_client(stalled.port)
    try:
        with tempfile.TemporaryDirectory(prefix="radarcl-bench-") as tmp:
            def variant(fox):
                def go():
                    fuse.run(runtime, source, config, Path(tmp) / "m.npz", report=lambda *_: None, foxglove=fox,
                             overwrite=True)
                return go

            load = {}
            t = interleaved_medians(dict(plain=variant(None), served=variant(served), stalled_client=variant(stalled)),
                                    repeat, block=1, warmup=1, load=load)
        published = dict(served=served.published, stalled_client=stalled.published)
    finally:
        served.close()
        stalled.close()
        client.close()
    return dict(benchmark="foxglove", repeat=repeat, scans=len(source), rate_hz=rate_hz, device=runtime.name,
                seconds=t, vs_plain={k: t[k] / t["plain"] for k in t if k != "plain"},
                channels_subscribed_by_the_stalled_client=subscribed, snapshots_published=published, load=load,
                goal="stalled_client vs plain no more than served vs plain (the stall costs the map nothing)")


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    lines = [f"{result['scans']} Oxford scans fused on {result['device']}, Foxglove at most {result['rate_hz']:g} "
             f"updates/s, median of {result['repeat']} interleaved runs per variant",
             f"{'variant':>15} {'s per fuse':>11} {'vs plain':>9}"]
    for k, s in result["seconds"].items():
        lines.append(f"{k:>15} {s:>11.2f} {('1.00' if k == 'plain' else format(result['vs_plain'][k], '.2f')):>9}")
    lines.append(f"snapshots published: {result['snapshots_published']}; the stalled client subscribed to "
                 f"{result['channels_subscribed_by_the_stalled_client']} channels and read nothing after")
    lines.append(f"goal: {result['goal']}")
    return lines


def add_arguments(parser):
    """`radarcl bench foxglove` options."""
    from radarcl.commands.options import positive_float, positive_int

    parser.add_argument("--repeat", type=positive_int, default=6, help="timed fuses per variant (default: %(default)s)")
    parser.add_argument("--rate", type=positive_float, default=2.0, help="Foxglove updates per second (default: "
                                                                         "%(default)s)")
    parser.add_argument("--data", default=None, help="the shared data directory (default: $RADARCL_DATA or "
                                                     "../shared/data beside the source)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.commands.options import default_data

    root = Path(args.data) if args.data else default_data("")
    result = run(runtime(), root, repeat=args.repeat, rate_hz=args.rate)
    return result, format_table(result)
