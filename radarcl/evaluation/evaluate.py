"""Run recorded observations of the reference scene through the pipeline and score the map.

``map_observations`` fuses every frame with one configuration (a ``mapconfig.Resolved``: voxel
size, zero padding, beam model, CFAR, eq. 12 constants) on the device, timing the pipeline, and
marks the voxels some beam's volume reached (a second fusion of constant evidence into a count
grid, outside the timing). ``baseline_map`` inserts the same frames' CFAR detections
OctoMap-style (``evaluation.baseline``). ``score`` gives ``evaluation.metrics`` against the
scene's truth.
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from radarcl import logodds, mapconfig
from radarcl.evaluation.baseline import OctoMapBaseline
from radarcl.evaluation.metrics import evaluate
from radarcl.grid import EvidenceGrid
from radarcl.pipeline import Mapping
from radarcl.stages.fusion import Fusion


def paper_config(voxel_m=0.1, values=None):
    """The paper radar's configuration at ``voxel_m`` with ``values`` {"section.key": value}
    set by the program (the reference scene lies in the paper's grid)."""
    return mapconfig.resolve("paper", program={"grid.voxel_m": voxel_m, **(values or {})})


@dataclass
class MapResult:
    """A fused map and how it was made: dense (nz, ny, nx) log-odds [nat] and observed mask."""

    config: object
    spec: object
    log_odds: np.ndarray
    observed: np.ndarray
    ms_per_frame: float
    detections: list
    memory: dict
    grid: object = None


def map_observations(runtime, obs, config, progress=None):
    """Fuse ``obs`` (``scene.observe.Observations``) with ``config`` (a ``mapconfig.Resolved``);
    returns a ``MapResult``.

    ``progress(done, total)`` counts observations (beams), frame by frame. The timing covers
    the pipeline of every frame (upload, range FFT, CFAR, eq. 12, planning the new pose, fusion)
    until the device is idle; the observed mask and the detections for the baseline are
    computed afterwards."""
    mapping = Mapping.from_config(runtime, config=config)
    grid, spec, lattice, model = mapping.grid, mapping.grid.spec, mapping.fusion.lattice, mapping.fusion.model
    n_frames, per_frame = len(obs.samples), lattice.n_beams
    mapping.fuse(obs.samples[0], obs.poses[0])         # warm-up: kernel builds, first allocations
    runtime.queue.finish()
    grid.clear()
    start = time.perf_counter()
    for j in range(n_frames):
        mapping.fuse(obs.samples[j], obs.poses[j])
        if progress is not None:
            progress((j + 1) * per_frame, n_frames * per_frame)
    runtime.queue.finish()
    ms_per_frame = (time.perf_counter() - start) * 1e3 / n_frames

    count = EvidenceGrid(runtime, spec)
    fusion = mapping.fusion
    counter = Fusion(runtime, count, lattice, model, fusion.n_bins, fusion.bin_spacing_m, fusion.first_bin,
                     fusion.last_bin)
    counter.upload(np.full(counter.evidence_shape, logodds.SCALE, np.int32)).wait()
    detections = []
    for j in range(n_frames):
        counter.enqueue(plan=counter.plan(obs.poses[j]))
        profiles = mapping.range_fft(obs.samples[j]).profiles
        detections.append(mapping.detection.cfar(profiles).mask.reshape(lattice.n_beams, -1))
    runtime.queue.finish()
    log_odds = (grid.snapshot() / np.float32(logodds.SCALE)).astype(np.float32)
    return MapResult(config, spec, log_odds, count.snapshot() > 0, ms_per_frame, detections, grid.memory(), grid)


def baseline_map(obs, detections, config):
    """The OctoMap-style baseline on the same frames' detections: (log_odds, touched, ms_per_frame)."""
    spec = config.grid_spec()
    base = OctoMapBaseline(spec)
    axes = config.sensor.lattice().beam_rotations()[:, :, 0]
    ranges = config.sensor.radar.bin_ranges_m(config.n_fft)
    i = config.interpret_config()
    start = time.perf_counter()
    for pose, mask in zip(obs.poses, detections):
        base.insert_scan(pose[:3, 3], axes @ pose[:3, :3].T, ranges, mask, i.range_min_m, i.range_max_m)
    ms = (time.perf_counter() - start) * 1e3 / max(1, len(obs.poses))
    return base.log_odds, base.touched, ms


def score(log_odds, observed, truth):
    """``metrics.evaluate`` with NaN turned into None (JSON)."""
    out = evaluate(log_odds, truth, observed)
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}
