"""`radarcl poses`: a trajectory file read as fuse, navtech-map and live read it (``io.poses``),
summarised, and written in TUM form."""

import json

from radarcl.commands.options import add_trajectory_options, read_trajectory
from radarcl.io import files

SUMMARY = "read a trajectory (Oxford odometry, TUM, KITTI, RADIATE GPS/IMU, Boreas, ...): summary, TUM output"
DESCRIPTION = ("Reads FILE as `fuse --poses` does (its format told from its name and first line, or "
               "--poses-format; RADIATE's GPS/IMU with its clock offset found from the lidar or given), checks it "
               "(times that run backwards, jumps faster than --max-speed), prints its length, duration and speed, "
               "and with --out writes it as TUM ('t tx ty tz qx qy qz qw', the format evo and most SLAM tools read).")


def add_arguments(parser):
    parser.add_argument("file", help="a pose file, or a RADIATE sequence's directory (its GPS_IMU_Twist)")
    add_trajectory_options(parser, "the file")
    parser.add_argument("--out", default=None, metavar="FILE.tum", help="write the trajectory in TUM form")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--json", action="store_true", help="print the summary as one JSON object")


def run(args):
    args.poses = args.file
    out = files.check(args.out, args.force, inputs=[args.file], what="trajectory file") if args.out else None
    track = read_trajectory(args)
    s = track.summary()
    if args.json:
        print(json.dumps(dict(source=track.source, notes=list(track.notes), **s)))
    else:
        print(f"{track.source}: {s['poses']} poses from t = {s['start_s']:.3f} to {s['end_s']:.3f} s (UNIX, the "
              f"radar's clock)\n  duration {s['duration_s']:.2f} s, length {s['length_m']:.1f} m, speed mean "
              f"{s['speed_mean_m_s']:.2f} m/s, max {s['speed_max_m_s']:.2f} m/s between two poses, turn "
              f"{s['turn_deg']:+.1f} deg")
    if out is not None:
        with files.atomic(out) as tmp:
            tmp.write_text(track.tum_text())
        if not args.json:
            print(f"wrote {out} (TUM: t tx ty tz qx qy qz qw)")
    return 0
