"""`radarcl bench drive`: a whole drive in bounded memory.

The 11 Oxford scans (``navtech_oxford/radar``) replayed cyclically along the full 37-minute
odometry of ``navtech_oxford/full_seq_1_gt`` (8866 steps, about 9 km): real radar texture on a
real trajectory, but the scans REPEAT (scan j is file j mod 11, whatever the street), so the map
is not a map of Oxford; what it measures is the engine on a drive's length and motion. Each frame
is decoded from its PNG, sent to the device as its 8-bit levels (turned into power there,
``stages.levels``), CFAR'd, interpreted and fused at per-azimuth poses (the car moves during
the turn), into a rolling map (``maps.rolling``: the window's bricks on the device, the rest in
the map store, written as they leave).

Measured per run, each run in a process of its own (so one run's memory is not another's):
scans per second against the radar's 4 Hz (the real-time factor), the device's high-water mark
(the grid's pool chunks plus the pipeline's buffers; on a CPU device that memory is host memory
too), the host's (the process's resident set, sampled every frame), the store's size, and the
frame latency (from reading the PNG to the frame fused on the device, its wait for the device
included) p50 and p99. The next
scans are decoded on a reader thread while the device fuses (``io.prefetch``). The same drive
again, in blocks of frames read ahead and read inline (decode, then fuse) in turn, times the
overlap and its two parts under the same load (the machine's other work comes and goes; two runs
one after the other would compare two loads): end-to-end, decode-alone and fuse-alone rates
(medians over frames), and its map's digest against the first run's (they must agree). The baseline,
in the same run: today's unbounded grid on the same frames. Beside them: the memory of planar
(8 x 8 x 1) and cubic (8^3) bricks for the same scans, and the same integers in both.
"""

import hashlib
import math
import multiprocessing
import os
import queue as queues
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError
from radarcl.io import polar_png, prefetch

RADAR_HZ = 4.0                      # the CTS350-X turns at 4 Hz
DEFAULT_VOXEL_M = 0.2
MEMORY_SCANS = 22                   # scans of the planar / cubic memory comparison (twice the 11)
ALTERNATE = 10                      # scans a block when reading ahead and reading inline take turns
MIN_BLOCK = 3                       # the least block with a frame read beside one fused and fused beside one read
MIN_SCANS = 2 * MIN_BLOCK           # the least drive that times the overlap: a block of each kind


def _paths(data):
    data = Path(data)
    scans = sorted((data / "radar").glob("*.png"))
    seq = data / "full_seq_1_gt"
    if len(scans) < 1 or not (seq / "radar_odometry.csv").is_file() or not (seq / "radar.timestamps").is_file():
        from radarcl.errors import ConfigError

        raise ConfigError(f"{data}: expected radar/*.png and full_seq_1_gt/radar_odometry.csv and radar.timestamps "
                          "(the Oxford set of ../shared/data, see its README)")
    return scans, seq


def drive_track(data):
    """(Trajectory of the whole drive, the radar's scan times [ns] within it (n,)): the odometry
    chained (``io.poses``, Oxford format) and the sequence's scan timestamps."""
    from radarcl.io import poses as pose_files

    _, seq = _paths(data)
    track = pose_files.read_trajectory(seq / "radar_odometry.csv", "oxford")
    stamps = np.loadtxt(seq / "radar.timestamps", dtype=np.int64, usecols=0) * 1000
    lo, hi = track.times_ns[0], track.times_ns[-1]
    return track, stamps[(stamps >= lo) & (stamps <= hi)]


def frame_poses(track, start_ns, period_ns, scan, n_az):
    """(n_az, 4, 4) per-azimuth poses of ``scan`` replayed at ``start_ns``: the drive's pose at
    each azimuth's time (the scan's own azimuth times, moved to start there, within one period),
    turned by the azimuth's measured angle less the lattice's (``scan_poses.azimuth_turns``)."""
    from radarcl.io import scan_poses

    t = scan_poses.azimuth_times(scan)
    frac = (t - t.min()) / max(float(np.ptp(t)), 1.0) * (n_az - 1) / n_az
    hi = track.times_ns[-1]
    moved = track.at(np.minimum(start_ns + np.rint(frac * period_ns).astype(np.int64), hi))
    return moved @ scan_poses.azimuth_turns(scan.angles_rad, n_az)


def _rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _stage_bytes(mapping):
    """Device bytes of the pipeline's own buffers (levels, CFAR, eq. 12, fusion inputs)."""
    total = 0
    for stage in (mapping.range_fft, mapping.levels, mapping.detection.cfar, mapping.detection.interpreter,
                  mapping.fusion):
        if stage is not None:
            total += sum(int(a.nbytes) for a in stage.arrays.values())
    return total


def _config(voxel_m, n_bins, range_m=None):
    from radarcl.config import mapconfig

    program = {"grid.voxel_m": voxel_m}
    if range_m is not None:
        program["interpret.range_max_m"] = float(range_m)
    config = mapconfig.resolve("navtech-cts350x", program=program)
    if config.sensor.n_bins() is None:
        config = config.for_sensor(config.sensor.with_bins(n_bins))
    return config


def map_digest(keys, channels):
    """SHA-256 of a map's bricks: ``keys`` (n, 3) and ``channels`` (name -> (n, ...) int32 in
    the keys' order), taken in key order (the same map digests the same whatever its slots)."""
    keys = np.asarray(keys, np.int32)
    order = np.lexsort(keys.T[::-1])
    h = hashlib.sha256(keys[order].tobytes())
    for name in sorted(channels):
        h.update(name.encode())
        h.update(np.ascontiguousarray(np.asarray(channels[name], np.int32)[order]).tobytes())
    return h.hexdigest()


def _store_digest(store):
    from radarcl.maps import disk

    _, keys, data, _, channels = disk.read_map(store)
    arrays = {"evidence": data}
    if channels is not None:
        arrays.update(knowledge=channels.knowledge, looks=channels.looks)
    return map_digest(keys, arrays)


def run_drive(data, n_frames, voxel_m=DEFAULT_VOXEL_M, window_m=None, store=None, brick_z=1, progress=True,
              picture=None, first=0, range_m=None, read_ahead=prefetch.DEFAULT_DEPTH, alternate=None):
    """One drive of ``n_frames`` frames from frame ``first`` (in this process): rolling with
    ``window_m`` into the store ``store``, or unbounded (``window_m`` None); ``range_m``: map out
    to this range (default: the sensor's); ``read_ahead``: frames decoded ahead on a reader
    thread while the device fuses (0: decoded inline, one after the other); ``alternate``: blocks
    of this many frames read ahead and read inline in turn (``io.prefetch``'s ``overlap``), which
    times the overlap and its parts under the same load (``overlap_figures``). Returns its figures
    (a dict): with the seconds spent reading frames (``read_s``: decoding, converting, posing)
    and fusing them (``fuse_s``: from the frame in hand to its fusion finished on the device),
    each summed over the frames, and the map's digest (``map_digest``)."""
    from radarcl.cl import Runtime
    from radarcl.io import polar_png
    from radarcl.jobs.fuse import drive_spec
    from radarcl.maps.rolling import RollingStore, RollingWindow
    from radarcl.oracle import FLAG_SILENT
    from radarcl.pipeline import Mapping, new_grid

    if alternate is not None and (read_ahead != 1 or int(alternate) < MIN_BLOCK):
        raise ConfigError(f"timing the overlap (alternate={alternate!r}) takes blocks of at least {MIN_BLOCK} frames "
                          f"read one ahead (read_ahead=1, got {read_ahead!r}): inline frames are held back only then")
    scans, _ = _paths(data)
    track, stamps = drive_track(data)
    stamps = stamps[int(first):]
    n_frames = min(int(n_frames), len(stamps) - 1)
    runtime = Runtime()
    layout = polar_png.PolarLayout.of(_config(voxel_m, 1).sensor)
    first_scan = polar_png.load_scan(scans[0], layout)
    config = _config(voxel_m, first_scan.n_bins, range_m)
    n_az = config.sensor.n_azimuth
    spec = drive_spec(config, track.at(stamps[:n_frames + 1])[:, :3, 3])
    if brick_z != spec.brick_z:
        from radarcl.gridspec import GridSpec

        spec = GridSpec(spec.origin_m, spec.voxel_m, spec.shape, brick_z)
    grid = new_grid(runtime, config, spec)
    mapping = Mapping.from_config(runtime, config=config, grid=grid, per_beam_poses=True)
    rolling = backing = None
    if window_m is not None:
        rolling = RollingWindow(grid, None, window_m)
        rolling.check_reach(mapping.fusion.r_hi)
        backing = RollingStore(store, spec, config.sensor.toml(), config.as_dict(), overwrite=True,
                               reading=config.reading())
        rolling.backing = grid.backing = backing

    def read(j):
        """Frame j as the device takes it, with when its reading began and how long it took."""
        t0 = time.perf_counter()
        scan = polar_png.load_scan(scans[j % len(scans)], layout)              # decoding counts
        poses = frame_poses(track, int(stamps[j]), int(stamps[j + 1] - stamps[j]), scan, n_az)
        flags = np.where(scan.valid, 0, FLAG_SILENT).astype(np.uint8)
        # the device turns levels (their rows' differences, as the file holds them) into power
        return scan.coded_levels, scan.differenced, poses, flags, t0, time.perf_counter() - t0

    latencies, device_max, host_max, trajectory, bricks_max = [], 0, _rss_bytes(), [], 0
    read_s = fuse_s = 0.0
    overlap = None if alternate is None else (lambda j: (j // alternate) % 2 == 0)
    times = dict(overlapped=[], read=[], fused=[])          # per frame, for ``overlap_figures``
    start = t3 = time.perf_counter()
    for j, (levels, differenced, poses, flags, t0, took) in enumerate(prefetch.prefetched(read, n_frames, read_ahead,
                                                                                        overlap)):
        t1, before = time.perf_counter(), t3       # from the last frame's bookkeeping done, as fused alone leaves it out
        if rolling is not None:
            rolling.update(poses[n_az // 2, :3, 3])
        mapping.fuse(levels, poses, flags=flags, db_per_level=layout.db_per_level, differenced=differenced)
        runtime.queue.finish()
        t2 = time.perf_counter()
        read_s, fuse_s = read_s + took, fuse_s + (t2 - t1)
        if overlap is not None:
            if 0 < j < n_frames - 1 and overlap(j) and overlap(j + 1):   # read beside the last fuse, fused beside the next read
                times["overlapped"].append(t2 - before)
            if not overlap(j):
                times["read"].append(took)                  # read with nothing beside it
            if not overlap(j + 1):
                times["fused"].append(t2 - t1)              # fused with nothing read beside it
        latencies.append(t2 - t0)             # from reading the PNG, waiting in the queue included
        trajectory.append(poses[n_az // 2].copy())               # a copy: a view would keep the frame's poses
        device_max = max(device_max, grid.memory()["device_bytes"] + _stage_bytes(mapping))
        bricks_max = max(bricks_max, grid.n_bricks)
        host_max = max(host_max, _rss_bytes())
        if progress and (j + 1) % 10 == 0:
            print(f"  {'rolling' if rolling else 'unbounded'} ({brick_z}-deep bricks, read ahead {read_ahead}): "
                  f"{j + 1}/{n_frames} scans, {(j + 1) / (time.perf_counter() - start):.2f} scans/s, device "
                  f"{device_max / 2**20:.0f} MiB, host {host_max / 2**20:.0f} MiB", file=sys.stderr, flush=True)
        t3 = time.perf_counter()                    # the bench's own bookkeeping ends: the next interval begins
    wall_s = time.perf_counter() - start
    result = dict(frames=n_frames, drive_s=float(stamps[n_frames] - stamps[0]) / 1e9, wall_s=wall_s,
                  scans_per_s=n_frames / wall_s, read_s=read_s, fuse_s=fuse_s, read_ahead=read_ahead,
                  device_mib_max=device_max / 2**20, host_mib_max=host_max / 2**20,
                  latency_p50_ms=float(np.percentile(latencies, 50)) * 1e3,
                  latency_p99_ms=float(np.percentile(latencies, 99)) * 1e3,
                  grid=f"{spec.shape[0]} x {spec.shape[1]} x {spec.shape[2]} at {spec.voxel_m:g} m",
                  device=runtime.name, brick_z=brick_z, device_bricks_max=bricks_max)
    result["realtime_factor"] = result["drive_s"] / wall_s
    if overlap is not None:
        result.update(alternate=alternate, **{f"{k}_frames": len(v) for k, v in times.items()},
                      **{f"{k}_median_s": float(np.median(v)) if v else math.nan for k, v in times.items()})
    if rolling is not None:
        t0 = time.perf_counter()
        stored = rolling.finish(dict(poses=np.asarray(trajectory).reshape(-1, 16).tolist()))
        result.update(finish_s=time.perf_counter() - t0, bricks=stored, evicted=rolling.evicted,
                      restored=backing.stats["restored"], restored_from_disk=backing.stats["restored_from_disk"],
                      store_mib=sum(f.stat().st_size for f in Path(store).rglob("*") if f.is_file()) / 2**20,
                      window_m=rolling.window_m, map_digest=_store_digest(store))
    else:
        mem = grid.memory()
        keys, channels = grid.read_slots(grid.live_slots(), channels=grid.channels)
        result.update(bricks=mem["bricks"], map_mib=mem["bricks"] * spec.brick_bytes / 2**20,
                      map_digest=map_digest(keys, channels))
    if picture is not None and rolling is not None:
        drive_picture(store, np.asarray(trajectory), picture, n_frames)
    return result


def drive_picture(store, trajectory, png, n_frames):
    """The drive's map from above: one pixel per brick (its most telling voxel: the largest
    log-odds where positive, else the smallest), the trajectory in black. The image is
    (ny, nx), as ``figures.plane_map_figure`` takes it."""
    from radarcl import logodds
    from radarcl.gridspec import BRICK, GridSpec
    from radarcl.maps import disk
    from radarcl.report import figures

    spec, keys, data = disk.read(store)
    flat = data.reshape(len(data), -1).astype(np.int64)
    hi, lo = flat.max(axis=1), flat.min(axis=1)
    telling = np.where(hi > 0, hi, lo)
    nbx, nby, _ = spec.brick_shape
    image = np.zeros((nby, nbx))
    image[keys[:, 1], keys[:, 0]] = telling / logodds.SCALE
    coarse = GridSpec(spec.origin_m, spec.voxel_m * BRICK, (nbx, nby, 1))
    fig = figures.plane_map_figure(image, coarse, trajectory[::20],
                                   f"bench drive: {n_frames} Oxford scans (the 11 scans repeat)\nalong the "
                                   f"full_seq_1 odometry, {spec.voxel_m:g} m voxels;\none pixel per "
                                   f"{BRICK} x {BRICK} brick (its most telling voxel)", "sensor path (every 20th scan)",
                                   "most telling log-odds of the brick [nat]")
    figures.save(fig, png, dpi=110)


def _child(queue, kwargs):
    from radarcl import self_test

    self_test.register()                         # a spawned process: the device check its parent registered
    try:
        queue.put(("ok", run_drive(**kwargs)))
    except Exception as exc:                     # noqa: BLE001 - said by the parent
        queue.put(("error", f"{type(exc).__name__}: {exc}"))


def in_process(**kwargs):
    """``run_drive`` in a fresh process (its memory high-water marks are its own). A process that
    dies without answering (killed for memory, a driver's crash) is an error, not a wait for ever."""
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    p = ctx.Process(target=_child, args=(queue, kwargs))
    p.start()
    status, value = _answer(queue, p)
    p.join()
    if status != "ok":
        from radarcl.errors import RadarclError

        raise RadarclError(f"the drive failed: {value}")
    return value


def _answer(queue, process, poll_s=1.0):
    """The child's (status, value), or ("error", why) once it has ended without putting one."""
    while True:
        try:
            return queue.get(timeout=poll_s)
        except queues.Empty:
            if not process.is_alive():
                try:                                # it may have answered just before it ended
                    return queue.get(timeout=poll_s)
                except queues.Empty:
                    return "error", f"its process ended (exit code {process.exitcode}) without a result"


def memory_ratio(data, voxel_m, n_frames=MEMORY_SCANS):
    """Planar (8 x 8 x 1) against cubic (8^3) bricks, unbounded, for the same scans: device
    bytes of the map's bricks, and whether the integers agree."""
    planar = in_process(data=data, n_frames=n_frames, voxel_m=voxel_m, brick_z=1, progress=False)
    cubic = in_process(data=data, n_frames=n_frames, voxel_m=voxel_m, brick_z=8, progress=False)
    return dict(frames=n_frames, planar_map_mib=planar["map_mib"], cubic_map_mib=cubic["map_mib"],
                planar_device_mib=planar["device_mib_max"], cubic_device_mib=cubic["device_mib_max"],
                ratio=planar["map_mib"] / cubic["map_mib"], bricks=(planar["bricks"], cubic["bricks"]))


def run(data, minutes=None, scans=None, voxel_m=DEFAULT_VOXEL_M, window_m=None, baseline_scans=None, picture=None,
        report=None, memory_scans=MEMORY_SCANS):
    """The bench: the rolling drive, the unbounded baseline on the same frames (or its first
    ``baseline_scans``), the planar / cubic memory on ``memory_scans``; returns the --json dict."""
    say = report or (lambda _: None)
    track, stamps = drive_track(data)
    n = len(stamps) - 1
    if scans is not None:
        n = min(n, int(scans))
    if minutes is not None:
        n = min(n, int(np.searchsorted(stamps, stamps[0] + minutes * 60e9)))
    if n < MIN_SCANS:
        raise ConfigError(f"the drive has {n} scans; bench drive times reading ahead against reading inline on at "
                          f"least {MIN_SCANS} (--scans, --minutes)")
    from radarcl.config import mapconfig

    if window_m is None:
        window_m = 1.5 * float(mapconfig.resolve("navtech-cts350x")["interpret.range_max_m"])
    load = os.getloadavg()
    tmp = Path(tempfile.mkdtemp(prefix="radarcl-drive-"))
    try:
        say(f"rolling drive: {n} scans (the 11 Oxford scans repeat) along the full_seq_1 odometry, {voxel_m:g} m "
            f"voxels, window {window_m:g} m ...")
        rolling = in_process(data=data, n_frames=n, voxel_m=voxel_m, window_m=window_m, store=tmp / "drive.rcmap",
                             picture=picture)
        block = max(MIN_BLOCK, min(ALTERNATE, n // 4))      # a short drive still has frames of each kind
        say(f"the same drive, blocks of {block} scans read ahead and read inline (decoding, then fusing) in "
            f"turn: end-to-end, decode-alone and fuse-alone times under the same load ...")
        timing = in_process(data=data, n_frames=n, voxel_m=voxel_m, window_m=window_m, store=tmp / "timing.rcmap",
                            alternate=block)
        nb = n if baseline_scans is None else min(n, int(baseline_scans))
        say(f"baseline: today's unbounded grid on the first {nb} of those scans ...")
        baseline = in_process(data=data, n_frames=nb, voxel_m=voxel_m)
        say(f"planar vs cubic bricks on {memory_scans} scans ...")
        memory = memory_ratio(data, voxel_m, memory_scans)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    result = dict(benchmark="drive", scans_repeat=True, frames=n, whole_drive_frames=len(stamps) - 1,
                  voxel_m=voxel_m, window_m=window_m, load_before=list(load), load_after=list(os.getloadavg()),
                  rolling=rolling, timing=timing, baseline=baseline, baseline_prefix=nb < n, memory=memory,
                  overlap=overlap_figures(timing, rolling))
    for k in ("realtime_factor", "device_mib_max", "host_mib_max", "latency_p50_ms", "latency_p99_ms"):
        result[k] = rolling[k]
    return result


def overlap_figures(timing, overlapped):
    """The reader thread's worth, from a drive read ahead and read inline in turn (``timing``:
    ``run_drive`` with ``alternate``): end-to-end scans/s where reading overlaps fusing (the
    median time between two frames fused), decode-alone and fuse-alone scans/s (the medians of
    the inline frames' reading and fusing, timed apart), the end-to-end rate over the fuse-alone
    one; and whether its map is the map of the drive read ahead throughout (``overlapped``)."""
    return dict(end_to_end_per_s=1 / timing["overlapped_median_s"], decode_alone_per_s=1 / timing["read_median_s"],
                fuse_alone_per_s=1 / timing["fused_median_s"],
                end_to_end_over_fuse_alone=timing["fused_median_s"] / timing["overlapped_median_s"],
                frames=(timing["overlapped_frames"], timing["read_frames"], timing["fused_frames"]),
                same_map=overlapped["map_digest"] == timing["map_digest"])


def format_table(r):
    ro, b, m = r["rolling"], r["baseline"], r["memory"]
    lines = [f"drive: {r['frames']} of the {r['whole_drive_frames']} scans of the 37-minute full_seq_1 odometry "
             f"({ro['drive_s'] / 60:.1f} min of driving), the 11 Oxford scans REPEATED cyclically along it, "
             f"{r['voxel_m']:g} m voxels, grid {ro['grid']}, on {ro['device']} "
             f"(load {r['load_before'][0]:.1f} before, {r['load_after'][0]:.1f} after)"]
    for name, x in (("rolling, window %g m" % r["window_m"], ro), ("baseline, unbounded" + (
            f" (first {b['frames']} scans)" if r["baseline_prefix"] else ""), b)):
        lines.append(f"  {name:32s} {x['scans_per_s']:6.2f} scans/s = {x['realtime_factor']:5.2f}x real time, device "
                     f"{x['device_mib_max']:7.1f} MiB, host {x['host_mib_max']:7.1f} MiB, frame latency p50 "
                     f"{x['latency_p50_ms']:6.0f} ms p99 {x['latency_p99_ms']:6.0f} ms, {x['bricks']} bricks")
    o = r["overlap"]
    lines.append(f"  reading ahead on a thread (medians of {o['frames'][0]} frames read ahead, {o['frames'][1]} read and "
                 f"{o['frames'][2]} fused alone, in turn): end-to-end {o['end_to_end_per_s']:.2f} scans/s = "
                 f"{o['end_to_end_over_fuse_alone']:.2f}x fuse-alone {o['fuse_alone_per_s']:.2f} scans/s; "
                 f"decode-alone {o['decode_alone_per_s']:.2f} scans/s; "
                 f"maps {'bit-identical' if o['same_map'] else 'DIFFER'} read ahead throughout and in turns")
    lines.append(f"  rolling store {ro['store_mib']:.1f} MiB ({ro['bricks']} bricks; {ro['evicted']} left the window, "
                 f"{ro['restored']} came back, {ro['restored_from_disk']} read from disk; finishing {ro['finish_s']:.2f} s)")
    lines.append(f"  planar vs cubic bricks, {m['frames']} scans unbounded: {m['planar_map_mib']:.1f} MiB vs "
                 f"{m['cubic_map_mib']:.1f} MiB of bricks = {m['ratio']:.3f} ({m['bricks'][0]} and {m['bricks'][1]} "
                 f"bricks); device incl. pool chunks and buffers {m['planar_device_mib']:.0f} vs "
                 f"{m['cubic_device_mib']:.0f} MiB")
    return lines


def add_arguments(parser):
    """`radarcl bench drive` options."""
    from radarcl.commands.options import default_data, positive_float, positive_int

    parser.add_argument("--data", default=None, help="the Oxford set (default: ../shared/data/navtech_oxford)")
    parser.add_argument("--minutes", type=positive_float, default=None, help="drive only this many minutes of it")
    parser.add_argument("--scans", type=positive_int, default=None, help="drive only this many scans of it")
    parser.add_argument("--voxel", type=positive_float, default=DEFAULT_VOXEL_M, help="voxel [m] (default: %(default)s)")
    parser.add_argument("--window", type=positive_float, default=None,
                        help="the rolling window [m] (default: 1.5 x the mapped range)")
    parser.add_argument("--baseline-scans", type=positive_int, default=None,
                        help="run the unbounded baseline on only the first N scans (default: all of them)")
    parser.add_argument("--picture", default=None, metavar="PNG", help="write the drive's map from above here")
    parser.set_defaults(data_default=default_data("navtech_oxford"))


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    data = args.data or args.data_default
    result = run(data, args.minutes, args.scans, args.voxel, args.window, args.baseline_scans, args.picture,
                 report=lambda line: print(line, file=sys.stderr))
    return result, format_table(result)
