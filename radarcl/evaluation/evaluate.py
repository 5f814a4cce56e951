"""Run recorded observations of the reference scene through the pipeline and score the map.

``map_observations`` fuses every frame with one ``MapConfig`` (voxel size, zero padding, beam
model, CFAR, eq. 12 constants) on the device, timing the pipeline, and marks the voxels some
beam's volume reached (a second fusion of constant evidence into a count grid, outside the
timing). ``baseline_map`` inserts the same frames' CFAR detections OctoMap-style
(radarcl.baseline). ``score`` gives ``radarcl.metrics`` against the scene's truth.
"""

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from radarcl import logodds
from radarcl.evaluation.baseline import OctoMapBaseline
from radarcl.config import PAPER_RADAR, CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice, BeamModel
from radarcl.grid import EvidenceGrid
from radarcl.evaluation.metrics import evaluate
from radarcl.pipeline import Mapping
from radarcl.scene.outdoor import paper_grid
from radarcl.stages.fusion import Fusion

# The beam volumes compared (``bench quality``): the axis alone (what a point cloud sees), a
# uniform cone, a cone weighted by the two-way Gaussian, and the paper's cylindrical-conical
# volume with the Gaussian (Fig. 7c).
BEAM_MODELS = ("axis", "uniform-cone", "gaussian-cone", "cylindrical-conical")
AXIS_BEAMWIDTH_RAD = 1e-6        # "axis": a cylinder of half a voxel around the beam axis


def beam_model(name, radar, voxel_m):
    """The ``BeamModel`` called ``name`` (one of BEAM_MODELS) for ``radar`` at ``voxel_m``."""
    if name == "axis":
        return BeamModel(AXIS_BEAMWIDTH_RAD, AXIS_BEAMWIDTH_RAD, 0.5 * voxel_m, 0.5 * voxel_m, True, False)
    if name == "uniform-cone":
        return BeamModel.from_radar(radar, near_field=False, gaussian=False)
    if name == "gaussian-cone":
        return BeamModel.from_radar(radar, near_field=False, gaussian=True)
    if name == "cylindrical-conical":
        return BeamModel.from_radar(radar, near_field=True, gaussian=True)
    raise ConfigError(f"beam model must be one of {', '.join(BEAM_MODELS)}, got {name!r}")


@dataclass(frozen=True)
class MapConfig:
    """One way of making the map; defaults: the paper's pipeline at the paper's 0.1 m."""

    voxel_m: float = 0.1
    n_fft: int = 1024
    beam: str = "cylindrical-conical"
    cfar: CfarConfig = field(default_factory=CfarConfig)
    interpret: InterpretConfig = field(default_factory=InterpretConfig)

    def label(self):
        """Short text naming what differs from the defaults."""
        base = MapConfig()
        parts = [f"{name}={getattr(self, name)}" for name in ("voxel_m", "n_fft", "beam")
                 if getattr(self, name) != getattr(base, name)]
        c, i = self.cfar, self.interpret
        if c != base.cfar:
            parts.append(f"cfar={c.kind}" + (f"/k{c.rank}" if c.rank else "") + f"/pfa{c.pfa:g}/g{c.guard}/t{c.train}")
        if i != base.interpret:
            parts.append(f"k_occ={i.k_occ:g},E_h={i.e_high:g},E_l={i.e_low:g},wide={i.wide_pulse_m:.3g}m")
        return ", ".join(parts) or "defaults (the paper's)"

    def as_dict(self):
        """JSON-ready description."""
        return dict(voxel_m=self.voxel_m, n_fft=self.n_fft, beam=self.beam, cfar_kind=self.cfar.kind,
                    cfar_guard=self.cfar.guard, cfar_train=self.cfar.train, cfar_pfa=self.cfar.pfa,
                    cfar_rank=self.cfar.rank, k_occ=self.interpret.k_occ, e_high=self.interpret.e_high,
                    e_low=self.interpret.e_low, wide_pulse_m=self.interpret.wide_pulse_m)


def interpret_config(config, radar):
    """``config.interpret`` limited to the radar's range of operation."""
    i = config.interpret
    return replace(i, range_min_m=max(i.range_min_m, radar.range_min_m), range_max_m=min(i.range_max_m, radar.range_max_m))


@dataclass
class MapResult:
    """A fused map and how it was made: dense (nz, ny, nx) log-odds [nat] and observed mask."""

    config: MapConfig
    spec: object
    log_odds: np.ndarray
    observed: np.ndarray
    ms_per_frame: float
    detections: list
    memory: dict
    grid: object = None


def make_mapping(runtime, config=MapConfig(), radar=PAPER_RADAR):
    """The ``Mapping`` (int16 raw frames -> paper grid) that ``config`` describes."""
    lattice = BeamLattice.from_radar(radar)
    model = beam_model(config.beam, radar, config.voxel_m)
    grid = EvidenceGrid(runtime, paper_grid(config.voxel_m))
    return Mapping(runtime, grid, lattice, model, radar=radar, n_fft=config.n_fft, dtype=np.int16,
                   cfar_config=config.cfar, interpret_config=interpret_config(config, radar))


def map_observations(runtime, obs, config=MapConfig(), radar=PAPER_RADAR, progress=None):
    """Fuse ``obs`` (``scene.observe.Observations``) with ``config``; returns a ``MapResult``.

    ``progress(done, total)`` counts observations (beams), frame by frame. The timing covers
    the pipeline of every frame (upload, range FFT, CFAR, eq. 12, planning the new pose, fusion)
    until the device is idle; the observed mask and the detections for the baseline are
    computed afterwards."""
    mapping = make_mapping(runtime, config, radar)
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


def baseline_map(obs, detections, config=MapConfig(), radar=PAPER_RADAR):
    """The OctoMap-style baseline on the same frames' detections: (log_odds, touched, ms_per_frame)."""
    spec = paper_grid(config.voxel_m)
    base = OctoMapBaseline(spec)
    axes = BeamLattice.from_radar(radar).beam_rotations()[:, :, 0]
    ranges = radar.bin_ranges_m(config.n_fft)
    i = interpret_config(config, radar)
    start = time.perf_counter()
    for pose, mask in zip(obs.poses, detections):
        base.insert_scan(pose[:3, 3], axes @ pose[:3, :3].T, ranges, mask, i.range_min_m, i.range_max_m)
    ms = (time.perf_counter() - start) * 1e3 / max(1, len(obs.poses))
    return base.log_odds, base.touched, ms


def score(log_odds, observed, truth):
    """``metrics.evaluate`` with NaN turned into None (JSON)."""
    out = evaluate(log_odds, truth, observed)
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}
