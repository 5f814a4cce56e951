"""`radarcl bench polar-read`: reading a polar scan (``io.polar_png.load_scan``: the PNG's
checksums verified, decoded, its layout applied, each azimuth timed and turned into REP-103) to
its levels, as the device takes them (a "Sub" PNG's rows kept as their differences: the device
sums them, ``stages.levels``) and converted to power, against decoding the same PNG with PIL
alone (``Image.open`` + ``numpy.asarray``), interleaved in one run: the goal is that reading costs
no more than decoding.

The scans are the shared data's own (RADIATE's 576 x 400 range-row scans with the
``radiate-cts350x`` profile, Oxford's 400 x 3779 azimuth-row scans with ``navtech-cts350x``); each
variant reads the same files in turn (from the page cache after the warm-up).
"""

import numpy as np

from radarcl.bench.timing import interleaved_medians
from radarcl.config import sensors
from radarcl.io import polar_png
from radarcl.io.polar_layout import scan_times_ns

SETS = {"radiate": ("radiate_fog", "radiate-cts350x"), "oxford": ("navtech_oxford", "navtech-cts350x")}


def run(data_root, repeat=100, sets=tuple(SETS)):
    """Scans per second of each variant per data set; returns the --json dict."""
    from PIL import Image

    out = []
    for name in sets:
        folder, profile = SETS[name]
        sensor = sensors.load(profile)
        layout = polar_png.PolarLayout.of(sensor)
        directory = polar_png.scan_directory(data_root / folder, layout)
        paths = polar_png.scan_paths(directory)
        times = scan_times_ns(paths, layout, directory)
        state = {"i": 0}

        def next_path():
            state["i"] = (state["i"] + 1) % len(paths)
            return state["i"]

        def pil_only():
            with Image.open(paths[next_path()]) as image:
                return np.asarray(image)

        def reading(take):
            """The next scan read, then ``take(scan)``."""
            def read():
                i = next_path()
                return take(polar_png.load_scan(paths[i], layout, times[i]))
            return read

        t = interleaved_medians(dict(pil=pil_only, read=reading(lambda s: s.levels),
                                     read_coded=reading(lambda s: s.coded_levels),
                                     read_power=reading(lambda s: s.power())), repeat)
        shape = np.asarray(Image.open(paths[0])).shape
        out.append(dict(data=name, profile=profile, scans=len(paths), png_shape=list(shape),
                        pil_scans_per_s=1 / t["pil"], read_scans_per_s=1 / t["read"],
                        read_coded_scans_per_s=1 / t["read_coded"], read_coded_vs_read=t["read_coded"] / t["read"],
                        read_power_scans_per_s=1 / t["read_power"], read_vs_pil=t["read"] / t["pil"],
                        read_power_vs_pil=t["read_power"] / t["pil"]))
    return dict(benchmark="polar-read", repeat=repeat, goal="read_vs_pil <= 1.0 (reading costs no more than "
                                                                  "decoding the PNG)", runs=out)


def format_table(result):
    """Human-readable lines for a ``run`` result."""
    lines = [f"polar scans read, median of {result['repeat']} interleaved reads per variant",
             f"{'data':>8} {'PNG':>11} {'PIL alone':>12} {'reader':>12} {'for device':>12} {'reader+power':>13} "
             f"{'reader/PIL':>11} {'+power/PIL':>11} {'device/reader':>14}"]
    for r in result["runs"]:
        lines.append(f"{r['data']:>8} {'x'.join(map(str, r['png_shape'])):>11} {r['pil_scans_per_s']:>8.0f} /s "
                     f"{r['read_scans_per_s']:>8.0f} /s {r['read_coded_scans_per_s']:>8.0f} /s "
                     f"{r['read_power_scans_per_s']:>9.0f} /s {r['read_vs_pil']:>11.2f} {r['read_power_vs_pil']:>11.2f} "
                     f"{r['read_coded_vs_read']:>14.2f}")
    lines.append("reader: a scan's levels on the host; for device: as the device takes them (a \"Sub\" PNG's rows "
                 "kept as their differences, which the device sums)")
    lines.append(f"goal: {result['goal']}")
    return lines


def add_arguments(parser):
    """`radarcl bench polar-read` options."""
    from radarcl.commands.options import positive_int

    parser.add_argument("--repeat", type=positive_int, default=100, help="timed reads per variant "
                                                                          "(default: %(default)s)")
    parser.add_argument("--data", default=None, help="the shared data directory (default: $RADARCL_DATA or "
                                                     "../shared/data beside the source)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines). Needs no OpenCL device."""
    from pathlib import Path

    from radarcl.commands.options import default_data

    root = Path(args.data) if args.data else default_data("")
    result = run(root, repeat=args.repeat)
    return result, format_table(result)
