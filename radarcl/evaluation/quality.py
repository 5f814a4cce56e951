"""Map error against run time on the reference scene: the sweep of `radarcl bench quality`.

One recording of the paper's 3,840 observations (``config.presets.EVALUATION_SEED``) is mapped with the
tuned configuration (``tuning.TUNED``) and with one setting changed at a time: zero padding
(n_fft 256 = none, 512 = x2, 1024 = x4), the beam model (``geometry.BEAM_MODELS``), the voxel
size (0.8, 0.4, 0.2, 0.1 m) and the CFAR kind; beside them the default model (detection statistics,
``sensor_model``) with its pipeline's knobs changed (``DEFAULT_MODEL_CHANGES``, the voxel, and the
binary "detection" evidence stacked on each cheaper grid: ``budget_variants``), and its map read
in other ways (``READINGS``: the look limit, and without the knowledge channel), which cost no run
time of their own. Every run is scored on one fixed voxel set: what the reference configuration's
beams reach at its voxel size (``evaluate.instrument``), with the visibility truth
(``evaluation.visibility``) and ``metrics.radar_scores``; a map of another voxel size is read on
that set's voxels (``on_voxel_set``), so that the voxel trades against the rest on one front. Beside
them, the three baselines of ``evaluation.baseline`` (prior_only, raw_intensity, octomap) on the same set.
For each run, measured in this process: ``ms_per_frame`` (the device pipeline, planning
included; the median of ``TIMING_PASSES``), the scores, and ``max_dev_nats``: the largest
|kernel - float64 oracle| over the voxels that ``ORACLE_BEAMS`` of the middle frame reach, the
oracle being ``radarcl.oracle`` end to end (range profile, CFAR, eq. 12, ``fusion_at_points``),
voxels whose decisions lie within ``FUSION_DECISION_MARGIN`` of a boundary left out (the default model's through
``interpret_detstats`` and its node tables). Runs on a Pareto front (no other run both faster and
higher in ``auc_detectable``; or faster and lower in ``ece_occupied``, the calibration of the
occupied calls) are marked; ``report.quality`` prints the table and draws both against ms per
frame, and a reliability diagram.
"""

import numpy as np

from radarcl import logodds, node_pairs, oracle, sensor_model
from radarcl.cfar_theory import CFAR_KINDS
from radarcl.config.keys import BUILTIN
from radarcl.errors import ConfigError
from radarcl.evaluation.evaluate import baselines, fuse_timed, instrument, map_observations, radar_score, read_map
from radarcl.geometry import BEAM_MODELS
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping
from radarcl.stages.fusion import Fusion

ORACLE_BEAMS = (0, 85, 170, 255)
# Each pipeline's run time is the median of this many passes, the later ones interleaved over every
# run after all are scored: a front drawn from one timing each follows the load of a shared machine.
TIMING_PASSES = 5
DECISION_MARGIN = 1e-3           # as tests/tolerances.FUSION_DECISION_MARGIN
VOXELS = (0.8, 0.4, 0.2, 0.1)
N_FFTS = (256, 512, 1024)


def variants(reference_config, voxels=VOXELS, default_config=None):
    """(dimension, Resolved) of every run of the pipeline: the reference and each one-setting
    change of it; with ``default_config`` (the detection-statistics model's) also that and
    ``model_variants`` of it. A configuration met twice is run once."""
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


# The default model's pipeline knobs, changed one at a time around its defaults (``sensor_model``):
# what it takes as evidence ("detection": only whether the CFAR called the bin, which spares the
# likelihood of the measured power), how much a nearer echo leaves to see behind it (0: no gap, no
# mixture), the range FFT's zero padding (the bins its tables are built on). Each is a run of its own.
DEFAULT_MODEL_CHANGES = (("evidence", "sensor_model__evidence", ("snr", "detection")),
                         ("blocker gap", "sensor_model__blocker_gap", (0.0, 0.1)),
                         ("zero padding", "range_fft__n_fft", N_FFTS))
# What a user on a budget stacks: the binary evidence (no likelihood of the measured power to
# compute) with each cheaper grid of bins or voxels.
BUDGET_EVIDENCE = "detection"
# How the default model's map is read (``sensor_model.read_log_odds``): changed on the same map, so
# at the same run time; and the map without its knowledge channel (``KNOWLEDGE_OFF``).
READINGS = (("look limit", "sensor_model__look_limit", (1.0, 4.0, 16.0)),)
KNOWLEDGE_OFF = "knowledge channel off"


def model_variants(default_config, voxels=VOXELS):
    """(dimension, Resolved) of the default model's pipeline runs: its configuration, each
    one-setting change of ``DEFAULT_MODEL_CHANGES`` and of the voxel, and ``budget_variants``
    (dimensions prefixed "default model: ")."""
    out = [("default model", default_config)]
    for dim, key, values in DEFAULT_MODEL_CHANGES:
        out += [(f"default model: {dim}", default_config.replaced(**{key: v})) for v in values]
    out += [("default model: voxel", default_config.replaced(grid__voxel_m=v)) for v in voxels]
    return out + budget_variants(default_config, voxels)


def budget_variants(default_config, voxels=VOXELS):
    """(dimension "default model: budget", Resolved): ``BUDGET_EVIDENCE`` with each zero padding
    and each voxel below the default's costs (fewer bins, larger voxels)."""
    cheap = dict(sensor_model__evidence=BUDGET_EVIDENCE)
    out = [default_config.replaced(**cheap, range_fft__n_fft=n) for n in N_FFTS if n < default_config.n_fft]
    out += [default_config.replaced(**cheap, grid__voxel_m=v) for v in voxels if v > default_config["grid.voxel_m"]]
    return [("default model: budget", c) for c in out]


def readings(default_config):
    """(dimension, label, Resolved to read with, with its knowledge channel) of ``READINGS`` and
    ``KNOWLEDGE_OFF``: the default model's one map read in other ways."""
    out = [(f"default model: {dim}", None, default_config.replaced(**{key: v}), True)
           for dim, key, values in READINGS for v in values if v != default_config[key.replace("__", ".")]]
    return out + [("default model: knowledge", KNOWLEDGE_OFF, default_config, False)]


def voxel_readable(voxel_m, set_voxel_m):
    """Whether a map of ``voxel_m`` can be read on a voxel set of ``set_voxel_m`` (``on_voxel_set``):
    as large or larger, or a finer voxel that divides it."""
    ratio = set_voxel_m / voxel_m
    return ratio <= 1 + 1e-9 or abs(ratio - round(ratio)) <= 1e-6 * ratio


def check_voxels(set_voxel_m, voxels):
    """ConfigError unless every voxel of ``voxels`` can be read on a set of ``set_voxel_m``."""
    bad = [v for v in voxels if not voxel_readable(v, set_voxel_m)]
    if bad:
        raise ConfigError(f"voxel {bad[0]:g} m cannot be scored on the {set_voxel_m:g} m voxel set: expected a voxel "
                          f"as large or larger, or a finer one that divides it")


def on_voxel_set(spec, target, log_odds, knowledge=None):
    """A map's dense (nz, ny, nx) ``log_odds`` (and ``knowledge``) made on ``spec``, read on the
    voxels of ``target`` (a ``GridSpec``, the fixed voxel set's grid). A map voxel as large or
    larger: each target voxel reads the map voxel that holds its centre (what a query there
    reads; beyond the map, the nearest). A finer one, whose edge must divide the target's on a
    lattice through the target's origin: each target voxel reads its most occupied map voxel (the
    highest log-odds, the first of equals) and that voxel's knowledge, as "is anything in this
    voxel" reads. Returns (log_odds, knowledge or None)."""
    ratio = target.voxel_m / spec.voxel_m
    if ratio <= 1 + 1e-9:
        index = []
        for axis in (2, 1, 0):                   # (z, y, x) of the dense arrays
            centres = target.origin_m[axis] + (np.arange(target.shape[axis]) + 0.5) * target.voxel_m
            index.append(np.clip(np.floor((centres - spec.origin_m[axis]) / spec.voxel_m).astype(np.int64), 0,
                                 spec.shape[axis] - 1))
        pick = np.ix_(*index)
        return log_odds[pick], None if knowledge is None else knowledge[pick]
    k = round(ratio)
    offsets = [(target.origin_m[a] - spec.origin_m[a]) / spec.voxel_m for a in (2, 1, 0)]
    if not voxel_readable(spec.voxel_m, target.voxel_m) or any(abs(o - round(o)) > 1e-6 for o in offsets):
        raise ConfigError(f"a map of {spec.voxel_m:g} m voxels cannot be read on a set of {target.voxel_m:g} m "
                          f"voxels: expected a finer voxel that divides it, on a lattice through its origin")
    # the map voxels of each target voxel, clipped to the map: a target voxel partly beyond it reads the
    # ones inside (the clipped index repeats one of them), one wholly beyond it the nearest, as above
    pick = np.ix_(*(np.clip(round(offset) + np.arange(target.shape[axis] * k), 0, spec.shape[axis] - 1)
                    for axis, offset in zip((2, 1, 0), offsets)))
    nz, ny, nx = (target.shape[a] for a in (2, 1, 0))

    def blocks(a):                               # (nz, ny, nx, k^3): each target voxel's map voxels
        return a.reshape(nz, k, ny, k, nx, k).transpose(0, 2, 4, 1, 3, 5).reshape(nz, ny, nx, k ** 3)
    fine = blocks(log_odds[pick])
    most = fine.argmax(axis=-1)[..., None]
    read = np.take_along_axis(fine, most, -1)[..., 0]
    if knowledge is None:
        return read, None
    return read, np.take_along_axis(blocks(knowledge[pick]), most, -1)[..., 0]


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
           detstats=pairs, terrain_dz=fusion.terrain_dz, classes=fusion.classes)(only.reshape(fusion.evidence_shape),
                                                                                 obs.poses[j])
    keys, data = check.bricks()
    index = spec.brick_voxels(keys[(data != 0).reshape(len(keys), -1).any(axis=1)])

    profiles = oracle.range_profile(obs.samples[j].astype(np.float64), config.n_fft, output="power")
    noise, _, mask = oracle.cfar(profiles, config.cfar_config())
    want = it.model.oracle(profiles, noise, mask, config.interpret_config(), fusion.bin_spacing_m, it.bin_model)
    if pairs:
        shape = (lattice.n_beams, it.n_bins) + want.shape[-2:]
        node_pairs.kept_classes(want, it.classes)       # the premise of the classes the pipeline dropped: all 0
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
    (higher better, or lower with ``higher`` False), one strictly, and no earlier run sits on the
    same point (another reading of one map that reads the same is no second point). A run
    without ``key`` (None) is on no front and dominates none."""
    sign = 1.0 if higher else -1.0
    flags, seen = [], set()
    scored = [r for r in runs if r.get(key) is not None]
    for r in runs:
        if r.get(key) is None:
            flags.append(False)
            continue
        g, point = sign * r[key], (r["ms_per_frame"], r[key])
        dominated = any(o["ms_per_frame"] <= r["ms_per_frame"] and sign * o[key] >= g
                        and (o["ms_per_frame"] < r["ms_per_frame"] or sign * o[key] > g) for o in scored)
        flags.append(not dominated and point not in seen)
        seen.add(point)
    return flags


def run(runtime, scene, obs, reference_config, voxels=VOXELS, report=None, default_config=None, passes=TIMING_PASSES,
        prepared=None):
    """Measure every variant of ``reference_config`` (and, given ``default_config``, of the
    default model's, with its ``readings``) on ``obs`` (simulated from ``scene``), each scored on
    the fixed voxel set of ``reference_config``'s voxel size (``evaluate.instrument``; other voxel
    sizes read on it by ``on_voxel_set``), beside the three baselines; each pipeline's run time
    the median of ``passes`` timings. Returns the --json dict; each run carries ``pareto`` (the
    front of AUC detectable against ms per frame) and ``pareto_ece`` (the front of the occupied
    calls' ECE, lower better). ``prepared``: (the instrument, the baselines) a caller already made
    for ``reference_config`` on ``obs`` (``evaluate.instrument``, ``evaluate.baselines``), not
    made again."""
    say = report or (lambda _: None)
    if isinstance(passes, bool) or not isinstance(passes, int) or passes < 1:
        raise ConfigError(f"passes must be a whole number of timings, 1 or more, got {passes!r}")
    check_voxels(reference_config["grid.voxel_m"], voxels)
    if prepared is None:
        say(f"truth and baselines at {reference_config['grid.voxel_m']} m ...")
        inst = instrument(runtime, scene, obs, reference_config)
        base = baselines(runtime, inst, obs)
    else:
        inst, base = prepared
    runs = []
    pipelines = variants(reference_config, voxels, default_config)
    times = {id(c): [] for _, c in pipelines}
    for dim, config in pipelines:
        model_base = default_config if dim.startswith("default model") else reference_config
        say(f"{dim}: {config.label(model_base)} ...")
        res = inst.reference_map if config is reference_config else map_observations(runtime, obs, config)
        dev, exact, compared = oracle_deviation(runtime, obs, config)
        if config is reference_config:
            label = "reference: " + config.label()
        elif config is default_config:
            label = "default model: " + config.label()
        else:
            label = config.label(model_base)
        times[id(config)].append(res.ms_per_frame)
        common = dict(voxel_m=config["grid.voxel_m"], pipeline=id(config), max_dev_nats=dev,
                      exact_fraction=exact, oracle_voxels=compared, memory_mib=res.memory["sparse_bytes"] / 2 ** 20,
                      model=config["interpret.model"])
        read = [(dim, label, config, True)]
        if config is default_config:                # the same map read in other ways, at the same cost
            read += readings(default_config)
        for d, name, reading, known in read:
            log_odds, knowledge = (res.log_odds, res.knowledge) if reading is config else read_map(res.grid, reading)
            log_odds, knowledge = on_voxel_set(res.spec, inst.spec, log_odds, knowledge if known else None)
            m = radar_score(inst, log_odds, knowledge)
            runs.append(dict(dimension=d, label=name or reading.label(default_config), config=reading.as_dict(),
                             **common, **{k: m.get(k) for k in SCORE_KEYS}, objects=m["objects"],
                             reliability=m["reliability"]))
        del res
    for k in range(1, passes):
        say(f"timing pass {k + 1} of {passes} over the {len(pipelines)} pipelines ...")
        for _, config in pipelines:
            times[id(config)].append(fuse_timed(runtime, Mapping.from_config(runtime, config=config), obs))
    for r in runs:
        took = times[r.pop("pipeline")]
        r.update(ms_per_frame=float(np.median(took)), ms_per_frame_passes=took)
    median = fronts(runs)
    for r, front, calibrated in zip(runs, *median):
        r["pareto"], r["pareto_ece"] = front, calibrated
    # how far each front holds under the load's noise: the fronts of each timing pass alone
    by_pass = [fronts([dict(r, ms_per_frame=r["ms_per_frame_passes"][k]) for r in runs]) for k in range(passes)]
    for i, r in enumerate(runs):
        r["pareto_passes"] = sum(auc[i] for auc, _ in by_pass)
        r["pareto_ece_passes"] = sum(ece[i] for _, ece in by_pass)
    return dict(benchmark="quality", device=runtime.name, frames=len(obs.samples), timing_passes=passes,
                observations=int(np.prod(obs.samples.shape[:3])), seed=obs.seed,
                reference_voxel_m=float(reference_config["grid.voxel_m"]), voxel_set=inst.describe(),
                classes=inst.truth.counts(), hidden_objects=inst.hidden, runs=runs, baselines=base,
                pareto_front=[r["label"] for r in runs if r["pareto"] or r["pareto_ece"]],
                default_model_on_front=default_on_front(runs, *median),
                default_model_on_front_by_pass=[default_on_front(runs, *f) for f in by_pass])


def fronts(runs):
    """(AUC front flags, occupied-call ECE front flags) of ``runs`` (``pareto``)."""
    return pareto(runs), pareto(runs, "ece_occupied", higher=False)


def default_on_front(runs, auc, ece):
    """How many of the default model's ``runs`` are on either front (``auc``, ``ece``: flags)."""
    return sum(1 for r, a, e in zip(runs, auc, ece) if (a or e) and r["model"] == BUILTIN["interpret.model"])
