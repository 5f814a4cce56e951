"""Command line: `radarcl info | demo | bench | tune | navtech | navtech-map | fuse | render | view`."""

import argparse
import dataclasses
import json
import logging
import sys

from radarcl.errors import RadarclError


def _runtime():
    from radarcl.cl import Runtime

    return Runtime()


def cmd_info(args):
    """List OpenCL platforms and devices."""
    from radarcl.cl import device_report

    print("\n".join(device_report()))
    return 0


class ProgressBar:
    """A one-line progress bar on stderr: ``bar(done, total, what)``; a new ``what`` starts a new line."""

    def __init__(self, stream=sys.stderr, width=30):
        self.stream, self.width, self.what = stream, width, None

    def __call__(self, done, total, what):
        if not self.stream.isatty() and done < total:
            return                                # a log file gets the finished line only
        if what != self.what and self.what is not None:
            self.stream.write("\n")
        self.what = what
        filled = int(self.width * done / max(1, total))
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} {what}")
        if done >= total:
            self.stream.write("\n")
            self.what = None
        self.stream.flush()


def cmd_demo(args):
    """Run the main job on the built-in default."""
    from radarcl.jobs import demo

    demo.run(_runtime(), args.out, seed=args.seed, quick=args.quick, replay=args.replay, report=print,
             progress=None if args.no_progress else ProgressBar())
    return 0


def _reference_observations(args, say):
    """The reference scene's observations: replayed, or simulated with ``args.seed``."""
    from radarcl.config import PAPER_RADAR
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG, paper_scene

    if args.replay:
        return recording.load(args.replay, PAPER_RADAR.n_azimuth, PAPER_RADAR.n_elevation, PAPER_RADAR.n_samples)
    say(f"simulating the reference scene, seed {args.seed} ...")
    return observe(paper_scene(), PAPER_TILTS_DEG, seed=args.seed)


def cmd_tune(args):
    """The documented search for the eq. 12 constants and CFAR settings (radarcl.tuning)."""
    from radarcl.evaluation import tuning
    from radarcl.scene.outdoor import paper_grid, paper_scene

    obs = _reference_observations(args, print)
    truth = paper_scene().truth(paper_grid(tuning.TUNING_VOXEL_M))
    best, _ = tuning.tune(_runtime(), obs, truth, report=print)
    print(f"chosen: {best.label()}")
    return 0


def cmd_bench(args):
    """Run a benchmark."""
    from radarcl.bench import cfar, fusion, range_fft

    if not args.json:
        print(f"measuring {args.which}, {args.repeat} repetitions per variant ...", file=sys.stderr)
    if args.which == "viewer":
        from radarcl.bench import viewer

        say = (lambda line: None) if args.json else (lambda line: print(line, file=sys.stderr))
        result = viewer.run(args.map, repeat=min(args.repeat, 12), report=say)
        lines = viewer.format_table(result)
    elif args.which == "range-fft":
        result = range_fft.run(_runtime(), n_ffts=tuple(args.n_fft), repeat=args.repeat)
        lines = range_fft.format_table(result)
    elif args.which == "quality":
        from radarcl.bench import quality
        from radarcl.evaluation.evaluate import MapConfig
        from radarcl.scene.outdoor import paper_grid, paper_scene
        from radarcl.evaluation.tuning import EVALUATION_SEED, TUNED

        say = (lambda line: None) if args.json else (lambda line: print(line, file=sys.stderr))
        args.seed = EVALUATION_SEED if args.seed is None else args.seed
        obs = _reference_observations(args, say)
        scene = paper_scene()
        reference = TUNED if not args.paper else MapConfig()
        result = quality.run(_runtime(), obs, lambda v: scene.truth(paper_grid(v)),
                             dataclasses.replace(reference, voxel_m=args.voxel), voxels=tuple(args.voxels), report=say)
        quality.chart(result, args.chart)
        say(f"wrote {args.chart}")
        lines = quality.format_table(result)
    elif args.which == "fusion":
        progress = None if args.json else (lambda line: print(line, file=sys.stderr))
        result = fusion.run(_runtime(), repeat=min(args.repeat, 40), report=progress)
        lines = fusion.format_table(result)
    else:
        result = cfar.run(_runtime(), repeat=args.repeat)
        lines = cfar.format_table(result)
    print(json.dumps(result) if args.json else "\n".join(lines))
    return 0


def cmd_navtech(args):
    """CFAR + eq. 12 on a Navtech scan; plot one azimuth like the paper's Fig. 10."""
    from radarcl.jobs.navtech_report import report

    report(_runtime(), args, print)
    return 0


def cmd_navtech_map(args):
    """Fuse the Navtech scans with their odometry; consistency numbers and a top-down PNG."""
    from radarcl.jobs import navtech_map

    results, grid, poses = navtech_map.run(_runtime(), args.data, voxel_m=args.voxel, range_max_m=args.range_max,
                                           report=print)
    navtech_map.plot_map(grid, poses, args.out, results)
    mem = grid.memory()
    print(f"map: {mem['bricks']} bricks, {mem['sparse_bytes'] / 2**20:.1f} MiB allocated "
          f"({mem['dense_bytes'] / 2**20:.1f} MiB dense); wrote {args.out}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


def cmd_fuse(args):
    """Fuse a recording into a map file."""
    from radarcl.jobs import fuse_recording

    fuse_recording.run(_runtime(), args.recording, args.out, voxel_m=args.voxel, paper=args.paper, every=args.every,
             progress=None if args.no_progress else ProgressBar())
    return 0


def _settings(args):
    from radarcl.viewer.modes import Settings

    return Settings(threshold=args.threshold, lo=args.lo, hi=args.hi, gamma=args.gamma, colormap=args.colormap,
                    step=args.step)


def cmd_render(args):
    """Render a map file to a PNG through EGL, no display needed."""
    from radarcl.viewer.headless import render_map

    render_map(args.map, args.out, args.mode, args.camera, tuple(args.size), _settings(args),
               colorbar=not args.no_colorbar)
    return 0


def cmd_view(args):
    """The interactive viewer."""
    from radarcl.viewer.app import run

    status = run(args.map, mode_name=args.mode, camera=args.camera, size=tuple(args.size), settings=_settings(args),
                 live=args.live, frames=args.frames, screenshot=args.screenshot, keys=args.keys, window=args.window)
    if args.screenshot:
        print(f"saved {args.screenshot}")
    return status


def _view_options(p, size):
    from radarcl.viewer.modes import COLORMAPS, MODES

    p.add_argument("map", help="a map file: the npz that EvidenceGrid.save writes (radarcl demo's map.npz)")
    p.add_argument("--mode", choices=list(MODES), default="occupancy",
                   help="; ".join(f"{m.name}: {m.description}" for m in MODES.values()) + " (default: %(default)s)")
    p.add_argument("--camera", default="iso",
                   help="iso, top, front, side or AZ,EL[,DIST[,X,Y,Z]] in degrees and metres (default: %(default)s)")
    p.add_argument("--size", type=int, nargs=2, default=size, metavar=("W", "H"), help="pixels (default: %(default)s)")
    p.add_argument("--threshold", type=float, default=1.0,
                   help="occupancy threshold [nat]: the isosurface and the low end of the colours (default: %(default)s)")
    p.add_argument("--lo", type=float, default=None, help="low end of the transfer function [nat] (default: --threshold)")
    p.add_argument("--hi", type=float, default=None,
                   help="high end [nat] (default: the 99.9th percentile of the values above --lo)")
    p.add_argument("--gamma", type=float, default=1.0, help="transfer-function gamma (default: %(default)s)")
    p.add_argument("--colormap", choices=COLORMAPS, default="inferno", help="(default: %(default)s)")
    p.add_argument("--step", type=float, default=1.0, help="ray-march step [voxels] (default: %(default)s)")


def build_parser():
    """The argparse parser of the `radarcl` command."""
    parser = argparse.ArgumentParser(
        prog="radarcl",
        description="FMCW radar to 3D evidence grids (Foessel-Bunting sensor model) with OpenCL kernels. "
                    "The device comes from RADARCL_DEVICE (P:D or a name substring); PoCL's CPU is the fallback.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages (kernel builds...)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("info", help="list OpenCL platforms and devices and what the kernels need")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("demo", help="the main job: the paper's reference scene simulated, fused at 0.1 m, scored "
                                    "against ground truth and the OctoMap-style baseline, plotted",
                       description="Simulates the outdoor scene of the paper's §4.3 (3,840 observations), fuses it "
                                   "with the paper's and the tuned constants, prints metrics and timings and writes "
                                   "the recording, the map, plots and summary.json to --out.")
    p.add_argument("--out", default="out/demo", help="output directory (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="simulation seed (default: %(default)s, the evaluation seed)")
    p.add_argument("--quick", action="store_true", help="0.4 m voxels instead of the paper's 0.1 m (CI-sized)")
    p.add_argument("--replay", default=None, help="replay a recording (reference_scene.npz) instead of simulating")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("tune", help="the documented search for k_occ, E_h, E_l and the CFAR settings on the "
                                    "reference scene (tuning seed, 0.2 m)")
    p.add_argument("--seed", type=int, default=2, help="simulation seed (default: %(default)s, the tuning seed)")
    p.add_argument("--replay", default=None, help="tune on a recording instead of simulating")
    p.set_defaults(func=cmd_tune)

    p = sub.add_parser("bench", help="benchmarks, each against a baseline measured in the same run")
    p.add_argument("which", choices=["range-fft", "cfar", "fusion", "quality", "viewer"],
                   help="range-fft: window+FFT+magnitude vs scipy; cfar: CFAR + eq. 12 vs numpy; fusion: one "
                        "frame into the paper's 0.1 m grid vs the float64 oracle and the memory floor "
                        "(--repeat capped at 40); quality: map error against run time on the reference scene "
                        "(zero padding, beam model, voxel size, CFAR kind) with the OctoMap-style baseline; viewer: the paper's "
                        "full grid rendered at 512 x 512 through EGL vs a plain ray march (--repeat capped at 12)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--repeat", type=int, default=200, help="timed repetitions per variant (default: %(default)s)")
    p.add_argument("--n-fft", type=int, nargs="+", default=[512, 1024],
                   help="range-fft only: FFT lengths (default: 512 1024)")
    p.add_argument("--voxel", type=float, default=0.2, help="quality only: voxel of the reference run (default: %(default)s)")
    p.add_argument("--voxels", type=float, nargs="+", default=[0.4, 0.2, 0.1],
                   help="quality only: voxel sizes swept (default: 0.4 0.2 0.1)")
    p.add_argument("--paper", action="store_true", help="quality only: sweep around the paper's constants, not the tuned")
    p.add_argument("--seed", type=int, default=None, help="quality only: simulation seed (default: the evaluation seed)")
    p.add_argument("--replay", default=None, help="quality only: a recording instead of simulating")
    p.add_argument("--chart", default="quality.png", help="quality only: PNG chart to write (default: %(default)s)")
    p.add_argument("--map", default=None, help="viewer only: time this map file instead of the reference scene's")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("navtech", help="CFAR and the eq. 12 interpreter on a Navtech polar scan (Oxford "
                                       "format PNG); plot one azimuth like the paper's Fig. 10",
                       description="Reads a scan, converts its dB levels to power (1 dB per level), runs "
                                   "CFAR and eq. 12 on every azimuth with the kernels, prints what was "
                                   "found and writes a Fig. 10 style PNG of one azimuth.")
    p.add_argument("scan", help="a <unix_us>.png scan")
    p.add_argument("--azimuth", type=int, default=0, help="azimuth index to plot (default: %(default)s)")
    p.add_argument("--out", default="navtech_fig10.png", help="PNG to write (default: %(default)s)")
    p.add_argument("--kind", choices=["ca", "go", "so", "os"], default="ca", help="CFAR kind (default: %(default)s)")
    p.add_argument("--guard", type=int, default=16, help="guard cells per side (default: %(default)s)")
    p.add_argument("--train", type=int, default=16, help="training cells per side (default: %(default)s)")
    p.add_argument("--pfa", type=float, default=1e-3, help="design false-alarm probability (default: %(default)s)")
    p.add_argument("--range-min", type=float, default=2.0,
                   help="no evidence nearer than this [m]; the radome echo fills the first ~1.5 m (default: %(default)s)")
    p.add_argument("--range-max", type=float, default=None, help="no evidence beyond this [m] (default: the last bin)")
    p.add_argument("--wide-m", type=float, default=None,
                   help="wide-pulse width at the threshold [m] (default: the paper's geometry, 1.87 m)")
    p.set_defaults(func=cmd_navtech)

    p = sub.add_parser("navtech-map", help="fuse the Navtech scans with their ground-truth odometry into a map; "
                                           "check the geometry by half-map consistency",
                       description="Fuses scans 1-5 and 6-11 into two maps and prints how well they agree "
                                   "with the true poses and with the second half moved 1 m, turned 2 deg, "
                                   "without motion within a scan, with the azimuths or the odometry reversed; "
                                   "then fuses all scans and writes a top-down PNG.")
    p.add_argument("data", nargs="?", default="../shared/data/navtech_oxford",
                   help="directory with radar/ and gt/radar_odometry.csv (default: %(default)s)")
    p.add_argument("--voxel", type=float, default=0.3, help="voxel edge [m] (default: %(default)s)")
    p.add_argument("--range-max", type=float, default=80.0, help="no evidence beyond this [m] (default: %(default)s)")
    p.add_argument("--out", default="navtech_map.png", help="PNG to write (default: %(default)s)")
    p.add_argument("--json", default=None, help="also write the consistency numbers to this JSON file")
    p.set_defaults(func=cmd_navtech_map)

    p = sub.add_parser("fuse", help="fuse a recording of raw frames into a map file (rewritten every --every "
                                    "frames for radarcl view --live)")
    p.add_argument("recording", help="a radarcl recording, e.g. radarcl demo's reference_scene.npz")
    p.add_argument("--out", default="map.npz", help="map file to write (default: %(default)s)")
    p.add_argument("--voxel", type=float, default=0.1, help="voxel edge [m] (default: %(default)s)")
    p.add_argument("--paper", action="store_true", help="the paper's constants instead of the tuned ones")
    p.add_argument("--every", type=int, default=None, help="rewrite the map file every N frames")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_fuse)

    p = sub.add_parser("render", help="render a map file to a PNG through EGL (no display needed)",
                       description="Ray-marches the map as a 3D texture (or draws the Fig. 11 spheres) offscreen "
                                   "through EGL and writes a PNG with a colour bar.")
    _view_options(p, [1024, 768])
    p.add_argument("--out", default="view.png", help="PNG to write (default: %(default)s)")
    p.add_argument("--no-colorbar", action="store_true", help="leave the colour bar out")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("view", help="the interactive volume viewer (press h in the window for the keys)",
                       description="Opens a window on the map: drag to orbit, right-drag or shift-drag to pan, "
                                   "wheel to zoom; 1-4 modes, t/T threshold, x/y/z slices, c colormap, s screenshot, "
                                   "h help. --live follows a map file that a running fusion rewrites.")
    _view_options(p, [1024, 768])
    p.add_argument("--live", action="store_true",
                   help="watch MAP and upload the bricks that changed whenever it is rewritten")
    p.add_argument("--window", default="pyglet", help="moderngl-window backend: pyglet, glfw, headless "
                                                      "(default: %(default)s)")
    p.add_argument("--screenshot", default=None, help="save the last frame to this PNG when the window closes")
    p.add_argument("--frames", type=int, default=None, help="close after this many frames (scripts, tests)")
    p.add_argument("--keys", default="", help="keys pressed one per frame at the start, e.g. '2t' (scripts, tests)")
    p.set_defaults(func=cmd_view)
    return parser


def main(argv=None):
    """Entry point; returns the exit status (2 for a radarcl error, with its message)."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except RadarclError as exc:
        print(f"radarcl: error: {exc}", file=sys.stderr)
        return 2
