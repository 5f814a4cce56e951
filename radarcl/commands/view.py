"""`radarcl view`: the interactive volume viewer (``viewer.app``)."""

from radarcl.commands.options import positive_int
from radarcl.commands.render import DEFAULT_CAMERA, DEFAULT_MODE, add_view_options, settings
from radarcl.errors import ConfigError
from radarcl.io import files

SUMMARY = "the interactive volume viewer (press h in the window for the keys)"
DESCRIPTION = ("Opens a window on the map: drag to orbit, right-drag or shift-drag to pan, wheel to zoom; 1-5 "
               "modes (5: free space too), t/T threshold, x/y/z slices, c colormap, a guides, s screenshot, "
               "h help. --live follows a map file that a running fusion rewrites.")


def add_arguments(parser):
    p = parser
    add_view_options(p, follow=True)
    p.add_argument("--live", action="store_true", help="watch MAP and upload the bricks that changed whenever it is "
                                                       "rewritten")
    p.add_argument("--follow", default=None, metavar="HOST:PORT",
                   help="show the map a running `radarcl live --serve` fuses, brick by brick as it changes")
    p.add_argument("--window", default="pyglet", help="moderngl-window backend: pyglet, glfw, headless "
                                                      "(default: %(default)s)")
    p.add_argument("--screenshot", default=None, help="save the last frame to this PNG when the window closes")
    p.add_argument("--force", action="store_true", help="replace an existing screenshot")
    p.add_argument("--frames", type=positive_int, default=None, help="close after this many frames (scripts, tests)")
    p.add_argument("--keys", default="", help="keys pressed one per frame at the start, e.g. '2t' (scripts, tests)")


def run(args):
    from radarcl.viewer.app import run as run_viewer

    if (args.map is None) == (args.follow is None):
        raise ConfigError("give a MAP file to view, or --follow HOST:PORT of a running radarcl live --serve (not both)")
    shot = files.check(args.screenshot, args.force, inputs=[args.map], what="screenshot") if args.screenshot else None
    status = run_viewer(args.map, mode_name=args.mode or DEFAULT_MODE, camera=args.camera or DEFAULT_CAMERA,
                        size=tuple(args.size), settings=settings(args),
                        live=args.live, frames=args.frames, screenshot=shot, keys=args.keys, window=args.window,
                        follow=args.follow)
    if shot:
        print(f"saved {shot}")
    return status
