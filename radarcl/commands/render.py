"""`radarcl render`: a map rendered to a PNG through EGL; the options `radarcl view` shares
(``add_view_options``, ``settings``)."""

from radarcl.commands.options import add_output, bounded_int, positive_float
from radarcl.io import files
from radarcl.viewer.modes import COLORMAPS, MODES, Settings

SUMMARY = "render a map file to a PNG through EGL (no display needed)"
DESCRIPTION = ("Ray-marches the map as a 3D texture (or draws the Fig. 11 spheres) offscreen through EGL and "
               "writes a PNG with a colour bar.")


def add_view_options(p, follow=False):
    """The map, render mode, camera and transfer function of `radarcl render` and `radarcl view`."""
    p.add_argument("map", nargs="?" if follow else None,
                   help="a map file or store (radarcl demo's map.npz)" + (" (or --follow)" if follow else ""))
    p.add_argument("--mode", choices=list(MODES), default="occupancy",
                   help="; ".join(f"{m.name}: {m.description}" for m in MODES.values()) + " (default: %(default)s)")
    p.add_argument("--camera", default="iso",
                   help="iso, top, front, side or AZ,EL[,DIST[,X,Y,Z]] in degrees and metres (default: %(default)s)")
    p.add_argument("--size", type=bounded_int(1, 16384), nargs=2, default=[1024, 768], metavar=("W", "H"),
                   help="pixels, 1-16384 (default: %(default)s)")
    p.add_argument("--threshold", type=float, default=1.0,
                   help="occupancy threshold [nat]: the isosurface and the low end of the colours (default: %(default)s)")
    p.add_argument("--free-threshold", type=float, default=-1.0,
                   help="free mode: free space below this log-odds [nat] shows as a blue haze (default: %(default)s)")
    p.add_argument("--lo", type=float, default=None, help="low end of the transfer function [nat] (default: --threshold)")
    p.add_argument("--hi", type=float, default=None,
                   help="high end [nat] (default: the 90th percentile of the map's values above --lo)")
    p.add_argument("--gamma", type=positive_float, default=1.0, help="transfer-function gamma (default: %(default)s)")
    p.add_argument("--colormap", choices=COLORMAPS, default="inferno", help="(default: %(default)s)")
    p.add_argument("--step", type=positive_float, default=1.0, help="ray-march step [voxels] (default: %(default)s)")


def settings(args):
    """The viewer's ``Settings`` of the transfer-function options."""
    return Settings(threshold=args.threshold, free_threshold=args.free_threshold, lo=args.lo, hi=args.hi,
                    gamma=args.gamma, colormap=args.colormap, step=args.step)


def add_arguments(parser):
    add_view_options(parser)
    add_output(parser, "--out", "view.png", "PNG to write")
    parser.add_argument("--no-colorbar", action="store_true", help="leave the colour bar out")
    parser.add_argument("--no-guides", action="store_true", help="leave the ground grid, axes and sensor poses out")


def run(args):
    from radarcl.viewer.headless import render_map

    out = files.check(args.out, args.force, inputs=[args.map], what="image")
    with files.atomic(out) as tmp:
        render_map(args.map, tmp, args.mode, args.camera, tuple(args.size), settings(args),
                   colorbar=not args.no_colorbar, report=lambda line: print(line.replace(str(tmp), str(out))),
                   guides=not args.no_guides)
    return 0
