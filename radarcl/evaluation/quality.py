"""Map error against run time on the reference scene: the sweep of `radarcl bench quality`.

One recording of the paper's 3,840 observations (``config.presets.EVALUATION_SEED``) is mapped with the
tuned configuration (``tuning.TUNED``) and with one setting changed at a time: zero padding
(n_fft 256 = none, 512 = x2, 1024 = x4), the beam model (``geometry.BEAM_MODELS``), the voxel
size (0.4, 0.2, 0.1 m) and the CFAR kind; beside them the default model (detection statistics,
``sensor_model``) with its own knobs changed one at a time (``DEFAULT_MODEL_CHANGES``, the voxel,
and its map read without the knowledge channel). Every run is scored on one fixed voxel set per voxel
size: what the reference configuration's beams reach at that size (``evaluate.instrument``),
with the visibility truth (``evaluation.visibility``) and ``metrics.radar_scores``; beside the
three baselines of ``evaluation.baseline`` (prior_only, raw_intensity, octomap) on the same set.
For each run, measured in this process: ``ms_per_frame`` (the device pipeline, planning
included), the scores, and ``max_dev_nats``: the largest |kernel - float64 oracle| over the
voxels that ``ORACLE_BEAMS`` of the middle frame reach, the oracle being ``radarcl.oracle`` end
to end (range profile, CFAR, eq. 12, ``fusion_at_points``), voxels whose decisions lie within
``FUSION_DECISION_MARGIN`` of a boundary left out (the default model's through
``interpret_detstats`` and its node tables). Runs on a Pareto front within their voxel size (no
other run both faster and higher in ``auc_detectable``; or faster and lower in ``ece_occupied``,
the calibration of the occupied calls) are marked; ``report.quality`` prints the table and draws
both against ms per frame, and a reliability diagram.
"""

import numpy as np

from radarcl import logodds, oracle
from radarcl.cfar_theory import CFAR_KINDS
from radarcl.config.keys import BUILTIN
from radarcl.evaluation.evaluate import baselines, instrument, map_observations, radar_score
from radarcl.geometry import BEAM_MODELS
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping
from radarcl.stages.fusion import Fusion

ORACLE_BEAMS = (0, 85, 170, 255)
DECISION_MARGIN = 1e-3           # as tests/tolerances.FUSION_DECISION_MARGIN
VOXELS = (0.4, 0.2, 0.1)
N_FFTS = (256, 512, 1024)


def variants(reference_config, voxels=VOXELS, default_config=None):
    """(dimension, Resolved) for the reference and each one-setting change of it; with
    ``default_config`` (the detection-statistics model's) also that and each one-setting change
    of its own knobs (``DEFAULT_MODEL_CHANGES``, ``model_variants``)."""
    out = [("reference", reference_config)]
    for n in N_FFTS:
        out.append(("zero padding", reference_config.replaced(range_fft__n_fft=n)))
    for b in BEAM_MODELS:
        out.append(("beam model", reference_config.replaced(beam__model=b)))
    for v in voxels:
        out.append(("voxel", reference_config.replaced(grid__voxel_m=v)))
    for k in CFAR_KINDS:
        out.append(("cfar", reference_config.replaced(cfar__kind=k)))
    if default_config is not None:
        out += model_variants(default_config, voxels)
    seen, unique = set(), []
    for dim, c in out:                   # the reference reappears in each dimension: run it once
        key = tuple(sorted(c.values.items()))
        if key not in seen:
            seen.add(key)
            unique.append((dim, c))
    return unique


# The default model's knobs swept one at a time around its defaults (``sensor_model``): what it
# takes as evidence, how much a nearer echo leaves to see behind it, how many correlated looks'
# worth the reading counts, the range FFT's zero padding (the bins its tables are built on).
DEFAULT_MODEL_CHANGES = (("evidence", "sensor_model__evidence", ("snr", "detection")),
                         ("blocker gap", "sensor_model__blocker_gap", (0.0, 0.1)),
                         ("look limit", "sensor_model__look_limit", (1.0, 4.0, 16.0)),
                         ("zero padding", "range_fft__n_fft", N_FFTS))
KNOWLEDGE_OFF = "knowledge channel off"


def model_variants(default_config, voxels=VOXELS):
    """(dimension, Resolved) of the default model: its configuration and each one-setting change
    of ``DEFAULT_MODEL_CHANGES`` and of the voxel (dimensions prefixed "default model: ")."""
    out = [("default model", default_config)]
    for dim, key, values in DEFAULT_MODEL_CHANGES:
        out += [(f"default model: {dim}", default_config.replaced(**{key: v})) for v in values]
    out += [("default model: voxel", default_config.replaced(grid__voxel_m=v)) for v in voxels]
    return out


def oracle_deviation(runtime, obs, config, beams=ORACLE_BEAMS):
    """Max |kernel map - float64 oracle map| [nat] of ``beams`` of the middle frame, the
    fraction of compared voxels that agree exactly, and how many were compared. The default
    model's: its evidence sums (``oracle.interpret_detstats`` and its node tables fused); the
    knowledge sums must agree within the same bound (``max_dev_knowledge``, in looks, beside)."""
    j = len(obs.samples) // 2
    mapping = Mapping.from_config(runtime, config=config)
    spec, lattice, model = mapping.grid.spec, mapping.fusion.lattice, mapping.fusion.model
    mapping.fuse(obs.samples[j], obs.poses[j])
    runtime.queue.finish()
    it, fusion = mapping.detection.interpreter, mapping.fusion
    pairs = it.node_pairs                        # the model's evidence is node pairs, not one value a bin
    evidence = it.arrays["evidence"].get(runtime.queue).reshape(lattice.n_beams, it.n_bins, *it.arrays["evidence"].shape[
        len(it.input_shape):])
    only = np.zeros_like(evidence)
    only[list(beams)] = evidence[list(beams)]
    check = EvidenceGrid(runtime, spec, knowledge=it.model.knowledge)
    Fusion(runtime, check, lattice, model, it.n_bins, fusion.bin_spacing_m, fusion.first_bin, fusion.last_bin,
           detstats=pairs, terrain_dz=fusion.terrain_dz)(only.reshape(fusion.evidence_shape), obs.poses[j])
    keys, data = check.bricks()
    index = spec.brick_voxels(keys[(data != 0).reshape(len(keys), -1).any(axis=1)])

    profiles = oracle.range_profile(obs.samples[j].astype(np.float64), config.n_fft, output="power")
    noise, _, mask = oracle.cfar(profiles, config.cfar_config())
    want = it.model.oracle(profiles, noise, mask, config.interpret_config(), fusion.bin_spacing_m, it.bin_model)
    if pairs:
        shape = (lattice.n_beams, it.n_bins) + want.shape[-2:]
        evidence64, nodes = None, (want[0].reshape(shape), want[1].reshape(shape))
    else:
        evidence64, nodes = want.reshape(lattice.n_beams, -1), None
    out = oracle.fusion_at_points(spec.index_to_world(index), evidence64, lattice, model, obs.poses[j],
                                  fusion.bin_spacing_m, fusion.first_bin, fusion.last_bin, margin=DECISION_MARGIN,
                                  beams=beams, nodes=nodes, terrain_dz=fusion.terrain_dz)
    sums, ambiguous = out[0], out[2]
    got = check.snapshot()[index[:, 2], index[:, 1], index[:, 0]].astype(np.int64)
    err = np.abs(got - sums)[~ambiguous]
    if not err.size:
        return 0.0, 1.0, 0
    return float(err.max()) / logodds.SCALE, float((err == 0).mean()), int(err.size)


SCORE_KEYS = ("auc_detectable", "iou_detectable", "auc_obstacles", "iou_obstacles", "auc_weak", "false_free",
              "false_free_obstacles", "shadow_unknown", "ece", "brier", "ece_occupied", "occupied_calls",
              "objects_found", "objects_total", "detectable_found", "detectable_total")
BASELINES = ("prior_only", "raw_intensity", "octomap")


def pareto(runs, key="auc_detectable", higher=True):
    """Flags: run i is on the front when no run is at least as fast and as good in ``key``
    (higher better, or lower with ``higher`` False), one strictly. A run without ``key`` (None)
    is on no front and dominates none."""
    sign = 1.0 if higher else -1.0
    scored = [r for r in runs if r.get(key) is not None]
    flags = []
    for r in runs:
        if r.get(key) is None:
            flags.append(False)
            continue
        g = sign * r[key]
        dominated = any(o["ms_per_frame"] <= r["ms_per_frame"] and sign * o[key] >= g
                        and (o["ms_per_frame"] < r["ms_per_frame"] or sign * o[key] > g) for o in scored)
        flags.append(not dominated)
    return flags


def run(runtime, scene, obs, reference_config, voxels=VOXELS, report=None, default_config=None):
    """Measure every variant of ``reference_config`` (and, given ``default_config``, of the
    default model's) on ``obs`` (simulated from ``scene``), each scored on the fixed voxel set of
    its voxel size (``evaluate.instrument``: what ``reference_config`` reaches at that size, so
    both models are scored on the same voxels), beside the three baselines. Returns the --json
    dict; each run carries ``pareto`` (the front of AUC detectable against ms per frame within its
    voxel size) and ``pareto_ece`` (the front of the occupied calls' ECE, lower better)."""
    say = report or (lambda _: None)
    instruments, runs, by_voxel = {}, [], {}
    for dim, config in variants(reference_config, voxels, default_config):
        v = config["grid.voxel_m"]
        if v not in instruments:
            say(f"truth and baselines at {v} m ...")
            inst = instruments[v] = instrument(runtime, scene, obs, reference_config.replaced(grid__voxel_m=v))
            by_voxel[str(v)] = dict(voxel_set=inst.describe(), classes=inst.truth.counts(), hidden_objects=inst.hidden,
                                    baselines=baselines(runtime, inst, obs))
        inst = instruments[v]
        base = default_config if dim.startswith("default model") else reference_config
        say(f"{dim}: {config.label(base)} ...")
        res = map_observations(runtime, obs, config)
        dev, exact, compared = oracle_deviation(runtime, obs, config)
        if config is reference_config:
            label = "reference: " + config.label()
        elif config is default_config:
            label = "default model: " + config.label()
        else:
            label = config.label(base)
        common = dict(voxel_m=v, config=config.as_dict(), ms_per_frame=res.ms_per_frame, max_dev_nats=dev,
                      exact_fraction=exact, oracle_voxels=compared, memory_mib=res.memory["sparse_bytes"] / 2 ** 20,
                      model=config["interpret.model"])
        scored = [(dim, label, radar_score(inst, res.log_odds, res.knowledge))]
        if config is default_config:                # the same map read without its unknown class
            scored.append(("default model: knowledge", KNOWLEDGE_OFF, radar_score(inst, res.log_odds)))
        for d, name, m in scored:
            runs.append(dict(dimension=d, label=name, **common, **{k: m.get(k) for k in SCORE_KEYS},
                             objects=m["objects"], reliability=m["reliability"]))
        del res
    for v in {r["voxel_m"] for r in runs}:                 # the fronts within one voxel set
        same = [r for r in runs if r["voxel_m"] == v]
        for r, front, calibrated in zip(same, pareto(same), pareto(same, "ece_occupied", higher=False)):
            r["pareto"], r["pareto_ece"] = front, calibrated
    ref_v = str(reference_config["grid.voxel_m"])
    front = [r["label"] for r in runs if r["pareto"] or r["pareto_ece"]]
    return dict(benchmark="quality", device=runtime.name, frames=len(obs.samples),
                observations=int(np.prod(obs.samples.shape[:3])), seed=obs.seed, reference_voxel_m=float(ref_v),
                voxel_set=by_voxel[ref_v]["voxel_set"], runs=runs, baselines=by_voxel[ref_v]["baselines"],
                by_voxel=by_voxel, pareto_front=front,
                default_model_on_front=sum(1 for r in runs if (r["pareto"] or r["pareto_ece"])
                                           and r["model"] == BUILTIN["interpret.model"]))
