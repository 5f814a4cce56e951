"""The only module that chains stages: device buffers flow from one kernel to the next, ordered
by events, with no host round trip in between.

``Detection`` runs range profiles (a Navtech scan, or a frame after the range FFT in power)
through CFAR and the eq. 12 interpreter. ``Mapping`` runs raw frames (range FFT first) or
range profiles through detection and fuses the evidence into an ``EvidenceGrid`` (eq. 9).
What differs between evidence models is asked of the model (``radarcl.models``). The design, its
invariants and where to change what: docs/design/pipeline.md.
"""

import logging
import math
from dataclasses import dataclass

import numpy as np

from radarcl.config import mapconfig, sensors
from radarcl.errors import ConfigError, DeviceCapabilityError
from radarcl.geometry import BeamLattice, BeamModel
from radarcl.grid import EvidenceGrid
from radarcl.models import BeamGeometry
from radarcl.io import prefetch
from radarcl.node_pairs import N_CLASSES, live_segments
from radarcl.stages.cfar import Cfar, CfarResult
from radarcl.stages.fusion import Fusion
from radarcl.stages.interpret import Interpreter, InterpretResult
from radarcl.stages.levels import Levels
from radarcl.stages.range_fft import RangeFFT


@dataclass(frozen=True)
class DetectionResult:
    """CFAR outputs and interpreter outputs of one frame."""

    cfar: CfarResult
    interpret: InterpretResult


class Detection:
    """Range profiles -> CFAR -> interpreter, buffers allocated once.

    runtime: a ``radarcl.cl.Runtime``; batch: beam shape; n_bins: bins per profile;
    bin_spacing_m: range between bins; cfar_config, interpret_config: ``CfarConfig`` and
    ``InterpretConfig`` (defaults: the paper's); bin_model: the ``sensor_model.BinModel`` the
    detection-statistics interpreter needs. Extra keywords go to ``Cfar``.
    """

    def __init__(self, runtime, batch, n_bins, bin_spacing_m, cfar_config=None, interpret_config=None,
                 bin_model=None, **cfar_options):
        self.cfar = Cfar(runtime, batch, n_bins, cfar_config, **cfar_options)
        self.interpreter = Interpreter(runtime, batch, n_bins, bin_spacing_m, interpret_config, bin_model=bin_model)

    def enqueue(self, profiles=None, flags=None, wait_for=None, node_use=None):
        """Launch both stages on a device array of power profiles (default: the CFAR's own, as
        ``upload`` filled it) and optional per-beam flags; ``node_use``: the node pairs to
        make (``Interpreter.enqueue``). Returns the last event."""
        c = self.cfar
        done = c.enqueue(profiles, wait_for=wait_for)
        profiles = c.device("profiles", profiles)
        return self.interpreter.enqueue(profiles, c.arrays["noise"], c.arrays["mask"], flags, wait_for=[done],
                                        node_use=node_use)

    def __call__(self, profiles, flags=None):
        """One frame of power profiles (*batch, n_bins) float32 (host) -> DetectionResult."""
        events = [self.cfar.upload(profiles)]
        if flags is not None:
            events += self.interpreter.upload(flags_in=flags)
        done = self.enqueue(flags=None if flags is None else self.interpreter.arrays["flags_in"], wait_for=events)
        return DetectionResult(self.cfar.download(wait_for=[done]), self.interpreter.download(wait_for=[done]))


class Mapping:
    """Frames -> [range FFT] -> CFAR -> eq. 12 -> fusion into ``grid``, buffers allocated once.

    Build it with ``Mapping.from_config(runtime, sensor, config)``: a sensor profile and a map
    configuration in physical units. The constructor takes the parts assembled (tests and the
    fusion bench use it to pin a lattice, a beam model or a sample type):
    runtime: a ``radarcl.cl.Runtime``; grid: the ``EvidenceGrid`` to build; lattice, model: the
    frame's ``BeamLattice`` and ``BeamModel``.
    Raw input: give ``radar`` (a ``RadarConfig``) and ``n_fft``; frames are (n_az, n_el,
    n_samples) of ``dtype`` and go through the Hann-windowed range FFT in power.
    Profile input (Navtech): give ``n_bins`` and ``bin_spacing_m``; frames are power profiles
    (*lattice.batch, n_bins) float32 and enter at CFAR, or a polar scan's uint8 levels of that
    shape, which the ``levels`` stage turns into power on the device first (``fuse``).
    cfar_config, interpret_config: as for ``Detection``; per_beam_poses: as for ``Fusion``.
    An evidence model with node pairs (``EvidenceModel.knowledge``: the detection-statistics
    model) needs ``bin_model`` (a ``sensor_model.BinModel``), a grid with the knowledge channel and
    its ``terrain_dz``; ``from_config`` builds all three. Its interpreter then makes only the
    node pairs a frame's voxels read (a still plan's table knows them, a moving frame's beams bound
    them: ``Fusion.node_reach``); set ``every_node_pair`` to have it make them all, as a caller
    that reads the interpreter's arrays needs (``self_test``). The map is the same either way.
    """

    def __init__(self, runtime, grid, lattice, model, *, radar=None, n_fft=None, dtype=np.int16, n_bins=None,
                 bin_spacing_m=None, cfar_config=None, interpret_config=None, per_beam_poses=False, window="hann",
                 bin_model=None, terrain_dz=-math.inf):
        if not isinstance(grid, EvidenceGrid) or not isinstance(lattice, BeamLattice) or not isinstance(model, BeamModel):
            raise ConfigError("Mapping needs an EvidenceGrid, a BeamLattice and a BeamModel")
        if (radar is None) == (n_bins is None):
            raise ConfigError("give either radar and n_fft (raw frames) or n_bins and bin_spacing_m (profiles)")
        self.runtime, self.grid = runtime, grid
        self.range_fft = None
        if radar is not None:
            if (radar.n_azimuth, radar.n_elevation) != (lattice.n_az, lattice.n_el):
                raise ConfigError(f"the lattice has {lattice.n_az} x {lattice.n_el} beams, the radar "
                                  f"{radar.n_azimuth} x {radar.n_elevation}")
            n_fft = radar.check_n_fft(n_fft if n_fft is not None else 1024)
            n_bins, bin_spacing_m = radar.n_bins(n_fft), radar.bin_spacing_m(n_fft)
            batch = (lattice.n_az, lattice.n_el)     # raw frames are (n_az, n_el, n_samples), always
            self.range_fft = RangeFFT(runtime, batch, radar.n_samples, n_fft, dtype=dtype, window=window,
                                      output="power")
        elif bin_spacing_m is None:
            raise ConfigError("profile input needs bin_spacing_m")
        else:
            batch = lattice.batch
        self.detection = Detection(runtime, batch, n_bins, bin_spacing_m, cfar_config, interpret_config,
                                   bin_model=bin_model)
        it = self.detection.interpreter
        self.fusion = Fusion(runtime, grid, lattice, model, n_bins, bin_spacing_m, it.first_bin, it.last_bin,
                             per_beam_poses=per_beam_poses, detstats=it.node_pairs, terrain_dz=terrain_dz,
                             classes=it.classes if it.node_pairs else N_CLASSES,      # one count: the interpreter's
                             live_segments=live_segments(bin_model.opportunity, it.classes) if it.node_pairs else None)
        self.levels = None          # the ``Levels`` stage: uint8 levels -> power (``fuse``'s db_per_level)
        self.frames = 0
        self.every_node_pair = False    # True: the interpreter makes every node pair, read or not
        self.config = None          # the mapconfig.Resolved it was built from (from_config)

    @classmethod
    def from_config(cls, runtime, sensor=None, config=None, *, grid=None, per_beam_poses=None):
        """The pipeline of a sensor and a map configuration: the one way radarcl builds one.

        sensor: a ``sensors.SensorProfile``, a built-in name or a profile file (default: the
        paper's radar, or the configuration's own sensor); config: a ``mapconfig.Resolved``,
        a configuration file, or None for the sensor's defaults; grid: an ``EvidenceGrid`` to
        fuse into (default: a new one as [grid] says); per_beam_poses: one pose per beam
        (default: for a spinning radar, which moves during its turn)."""
        if not isinstance(config, mapconfig.Resolved):
            config = mapconfig.resolve(sensor, config)
        elif sensor is not None and sensors.load(sensor).name != config.sensor.name:
            raise ConfigError(f"the configuration is for sensor {config.sensor.name!r}, not {sensors.load(sensor).name!r}")
        sensor = config.sensor
        spec = grid.spec if grid is not None else config.grid_spec()
        _check_fits(runtime, config, spec)
        evidence_model = config.evidence_model()
        if grid is None:
            grid = new_grid(runtime, config, spec)
        model = sensor.beam_model(config["beam.model"], grid.spec.voxel_m)
        per_beam = sensor.spinning if per_beam_poses is None else per_beam_poses
        common = dict(cfar_config=config.cfar_config(), interpret_config=config.interpret_config(),
                      per_beam_poses=per_beam)
        if not sensor.raw and sensor.n_bins() is None:
            raise ConfigError(f"sensor {sensor.name} does not say how many range bins it has; the reader "
                              "learns it from the data (SensorProfile.with_bins)")
        if evidence_model.knowledge:
            common.update(bin_model=bin_model(config, grid.spec.voxel_m),
                          terrain_dz=evidence_model.terrain_dz(config.model_params()))
        if sensor.raw:
            mapping = cls(runtime, grid, sensor.lattice(), model, radar=sensor.radar, n_fft=config.n_fft,
                          dtype=sensor.sample_dtype, window=config["range_fft.window"], **common)
        else:
            mapping = cls(runtime, grid, sensor.lattice(), model, n_bins=sensor.n_bins(),
                          bin_spacing_m=sensor.bin_spacing_m(), **common)
        mapping.config, mapping.sensor = config, sensor
        reading = config.reading()
        if reading is not None:                     # a saved map carries how it reads, untold
            grid.reading = reading
        return mapping

    @property
    def frame_shape(self):
        """Shape of one frame: (n_az, n_el, n_samples) raw, (*batch, n_bins) profiles."""
        return self.range_fft.input_shape if self.range_fft is not None else self.detection.cfar.input_shape

    def fuse(self, frame, poses, flags=None, azimuths=None, db_per_level=None, differenced=False):
        """Fuse one frame taken at ``poses`` (4x4, or one per beam). The pose and the frame are
        checked before anything runs, so a refused frame leaves the map as it was. Returns the
        ``FramePlan`` (bricks reached, beams outside the grid); the device work is queued, not
        waited for (``snapshot`` and ``flags`` wait). ``azimuths`` (lo, hi): fuse only those
        azimuths' beams (``Fusion.restrict``): a part of a frame that has arrived so far.
        ``db_per_level``: the frame is a polar scan's uint8 levels of this many dB each (profile
        input only), turned into power on the device (``stages.levels``: the same floats as
        ``polar_png.levels_to_power``, so the same map); ``differenced``: its rows hold their
        levels' differences (``polar_png.PolarScan.differenced``), summed on the device."""
        levels = None
        if differenced and db_per_level is None:
            raise ConfigError("differenced frames are polar scans' levels; pass db_per_level with them")
        if self.range_fft is not None:
            if flags is not None:
                raise ConfigError("raw frames carry their own flags; pass flags with profiles only")
            if db_per_level is not None:
                raise ConfigError("raw frames are samples, not levels; pass db_per_level with profiles only")
            self.range_fft.check(frame)
        else:
            if db_per_level is None:
                self.detection.cfar.check(frame)
            else:
                levels = self._levels_at(db_per_level)
                levels.check(frame)
            if flags is not None:
                flags = self.detection.interpreter.check_flags(flags)
        plan = self.fusion.plan(poses, record=azimuths is None)        # checks the poses; allocates bricks
        if azimuths is not None:
            plan = self.fusion.restrict(plan, *azimuths)
        if self.range_fft is not None:
            done = self.range_fft.enqueue(wait_for=[self.range_fft.upload(frame)])
            profiles, flags_array = self.range_fft.arrays["profiles"], self.range_fft.arrays["flags"]
        else:
            events = [self.detection.cfar.upload(frame) if levels is None
                      else levels.enqueue(wait_for=[levels.upload(frame)], differenced=differenced)]
            flags_array = None
            if flags is not None:
                events += self.detection.interpreter.upload(flags_in=flags)
                flags_array = self.detection.interpreter.arrays["flags_in"]
            profiles, done = None, events
        node_use, reached = self._node_use(plan)
        done = (done if isinstance(done, list) else [done]) + ([] if reached is None else [reached])
        done = self.detection.enqueue(profiles, flags_array, wait_for=done, node_use=node_use)
        self.fusion.enqueue(self.detection.interpreter.arrays["evidence"], plan, wait_for=[done])
        self.frames += 1
        return plan

    def _node_use(self, plan):
        """(node_use, its event or None): the node pairs ``plan``'s voxels read, which the
        interpreter then makes alone; (None, None): it makes every pair."""
        if self.every_node_pair or self.detection.interpreter.nodes is None:
            return None, None
        if plan.table is not None:                  # a still plan's table knows them
            return plan.table.node_use, None
        return self.fusion.node_reach(plan) or (None, None)     # a moving frame's beams bound them

    def _levels_at(self, db_per_level):
        """The ``Levels`` stage that writes power into the CFAR's input, built on first use, at
        ``db_per_level`` (FrameFormatError for a scale float32 cannot hold)."""
        if self.levels is None:
            self.levels = Levels(self.runtime, self.detection.cfar.input_shape, db_per_level,
                                 power=self.detection.cfar.arrays["profiles"])
        self.levels.set_db_per_level(db_per_level)
        return self.levels

    def fuse_source(self, source, after_frame=None, before_frame=None, read_ahead=prefetch.DEFAULT_DEPTH):
        """Fuse every frame of ``source`` (an ``io.inputs.FrameSource``: frames, their poses and,
        for range profiles, their flags) in order; ``after_frame(j, trajectory)`` runs after
        frame j (progress, checkpoints), ``before_frame(j, position)`` before it, with the
        sensor's position (3,) [m] (a rolling window's eviction). The next ``read_ahead`` frames
        are read (decoded, converted) on a reader thread while the device fuses (``io.prefetch``;
        0: read inline); the map is the same either way. A source that offers its frames as
        levels (``FrameSource.levels``: polar scans) sends those, as their rows' differences
        where a scan holds those (``FrameSource.differenced``), and the device turns them into
        power (``fuse``'s ``db_per_level``, ``differenced``): the same map. Returns (the
        sensor's trajectory (n, 4, 4): each frame's pose, or its middle beam's, the number of
        beams that reached no voxel of the grid)."""
        raw = self.range_fft is not None
        levels = None if raw else getattr(source, "levels", None)
        frames = source.frames if levels is None else levels
        db_per_level = None if levels is None else source.db_per_level
        differenced = None if levels is None else getattr(source, "differenced", None)

        def read(j):
            return (frames[j], np.asarray(source.poses[j]), None if raw else source.flags[j],
                    differenced is not None and bool(differenced[j]))

        trajectory, outside = [], 0
        for j, (frame, poses, flags, diff) in enumerate(prefetch.prefetched(read, len(source), read_ahead)):
            if before_frame is not None:
                before_frame(j, (poses if poses.ndim == 2 else poses[len(poses) // 2])[:3, 3])
            plan = self.fuse(frame, poses, flags=flags, db_per_level=db_per_level, differenced=diff)
            trajectory.append(poses if poses.ndim == 2 else poses[len(poses) // 2])
            outside += plan.beams_outside
            if after_frame is not None:
                after_frame(j, trajectory)
        return np.array(trajectory).reshape(-1, 4, 4), outside

    def flags(self):
        """Per-beam flags (oracle.FLAG_*) of the last frame, uint8 (*batch,)."""
        return self.detection.interpreter.arrays["flags_out"].get(self.runtime.queue)

    def snapshot(self):
        """Dense int32 (nz, ny, nx) copy of the grid after every queued frame."""
        self.runtime.queue.finish()
        return self.grid.snapshot()


def new_grid(runtime, config, spec):
    """A new ``EvidenceGrid`` of ``spec`` for maps of ``config`` (a ``Resolved``): with the knowledge
    channel when its evidence model keeps one (``EvidenceModel.knowledge``)."""
    return EvidenceGrid(runtime, spec, knowledge=config.evidence_model().knowledge)


def evidence_config(config):
    """The configuration a job fuses its own per-bin evidence with (raw intensity, counts, oracle
    detections): ``config``'s sensor, grid, beams and beam model on the one-value-per-bin fusion
    path (``EvidenceModel.per_bin``), since a model with node pairs fuses tables, not one evidence
    value per bin."""
    model = config.evidence_model()
    return config.replaced(interpret__model=model.per_bin) if model.knowledge else config


def bin_model(config, voxel_m):
    """The host tables (``EvidenceModel.bin_model``: the detection-statistics model's
    ``sensor_model.BinModel``) of a configuration (a ``Resolved``) at ``voxel_m``, or None for a
    model that needs none: the correlated training cells of its x(n_fft / n_samples) zero padding
    (raw sensors) or of its bins per resolution cell (profiles, read as a Hann-windowed FFT's). A
    profile without the sensitivity the model needs gets its sentence, once, as a warning."""
    model = config.evidence_model()
    if not model.knowledge:
        return None
    sensor = config.sensor
    if config.sensitivity_missing():
        _warn_once(sensors.missing_sensitivity(sensor))
    if sensor.raw:
        oversampling = config.n_fft / sensor.radar.n_samples
    else:
        oversampling = max(1.0, sensor.range_resolution_m / sensor.bin_spacing_m())
    beam = BeamGeometry(sensor.n_bins(config.n_fft), config.bin_spacing_m, oversampling,
                        math.radians(sensor.get("beams", "beamwidth_az_deg")) / 2,
                        math.radians(sensor.get("beams", "beamwidth_el_deg")) / 2, voxel_m,
                        config["interpret.range_min_m"])
    return model.bin_model(config.model_params(), config.cfar_config(), beam)


_WARNED = set()


def _warn_once(sentence):
    if sentence not in _WARNED:
        _WARNED.add(sentence)
        logging.getLogger("radarcl").warning(sentence)


# A frame must fit one device buffer (the grid's brick pool). Refused before anything runs when
# even half the volume its beams sweep (the part a grid smaller than the frustum may cut away
# is bounded by the grid's own size) cannot fit.
FIT_FRACTION = 0.5


def _check_fits(runtime, config, spec):
    """DeviceCapabilityError, with the sizes, when one frame of ``config`` cannot fit the
    device's largest buffer (``radarcl info``: "largest buffer")."""
    v = spec.voxel_m
    swept = sensors.frame_volume_m3(config.sensor, config["interpret.range_min_m"], config["interpret.range_max_m"], v)
    voxels = min(FIT_FRACTION * swept / v ** 3, float(spec.n_voxels))
    needed, limit = 4.0 * voxels, float(runtime.limits.max_mem_alloc_size)
    if needed > limit:
        fits = v * (needed / limit) ** (1 / 3)
        raise DeviceCapabilityError(
            f"one frame of sensor {config.sensor.name} at {v:g} m voxels reaches at least {voxels:.3g} voxels "
            f"({needed / 2**30:.1f} GiB of int32), more than the largest buffer of {runtime.name}, "
            f"{limit / 2**30:.2f} GiB (radarcl info); use voxels of at least {fits:.3g} m, a shorter "
            "interpret.range_max_m, or a smaller grid")
