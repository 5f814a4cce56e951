"""`radarcl navtech-map`: polar scans fused with their odometry, the geometry checked by half
maps (``jobs.navtech_map``)."""

import json
from pathlib import Path

from radarcl.commands.options import (
    DATA_ENV,
    add_config,
    add_output,
    add_progress,
    add_trajectory_options,
    default_data,
    progress,
    resolve_config,
    runtime,
)
from radarcl.errors import ConfigError
from radarcl.io import files
from radarcl.maps.disk import reading_of, save_grid

SUMMARY = "fuse polar scans with their odometry into a map; check the geometry by half-map consistency"
DESCRIPTION = ("Fuses the first and second half of the scans into two maps and prints how well they agree with "
               "the true poses and with the second half moved 1 m, turned 2 deg, without motion within a scan, "
               "with the azimuths or the odometry reversed; prints the detector's pulse statistics; fuses all "
               "scans into a top-down PNG and, with --map, a map file.")


def add_arguments(parser):
    parser.add_argument("data", nargs="?", default=None,
                        help=f"a recording's directory: its scans in the sensor's layout (Oxford: radar/*.png), their "
                             f"poses found beside them or given with --poses (default: the Oxford scans in ${DATA_ENV} "
                             f"or ../shared/data beside the source)")
    add_output(parser, "--out", "navtech_map.png", "PNG to write")
    parser.add_argument("--map", default=None, help="also write the fused map file (npz)")
    parser.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    add_config(parser, "navtech-cts350x")
    add_trajectory_options(parser)
    add_progress(parser)


def run(args):
    from radarcl.jobs import navtech_map

    data = Path(args.data) if args.data else default_data("navtech_oxford")
    if not data.is_dir():
        raise ConfigError(f"no data directory {data}; give DATA (a recording's directory: its scans and poses) or "
                          f"set {DATA_ENV}")
    out = files.check(args.out, args.force, what="figure")
    map_out = files.check(args.map, args.force, what="map file") if args.map else None
    json_out = files.check(args.json, args.force, what="JSON file") if args.json else None
    config = resolve_config(args)
    results, grid, poses, pulses = navtech_map.run(runtime(), config, data, report=print, progress=progress(args),
                                                   poses=args.poses, poses_format=args.poses_format,
                                                   clock_offset_s=args.clock_offset, max_speed_m_s=args.max_speed)
    print(f"detector: {pulses['cfar']['kind'].upper()}-CFAR guard {pulses['cfar']['guard_bins']} train "
          f"{pulses['cfar']['train_bins']} bins; {pulses['detections_per_scan']:.0f} detections and "
          f"{pulses['pulses_per_scan']:.0f} pulses per scan, pulse width median {pulses['pulse_width_median_m']:.3f} m "
          f"(90 % below {pulses['pulse_width_p90_m']:.3f} m), {100 * pulses['wide_fraction']:.1f} % wide")
    navtech_map.plot_map(grid, poses, out, results, title=config.sensor.name, config=config)
    mem = grid.memory()
    print(f"map: {mem['bricks']} bricks, {mem['sparse_bytes'] / 2**20:.1f} MiB allocated "
          f"({mem['dense_bytes'] / 2**20:.1f} MiB dense); wrote {out}")
    if map_out:
        save_grid(grid, map_out, poses=poses, reading=reading_of(config) if grid.has_knowledge else None)
        print(f"wrote {map_out} (radarcl render / view open it)")
    if json_out:
        with files.atomic(json_out) as tmp:
            tmp.write_text(json.dumps(dict(consistency=results, detector=pulses, config=config.as_dict()), indent=1))
    return 0
