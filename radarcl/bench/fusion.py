"""`radarcl bench fusion`: one frame of the paper's radar into the paper's grid at 0.1 m.

Columns, all measured in the same run:
- fusion alone: the kernel on evidence already on the device, the frame's plan cached (a
  radar on its stand); planning a new pose (the host's brick listing) is timed apart;
- the whole pipeline: upload raw samples, range FFT, CFAR, eq. 12, fusion;
- the float64 numpy oracle (``oracle.fusion_at_points``), timed on ``ORACLE_BEAMS`` beams over
  the voxels of the reached bricks and scaled to the frame (it is linear in beams); the
  kernel's error is measured on those beams;
- the memory floor: one int32 read-modify-write of every voxel the frame updates, at the copy
  bandwidth measured here (numpy copy of a 256 MiB array: bytes read + written per second).
OctoMap is not a column: octomap-python is not a dependency (ARCHITECTURE.md measured it at
9.5 s per frame).
"""

import math
import time

import numpy as np

from radarcl import oracle
from radarcl.bench import interleaved_medians
from radarcl.config import PAPER_RADAR
from radarcl.geometry import BeamLattice, BeamModel, pose_from_xyz_rpy
from radarcl.grid import EvidenceGrid, GridSpec
from radarcl.pipeline import Mapping
from radarcl.scene.profiles import paper_like_samples
from radarcl.stages.fusion import Fusion

N_FFT = 1024
TILT_DEG = -7.0
# The paper's grid: 80 x 70 x 20 m at 0.1 m, the sensor 8 m from its near edge, mid-height.
PAPER_GRID = GridSpec((-8.0, -35.0, -10.0), 0.1, (800, 700, 200))
ORACLE_BEAMS = (0, 85, 170, 255)
GOAL_MS = 20.0


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


def run(runtime, repeat=20, report=None, spec=PAPER_GRID):
    """Measure; returns a dict (the --json object). ``report`` gets progress lines; ``spec``
    replaces the paper's grid (a coarser one makes a quick check)."""
    say = report or (lambda _: None)
    lattice = BeamLattice.from_radar(PAPER_RADAR, tilt_deg=TILT_DEG)
    model = BeamModel.from_radar(PAPER_RADAR)
    grid = EvidenceGrid(runtime, spec)
    mapping = Mapping(runtime, grid, lattice, model, radar=PAPER_RADAR, n_fft=N_FFT, dtype=np.float32)
    samples = paper_like_samples(seed=0, tilt_deg=TILT_DEG)
    pose = np.eye(4)
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

    def pipeline():
        mapping.fuse(samples, pose)
        runtime.queue.finish()

    moved = [pose_from_xyz_rpy(0.01 * k, 0.0, 0.0, yaw=1e-4 * k) for k in range(1, 4)]

    def new_pose():
        for p in moved:
            fusion.plan(p, cache=False)

    say(f"timing fusion and the pipeline, {repeat} frames each ...")
    t = interleaved_medians(dict(fusion=fusion_only, pipeline=pipeline), repeat, block=5, warmup=2)
    start = time.perf_counter()
    new_pose()
    plan_s = (time.perf_counter() - start) / len(moved)

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
    mem = grid.memory()
    return dict(
        benchmark="fusion", device=runtime.name, repeat=repeat, voxel_m=spec.voxel_m,
        grid_shape=list(spec.shape), n_beams=lattice.n_beams, n_bins=it.n_bins, tilt_deg=TILT_DEG,
        fusion_ms_per_frame=t["fusion"] * 1e3, pipeline_ms_per_frame=t["pipeline"] * 1e3,
        plan_ms_new_pose=plan_s * 1e3, plan_ms_first=first_plan_s * 1e3,
        voxels_per_frame=voxels, bricks_per_frame=int(len(plan.bricks)),
        copy_bandwidth_gb_s=bandwidth / 1e9, floor_ms_per_frame=floor_s * 1e3,
        ratio_vs_floor=t["fusion"] / floor_s,
        numpy_ms_per_frame=oracle_s * 1e3, ratio_vs_numpy=oracle_s / t["fusion"],
        oracle_beams=len(ORACLE_BEAMS), oracle_voxels_compared=int(clear.sum()),
        max_error_units=int(err[clear].max()), exact_fraction=float((err[clear] == 0).mean()),
        ambiguous_voxels=int(ambiguous.sum()),
        dense_mib=mem["dense_bytes"] / 2 ** 20, sparse_mib=mem["sparse_bytes"] / 2 ** 20,
        goal=f"pipeline_ms_per_frame <= {GOAL_MS}",
    )


def format_table(r):
    """Human-readable lines for a ``run`` result."""
    return [
        f"fusion of one paper frame ({r['n_beams']} beams x {r['n_bins']} bins, tilt {r['tilt_deg']} deg) into "
        f"{'x'.join(map(str, r['grid_shape']))} voxels of {r['voxel_m']} m on {r['device']}; median of {r['repeat']}",
        f"  fusion kernel            {r['fusion_ms_per_frame']:9.1f} ms/frame  ({r['voxels_per_frame']} voxels updated, "
        f"{r['bricks_per_frame']} bricks)",
        f"  whole pipeline           {r['pipeline_ms_per_frame']:9.1f} ms/frame  (goal <= {GOAL_MS:g})",
        f"  planning a new pose      {r['plan_ms_new_pose']:9.1f} ms/frame  (host: brick listing; cached for a still radar)",
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
    from radarcl.cli import bounded_int

    parser.add_argument("--repeat", type=bounded_int(1, 400), default=20,
                        help="timed frames per variant, 1-400 (default: %(default)s)")


def command(args, runtime, say):
    """Run the bench; returns (result dict, table lines)."""
    result = run(runtime(), repeat=args.repeat, report=say)
    return result, format_table(result)
