"""`radarcl demo`: the main job (``jobs.demo``)."""

from radarcl.commands.options import add_progress, progress, runtime

SUMMARY = ("the main job: the paper's reference scene simulated, fused (0.2 m; --full: the paper's 0.1 m), scored on "
           "its visibility truth beside three baselines, plotted")
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
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="0.4 m voxels (CI-sized, well under a minute)")
    size.add_argument("--full", action="store_true",
                      help="the paper's 0.1 m voxels: eight times the voxels of the default 0.2 m, and the memory "
                           "(several GiB; a workstation's run)")
    parser.add_argument("--replay", default=None, help="replay a recording (reference_scene.npz) instead of simulating")
    add_progress(parser)


def run(args):
    from radarcl.jobs import demo

    voxel = demo.QUICK_VOXEL_M if args.quick else demo.FULL_VOXEL_M if args.full else demo.DEFAULT_VOXEL_M
    demo.run(runtime(), args.out, seed=args.seed, voxel_m=voxel, replay=args.replay, report=print,
             progress=progress(args), shown=args.show)
    return 0
