"""`radarcl render`: a map rendered to a PNG through EGL; the options `radarcl view` shares
(``add_view_options``, ``settings``)."""

from radarcl.commands.options import add_output, bounded_int, positive_float
from radarcl.io import files
from radarcl.viewer.modes import COLORMAPS, MODES, Settings

SUMMARY = "render a map file to a PNG through EGL (no display needed)"
DESCRIPTION = ("Ray-marches the map as a 3D texture (or draws the Fig. 11 spheres) offscreen through EGL and "
               "writes a PNG with a colour bar.")


CLASSES = "classes"       # render's own picture: the classes seen from above (matplotlib), a planar map's default
DEFAULT_MODE, DEFAULT_CAMERA = "occupancy", "iso"


def add_view_options(p, follow=False, modes=()):
    """The map, render mode, camera and transfer function of `radarcl render` and `radarcl view`;
    ``modes``: (name, description) of a command's own modes beside the viewer's."""
    p.add_argument("map", nargs="?" if follow else None,
                   help="a map file or store (radarcl demo's map.npz)" + (" (or --follow)" if follow else ""))
    own = dict(modes)
    p.add_argument("--mode", choices=list(MODES) + list(own), default=None,
                   help="; ".join([f"{m.name}: {m.description}" for m in MODES.values()]
                                  + [f"{name}: {what}" for name, what in own.items()])
                        + f" (default: {DEFAULT_MODE}" + (f"; {CLASSES} for a planar map" if CLASSES in own else "")
                        + ")")
    p.add_argument("--camera", default=None,
                   help=f"iso, top, front, side or AZ,EL[,DIST[,X,Y,Z]] in degrees and metres (default: {DEFAULT_CAMERA})")
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
    add_view_options(parser, modes=[(CLASSES, "occupied, free, undecided and unknown seen from above, in metres, with "
                                              "the sensor's path (a planar map's default)")])
    add_output(parser, "--out", "view.png", "PNG to write")
    parser.add_argument("--no-colorbar", action="store_true", help="leave the colour bar out")
    parser.add_argument("--no-guides", action="store_true", help="leave the ground grid, axes and sensor poses out")


def run(args):
    out = files.check(args.out, args.force, inputs=[args.map], what="image")
    if args.mode == CLASSES or (args.mode is None and args.camera is None and _planar(args.map)):
        return _classes(args.map, out, args.threshold, args.free_threshold)
    from radarcl.viewer.headless import render_map

    args.mode, args.camera = args.mode or DEFAULT_MODE, args.camera or DEFAULT_CAMERA
    with files.atomic(out) as tmp:
        render_map(args.map, tmp, args.mode, args.camera, tuple(args.size), settings(args),
                   colorbar=not args.no_colorbar, report=lambda line: print(line.replace(str(tmp), str(out))),
                   guides=not args.no_guides)
    return 0


def _planar(path):
    """True for a map one voxel thick (a planar sensor's), which a 3D render shows edge-on."""
    from radarcl.maps.map import Map

    return Map.open(path).spec.shape[2] == 1


def _classes(path, out, occupied_nats, free_nats):
    """The map's classes at the thresholds [nat] seen from above (``report.figures.classes_figure``:
    matplotlib, metre axes; --size is the 3D renders') as the PNG ``out``."""
    from pathlib import Path

    from radarcl.maps.disk import read_poses
    from radarcl.maps.map import Map
    from radarcl.report import figures

    m = Map.open(path)
    poses = read_poses(path)
    figures.save(figures.classes_figure(m.classes_from_above(occupied_nats, free_nats), m.spec, [] if poses is None else poses,
                                        Path(str(path)).name), out)
    print(f"wrote {out}: {CLASSES} seen from above, {m.spec.shape[0]} x {m.spec.shape[1]} cells of {m.spec.voxel_m:g} m")
    return 0
