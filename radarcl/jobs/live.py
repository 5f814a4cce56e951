"""`radarcl live` and `radarcl replay`: the loop that fuses a radar's byte stream into a map as
it arrives (``livemap``: the session and the mapper it runs). The live map, a replay of its
recording and an offline fusion of the same beams are bit-identical.

The map is saved every ``checkpoint_s`` (a map store writes the changed bricks only): a crash
loses at most the beams since the last checkpoint, whose count the store's manifest keeps
("stream"). Ctrl-C finishes the fuse under way, saves and ends with a summary.
"""

import contextlib
import json
import os
import signal
import threading
import time

import numpy as np

from radarcl.errors import FrameFormatError, RadarclError, Terminated
from radarcl.io import emulator
from radarcl.io.files import atomic
from radarcl.io.stream import PortReader, StreamCounters, open_port, read_stream
from radarcl.livemap import LiveMapper, Session


def status(mapper, counters, wall_s, parse_s, final=False):
    """The figures a status line and ``--json-status`` show: latency percentiles over the beams
    fused in the last ``LiveMapper.LATENCY_WINDOW_S`` seconds (over the whole run when
    ``final``), so the start-up does not hold the p99 up for the rest of the run."""
    lat = np.asarray(mapper.latencies if final else mapper.recent_latencies()) * 1e3
    c = counters.as_dict() if isinstance(counters, StreamCounters) else dict(counters)
    return dict(beams=mapper.stats["beams"], frames=mapper.stats["frames"], beams_per_s=mapper.stats["beams"] / max(wall_s, 1e-9),
                bytes_per_s=c["bytes_in"] / max(wall_s, 1e-9),
                latency_p50_ms=float(np.percentile(lat, 50)) if lat.size else None,
                latency_p99_ms=float(np.percentile(lat, 99)) if lat.size else None,
                latency_window_s=None if final else mapper.LATENCY_WINDOW_S,
                parser_cpu_share=parse_s / max(wall_s, 1e-9), wall_s=wall_s,
                saved_beams=mapper.stats["saved_beams"], checkpoints=mapper.stats["checkpoints"],
                duplicates=mapper.stats["duplicates"] + c["duplicates"], refused=mapper.stats["refused"],
                bad_poses=mapper.stats["bad_poses"], beams_missing=mapper.missing(),
                late=mapper.stats["late"], **{k: c[k] for k in ("bytes_in", "bytes_dropped", "crc_failures",
                                                                   "header_failures", "sequence_gaps", "packets")})


def status_line(s):
    lat = "-" if s["latency_p50_ms"] is None else f"{s['latency_p50_ms']:.0f}/{s['latency_p99_ms']:.0f} ms"
    window = f" (last {s['latency_window_s']:g} s)" if s.get("latency_window_s") else ""
    return (f"live: {s['beams']} beams in {s['frames']} frames ({s['beams_per_s']:.0f}/s, "
            f"{s['bytes_per_s'] / 1e3:.1f} kB/s), latency p50/p99{window} {lat}, dropped {s['bytes_dropped']} B, "
            f"CRC {s['crc_failures']}, missing {s['beams_missing']}, saved {s['saved_beams']}")


def write_status(path, s):
    """``--json-status``: the status as JSON, replaced atomically."""
    with atomic(path) as tmp:
        with open(tmp, "w") as f:
            json.dump(s, f)


@contextlib.contextmanager
def stop_on_signals(stop):
    """While the block runs (in the main thread), Ctrl-C and SIGTERM set ``stop`` instead of
    raising wherever the main thread happens to be (halfway through taking beams from the queue
    would lose them); ``stop.signal`` says which came. Elsewhere nothing changes."""
    stop.signal = None
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def asked(signum, frame):
        stop.signal = signum
        stop.set()

    previous = {sig: signal.signal(sig, asked) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run(session, mapper, *, until=None, checkpoint_s=5.0, status_every_s=1.0, say=None, json_status=None,
        stop=None, after_fuse=None, stop_feeding=None):
    """The mapper's loop: fuse what arrives, checkpoint every ``checkpoint_s``, report status,
    until ``until()`` is true and nothing is left, or ``stop`` (an Event) is set, or Ctrl-C /
    SIGTERM (the fuse under way finishes). Then ``stop_feeding()`` (after it returns no byte
    reaches the session), every beam parsed so far is fused, those waiting for their pair too,
    and the map is saved: the map holds every beam whose bytes arrived, as a replay of the
    recording does. SIGTERM is raised again after the save (``errors.Terminated``).
    ``after_fuse()`` runs after each pass (the view stream). Returns the final status dict."""
    start = last_save = last_status = time.perf_counter()
    stop = stop if stop is not None else threading.Event()
    interrupted = None
    with stop_on_signals(stop):
        try:
            while not stop.is_set():
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
                    break
        except KeyboardInterrupt as exc:
            interrupted = exc
        if stop.signal is not None:
            interrupted = stop.signal
        if stop_feeding is not None:
            stop_feeding()
        while not session.beams.empty():
            mapper.add(session.drain(wait=0))
        mapper.flush()
        if mapper.stats["beams"]:
            mapper.save(extra=dict(counters=session.counters.as_dict()))
        if after_fuse is not None:
            after_fuse()
    s = status(mapper, session.counters, time.perf_counter() - start, session.parse_s, final=True)
    if json_status:
        write_status(json_status, s)
    if interrupted == signal.SIGTERM:
        raise Terminated()
    s["interrupted"] = interrupted is not None
    return s


MAX_GAP_S = emulator.MAX_GAP_S     # --speed recorded: a longer silence in a recording is skipped


def replay(path, mapper_factory, speed="max", say=None):
    """Feed a ``--record`` stream file through the same parser and mapper: at the recorded pace
    (``speed`` "recorded"; a silence longer than ``MAX_GAP_S`` is a clock that jumped: skipped,
    and said) or as fast as it parses ("max"). Returns (mapper, status, header); a
    recording damaged part way raises ``FrameFormatError`` after the beams before the damage
    are fused and saved."""
    header, records = read_stream(path)
    sensor, mapper = mapper_factory(header)
    session = Session(sensor)
    done, stopped = threading.Event(), threading.Event()
    failure, cut = [], []

    def feed_all():
        last_t, due = None, time.perf_counter()
        try:
            for t_ns, data in records:
                if stopped.is_set():
                    return
                if speed == "recorded" and last_t is not None:
                    gap = (t_ns - last_t) / 1e9
                    if gap > MAX_GAP_S:
                        cut.append(gap)
                    due += 0.0 if gap > MAX_GAP_S else max(gap, 0.0)     # a clock that runs back: no wait
                    wait = due - time.perf_counter()
                    if wait > 0 and stopped.wait(wait):
                        return
                last_t = t_ns
                session.feed(t_ns, data)
        except Exception as exc:                     # noqa: BLE001 - said on the main thread, after the save
            failure.append(exc)
        finally:
            done.set()

    feeder = threading.Thread(target=feed_all, name="radarcl-replay", daemon=True)
    feeder.start()

    def stop_feeding():
        stopped.set()
        feeder.join()

    s = run(session, mapper, until=done.is_set, say=say, stop_feeding=stop_feeding)
    if cut and say is not None:
        say(f"the recording's clock jumps {len(cut)} time(s) by up to {max(cut):.3g} s; each jump (a silence over "
            f"{MAX_GAP_S:g} s) was skipped")
    if records.torn and say is not None:
        say(f"the recording ends in a torn record ({records.torn} bytes left over: the writer was stopped mid-write)")
    if failure:
        exc = failure[0]
        if not isinstance(exc, RadarclError):
            raise exc
        raise FrameFormatError(f"{exc}; the map holds the {s['beams']} beams before the damage")
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
