"""`radarcl navtech`: CFAR and the interpreter (the profile's: detection statistics by default, eq. 12 with
--set interpret.model=paper) on one polar scan, one azimuth plotted as the paper's Fig. 10."""

from radarcl.commands.options import add_config, add_output, resolve_config, runtime
from radarcl.io import files

SUMMARY = "CFAR and the interpreter on one polar scan; plot one azimuth like the paper's Fig. 10"
DESCRIPTION = ("Reads a polar PNG scan (1 dB per level), runs CFAR and the interpreter (the configuration's: the "
               "detection-statistics model by default, plotted for a voxel on the beam's axis; eq. 12 with --set "
               "interpret.model=paper) on every azimuth with the kernels, prints what was found and writes a Fig. 10 "
               "style PNG of one azimuth.")


def add_arguments(parser):
    parser.add_argument("scan", help="a <unix_us>.png scan")
    parser.add_argument("--azimuth", type=int, default=0, help="azimuth index to plot (default: %(default)s)")
    add_output(parser, "--out", "navtech_fig10.png", "PNG to write")
    add_config(parser, "navtech-cts350x")


def run(args):
    from radarcl.jobs.navtech_report import report

    out = files.check(args.out, args.force, inputs=[args.scan], what="figure")
    report(runtime(), resolve_config(args), args.scan, args.azimuth, out, print)
    return 0
