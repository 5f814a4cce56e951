"""`radarcl bench fusion`: one frame of the paper's radar into the paper's grid at 0.1 m.

Columns, all measured in the same run, each the median of interleaved blocks (blocks during
which other processes used more than a quarter of a core are discarded: ``interleaved_medians``):
- still radar: the kernel on evidence already on the device, the frame's plan cached (a radar
  on its stand);
- moving radar: a new pose every frame, planning included (the bricks the beams reach and
  their candidate windows, ``Fusion.plan``, then the kernel);
- planning alone, on the device (``FusionPlanner``) and, as the baseline, the same windows in
  numpy (``candidate_windows``, how radarcl planned before);
- a spinning Navtech-like lattice (400 azimuths x 1, 1.8 x 40 deg beams, 0.0432 m bins) still,
  every bin -1 nat, into an 80 x 80 x 4 m grid at 0.1 m around it; and its whole pipeline (CFAR,
  interpreter, fusion) on a scan of noise and echoes, with eq. 12 and with the default model;
- the whole pipeline: upload raw samples, range FFT, CFAR, eq. 12, fusion;
- the same frame with the detection-statistics model (``sensor_model``; interpret.model
  "detstats"): the gather, the still table and the moving radar on its node pairs and knowledge
  pool, beside eq. 12's in the same interleaved run (the goal: at most 1.5x eq. 12's gather);
- the float64 numpy oracle (``oracle.fusion_at_points``), timed on ``ORACLE_BEAMS`` beams over
  the voxels of the reached bricks and scaled to the frame (it is linear in beams); the
  kernel's error is measured on those beams;
- the memory floor: one int32 read-modify-write of every voxel the frame updates, at the copy
  bandwidth measured here (numpy copy of a 256 MiB array: bytes read + written per second).
OctoMap is not a column: octomap-python is not a dependency (ARCHITECTURE.md measured it at
9.5 s per frame).
"""

import math
import os
import time

import numpy as np

from radarcl import oracle
from radarcl.bench.timing import interleaved_medians
from radarcl.config.stage_config import PAPER_RADAR
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GridSpec
from radarcl.pipeline import Mapping
from radarcl.scene.echoes import paper_like_samples
from radarcl.stages.fusion import Fusion

N_FFT = 1024
TILT_DEG = -7.0
# The paper's grid: 80 x 70 x 20 m at 0.1 m, the sensor 8 m from its near edge, mid-height.
PAPER_GRID = GridSpec((-8.0, -35.0, -10.0), 0.1, (800, 700, 200))
ORACLE_BEAMS = (0, 85, 170, 255)
GOAL_MS = 20.0                      # moving radar, planning included
STILL_GOAL_MS = 8.0
SPIN_GRID = GridSpec((-40.0, -40.0, -2.0), 0.1, (800, 800, 40))


def numpy_planning(fusion, pose):
    """The brick listing as radarcl did it before the device planner: numpy windows of the
    blocks of 8^3 bricks, then of every brick of the kept blocks (the baseline of planning_ms)."""
    from radarcl.geometry import check_poses
    from radarcl.gridspec import BRICK
    from radarcl.stages.fusion_plan import nonempty

    frame = fusion.head_frame(check_poses(pose, fusion.lattice.n_beams))
    shape = np.asarray(fusion.grid.spec.brick_shape)
    coarse = np.stack(np.meshgrid(*[np.arange(-(-n // 8)) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    kept = coarse[nonempty(fusion._windows(coarse, BRICK * 8, frame))]
    offsets = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), -1).reshape(-1, 3)
    fine = (kept[:, None, :] * 8 + offsets[None]).reshape(-1, 3)
    fine = fine[(fine < shape).all(axis=1)]
    windows = fusion._windows(fine, BRICK, frame)
    keep = nonempty(windows)
    return fine[keep], windows[keep]


def copy_bandwidth(nbytes=256 * 2 ** 20, repeat=5):
    """Bytes read + written per second by numpy copying an array of ``nbytes``."""
    a = np.ones(nbytes // 8)
    b = np.empty_like(a)
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - start)
    return 2 * nbytes / best


def run(runtime, repeat=20, report=None, spec=PAPER_GRID, spin_spec=SPIN_GRID):
    """Measure; returns a dict (the --json object). ``report`` gets progress lines; ``spec`` and
    ``spin_spec`` replace the paper's grid and the spinning radar's (coarser ones make a quick
    check)."""
    say = report or (lambda _: None)
    lattice = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT_DEG)
    model = BeamModel.from_radar(PAPER_RADAR)
    grid = EvidenceGrid(runtime, spec)
    mapping = Mapping(runtime, grid, lattice, model, radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32)
    samples = paper_like_samples(seed=0, tilt_deg=TILT_DEG)
    pose = np.eye(4)
    load_before = os.getloadavg()
    say("planning the frame (bricks the beams reach) ...")
    start = time.perf_counter()
    plan = mapping.fusion.plan(pose)
    first_plan_s = time.perf_counter() - start
    mapping.fuse(samples, pose)
    _, data = grid.bricks()
    voxels = int(np.count_nonzero(data))
    fusion, it = mapping.fusion, mapping.detection.interpreter

    def fusion_only():
        fusion.enqueue(it.arrays["evidence"], plan).wait()

    def gather_only():
        fusion.enqueue(it.arrays["evidence"], plan, gather=True).wait()

    def pipeline():
        mapping.fuse(samples, pose)
        runtime.queue.finish()

    step = iter(range(1, 10 ** 9))

    def moving_pose():
        """A new pose each call: 2 cm and 0.02 deg further (a robot at 0.4 m/s, 20 frames/s)."""
        k = next(step)
        return pose_from_xyz_rpy(0.02 * k, 0.0, 0.0, yaw=math.radians(0.02) * k)

    def moving():
        fusion.enqueue(it.arrays["evidence"], fusion.plan(moving_pose(), cache=False)).wait()

    def planning():
        fusion.plan(moving_pose(), cache=False)

    def planning_numpy():
        numpy_planning(fusion, moving_pose())

    ds = _detstats(runtime, spec, lattice, model, samples, pose, moving_pose)
    interpret = _interpreter_only(runtime, mapping, pose)
    spin = _spinning(runtime, spin_spec)
    spin_pipe = _spinning_pipelines(runtime, spin_spec)
    say(f"timing a still, a moving and a spinning radar, planning and the pipeline, {repeat} frames each ...")
    load = {}
    if plan.table is None:
        say("  (no still table: it would not fit the device's memory budget; still = the gather)")
    t = interleaved_medians(dict(still=fusion_only, gather=gather_only, moving=moving, planning=planning,
                                 planning_numpy=planning_numpy, spinning=spin["fuse"], spinning_gather=spin["gather"],
                                 pipeline=pipeline, detstats_still=ds["still"], detstats_gather=ds["gather"],
                                 detstats_moving=ds["moving"], detstats_pipeline=ds["pipeline"],
                                 spinning_pipeline=spin_pipe["paper"], detstats_spinning_pipeline=spin_pipe["detstats"],
                                 interpret=interpret, detstats_interpret=ds["interpret"],
                                 spinning_interpret=spin_pipe["paper_interpret"],
                                 detstats_spinning_interpret=spin_pipe["detstats_interpret"]),
                          repeat, block=10, warmup=2, load=load)
    plan_s = t["planning"]
    say(f"float64 oracle on {len(ORACLE_BEAMS)} of {lattice.n_beams} beams over {len(plan.bricks)} bricks ...")
    evidence = it.arrays["evidence"].get(runtime.queue).reshape(lattice.n_beams, it.n_bins)
    index = spec.brick_voxels(plan.bricks)
    start = time.perf_counter()
    sums, updates, ambiguous = oracle.fusion_at_points(spec.index_to_world(index), evidence, lattice, model,
                                                     pose, fusion.bin_spacing_m, fusion.first_bin, fusion.last_bin,
                                                     margin=1e-3, beams=ORACLE_BEAMS)
    oracle_s = (time.perf_counter() - start) * lattice.n_beams / len(ORACLE_BEAMS)
    only = np.zeros_like(evidence)
    only[list(ORACLE_BEAMS)] = evidence[list(ORACLE_BEAMS)]
    check = EvidenceGrid(runtime, spec)
    Fusion(runtime, check, lattice, model, it.n_bins, fusion.bin_spacing_m, fusion.first_bin, fusion.last_bin)(only, pose)
    got = check.snapshot()[index[:, 2], index[:, 1], index[:, 0]].astype(np.int64)
    clear = ~ambiguous
    err = np.abs(got - sums)

    bandwidth = copy_bandwidth()
    floor_s = voxels * 8 / bandwidth
    spin_floor_s = spin["voxels"] * 8 / bandwidth
    mem = grid.memory()
    return dict(
        benchmark="fusion", device=runtime.name, repeat=repeat, voxel_m=spec.voxel_m,
        grid_shape=list(spec.shape), n_beams=lattice.n_beams, n_bins=it.n_bins, tilt_deg=TILT_DEG,
        still_ms_per_frame=t["still"] * 1e3, gather_ms_per_frame=t["gather"] * 1e3,
        still_table_mib=(plan.table.nbytes / 2 ** 20) if plan.table is not None else None,
        moving_ms_per_frame=t["moving"] * 1e3,
        planning_ms=plan_s * 1e3, planning_ms_numpy=t["planning_numpy"] * 1e3,
        spinning_ms_per_frame=t["spinning"] * 1e3, spinning_gather_ms_per_frame=t["spinning_gather"] * 1e3,
        spinning_voxels_per_frame=spin["voxels"],
        spinning_floor_ms_per_frame=spin_floor_s * 1e3, spinning_grid_shape=list(spin_spec.shape),
        pipeline_ms_per_frame=t["pipeline"] * 1e3, plan_ms_first=first_plan_s * 1e3,
        detstats_still_ms_per_frame=t["detstats_still"] * 1e3, detstats_gather_ms_per_frame=t["detstats_gather"] * 1e3,
        detstats_moving_ms_per_frame=t["detstats_moving"] * 1e3,
        detstats_gather_ratio=t["detstats_gather"] / t["gather"],
        detstats_pipeline_ms_per_frame=t["detstats_pipeline"] * 1e3,
        spinning_pipeline_ms_per_frame=t["spinning_pipeline"] * 1e3,
        detstats_spinning_pipeline_ms_per_frame=t["detstats_spinning_pipeline"] * 1e3,
        interpret_ms_per_frame=t["interpret"] * 1e3, detstats_interpret_ms_per_frame=t["detstats_interpret"] * 1e3,
        spinning_interpret_ms_per_frame=t["spinning_interpret"] * 1e3,
        detstats_spinning_interpret_ms_per_frame=t["detstats_spinning_interpret"] * 1e3,
        voxels_per_frame=voxels, bricks_per_frame=int(len(plan.bricks)),
        copy_bandwidth_gb_s=bandwidth / 1e9, floor_ms_per_frame=floor_s * 1e3,
        ratio_vs_floor=t["still"] / floor_s, load=load, load_before=list(load_before), load_after=list(os.getloadavg()),
        numpy_ms_per_frame=oracle_s * 1e3, ratio_vs_numpy=oracle_s / t["still"],
        oracle_beams=len(ORACLE_BEAMS), oracle_voxels_compared=int(clear.sum()),
        max_error_units=int(err[clear].max()), exact_fraction=float((err[clear] == 0).mean()),
        ambiguous_voxels=int(ambiguous.sum()),
        dense_mib=mem["dense_bytes"] / 2 ** 20, sparse_mib=mem["sparse_bytes"] / 2 ** 20,
        goal=f"moving_ms_per_frame <= {GOAL_MS}, still_ms_per_frame <= {STILL_GOAL_MS}",
    )


def _detstats(runtime, spec, lattice, model, samples, pose, moving_pose):
    """The frame with the detection-statistics model into a grid of ``spec`` with the knowledge
    channel: {"still", "gather", "moving"}, callables fusing the frame's node pairs, "pipeline",
    the whole pipeline from raw samples (the interpreter's noise floors included), and
    "interpret", the interpreter alone."""
    from radarcl.config.presets import paper_config
    from radarcl.pipeline import bin_model
    from radarcl.sensor_model import terrain_dz

    config = paper_config(spec.voxel_m, {"interpret.model": "detstats"})
    grid = EvidenceGrid(runtime, spec, knowledge=True)
    mapping = Mapping(runtime, grid, lattice, model, radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32,
                      interpret_config=config.interpret_config(), bin_model=bin_model(config, spec.voxel_m),
                      terrain_dz=terrain_dz(config.model_params()))
    mapping.fuse(samples, pose)
    fusion, nodes = mapping.fusion, mapping.detection.interpreter.arrays["evidence"]
    plan = fusion.plan(pose)                        # the pose came back: the still table is recorded
    return dict(still=lambda: fusion.enqueue(nodes, plan).wait(), gather=lambda: fusion.enqueue(nodes, plan, gather=True).wait(),
                moving=lambda: fusion.enqueue(nodes, fusion.plan(moving_pose(), cache=False)).wait(),
                pipeline=lambda: (mapping.fuse(samples, pose), runtime.queue.finish()),
                interpret=_interpreter_only(runtime, mapping, pose))


def _interpreter_only(runtime, mapping, pose):
    """A callable running ``mapping``'s interpreter alone (all its launches) on the CFAR's outputs
    of the frame it fused last, as its pipeline runs it at ``pose``: where that pose's still table
    is recorded, making only the node pairs the table reads (``StillTable.node_use``)."""
    detection = mapping.detection
    cfar = detection.cfar
    profiles = mapping.range_fft.arrays["profiles"] if mapping.range_fft is not None else cfar.arrays["profiles"]
    table = mapping.fusion.plan(pose).table
    use = None if table is None else table.node_use
    return lambda: (detection.interpreter.enqueue(profiles, cfar.arrays["noise"], cfar.arrays["mask"], node_use=use),
                    runtime.queue.finish())


def _spinning(runtime, spec):
    """A Navtech-like spinning radar, still, every bin -1 nat: {"fuse": one frame, "voxels":
    the voxels it updates}."""
    from radarcl import logodds
    from radarcl.config import mapconfig

    config = mapconfig.resolve("navtech-cts350x")
    sensor = config.sensor
    grid = EvidenceGrid(runtime, spec)
    lattice = sensor.lattice()
    model = sensor.beam_model(config["beam.model"], spec.voxel_m)
    n_bins = sensor.n_bins()
    spacing = sensor.bin_spacing_m()
    i = config.interpret_config()
    first, last = i.bin_interval(spacing, n_bins)
    fusion = Fusion(runtime, grid, lattice, model, n_bins, spacing, first, last)
    evidence = np.full(fusion.evidence_shape, -logodds.SCALE, np.int32)
    fusion.upload(evidence).wait()
    plan = fusion.plan(np.eye(4))
    fusion.enqueue(plan=plan).wait()
    _, data = grid.bricks()
    fusion.plan(np.eye(4))                          # the pose came back: the still table is recorded
    return dict(fuse=lambda: fusion.enqueue(plan=plan).wait(), gather=lambda: fusion.enqueue(plan=plan, gather=True).wait(),
                voxels=int(np.count_nonzero(data)))


def _spinning_pipelines(runtime, spec):
    """The spinning radar's whole pipeline from its power profiles (CFAR, interpreter, fusion),
    still: {"paper": eq. 12's, "detstats": the default model's}, callables fusing one scan of
    exponential noise with echoes (a wall every 40 m of range on every azimuth, scattered strong
    bins) into a grid of ``spec`` each, and "paper_interpret", "detstats_interpret": their
    interpreters alone on that scan."""
    from radarcl.config import mapconfig

    rng = np.random.default_rng(3)
    out, scan = {}, None
    for model in ("paper", "detstats"):
        config = mapconfig.resolve("navtech-cts350x", flags={"interpret.model": model, "grid.voxel_m": spec.voxel_m,
                                                             "grid.origin_m": list(spec.origin_m),
                                                             "grid.size_m": [n * spec.voxel_m for n in spec.shape]})
        mapping = Mapping.from_config(runtime, config=config)
        if scan is None:                           # one scan for both models
            scan = rng.exponential(size=mapping.frame_shape).astype(np.float32)
            spacing = config.sensor.bin_spacing_m()
            for r in np.arange(10.0, 80.0, 40.0):
                scan[:, int(r / spacing):int(r / spacing) + 6] *= 1e3
            scan[rng.random(scan.shape) < 1e-3] *= 1e4
        pose = np.eye(4)
        for _ in range(2):                         # the pose came back: the still table is recorded
            mapping.fuse(scan, pose)
        runtime.queue.finish()
        out[model] = lambda m=mapping: (m.fuse(scan, pose), runtime.queue.finish())
        out[model + "_interpret"] = _interpreter_only(runtime, mapping, pose)
    return out


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    kept = sum(v["blocks_kept"] for v in r["load"].values())
    dropped = sum(v["blocks_discarded"] for v in r["load"].values())
    return [
        f"fusion of one paper frame ({r['n_beams']} beams x {r['n_bins']} bins, tilt {r['tilt_deg']} deg) into "
        f"{'x'.join(map(str, r['grid_shape']))} voxels of {r['voxel_m']} m on {r['device']}; medians of "
        f"interleaved blocks of {r['repeat']} frames ({dropped} of {kept + dropped} blocks discarded under load; "
        f"load average {r['load_before'][0]:.2f} before, {r['load_after'][0]:.2f} after)",
        f"  still radar              {r['still_ms_per_frame']:9.1f} ms/frame  (goal <= {STILL_GOAL_MS:g}; from the "
        f"recorded table, {r['still_table_mib'] or 0:.0f} MiB; the gather: {r['gather_ms_per_frame']:.1f} ms; "
        f"{r['voxels_per_frame']} voxels updated, {r['bricks_per_frame']} bricks)",
        f"  moving radar             {r['moving_ms_per_frame']:9.1f} ms/frame  (a new pose every frame, planning "
        f"included; goal <= {GOAL_MS:g})",
        f"  planning a new pose      {r['planning_ms']:9.1f} ms/frame  (device windows; numpy windows as before: "
        f"{r['planning_ms_numpy']:.1f} ms, ratio {r['planning_ms_numpy'] / r['planning_ms']:.1f})",
        f"  spinning radar, still    {r['spinning_ms_per_frame']:9.1f} ms/frame  (400 x 1 beams into "
        f"{'x'.join(map(str, r['spinning_grid_shape']))} voxels, {r['spinning_voxels_per_frame']} updated; the gather: "
        f"{r['spinning_gather_ms_per_frame']:.1f} ms; floor {r['spinning_floor_ms_per_frame']:.2f} ms)",
        f"  whole pipeline, still    {r['pipeline_ms_per_frame']:9.1f} ms/frame  (raw samples to map)",
        f"  spinning, whole pipeline {r['spinning_pipeline_ms_per_frame']:9.1f} ms/frame  (profiles to map, still; "
        f"detection statistics {r['detstats_spinning_pipeline_ms_per_frame']:.1f} ms, "
        f"{r['detstats_spinning_pipeline_ms_per_frame'] / r['spinning_pipeline_ms_per_frame']:.2f}x eq. 12's, goal <= 1.5; "
        f"its interpreter {r['detstats_spinning_interpret_ms_per_frame']:.2f} ms, eq. 12's "
        f"{r['spinning_interpret_ms_per_frame']:.2f} ms)",
        f"  detection statistics     {r['detstats_gather_ms_per_frame']:9.1f} ms/frame  (the gather on node pairs + "
        f"knowledge: {r['detstats_gather_ratio']:.2f}x eq. 12's gather, goal <= 1.5; still table "
        f"{r['detstats_still_ms_per_frame']:.1f} ms, moving {r['detstats_moving_ms_per_frame']:.1f} ms; whole pipeline "
        f"{r['detstats_pipeline_ms_per_frame']:.1f} ms, {r['detstats_pipeline_ms_per_frame'] / r['pipeline_ms_per_frame']:.2f}x "
        f"eq. 12's; its interpreter {r['detstats_interpret_ms_per_frame']:.2f} ms, eq. 12's "
        f"{r['interpret_ms_per_frame']:.2f} ms)",
        f"  float64 numpy oracle     {r['numpy_ms_per_frame']:9.0f} ms/frame  (timed on {r['oracle_beams']} beams, scaled)"
        f"  ratio_vs_numpy {r['ratio_vs_numpy']:.0f}",
        f"  memory floor             {r['floor_ms_per_frame']:9.2f} ms/frame  (int32 read+write of the updated voxels at "
        f"{r['copy_bandwidth_gb_s']:.1f} GB/s)  ratio_vs_floor {r['ratio_vs_floor']:.1f}",
        f"  error vs oracle: max {r['max_error_units']} unit(s), {100 * r['exact_fraction']:.4f} % exact over "
        f"{r['oracle_voxels_compared']} voxels ({r['ambiguous_voxels']} ambiguous not compared)",
        f"  memory: {r['sparse_mib']:.0f} MiB in bricks vs {r['dense_mib']:.0f} MiB dense",
    ]


def add_arguments(parser):
    """`radarcl bench fusion` options."""
    from radarcl.commands.options import bounded_int

    parser.add_argument("--repeat", type=bounded_int(1, 400), default=20,
                        help="timed frames per variant, 1-400 (default: %(default)s)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(runtime(), repeat=args.repeat, report=say)
    return result, format_table(result)
