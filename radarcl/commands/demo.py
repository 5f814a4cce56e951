"""`radarcl demo`: the main job (``jobs.demo``)."""

from radarcl.commands.options import add_progress, progress, runtime

SUMMARY = ("the main job: the paper's reference scene simulated, fused at 0.1 m, scored on its visibility truth "
           "beside three baselines, plotted")
DESCRIPTION = ("Simulates the outdoor scene of the paper's §4.3 (3,840 observations), fuses it with radarcl's default "
               "detection-statistics model, the paper's eq. 12 constants, the tuned ones and the calibrated "
               "occlusion-aware interpreter (radarcl calibrate), prints "
               "metrics and timings and writes the recording, one of the maps (--show), plots, summary.json and "
               "report.html to --out.")


def add_arguments(parser):
    parser.add_argument("--show", choices=("detection statistics", "tuned", "calibrated", "paper constants"),
                        default="detection statistics",
                        help="the map written, rendered and plotted (default: %(default)s; all four are scored)")
    parser.add_argument("--out", default="out/demo", help="output directory (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="simulation seed (default: %(default)s, the evaluation seed)")
    parser.add_argument("--quick", action="store_true", help="0.4 m voxels instead of the paper's 0.1 m (CI-sized)")
    parser.add_argument("--replay", default=None, help="replay a recording (reference_scene.npz) instead of simulating")
    add_progress(parser)


def run(args):
    from radarcl.jobs import demo

    demo.run(runtime(), args.out, seed=args.seed, quick=args.quick, replay=args.replay, report=print,
             progress=progress(args), shown=args.show)
    return 0
