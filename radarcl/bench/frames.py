"""`radarcl bench frames`: do the probabilities hold at any number of scans? Maps of 1, 10 and 100
frames of a still radar and of a moving one, scored on one fixed voxel set per case.

- still: the stand at one tilt (``STILL_TILT_DEG``) for every frame: the same scatterers and
  speckle each time, new receiver noise. Its voxel set is the first frame's reach (every frame
  reaches the same voxels).
- moving: the stand drives forward ``STEP_M`` per frame while it tilts through the paper's 15
  positions. Its voxel set is what all the frames reach; a map of fewer frames leaves the rest
  unknown (``ece_known`` scores the voxels a map knows; ``ece`` all visible ones).
Eq. 9 adds the looks as if they were independent, so a map that reads its sums as they are grows
surer with every repeat; the detection-statistics model counts at most ``look_limit`` looks'
worth (``sensor_model.read_log_odds``). The rows: the paper's constants, the tuned ones, the
detection-statistics model with its reading, without the limit, with a limit of one look and
without the prior (unknown read as 1/2, the last release's reading), on each held-out scene.
"""

import numpy as np

FRAME_COUNTS = (1, 10, 100)
STILL_TILT_DEG = -5.2            # a middle tilt of the paper's stand: its beams see ground and obstacles
STEP_M = 0.1                     # the moving stand's advance per frame (10 m over 100 frames)
KEYS = ("ece", "ece_known", "auc_detectable", "auc_obstacles", "false_free_obstacles", "shadow_unknown",
        "known_visible")


def configurations(voxel_m, extra=()):
    """(name, Resolved) of the compared maps."""
    from pathlib import Path

    from radarcl.config import mapconfig
    from radarcl.config.presets import EQ12, paper_config
    from radarcl.evaluation.calibration import DETSTATS_NO_PRIOR
    from radarcl.evaluation.tuning import TUNED

    detstats = paper_config(voxel_m, {"interpret.model": "detstats"})
    out = [("paper constants", paper_config(voxel_m, EQ12)), ("tuned", paper_config(voxel_m, TUNED)),
           ("detection statistics", detstats),
           ("detection statistics, no look limit", detstats.replaced(sensor_model__look_limit=1e4)),
           ("detection statistics, look limit 1", detstats.replaced(sensor_model__look_limit=1.0)),
           ("detection statistics, no prior", paper_config(voxel_m, DETSTATS_NO_PRIOR))]
    out += [(Path(f).stem, mapconfig.resolve(path=f, program={"grid.voxel_m": voxel_m}).replaced(grid__voxel_m=voxel_m))
            for f in extra]
    return out


def cases(scene, seed, frames):
    """{"still": Observations, "moving": Observations} of ``frames`` frames each."""
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG

    tilts = np.resize(np.asarray(PAPER_TILTS_DEG, float), frames)
    offsets = np.zeros((frames, 3))
    offsets[:, 0] = STEP_M * np.arange(frames)
    return {"still": observe(scene, [STILL_TILT_DEG] * frames, seed=seed),
            "moving": observe(scene, tilts, seed=seed, offsets_m=offsets)}


def run(runtime, seeds, voxel_m=0.4, counts=FRAME_COUNTS, report=None, extra=()):
    """Score every configuration at every frame count on every scene; returns the --json dict."""
    from radarcl.config.presets import paper_config
    from radarcl.evaluation.evaluate import for_scene, instrument, map_observations, radar_score
    from radarcl.evaluation.tuning import TUNED
    from radarcl.scene.generator import generate

    say = report or (lambda _: None)
    configs = configurations(voxel_m, extra)
    rows = {}
    for seed in seeds:
        scene, described = generate(seed)
        for case, obs in cases(scene, seed, max(counts)).items():
            say(f"scene {seed}, {case}: truth ...")
            inst = instrument(runtime, scene, obs.first(1) if case == "still" else obs, paper_config(voxel_m, TUNED))
            for name, config in configs:
                config = for_scene(config, described)
                for n in counts:
                    res = map_observations(runtime, obs.first(n), config)
                    s = radar_score(inst, res.log_odds, res.knowledge)
                    rows.setdefault((case, name, n), []).append({k: s.get(k) for k in KEYS})
                    del res
    mean = [dict(case=case, map=name, frames=n, **{k: _mean([r[k] for r in found]) for k in KEYS})
            for (case, name, n), found in rows.items()]
    return dict(benchmark="frames", device=runtime.name, seeds=list(seeds), voxel_m=voxel_m, counts=list(counts),
                still_tilt_deg=STILL_TILT_DEG, step_m=STEP_M, rows=mean)


def _mean(values):
    values = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(values)) if values else None


def format_table(r):
    """Human-readable lines."""
    lines = [f"maps of {', '.join(map(str, r['counts']))} frames, scenes {r['seeds']} at {r['voxel_m']} m, on "
             f"{r['device']}; still: one tilt ({r['still_tilt_deg']} deg), moving: {r['step_m']} m per frame through "
             "the 15 tilts; means over the scenes",
             f"  {'case':7s} {'map':38s} {'frames':>6s} " + " ".join(f"{k[:10]:>10s}" for k in KEYS)]
    for row in r["rows"]:
        cells = " ".join(f"{row[k]:10.3f}" if row[k] is not None else f"{'-':>10s}" for k in KEYS)
        lines.append(f"  {row['case']:7s} {row['map']:38s} {row['frames']:6d} {cells}")
    return lines


def add_arguments(parser):
    """`radarcl bench frames` options."""
    from radarcl.commands.options import positive_float

    parser.add_argument("--voxel", type=positive_float, default=0.4, help="voxel [m] (default: %(default)s)")
    parser.add_argument("--seeds", type=int, nargs="+", default=None, help="scene seeds (default: the held-out split)")
    parser.add_argument("--frames", type=int, nargs="+", default=list(FRAME_COUNTS), help="frame counts (default: 1 10 100)")
    parser.add_argument("--with", dest="extra", nargs="+", default=(), metavar="FILE",
                        help="also score these configuration files")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.errors import ConfigError
    from radarcl.scene.generator import HELD_OUT_SEEDS

    if min(args.frames) < 1:
        raise ConfigError(f"--frames takes counts of at least 1, got {args.frames}")
    result = run(runtime(), args.seeds or HELD_OUT_SEEDS, args.voxel, sorted(set(args.frames)), say, args.extra)
    return result, format_table(result)
