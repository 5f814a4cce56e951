"""`radarcl bench scenes`: the instrument on generated scenes, the training or the held-out split.

Each scene of the split (``scene.generator``) is simulated (the paper's 15 tilts, seeded by the
scene's seed) and mapped with the paper's constants, the tuned constants and each beam model of
the tuned configuration; every map and the three baselines (prior_only, raw_intensity, octomap)
are scored on that scene's fixed voxel set (what the tuned configuration's beams reach,
``evaluate.instrument``). The table gives per configuration the mean of each score over the
scenes (objects: found / total summed, an object found where one of its voxels reads p > 0.5
and, for a map with the knowledge channel, the map knows that voxel; det-obj: the same over the
objects with a DETECTABLE surface voxel, the ones a perfect per-bin detector sees; ECEocc: the
calibration of what the map calls occupied, the ECE over the visible voxels it knows and reads at
p >= 0.5 (without the knowledge channel: that hold evidence), beside their number summed over
the scenes, occ-n). Nothing is tuned here: the held-out split is for
reporting only. The two "oracle detections" rows are not maps one can make: the beams fused
with the noiseless truth of every bin (``evaluate.oracle_detections``), +1 nat on detectable bins
and 0 (or -1 nat) on the others: what a perfect per-bin detector gives through the same beam
footprint. They are not upper bounds on AUC (a graded evidence can rank better than +1/0,
whose ties count one half); they show what the footprint and strong free evidence cost.
"""

import numpy as np

from radarcl.errors import ConfigError
from radarcl.geometry import BEAM_MODELS

KEYS = ("auc_detectable", "iou_detectable", "auc_obstacles", "iou_obstacles", "auc_weak", "false_free",
        "false_free_obstacles", "shadow_unknown", "ece", "brier")
KNOWLEDGE_KEYS = ("ece_known", "known_visible")     # maps with the knowledge channel
OCCUPIED_KEYS = ("ece_occupied",)                   # what the map calls occupied (its count is summed)


RADARS = {"paper": "paper", "spinning": "spinning-sim"}      # --radar: the sensor profile it simulates
SPINNING_TURNS = 8                                           # turns of the spinning radar per street (10 m driven)


def configurations(voxel_m, extra=(), radar="paper"):
    """(name, Resolved) of the compared configurations; the first is the reference. ``extra``:
    configuration files (e.g. from `radarcl calibrate --save`), named by their stem, at
    ``voxel_m``. ``radar``: "paper" (the tilting stand) or "spinning" (``scene.streets``)."""
    from pathlib import Path

    from radarcl.config import mapconfig
    from radarcl.config.presets import EQ12
    from radarcl.evaluation.calibration import CALIBRATED, DETSTATS_NO_PRIOR
    from radarcl.evaluation.tuning import TUNED

    def preset(values=None):
        return mapconfig.resolve(RADARS[radar], program={"grid.voxel_m": voxel_m, **(values or {})})

    tuned = preset(TUNED)
    out = [("tuned", tuned), ("paper constants", preset(EQ12))]
    if radar == "paper":
        out += [(f"tuned, beam {b}", tuned.replaced(beam__model=b)) for b in BEAM_MODELS if b != tuned["beam.model"]]
    out += [("calibrated, occlusion", preset(CALIBRATED)),
            ("detection statistics", preset({"interpret.model": "detstats"})),
            ("detection statistics, no prior", preset(DETSTATS_NO_PRIOR))]
    out += [(Path(f).stem, mapconfig.resolve(path=f, program={"grid.voxel_m": voxel_m}).replaced(grid__voxel_m=voxel_m))
            for f in extra]
    return out


def run(runtime, seeds, voxel_m=0.2, report=None, extra=(), physics=0, radar="paper"):
    """Score every configuration and baseline on every scene of ``seeds``; returns the --json dict."""
    from radarcl.evaluation.evaluate import (baselines, for_scene, instrument, map_observations, oracle_detections,
                                             radar_score)
    from radarcl.scene import generator, streets
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import PAPER_TILTS_DEG

    say = report or (lambda _: None)
    configs = configurations(voxel_m, extra, radar)
    per_scene = []
    for n, seed in enumerate(seeds, 1):
        if radar == "spinning":
            scene, described = streets.generate(seed)
            say(f"street {seed} ({n}/{len(seeds)}): sensor at {described['sensor_height_m']} m, "
                f"{len(described['objects'])} solids ...")
            sensor = configs[0][1].sensor
            obs = streets.observe(scene, sensor.radar, sensor.lattice(), SPINNING_TURNS, seed=seed, physics=physics)
        else:
            scene, described = generator.generate(seed)
            say(f"scene {seed} ({n}/{len(seeds)}): {described['terrain']} terrain, sensor at "
                f"{described['sensor_height_m']} m, {len(described['objects'])} solids ...")
            obs = observe(scene, PAPER_TILTS_DEG, seed=seed, physics=physics)
        inst = instrument(runtime, scene, obs, configs[0][1])
        maps = {}
        for name, config in configs:
            config = for_scene(config, described)
            res = inst.reference_map if config is configs[0][1] else map_observations(runtime, obs, config)
            maps[name] = dict(radar_score(inst, res.log_odds, res.knowledge), ms_per_frame=res.ms_per_frame)
            del res
        ground = -described["sensor_height_m"] if radar == "spinning" else 0.0       # streets: the head at z = 0
        maps.update({f"baseline: {k}": v for k, v in baselines(runtime, inst, obs, ground).items()})
        maps["oracle detections, free 0"] = dict(oracle_detections(runtime, inst, obs), ms_per_frame=0.0)
        maps["oracle detections, free -1"] = dict(oracle_detections(runtime, inst, obs, -1.0), ms_per_frame=0.0)
        per_scene.append(dict(scene=described, voxel_set=inst.describe(), classes=inst.truth.counts(),
                              hidden_objects=inst.hidden, maps=maps))
    names = list(per_scene[0]["maps"]) if per_scene else []
    mean = {}
    for name in names:
        rows = [s["maps"][name] for s in per_scene if "error" not in s["maps"][name]]
        if not rows:
            mean[name] = dict(error=per_scene[0]["maps"][name].get("error"))
            continue
        mean[name] = {k: _mean([r.get(k) for r in rows]) for k in KEYS + KNOWLEDGE_KEYS + OCCUPIED_KEYS
                      + ("ms_per_frame",)}
        mean[name]["occupied_calls"] = sum(r["occupied_calls"] for r in rows)
        mean[name]["objects_found"] = sum(r["objects_found"] for r in rows)
        mean[name]["objects_total"] = sum(r["objects_total"] for r in rows)
        mean[name]["detectable_found"] = sum(r["detectable_found"] for r in rows)
        mean[name]["detectable_total"] = sum(r["detectable_total"] for r in rows)
    return dict(benchmark="scenes", device=runtime.name, radar=radar, seeds=list(seeds), voxel_m=voxel_m,
                physics=physics_names(physics), mean=mean, scenes=per_scene)


def physics_names(physics):
    """The simulator switches of a ``physics`` bit mask, as words."""
    from radarcl.scene.observe import PHYSICS_NAMES

    return [name for name, bit in PHYSICS_NAMES.items() if physics & bit] or ["none"]


def parse_physics(text):
    """The bit mask of --physics' comma-separated words (``scene.observe.PHYSICS_NAMES``)."""
    from radarcl.scene.observe import PHYSICS_NAMES

    words = [w.strip() for w in text.split(",") if w.strip()]
    unknown = [w for w in words if w not in PHYSICS_NAMES]
    if unknown:
        raise ConfigError(f"--physics takes {', '.join(PHYSICS_NAMES)} (comma-separated), got {', '.join(unknown)}")
    return sum(PHYSICS_NAMES[w] for w in set(words))


def _cell(v, width=6):
    return f"{'-':>{width}s}" if v is None else f"{v:{width}.3f}"


def _mean(values):
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def format_table(r):
    """Human-readable lines: the mean of each score per configuration over the scenes."""
    lines = [f"{len(r['seeds'])} generated {'streets, spinning radar' if r.get('radar') == 'spinning' else 'scenes'} "
             f"(seeds {', '.join(map(str, r['seeds']))}) at {r['voxel_m']} m, "
             f"harder physics: {', '.join(r.get('physics', ['none']))}, on {r['device']}; each scored on its own fixed "
             f"voxel set, means over the scenes (objects and occ-n summed)",
             f"  {'map':36s} {'AUCdet':>6s} {'IoUdet':>6s} {'AUCobs':>6s} {'IoUobs':>6s} {'AUCwk':>6s} {'f-free':>6s} "
             f"{'ff-obs':>6s} {'shd-unk':>7s} {'ECE':>6s} {'Brier':>6s} {'objects':>8s} {'det-obj':>7s} {'ms/frame':>8s} "
             f"{'ECEknwn':>7s} {'known':>7s} {'ECEocc':>6s} {'occ-n':>8s}"]
    for name, m in r["mean"].items():
        if "error" in m:
            lines.append(f"  {name:36s} {m['error']}")
            continue
        cells = " ".join(f"{m[k]:6.3f}" if m[k] is not None else f"{'-':>6s}" for k in KEYS[:7])
        extra = " ".join(f"{m.get(k):7.3f}" if m.get(k) is not None else f"{'-':>7s}" for k in KNOWLEDGE_KEYS)
        lines.append(f"  {name:36s} {cells} {m['shadow_unknown']:7.3f} {m['ece']:6.3f} {m['brier']:6.3f} "
                     f"{m['objects_found']:>3d}/{m['objects_total']:<4d} {m['detectable_found']:>3d}/{m['detectable_total']:<3d} "
                     f"{m['ms_per_frame']:8.1f} {extra} {_cell(m.get('ece_occupied'))} {m['occupied_calls']:8d}")
    for s in r["scenes"]:
        lines.append(f"  scene {s['scene']['seed']}: {s['voxel_set']}")
    return lines


def add_arguments(parser):
    """`radarcl bench scenes` options."""
    from radarcl.commands.options import positive_float

    parser.add_argument("--split", choices=("held-out", "train"), default="held-out",
                        help="which scenes (default: %(default)s; tune only on train)")
    parser.add_argument("--radar", choices=tuple(RADARS), default="paper",
                        help="paper: the tilting stand in generated scenes; spinning: a simulated Navtech-like radar "
                             "driving through generated streets (default: %(default)s)")
    parser.add_argument("--voxel", type=positive_float, default=0.2, help="voxel [m] (default: %(default)s)")
    parser.add_argument("--seeds", type=int, nargs="+", default=None, help="these scene seeds instead of a split")
    parser.add_argument("--physics", default="", metavar="LIST",
                        help="harder physics in the simulator, comma-separated: sidelobes, multipath, spread, clutter "
                             "(docs/guide/evaluation.md: Calibration and harder physics)")
    parser.add_argument("--with", dest="extra", nargs="+", default=(), metavar="FILE",
                        help="also score these configuration files (e.g. from radarcl calibrate --save)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    from radarcl.scene import streets
    from radarcl.scene.generator import HELD_OUT_SEEDS, TRAIN_SEEDS

    if args.radar == "spinning":
        seeds = args.seeds or (streets.HELD_OUT_SEEDS if args.split == "held-out" else streets.TRAIN_SEEDS)
    else:
        seeds = args.seeds or (HELD_OUT_SEEDS if args.split == "held-out" else TRAIN_SEEDS)
    physics = parse_physics(args.physics)
    result = run(runtime(), seeds, args.voxel, report=say, extra=args.extra, physics=physics, radar=args.radar)
    return result, format_table(result)
