"""`radarcl bench quality`: map error against run time on the reference scene, eq. 12's
configurations and the default model's on one fixed voxel set (``evaluation.quality``
measures, ``report.quality`` shows)."""

from radarcl.commands.options import add_output, positive_float
from radarcl.config.presets import EQ12, EVALUATION_SEED, paper_config
from radarcl.evaluation import quality
from radarcl.evaluation.quality import VOXELS
from radarcl.evaluation.tuning import TUNED
from radarcl.io import files
from radarcl.report.quality import chart, format_table, write_report


def add_arguments(parser):
    """`radarcl bench quality` options."""
    parser.add_argument("--voxel", type=positive_float, default=0.2,
                        help="voxel of the reference run [m] (default: %(default)s)")
    parser.add_argument("--voxels", type=positive_float, nargs="+", default=list(VOXELS),
                        help="voxel sizes swept [m], each scored on the reference voxel's set: as large or larger, "
                             "or a finer one that divides it (default: 0.8 0.4 0.2 0.1)")
    parser.add_argument("--paper", action="store_true", help="sweep around the paper's constants, not the tuned")
    parser.add_argument("--eq12-only", action="store_true",
                        help="sweep eq. 12's configurations only, not the default model's beside them")
    parser.add_argument("--seed", type=int, default=None,
                        help="simulation seed (default: the evaluation seed, 0; the tuning seed is 2)")
    parser.add_argument("--replay", default=None, help="a recording of the reference scene instead of simulating")
    add_output(parser, "--chart", "quality.png", "PNG chart to write (and its reliability diagram beside it, "
                                                   "*_reliability.png)")
    parser.add_argument("--report", default=None, metavar="FILE",
                        help="the HTML page (table and chart; default: the chart's name with .html)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.scene.observe import load_observations, observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_scene

    chart_path = files.check(args.chart, args.force, inputs=[args.replay], what="chart")
    page = files.check(args.report or chart_path.with_suffix(".html"), args.force, inputs=[args.replay, chart_path],
                       what="report")
    quality.check_voxels(args.voxel, args.voxels)
    scene = paper_scene()
    if args.replay:
        obs = load_observations(args.replay)
    else:
        seed = EVALUATION_SEED if args.seed is None else args.seed
        say(f"simulating the reference scene, seed {seed} ...")
        obs = observe(scene, PAPER_TILTS_DEG, seed=seed)
    reference = paper_config(args.voxel, EQ12 if args.paper else TUNED)      # error against run time of eq. 12's choices
    default = None if args.eq12_only else paper_config(args.voxel)            # the default model's, beside them
    result = quality.run(runtime(), scene, obs, reference, voxels=tuple(args.voxels), report=say,
                         default_config=default)
    reliability = files.check(chart_path.with_name(chart_path.stem + "_reliability.png"), args.force,
                              inputs=[args.replay], what="reliability chart")
    chart(result, chart_path, reliability)
    write_report(result, chart_path, page, reliability)
    say(f"wrote {chart_path}, {reliability} and {page}")
    return result, format_table(result)
