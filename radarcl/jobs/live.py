"""`radarcl live` and `radarcl replay`: the loop that fuses a radar's byte stream into a map as
it arrives (``livemap``: the session and the mapper it runs). The live map, a replay of its
recording and an offline fusion of the same beams are bit-identical.

The map is saved every ``checkpoint_s`` (a map store writes the changed bricks only): a crash
loses at most the beams since the last checkpoint, whose count the store's manifest keeps
("stream"). Ctrl-C finishes the fuse under way, saves and ends with a summary.
"""

import json
import os
import threading
import time

import numpy as np

from radarcl.io import emulator
from radarcl.io.files import atomic
from radarcl.io.stream import PortReader, StreamCounters, open_port, read_stream
from radarcl.livemap import LiveMapper, Session


def status(mapper, counters, wall_s, parse_s):
    """The figures a status line and ``--json-status`` show."""
    lat = np.asarray(mapper.latencies[-10000:]) * 1e3
    c = counters.as_dict() if isinstance(counters, StreamCounters) else dict(counters)
    return dict(beams=mapper.stats["beams"], frames=mapper.stats["frames"], beams_per_s=mapper.stats["beams"] / max(wall_s, 1e-9),
                bytes_per_s=c["bytes_in"] / max(wall_s, 1e-9),
                latency_p50_ms=float(np.percentile(lat, 50)) if lat.size else None,
                latency_p99_ms=float(np.percentile(lat, 99)) if lat.size else None,
                parser_cpu_share=parse_s / max(wall_s, 1e-9), wall_s=wall_s,
                saved_beams=mapper.stats["saved_beams"], checkpoints=mapper.stats["checkpoints"],
                duplicates=mapper.stats["duplicates"] + c["duplicates"], refused=mapper.stats["refused"],
                late=mapper.stats["late"], **{k: c[k] for k in ("bytes_in", "bytes_dropped", "crc_failures",
                                                                   "header_failures", "sequence_gaps", "packets")})


def status_line(s):
    lat = "-" if s["latency_p50_ms"] is None else f"{s['latency_p50_ms']:.0f}/{s['latency_p99_ms']:.0f} ms"
    return (f"live: {s['beams']} beams in {s['frames']} frames ({s['beams_per_s']:.0f}/s, "
            f"{s['bytes_per_s'] / 1e3:.1f} kB/s), latency p50/p99 {lat}, dropped {s['bytes_dropped']} B, "
            f"CRC {s['crc_failures']}, gaps {s['sequence_gaps']}, saved {s['saved_beams']}")


def write_status(path, s):
    """``--json-status``: the status as JSON, replaced atomically."""
    with atomic(path) as tmp:
        with open(tmp, "w") as f:
            json.dump(s, f)


def run(session, mapper, *, until=None, checkpoint_s=5.0, status_every_s=1.0, say=None, json_status=None,
        stop=None, after_fuse=None):
    """The mapper's loop: fuse what arrives, checkpoint every ``checkpoint_s``, report status,
    until ``until()`` is true and nothing is left, or ``stop`` (an Event) is set, or Ctrl-C /
    SIGTERM (the fuse under way finishes and the map is saved; SIGTERM re-raises after that).
    ``after_fuse()`` runs after each pass (the view stream). Returns the final status dict."""
    start = last_save = last_status = time.perf_counter()
    interrupted = None
    try:
        while not (stop is not None and stop.is_set()):
            mapper.add(session.drain())
            if after_fuse is not None:
                after_fuse()
            now = time.perf_counter()
            if checkpoint_s and now - last_save >= checkpoint_s and mapper.stats["beams"] > mapper.stats["saved_beams"]:
                mapper.save(extra=dict(counters=session.counters.as_dict()))
                last_save = now
            if now - last_status >= status_every_s:
                s = status(mapper, session.counters, now - start, session.parse_s)
                if say is not None:
                    say(status_line(s))
                if json_status:
                    write_status(json_status, s)
                last_status = now
            if until is not None and until() and session.beams.empty():
                mapper.add(session.drain(wait=0))
                break
    except (KeyboardInterrupt, SystemExit) as exc:
        interrupted = exc
    mapper.add(session.drain(wait=0))
    mapper.save(extra=dict(counters=session.counters.as_dict()))
    s = status(mapper, session.counters, time.perf_counter() - start, session.parse_s)
    if json_status:
        write_status(json_status, s)
    if isinstance(interrupted, SystemExit):
        raise interrupted
    s["interrupted"] = interrupted is not None
    return s


def replay(path, mapper_factory, speed="max", say=None):
    """Feed a ``--record`` stream file through the same parser and mapper: at the recorded pace
    (``speed`` "recorded") or as fast as it parses ("max"). Returns (mapper, status, header)."""
    header, records = read_stream(path)
    sensor, mapper = mapper_factory(header)
    session = Session(sensor)
    done = threading.Event()
    start_wall, first_t = time.perf_counter(), None

    def feed_all():
        nonlocal first_t
        try:
            for t_ns, data in records:
                if speed == "recorded":
                    first_t = t_ns if first_t is None else first_t
                    due = start_wall + (t_ns - first_t) / 1e9 - time.perf_counter()
                    if due > 0 and done.wait(due):
                        return
                session.feed(t_ns, data)
        finally:
            done.set()

    feeder = threading.Thread(target=feed_all, name="radarcl-replay", daemon=True)
    feeder.start()
    s = run(session, mapper, until=done.is_set, say=say)
    feeder.join()
    if records.torn and say is not None:
        say(f"the recording ends in a torn record ({records.torn} bytes left over: the writer was stopped mid-write)")
    return mapper, s, header


def over_pty(runtime, config, packets, faults=None, baud=None, saver=None, recorder=None, timeout_s=600):
    """Play ``packets`` (bytes) through the emulator on a fresh pseudo-terminal into a live
    session, as `radarcl live` reads a radar (the bench and the tests). Returns (mapper, status,
    emulator, intact flags per packet); ``mapper.fused_log`` lists the beams that reached the map."""
    faults = faults or emulator.Faults()
    master, name, slave = emulator.open_pty()
    try:
        session = Session(config.sensor, recorder)
        mapper = LiveMapper(runtime, config, saver)
        mapper.fused_log = []
        mapper.prepare()
        reader = PortReader(open_port(name), session.feed).start()      # reading before anything is sent
        damaged, intact = faults.apply(packets)
        emu = emulator.Emulator(damaged, lambda b: os.write(master, b), baud, faults).start()
        stop = threading.Event()
        timer = threading.Timer(timeout_s, stop.set)
        timer.start()
        try:
            s = run(session, mapper, until=lambda: emu.done.is_set() and session.counters.bytes_in >= emu.sent,
                    checkpoint_s=0.5 if saver is not None else 0, stop=stop)
        finally:
            timer.cancel()
            reader.stop()
            emu.stop()
        if stop.is_set():
            raise TimeoutError(f"the emulated stream did not arrive in {timeout_s} s")
        return mapper, s, emu, intact
    finally:
        os.close(master)
        os.close(slave)
