"""`radarcl bench all`: every benchmark that tells a device apart, in one run, into one JSON.

Made for a lent GPU, whose minutes are few: the range FFT, CFAR + eq. 12, the fusion (a still, a
moving and a spinning radar, planning, the whole pipeline, and the detection-statistics model,
the default, which the fusion bench times beside eq. 12), the live engine, a drive and the viewer,
each through its own module's ``run`` at a size (``SUITE``) that keeps the whole run within about
5 minutes on a GPU; ``--quick`` is a smoke run of a minute or two. Nothing is measured here: each
bench measures its figures and its baseline in the same run, as ``radarcl bench NAME`` does, and
this module only picks the headline rows (``rows`` of each entry) from the result the bench
returns: the ratio the bench itself prints, or, where it prints a figure and its baseline side by
side without one, their quotient (``_over``), each with which way round it is.

The JSON: the device's name and limits (``DeviceLimits``), the CPU, the load average before and
after (the run's and each bench's), radarcl's version and the date; per bench its sizes, wall
time, headline rows, its own table lines and its whole result, or its error sentence (and
traceback) when it failed. It is rewritten after every bench (``"complete": false`` until the
end), so a run stopped by a time limit keeps what it measured. A bench that fails does not stop
the others; the exit status is 1 when one failed, 0 when none did.
"""

import argparse
import dataclasses
import datetime
import json
import math
import os
import platform
import sys
import time
import traceback

from radarcl.bench import cfar, drive, fusion, live, range_fft, viewer
from radarcl.commands.options import default_data
from radarcl.errors import RadarclError
from radarcl.io import files

SUMMARY = "every benchmark that tells a device apart (range FFT, CFAR, fusion, live, drive, viewer) into one JSON"
DESCRIPTION = ("Runs the benchmarks that tell a device apart (range FFT, CFAR + eq. 12, fusion: still, moving and "
               "spinning radar, planning, the whole pipeline and the detection-statistics model; live; drive; "
               "viewer), each at a size that keeps the run within about 5 minutes on a GPU (--quick: a smoke run of "
               "a minute or two), and prints one table: benchmark, figure, unit, baseline and the bench's ratio to "
               "it, measured in the same run. --json also keeps the device's limits, the CPU, the load average and "
               "every bench's whole result. A bench that fails is recorded with its error and the others run; the "
               "exit status is 1 when one failed.")
FIGURE_OF_BASELINE = "figure / baseline"        # how a row's ratio is formed (the bench's own ratio)
BASELINE_OF_FIGURE = "baseline / figure"


@dataclasses.dataclass(frozen=True)
class Entry:
    """One bench of the suite: ``measure(device, say, **size)`` runs it and returns its result
    dict; ``full`` and ``quick`` are its sizes; ``rows(result)`` its headline rows (``row``)."""

    module: object
    measure: object
    full: dict
    quick: dict
    rows: object


def row(figure, value, unit, baseline=None, baseline_value=None, ratio=None, ratio_is=None):
    """A headline row: ``figure`` measured at ``value`` ``unit``; ``baseline`` names what it is
    compared with in the same run (its value in the same unit), ``ratio`` the bench's ratio and
    ``ratio_is`` how it is formed (``FIGURE_OF_BASELINE`` or ``BASELINE_OF_FIGURE``)."""
    return dict(figure=figure, value=value, unit=unit, baseline=baseline, baseline_value=baseline_value,
                ratio=ratio, ratio_is=ratio_is)


# -- the benches: how each is run, and its headline rows ---------------------------------------------
def _over(a, b):
    """a / b, or None where either is missing or b is 0 (a ratio this module forms itself)."""
    return None if a is None or not b else a / b


def _range_fft_rows(r):
    rows = []
    for x in r["runs"]:
        rows.append(row(f"kernel + upload, n_fft {x['n_fft']}", x["ms_per_frame"], "ms/frame", "scipy.fft",
                        x["scipy_ms_per_frame"], x["ratio_vs_scipy"], FIGURE_OF_BASELINE))
    rows.append(row(f"max rel error vs float64, n_fft {r['n_fft']}", r["max_rel_err"], "", "scipy.fft",
                    r["scipy_max_rel_err"]))
    return rows


def _cfar_rows(r):
    return [row("CFAR + eq. 12, upload included", r["ms_per_frame"], "ms/frame", "numpy (cumulative sums)",
                r["numpy_ms_per_frame"], r["ratio_vs_numpy"], BASELINE_OF_FIGURE),
            row("mask mismatches vs float64", r["mask_mismatches"], "bins"),
            row("evidence error vs float64", r["evidence_max_abs_err_units"], "units", "numpy",
                r["numpy_evidence_max_abs_err_units"])]


def _fusion(device, say, repeat, voxel_m):
    """The fusion bench on the paper's grid and the spinning radar's, both at ``voxel_m`` (same
    extent; the paper's 0.1 m unless a quick run coarsens it)."""
    return fusion.run(device(), repeat=repeat, report=say, spec=_at_voxel(fusion.PAPER_GRID, voxel_m),
                      spin_spec=_at_voxel(fusion.SPIN_GRID, voxel_m))


def _at_voxel(spec, voxel_m):
    """``spec``'s extent at ``voxel_m`` (``spec`` itself at its own voxel)."""
    if voxel_m == spec.voxel_m:
        return spec
    shape = tuple(max(1, round(n * spec.voxel_m / voxel_m)) for n in spec.shape)
    return dataclasses.replace(spec, voxel_m=voxel_m, shape=shape)


def _fusion_rows(r):
    floor, spin_floor = r["floor_ms_per_frame"], r["spinning_floor_ms_per_frame"]
    return [
        row("still radar", r["still_ms_per_frame"], "ms/frame", "memory floor", floor, r["ratio_vs_floor"],
            FIGURE_OF_BASELINE),
        row("still radar, vs the oracle", r["still_ms_per_frame"], "ms/frame", "float64 numpy oracle",
            r["numpy_ms_per_frame"], r["ratio_vs_numpy"], BASELINE_OF_FIGURE),
        row("moving radar, planning included", r["moving_ms_per_frame"], "ms/frame", "memory floor", floor,
            _over(r["moving_ms_per_frame"], floor), FIGURE_OF_BASELINE),
        row("planning a new pose", r["planning_ms"], "ms", "numpy windows", r["planning_ms_numpy"],
            _over(r["planning_ms_numpy"], r["planning_ms"]), BASELINE_OF_FIGURE),
        row("spinning radar, still", r["spinning_ms_per_frame"], "ms/frame", "memory floor", spin_floor,
            _over(r["spinning_ms_per_frame"], spin_floor), FIGURE_OF_BASELINE),
        row("whole pipeline, still", r["pipeline_ms_per_frame"], "ms/frame"),
        row("detection statistics, gather", r["detstats_gather_ms_per_frame"], "ms/frame", "eq. 12's gather",
            r["gather_ms_per_frame"], r["detstats_gather_ratio"], FIGURE_OF_BASELINE),
        row("detection statistics, still", r["detstats_still_ms_per_frame"], "ms/frame", "eq. 12's still",
            r["still_ms_per_frame"], _over(r["detstats_still_ms_per_frame"], r["still_ms_per_frame"]),
            FIGURE_OF_BASELINE),
        row("detection statistics, moving", r["detstats_moving_ms_per_frame"], "ms/frame", "eq. 12's moving",
            r["moving_ms_per_frame"], _over(r["detstats_moving_ms_per_frame"], r["moving_ms_per_frame"]),
            FIGURE_OF_BASELINE),
        row("detection statistics, whole pipeline", r["detstats_pipeline_ms_per_frame"], "ms/frame",
            "eq. 12's pipeline", r["pipeline_ms_per_frame"],
            _over(r["detstats_pipeline_ms_per_frame"], r["pipeline_ms_per_frame"]), FIGURE_OF_BASELINE),
        row("detection statistics, spinning pipeline", r["detstats_spinning_pipeline_ms_per_frame"], "ms/frame",
            "eq. 12's spinning pipeline", r["spinning_pipeline_ms_per_frame"],
            _over(r["detstats_spinning_pipeline_ms_per_frame"], r["spinning_pipeline_ms_per_frame"]), FIGURE_OF_BASELINE),
        row("error vs float64 oracle", r["max_error_units"], "units"),
    ]


def _live_rows(r):
    w = r["whole_frame"]
    return [row("beam latency p50 at 921600 baud", r["latency_p50_ms"], "ms", "whole frames (median beam)",
                w["latency_median_beam_ms"], r["latency_ratio_vs_whole_frames"], BASELINE_OF_FIGURE),
            row("beam latency p99 at 921600 baud", r["latency_p99_ms"], "ms"),
            row("beams at the pty's maximum rate", r["max"]["beams_per_s"], "beams/s"),
            row("intact beams delivered at BER 1e-4", r["intact_delivered_share"]["0.0001"], "share")]


def _drive(device, say, scans, memory_scans, data):
    return drive.run(data, scans=scans, memory_scans=memory_scans, report=say)


def _drive_rows(r):
    ro, b, m, o = r["rolling"], r["baseline"], r["memory"], r["overlap"]
    return [row("rolling map", ro["scans_per_s"], "scans/s", "unbounded grid", b["scans_per_s"],
                _over(ro["scans_per_s"], b["scans_per_s"]), FIGURE_OF_BASELINE),
            row("decoding on a reader thread, end to end", o["end_to_end_per_s"], "scans/s", "fusion alone",
                o["fuse_alone_per_s"], o["end_to_end_over_fuse_alone"], FIGURE_OF_BASELINE),
            row("rolling map, real time", ro["realtime_factor"], "x real time"),
            row("bricks that left the rolling window", ro["evicted"], "bricks"),
            row("rolling map, device high-water", ro["device_mib_max"], "MiB", "unbounded grid",
                b["device_mib_max"], _over(ro["device_mib_max"], b["device_mib_max"]), FIGURE_OF_BASELINE),
            row("frame latency p99", ro["latency_p99_ms"], "ms", "unbounded grid", b["latency_p99_ms"],
                _over(ro["latency_p99_ms"], b["latency_p99_ms"]), FIGURE_OF_BASELINE),
            row("planar bricks", m["planar_map_mib"], "MiB", "cubic bricks", m["cubic_map_mib"], m["ratio"],
                FIGURE_OF_BASELINE)]


def _viewer_rows(r):
    rows = []
    for name, m in r["modes"].items():
        if "naive_ms_per_frame" in m:
            rows.append(row(f"{name}, 512 x 512", m["ms_per_frame"], "ms/frame", "plain ray march",
                            m["naive_ms_per_frame"], m["ratio_vs_naive"], BASELINE_OF_FIGURE))
        else:
            rows.append(row(f"{name}, 512 x 512", m["ms_per_frame"], "ms/frame"))
    pixels = max((m["max_pixel_diff"] for m in r["modes"].values() if "max_pixel_diff" in m), default=None)
    rows.append(row("pixel difference skipping vs plain", pixels, "levels"))
    return rows


# The benches outside the suite (they tell no device apart) have headline rows too, for the
# measured-figures page of the documentation (``HEADLINES``).
def _fuse_bag_rows(r):
    return [row(f"fused from a ROS 2 bag ({k.removeprefix('bag_')})", r["seconds"][k], f"s per {r['scans']} scans",
                "the PNG folder", r["seconds"]["files"], ratio, FIGURE_OF_BASELINE)
            for k, ratio in r["bag_vs_files"].items()]


def _store_rows(r):
    return [row("map store, save", r["store_save_s"], "s", ".npz (savez_compressed)", r["npz_save_s"],
                r["save_ratio"], BASELINE_OF_FIGURE),
            row("map store, load", r["store_load_s"], "s", ".npz", r["npz_load_s"], r["load_ratio"], BASELINE_OF_FIGURE),
            row(f"map store, saving {r['changed_bricks']} changed bricks", r["store_incremental_s"], "s",
                ".npz (saves the whole map)", r["npz_save_s"], r["incremental_ratio"], BASELINE_OF_FIGURE),
            row(f"map store, size ({r['bricks']} bricks at {r['voxel_m']:g} m)", r["store_mib"], "MiB", ".npz",
                r["npz_mib"], _over(r["store_mib"], r["npz_mib"]), FIGURE_OF_BASELINE)]


def _polar_read_rows(r):
    rows = []
    for x in r["runs"]:
        rows += [row(f"{x['data']}: scan read", x["read_scans_per_s"], "scans/s", "PIL decoding the PNG alone",
                     x["pil_scans_per_s"], x["read_vs_pil"], BASELINE_OF_FIGURE),
                 row(f"{x['data']}: scan read for the device (its rows as stored)", x["read_coded_scans_per_s"],
                     "scans/s", "the scan read to its levels", x["read_scans_per_s"], x["read_coded_vs_read"],
                     BASELINE_OF_FIGURE),
                 row(f"{x['data']}: scan read, power computed", x["read_power_scans_per_s"], "scans/s",
                     "PIL decoding the PNG alone", x["pil_scans_per_s"], x["read_power_vs_pil"], BASELINE_OF_FIGURE)]
    return rows


def _quality_rows(r):
    """The runs on a Pareto front, each beside eq. 12's tuned reference of the same run."""
    ref = r["runs"][0]
    names = {"paper": "eq. 12", "detstats": "default model"}

    def held(x, key):                   # of the timing passes alone, how many put it on this front
        return f" in {x[key]} of {r['timing_passes']} passes" if key in x and r.get("timing_passes") else ""
    rows = []
    for x in r["runs"]:
        fronts = [f"{name}{held(x, k)}" for name, k, on in (("AUC", "pareto_passes", x["pareto"]),
                                                            ("ECE occupied", "pareto_ece_passes", x["pareto_ece"])) if on]
        if fronts:
            label = x["label"] if x["label"].startswith(("reference", "default model")) else (
                f"{names.get(x['model'], x['model'])}: {x['label']}")
            ece = "-" if x["ece_occupied"] is None else f"{x['ece_occupied']:.3f}"
            auc = "-" if x["auc_detectable"] is None else f"{x['auc_detectable']:.3f}"
            rows.append(row(f"{label} ({x['voxel_m']:g} m; front: {', '.join(fronts)}; AUC det "
                            f"{auc}, ECE occupied {ece})", x["ms_per_frame"], "ms/frame",
                            "eq. 12's tuned reference", ref["ms_per_frame"], _over(x["ms_per_frame"], ref["ms_per_frame"]),
                            FIGURE_OF_BASELINE))
    return rows


# Sizes: a full run stays within 5 minutes on a GPU, where what runs on the host (the numpy
# baselines, PNG decoding, the pty's airtime, the first kernel builds) takes about as long as on a
# CPU, so a CPU's run time bounds it (docs/guide/drives.md gives one). The drive's car stands still for its
# first ~250 scans: 480 scans (2 minutes of driving, ~300 m) take the rolling window past its
# 120 m, so bricks leave it.
SUITE = {
    "range-fft": Entry(range_fft, lambda device, say, **size: range_fft.run(device(), **size),
                       dict(n_ffts=[512, range_fft.GOAL_N_FFT], repeat=400), dict(n_ffts=[512], repeat=20),
                       _range_fft_rows),
    "cfar": Entry(cfar, lambda device, say, **size: cfar.run(device(), **size), dict(repeat=400), dict(repeat=20),
                  _cfar_rows),
    "fusion": Entry(fusion, _fusion, dict(repeat=40, voxel_m=0.1), dict(repeat=2, voxel_m=0.5), _fusion_rows),
    "live": Entry(live, lambda device, say, **size: live.run(report=say, **size), dict(voxel_m=0.1, frames=4),
                  dict(voxel_m=0.4, frames=1), _live_rows),
    "drive": Entry(drive, _drive, dict(scans=480, memory_scans=drive.MEMORY_SCANS), dict(scans=11, memory_scans=11),
                   _drive_rows),
    "viewer": Entry(viewer, lambda device, say, **size: viewer.run(report=say, **size), dict(repeat=10),
                    dict(repeat=2), _viewer_rows),
}

# Every bench's headline rows by name: the suite's, and those of the benches outside it.
HEADLINES = {**{name: entry.rows for name, entry in SUITE.items()}, "fuse-bag": _fuse_bag_rows, "store": _store_rows,
             "polar-read": _polar_read_rows, "quality": _quality_rows}


# -- the run --------------------------------------------------------------------------------------------
def measure(names, device, quick=False, data=None, json_path=None, say=None):
    """Run the benches ``names`` of ``SUITE`` in order; returns the report (the JSON object),
    written to ``json_path`` after every bench when given. ``device`` makes a fresh runtime
    (each bench gets its own, as ``radarcl bench NAME`` does); ``data``: the Oxford set."""
    say = say or (lambda line: None)
    first = device()
    report = dict(benchmark="all", complete=False, quick=quick, **context(), device=first.name,
                  limits=dataclasses.asdict(first.limits), load_after=None, wall_s=None, failed=[], benches={})
    del first
    say(f"device {report['device']}; CPU {report['cpu']['model']} ({report['cpu']['cores']} cores); load average "
        f"{report['load_before'][0]:.2f}; {'--quick' if quick else 'full'} sizes")
    start = time.perf_counter()
    for i, name in enumerate(names, 1):
        entry = SUITE[name]
        size = dict(entry.quick if quick else entry.full)
        if name == "drive":
            size["data"] = str(data)
        say(f"[{i}/{len(names)}] {name} {_sizes(size)} (elapsed {time.perf_counter() - start:.0f} s) ...")
        report["benches"][name] = _one(entry, size, device, lambda line: say(f"    {line}"))
        b = report["benches"][name]
        if b["status"] == "ok":
            say(f"[{i}/{len(names)}] {name} done in {b['wall_s']:.1f} s:")
            for line in b["lines"]:
                say(f"    {line}")
        else:
            report["failed"].append(name)
            say(f"[{i}/{len(names)}] {name} FAILED after {b['wall_s']:.1f} s: {b['error']}")
        report.update(wall_s=time.perf_counter() - start, load_after=list(os.getloadavg()))
        if json_path is not None:
            write(json_path, report)
    report["complete"] = True
    if json_path is not None:
        write(json_path, report)
    return report


def _one(entry, size, device, say):
    """One bench: {"status": "ok", sizes, wall time, load, rows, its table lines, its result} or
    {"status": "failed", ..., "error": its sentence, "traceback"}."""
    out = dict(status="ok", size=size, load_before=list(os.getloadavg()))
    start = time.perf_counter()
    try:
        result = entry.measure(device, say, **size)
    except Exception as exc:                          # noqa: BLE001 - recorded, and the others run
        out.update(status="failed", error=_sentence(exc), traceback=traceback.format_exc())
    else:
        out["result"] = result
        try:
            out.update(rows=entry.rows(result), lines=entry.module.format_table(result))
        except Exception as exc:                      # noqa: BLE001 - a figure missing: the result is kept
            out.update(status="failed", error=f"measured, but its table failed: {_sentence(exc)}",
                       traceback=traceback.format_exc())
    out.update(wall_s=time.perf_counter() - start, load_after=list(os.getloadavg()))
    return out


def _sentence(exc):
    """A radarcl error's own sentence; any other exception's type and message (a bug)."""
    return str(exc) if isinstance(exc, RadarclError) else f"{type(exc).__name__}: {exc}"


def _sizes(size):
    return ", ".join(f"{k}={v}" for k, v in size.items() if k != "data")


def table(report):
    """Lines a person reads at a glance: one per headline row (benchmark, figure, value, unit,
    baseline, ratio), a failed bench as one line with its error, then the run's context."""
    head = ("benchmark", "figure", "value", "unit", "baseline", "ratio")
    cells, failures = [], {}
    for name, b in report["benches"].items():
        if b["status"] != "ok":
            failures.setdefault(len(cells), []).append(f"{name}  FAILED: {b['error']}")
            continue
        for r in b["rows"]:
            base = "" if r["baseline"] is None else (
                r["baseline"] if r["baseline_value"] is None else f"{r['baseline']} {_number(r['baseline_value'])}")
            ratio = "" if r["ratio"] is None else f"{_number(r['ratio'], 3)} ({r['ratio_is']})"
            cells.append((name, r["figure"], _number(r["value"]), r["unit"], base, ratio))
    widths = [max(len(c[i]) for c in (head, *cells)) for i in range(len(head))]
    fmt = "  ".join(f"{{:{'>' if i == 2 else '<'}{w}}}" for i, w in enumerate(widths))
    lines = [fmt.format(*head).rstrip(), "  ".join("-" * w for w in widths)]
    for i in range(len(cells) + 1):
        lines += failures.get(i, [])
        if i < len(cells):
            lines.append(fmt.format(*cells[i]).rstrip())
    load = report["load_before"], report["load_after"] or report["load_before"]
    lines.append(f"device {report['device']}; CPU {report['cpu']['model']} ({report['cpu']['cores']} cores); load "
                 f"average {load[0][0]:.2f} before, {load[1][0]:.2f} after; {report['wall_s'] or 0:.0f} s"
                 + ("; --quick" if report["quick"] else ""))
    failed = report["failed"]
    lines.append(f"{len(failed)} of {len(report['benches'])} benchmarks FAILED: {', '.join(failed)}" if failed
                 else f"all {len(report['benches'])} benchmarks ran")
    return lines


def _number(value, digits=4):
    if value is None:
        return "-"
    if isinstance(value, int):
        return str(value)
    return "nan" if not math.isfinite(value) else f"{value:.{digits}g}"


# -- the JSON and the run's context -------------------------------------------------------------------------
def write(path, report):
    """``report`` as JSON at ``path``, atomically (non-finite numbers as null: valid JSON)."""
    with files.atomic(path) as tmp:
        tmp.write_text(json.dumps(_plain(report), indent=1, allow_nan=False) + "\n")


def _plain(value):
    """``value`` with numpy scalars as Python numbers, tuples as lists and NaN or infinity as None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item):       # a numpy scalar
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def context():
    """Where and when a bench runs: the date, radarcl's and its libraries' versions, the CPU and
    the load average (1, 5 and 15 minutes, as `uptime` prints it) before it starts."""
    return dict(date=_now(), radarcl_version=_version(), versions=_versions(), cpu=_cpu(),
                load_before=list(os.getloadavg()))


def _now():
    return datetime.datetime.now(datetime.timezone.utc).astimezone().isoformat(timespec="seconds")


def _version():
    import radarcl

    return radarcl.__version__


def _versions():
    import numpy
    import pyopencl

    return dict(python=platform.python_version(), numpy=numpy.__version__, pyopencl=pyopencl.VERSION_TEXT)


def _cpu():
    """The CPU: /proc/cpuinfo's first model name, family and model number (else ``platform``'s
    name), and the cores this process may use."""
    info = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if not line.strip():
                    break                               # the first processor's block is enough
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return dict(model=info.get("model name") or platform.processor() or platform.machine(),
                family=info.get("cpu family"), model_number=info.get("model"), cores=cores,
                logical_cpus=os.cpu_count())


# -- the command ----------------------------------------------------------------------------------------------
def add_arguments(parser):
    """`radarcl bench all` options."""
    parser.add_argument("--json", default=None, metavar="PATH",
                        help="write the report here (replaced if it exists; rewritten after every bench)")
    parser.add_argument("--quick", action="store_true", help="smaller sizes: a smoke run of a minute or two")
    parser.add_argument("--only", type=_names, default=list(SUITE), metavar="NAME,...",
                        help=f"run only these, in the suite's order (default: {','.join(SUITE)})")
    parser.add_argument("--data", default=None, help="the Oxford set for the drive (default: "
                                                     "../shared/data/navtech_oxford)")
    parser.set_defaults(data_default=default_data("navtech_oxford"))


def _names(text):
    """argparse type of --only: names of ``SUITE``, in its order."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in SUITE]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"expected names from {', '.join(SUITE)}, got {text!r}")
    return [n for n in SUITE if n in names]


def main(args, device):
    """Run the suite; the table on stdout, progress on stderr; returns the exit status (1 when a
    bench failed)."""
    path = files.check(args.json, force=True, what="bench report") if args.json else None
    report = measure(args.only, device, quick=args.quick, data=args.data or args.data_default, json_path=path,
                     say=lambda line: print(line, file=sys.stderr, flush=True))
    print("\n".join(table(report)))
    if report["failed"]:
        print(f"radarcl: bench all: {len(report['failed'])} of {len(report['benches'])} benchmarks failed "
              f"({', '.join(report['failed'])}); their errors are in the table" + (f" and {path}" if path else ""),
              file=sys.stderr)
        return 1
    return 0
