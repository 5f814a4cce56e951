"""`radarcl bench live`: the reference scene streamed beam by beam over a pseudo-terminal into
the live engine, as `radarcl live` runs it (emulator -> pty -> pyserial reader thread -> parser
-> beam-by-beam fusion).

Measured: at 921600 baud and at the pty's maximum rate, beams per second sustained, bytes per
second, the latency from a beam's last byte to its evidence in the map (median, p99) and the
parser's share of the CPU; with bit errors at 1e-4 and 1e-3, the share of the beams whose bytes
arrived intact that reached the map (resync must never lose one: 1.0) and the resync cost
(the time from a damaged packet's first byte to the end of the next packet delivered, at
921600 baud). The baseline, from the same
run: an engine that waits for whole frames, whose latency is a frame's airtime plus a
whole-frame fuse.
"""

import time

import numpy as np

BAUD = 921600


def _scene(frames):
    from radarcl.config.presets import EVALUATION_SEED
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_scene

    obs = observe(paper_scene(), PAPER_TILTS_DEG[:frames], seed=EVALUATION_SEED)
    return obs.samples, obs.poses


def stream_once(runtime, config, packets, baud, faults=None):
    """One run over a fresh pty: (status dict, intact flags, delivered (frame, az, el), chunk sizes)."""
    from radarcl.jobs import live

    mapper, s, _, intact = live.over_pty(runtime, config, packets, faults, baud)
    first = np.asarray(mapper.new_pose_latencies) * 1e3
    s["new_pose_first_fuse_max_ms"] = float(first.max()) if first.size else None
    s["latency_max_ms"] = float(np.max(mapper.latencies)) * 1e3 if mapper.latencies else None
    sizes = [len(d) for d in (faults.apply(packets)[0] if faults else packets)]
    return s, intact, mapper.fused_log, sizes


def run(voxel_m=0.1, frames=2, report=None):
    """Measure; returns the --json dict."""
    from radarcl.cl import Runtime
    from radarcl.config import mapconfig
    from radarcl.io import emulator
    from radarcl.pipeline import Mapping

    say = report or (lambda _: None)
    runtime = Runtime()
    config = mapconfig.resolve("paper", program={"grid.voxel_m": voxel_m})
    samples, poses = _scene(frames)
    packets = emulator.beam_packets(samples, poses)
    beams = samples.shape[1] * samples.shape[2]
    keys = [(j, i, k) for j in range(frames) for i in range(samples.shape[1]) for k in range(samples.shape[2])]
    result = dict(benchmark="live", device=runtime.name, voxel_m=voxel_m, frames=frames, beams=len(packets),
                  packet_bytes=len(packets[0]), baud=BAUD)
    for label, baud in (("921600", BAUD), ("max", None)):
        say(f"streaming {frames} frames at {label} baud ...")
        s, _, _, _ = stream_once(runtime, config, packets, baud)
        result[label] = {k: s[k] for k in ("beams", "beams_per_s", "bytes_per_s", "latency_p50_ms", "latency_p99_ms",
                                           "latency_max_ms", "new_pose_first_fuse_max_ms", "parser_cpu_share",
                                           "wall_s")}
    # the baseline: wait for a whole frame, then fuse it (same run, same device)
    whole = Mapping.from_config(runtime, config=config)
    whole.fuse(samples[0], poses[0])
    runtime.queue.finish()
    times = []
    for j in range(frames):
        start = time.perf_counter()
        whole.fuse(samples[j], poses[j])                  # planning a new pose included, as live does
        runtime.queue.finish()
        times.append(time.perf_counter() - start)
    frame_air_ms = beams * len(packets[0]) * 10 / BAUD * 1e3
    fuse_ms = float(np.median(times)) * 1e3
    result["whole_frame"] = dict(fuse_ms=fuse_ms, airtime_ms=frame_air_ms,
                                 latency_last_beam_ms=fuse_ms, latency_first_beam_ms=frame_air_ms + fuse_ms,
                                 latency_median_beam_ms=frame_air_ms / 2 + fuse_ms)
    live_p50 = result["921600"]["latency_p50_ms"]
    result["latency_ratio_vs_whole_frames"] = result["whole_frame"]["latency_median_beam_ms"] / live_p50 if live_p50 else None
    for ber in (1e-4, 1e-3):
        say(f"streaming with bit errors at {ber:g} ...")
        s, intact, delivered, sizes = stream_once(runtime, config, packets, None, emulator.Faults(ber=ber, seed=11))
        got = set(delivered)
        intact_keys = [k for k, ok in zip(keys, intact) if ok]
        offsets = np.cumsum([0] + sizes)
        resync = []                # from a damaged packet's first byte to the last byte of the next delivered one
        for i, ok in enumerate(intact):
            if not ok:
                j = next((j for j in range(i + 1, len(keys)) if keys[j] in got), None)
                if j is not None:
                    resync.append(offsets[j + 1] - offsets[i])
        result[f"ber_{ber:g}"] = dict(
            intact=len(intact_keys), delivered=len(got), intact_delivered=sum(k in got for k in intact_keys),
            intact_delivered_share=sum(k in got for k in intact_keys) / max(1, len(intact_keys)),
            delivered_not_intact=len(got - set(intact_keys)), crc_failures=s["crc_failures"],
            header_failures=s["header_failures"],
            resync_ms_p50=float(np.percentile(resync, 50)) * 10 / BAUD * 1e3 if resync else None,
            resync_ms_p99=float(np.percentile(resync, 99)) * 10 / BAUD * 1e3 if resync else None,
            packet_ms=len(packets[0]) * 10 / BAUD * 1e3)
    r = result["921600"]
    result.update(beams_per_s=r["beams_per_s"], latency_p50_ms=r["latency_p50_ms"], latency_p99_ms=r["latency_p99_ms"],
                  latency_max_ms=r["latency_max_ms"], new_pose_first_fuse_max_ms=r["new_pose_first_fuse_max_ms"],
                  intact_delivered_share={k: result[f"ber_{k}"]["intact_delivered_share"] for k in ("0.0001", "0.001")})
    return result


def format_table(r):
    lines = [f"live: {r['frames']} frames of the reference scene ({r['beams']} beams of {r['packet_bytes']} bytes) over a "
             f"pty into {r['voxel_m']} m voxels on {r['device']}"]
    for label in ("921600", "max"):
        x = r[label]
        lines.append(f"  {label:>7} baud: {x['beams_per_s']:7.0f} beams/s, {x['bytes_per_s'] / 1e3:8.1f} kB/s, latency "
                     f"p50 {x['latency_p50_ms']:6.1f} ms p99 {x['latency_p99_ms']:6.1f} ms max {x['latency_max_ms']:6.1f} ms "
                     f"(a new pose's first fuse: {x['new_pose_first_fuse_max_ms']:.1f} ms at most), parser CPU "
                     f"{100 * x['parser_cpu_share']:.1f} %")
    w = r["whole_frame"]
    lines.append(f"  baseline, whole frames: airtime {w['airtime_ms']:.0f} ms + fuse {w['fuse_ms']:.1f} ms: a beam waits "
                 f"{w['latency_median_beam_ms']:.0f} ms (median) -> live is {r['latency_ratio_vs_whole_frames']:.0f}x sooner")
    for ber in ("0.0001", "0.001"):
        x = r[f"ber_{float(ber):g}"]
        lines.append(f"  BER {ber}: {x['intact']} beams intact, {x['intact_delivered']} of them delivered "
                     f"(share {x['intact_delivered_share']:.3f}), {x['delivered_not_intact']} damaged delivered, "
                     f"damage to the next delivery p50 {_ms(x['resync_ms_p50'])} p99 {_ms(x['resync_ms_p99'])} at 921600 "
                     f"baud (one packet: {x['packet_ms']:.1f} ms)")
    return lines


def _ms(x):
    return "-" if x is None else f"{x:.1f} ms"


def add_arguments(parser):
    """`radarcl bench live` options."""
    from radarcl.commands.options import bounded_int, positive_float

    parser.add_argument("--voxel", type=positive_float, default=0.1, help="voxel [m] (default: %(default)s)")
    parser.add_argument("--frames", type=bounded_int(1, 15), default=2, help="frames streamed per run "
                                                                            "(default: %(default)s; 1.4 s each at 921600)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(args.voxel, args.frames, report=say)
    return result, format_table(result)
