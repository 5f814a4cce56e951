"""`radarcl tune`: the documented search for the CFAR settings and eq. 12's constants."""

from radarcl.commands.options import add_progress, positive_float, progress, runtime
from radarcl.config.presets import TUNING_SEED, TUNING_VOXEL_M
from radarcl.io import files

SUMMARY = ("the documented search for the CFAR settings and the eq. 12 constants on the reference scene; --save "
           "writes the choice as a configuration file")
DESCRIPTION = ("Runs the coordinate search of radarcl/evaluation/tuning.py (CFAR kind and P_fa, wide-pulse width, "
               "E_h and E_l, common scale) on the reference scene simulated with the tuning seed, and with --save "
               "writes the chosen configuration for --config.")


def add_arguments(parser):
    parser.add_argument("--seed", type=int, default=TUNING_SEED,
                        help="simulation seed (default: %(default)s, the tuning seed)")
    parser.add_argument("--replay", default=None, help="tune on a recording of the reference scene instead of simulating")
    parser.add_argument("--voxel", type=positive_float, default=TUNING_VOXEL_M, help="voxel edge [m] (default: %(default)s)")
    parser.add_argument("--save", default=None, metavar="FILE", help="write the chosen configuration to FILE")
    parser.add_argument("--force", action="store_true", help="replace an existing --save file")
    add_progress(parser)


def run(args):
    from radarcl.config.presets import EQ12, paper_config
    from radarcl.evaluation import tuning
    from radarcl.scene.observe import load_observations, observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_grid, paper_scene

    save = files.check(args.save, args.force, inputs=[args.replay], what="configuration file") if args.save else None
    if args.replay:
        obs = load_observations(args.replay)
    else:
        print(f"simulating the reference scene, seed {args.seed} ...")
        obs = observe(paper_scene(), PAPER_TILTS_DEG, seed=args.seed)
    base = paper_config(args.voxel, EQ12)                # the search is over eq. 12's CFAR and constants
    truth = paper_scene().truth(paper_grid(args.voxel))
    best, _ = tuning.tune(runtime(), obs, truth, base, report=print, progress=progress(args))
    print(f"chosen: {best.label(base)}")
    if save:
        best.save(save, header=("radarcl map configuration chosen by `radarcl tune`",
                                f"reference scene, seed {obs.seed}, {args.voxel} m; the search of radarcl/evaluation/tuning.py"),
                  overwrite=True)
        print(f"wrote {save} (use it with --config)")
    return 0
