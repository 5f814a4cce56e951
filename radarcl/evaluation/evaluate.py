"""Run recorded observations of the reference scene through the pipeline and score the map.

``map_observations`` fuses every frame with one configuration (a ``mapconfig.Resolved``: voxel
size, zero padding, beam model, CFAR, eq. 12 constants) on the device, timing the pipeline, and
marks the voxels some beam's volume reached (a second fusion of constant evidence into a count
grid, outside the timing). ``baseline_map`` inserts the same frames' CFAR detections into
OctoMap (``evaluation.baseline``). ``score`` gives ``evaluation.metrics`` against the
scene's truth.
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from radarcl import logodds, oracle, sensor_model
from radarcl.errors import ConfigError
from radarcl.evaluation import baseline
from radarcl.evaluation import visibility as vis
from radarcl.evaluation.baseline import detection_scans, octree, read_back
from radarcl.evaluation.metrics import evaluate, radar_scores
from radarcl.evaluation.visibility import DETECTABLE_DB
from radarcl.grid import EvidenceGrid
from radarcl.maps.map import KNOWN_LOOKS
from radarcl.pipeline import Mapping, evidence_config
from radarcl.scene import streets
from radarcl.scene.observe import NOISE_RMS, observe
from radarcl.stages.fusion import Fusion


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
    knowledge: np.ndarray = None     # detstats: (nz, ny, nx) float32 summed detection opportunity [looks]


def map_observations(runtime, obs, config, progress=None):
    """Fuse ``obs`` (``scene.observe.Observations``) with ``config`` (a ``mapconfig.Resolved``);
    returns a ``MapResult``.

    ``progress(done, total)`` counts observations (beams), frame by frame. The timing covers
    the pipeline of every frame (upload, range FFT, CFAR, eq. 12, planning the new pose, fusion)
    until the device is idle; the observed mask and the detections for the baseline are
    computed afterwards."""
    mapping = Mapping.from_config(runtime, config=config)
    grid, spec, lattice, model = mapping.grid, mapping.grid.spec, mapping.fusion.lattice, mapping.fusion.model
    n_frames = len(obs.samples)
    ms_per_frame = fuse_timed(runtime, mapping, obs, progress)

    count = EvidenceGrid(runtime, spec)
    fusion = mapping.fusion
    counter = Fusion(runtime, count, lattice, model, fusion.n_bins, fusion.bin_spacing_m, fusion.first_bin,
                     fusion.last_bin, per_beam_poses=fusion.per_beam_poses)
    counter.upload(np.full(counter.evidence_shape, logodds.SCALE, np.int32)).wait()
    detections = []
    for j in range(n_frames):
        counter.enqueue(plan=counter.plan(obs.poses[j]))
        profiles = mapping.range_fft(obs.samples[j]).profiles
        detections.append(mapping.detection.cfar(profiles).mask.reshape(lattice.n_beams, -1))
    runtime.queue.finish()
    log_odds, knowledge = read_map(grid, config)
    return MapResult(config, spec, log_odds, count.snapshot() > 0, ms_per_frame, detections, grid.memory(), grid,
                     knowledge)


def fuse_timed(runtime, mapping, obs, progress=None):
    """Fuse every frame of ``obs`` into ``mapping``'s grid, cleared after a warm-up frame (kernel
    builds, first allocations); returns the pipeline's ms per frame, until the device is idle."""
    n_frames, per_frame = len(obs.samples), mapping.fusion.lattice.n_beams
    mapping.fuse(obs.samples[0], obs.poses[0])
    runtime.queue.finish()
    mapping.grid.clear()
    start = time.perf_counter()
    for j in range(n_frames):
        mapping.fuse(obs.samples[j], obs.poses[j])
        if progress is not None:
            progress((j + 1) * per_frame, n_frames * per_frame)
    runtime.queue.finish()
    return (time.perf_counter() - start) * 1e3 / n_frames


def read_map(grid, config):
    """(log-odds [nat], knowledge [looks] or None), dense float32, of an ``EvidenceGrid`` made with
    ``config``: the detection-statistics model's as its reading says (``sensor_model.read_log_odds``)."""
    units = grid.snapshot()
    if not grid.has_knowledge:
        return (units / np.float32(logodds.SCALE)).astype(np.float32), None
    known = grid.knowledge_snapshot()
    log_odds = sensor_model.read_log_odds(units, known, grid.knowledge_snapshot("looks"),
                                          config.model_params().reading).astype(np.float32)
    return log_odds, (known / np.float32(logodds.KNOWLEDGE_SCALE)).astype(np.float32)


def read_units(grid, config):
    """``read_map`` in logodds units: (dense int32 log-odds as the map reads them, its known voxels
    (bool, knowledge of ``KNOWN_LOOKS`` looks or more) or None for a map without the channel)."""
    log_odds, knowledge = read_map(grid, config)
    return logodds.to_fixed(log_odds), (None if knowledge is None else knowledge >= KNOWN_LOOKS)


def for_scene(config, described):
    """``config`` for a generated scene: the detection-statistics model gets the scene's mounting
    (the sensor's height above its ground plane, as a user gives their own); others unchanged."""
    key = "sensor_model.ground_below_m"
    if key not in config.evidence_model().keys or not config.derived_from_sensor(key):
        return config
    return config.replaced(sensor_model__ground_below_m=described["sensor_height_m"])


def baseline_map(obs, detections, config):
    """OctoMap's map (``baseline.octree``, ``baseline.read_back``) of the same frames' CFAR
    detections: (log_odds, ms_per_frame); the time is OctoMap's insertion, not our read-back."""
    spec = config.grid_spec()
    scans = detection_scans(obs, detections, config)
    start = time.perf_counter()
    tree = octree(spec, scans)
    ms = (time.perf_counter() - start) * 1e3 / max(1, len(obs.poses))
    return read_back(tree, spec), ms


def score(log_odds, observed, truth):
    """``metrics.evaluate`` with NaN turned into None (JSON)."""
    out = evaluate(log_odds, truth, observed)
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}


# -- the instrument: visibility truth on one fixed voxel set, scores and baselines --------------------------
@dataclass
class Instrument:
    """What every map of one recording is scored against at one voxel size: the fixed voxel set
    (what the reference configuration's beams reach), its visibility truth and its objects."""

    spec: object
    truth: object
    objects: list
    hidden: list
    reference: object
    reference_map: MapResult
    noiseless_power: np.ndarray = None      # (n_frames, n_beams, n_bins) without receiver noise
    noise_power: float = None               # its noise level per bin

    def describe(self):
        """One line: the voxel set and its classes."""
        c = self.truth.counts()
        return (f"fixed voxel set: the {int(self.truth.observed.sum()):,} voxels the reference configuration's beams "
                f"reach at {self.spec.voxel_m} m ({self.reference.label()}); free-visible {c['free-visible']:,}, "
                f"detectable {c['detectable']:,}, weak {c['weak']:,}, shadowed {c['shadowed']:,}")


def instrument(runtime, scene, obs, reference, progress=None):
    """The ``Instrument`` of ``obs`` (simulated from ``scene``) at ``reference``'s voxel size.

    DETECTABLE/WEAK need the frames' noiseless range profiles: the recording is simulated again
    with its seed and tilts and no receiver noise or ADC (the same rays, phases and echoes: they
    are functions of the seed, ``observe.lattice_rays``)."""
    ref_map = map_observations(runtime, obs, reference, progress)
    radar = reference.sensor.radar
    if obs.poses.ndim == 4:                  # a spinning radar on a vehicle: one pose per beam (scene.streets)
        quiet = streets.observe(scene, radar, reference.sensor.lattice(), len(obs.poses), seed=obs.seed, noise_rms=0.0,
                                adc=None, poses=obs.poses, physics=obs.physics)
    else:
        quiet = observe(scene, obs.tilts_deg, radar=radar, seed=obs.seed, noise_rms=0.0, adc=None, physics=obs.physics,
                        offsets_m=obs.offsets_m)
    if quiet.rays_per_beam != obs.rays_per_beam or not np.allclose(quiet.poses, obs.poses):
        raise ConfigError(f"the recording (seed {obs.seed}, {obs.rays_per_beam} echoes per beam) was not simulated "
                          f"from this scene with radarcl's defaults ({quiet.rays_per_beam} echoes per beam): its "
                          f"noiseless echoes cannot be recomputed for the truth")
    n = quiet.samples.shape
    power = oracle.range_profile(quiet.samples.reshape(n[0], n[1] * n[2], n[3]), reference.n_fft, output="power")
    half = (math.radians(radar.beamwidth_az_deg) / 2, math.radians(radar.beamwidth_el_deg) / 2)
    noise = vis.noise_power_per_bin(NOISE_RMS, radar.n_samples)
    truth = vis.visibility_truth(scene, ref_map.spec, ref_map.observed, obs.poses, power, noise,
                                 reference.sensor.lattice(), half, radar.bin_spacing_m(reference.n_fft))
    objects, hidden = vis.object_surfaces(scene, truth, ref_map.spec)
    return Instrument(ref_map.spec, truth, objects, hidden, reference, ref_map, power, noise)


def radar_score(inst, log_odds, knowledge=None):
    """``metrics.radar_scores`` of ``log_odds`` (and the map's ``knowledge`` [looks], when it has
    one) on ``inst``, NaN as None (JSON)."""
    out = radar_scores(log_odds, inst.truth, inst.objects, knowledge)
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}


def baselines(runtime, inst, obs, ground_z_m=0.0):
    """The three baselines on ``inst``'s voxel set: {name: scores with ms_per_frame}; octomap
    uses the reference map's CFAR detections; prior_only knows the ground plane z = ``ground_z_m``.
    Without octomap-python, its entry says so."""
    out = {}
    out["prior_only"] = dict(radar_score(inst, baseline.prior_only(inst.spec, ground_z_m)), ms_per_frame=0.0)
    start = time.perf_counter()
    raw = baseline.raw_intensity(runtime, obs, inst.reference)
    out["raw_intensity"] = dict(radar_score(inst, raw), ms_per_frame=(time.perf_counter() - start) * 1e3 / len(obs.poses))
    try:
        log_odds, ms = baseline_map(obs, inst.reference_map.detections, inst.reference)
        out["octomap"] = dict(radar_score(inst, log_odds), ms_per_frame=ms)
    except ConfigError as exc:
        out["octomap"] = dict(error=str(exc))
    return out


def oracle_detections(runtime, inst, obs, free_nats=0.0):
    """Scores (on ``inst``) of the map a perfect per-bin detector would give through the same
    beams: +1 nat on every bin whose noiseless echo is DETECTABLE (>= 10 dB over the noise),
    ``free_nats`` on the other bins of the range window. It shows what the beam's footprint
    costs (free voxels beside a surface at the same range share its bins) and, with -1, what
    strong free evidence adds. Not an upper bound on AUC: graded evidence can rank better than
    +1/0, whose ties count one half."""
    mapping = Mapping.from_config(runtime, config=evidence_config(inst.reference))
    fusion = mapping.fusion
    loud = inst.noiseless_power >= inst.noise_power * 10 ** (DETECTABLE_DB / 10)
    for frame_loud, pose in zip(loud, obs.poses):
        evidence = np.where(frame_loud, 1.0, free_nats) * logodds.SCALE
        fusion.upload(np.rint(evidence).astype(np.int32).reshape(fusion.evidence_shape)).wait()
        fusion.enqueue(plan=fusion.plan(pose))
    runtime.queue.finish()
    return radar_score(inst, (mapping.grid.snapshot() / np.float32(logodds.SCALE)).astype(np.float32))
