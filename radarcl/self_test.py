"""Is a device fit to run radarcl? ``self_test`` builds every built-in sensor's pipeline on it
and compares one synthetic frame with the float64 oracle, stage by stage.

The OpenCL device check (``radarcl.cl.devices``) sits below what it checks, so it runs whatever
checks the application names (``register_device_check``) in a child process before it uses a
device, and caches the verdict. Importing this module registers nothing: each application calls
``register`` once before it chooses a device (``radarcl.cli.main`` for every command, a Dask
worker of ``jobs.fuse_many``, a spawned bench child, the test suite's conftest). A library user
who builds pipelines without the command line calls it too, or has devices checked with the
runtime's small probe kernel only.
"""

import numpy as np

from radarcl import models, node_pairs, oracle
from radarcl.cl.devices import register_device_check
from radarcl.config import mapconfig, sensors
from radarcl.errors import DeviceCapabilityError
from radarcl.pipeline import Mapping

# A device counts as fit when every built-in sensor's pipeline builds on it and one synthetic
# frame through it agrees with the float64 oracle. The bounds are loose on purpose: a compiler
# that miscompiles is wrong by orders of magnitude, while a sound device differs from float64
# only by rounding (tests/tolerances.py holds the tight bounds the kernel tests use), and a
# sound device must never be refused.
SELF_TEST_PROFILE_RTOL = 1e-3       # range FFT power against float64, relative to a frame's peak
SELF_TEST_MATCH = 0.99              # evidence bins within 1 unit, and clear voxels within 1 unit per update
SELF_TEST_VOXEL_M = 2.0             # coarse, and out to SELF_TEST_RANGE_M: the oracle's fusion visits
SELF_TEST_RANGE_M = 24.0            # every voxel for every beam
SELF_TEST_BEAMS = 32                # CFAR and eq. 12 compared on this many beams of a frame (they are per beam)
SELF_TEST_BIN_MARGIN = 1.25         # a profile sensor's bins reach this far past SELF_TEST_RANGE_M (CFAR's window)


def self_test(runtime):
    """Build every kernel of every built-in sensor's pipeline on ``runtime``'s device, with eq. 12
    and with the detection-statistics model, run one synthetic frame through each and compare it
    with the float64 oracle stage by stage (range FFT, CFAR and the interpreter, fusion).
    Returns None when all agree; a sentence saying where they differ (the device is unusable);
    or, where some sensor's pipeline does not fit the device (``DeviceCapabilityError``: local
    memory, the largest buffer), ``{"problem": None, "notes": [a sentence per sensor]}``: the
    device stays usable and that sensor is refused when it is asked for, with a sentence of the
    same kind (the notes hold at this check's sizes: 2 m voxels, SELF_TEST_RANGE_M; a map of
    other sizes is checked when it is built). A device that fits no built-in sensor at all is
    unusable. ``radarcl.cl.devices`` runs it in a child process before it uses a device (once
    ``register`` has named it), so a compiler that aborts cannot take radarcl down with it."""
    rng = np.random.default_rng(29)
    notes, ran = [], 0
    for name in sensors.builtin_names():
        sensor = sensors.load(name)
        for model in ("paper", "detstats"):
            program = {"grid.voxel_m": SELF_TEST_VOXEL_M, "interpret.model": model,
                       "interpret.range_max_m": min(SELF_TEST_RANGE_M, sensor.range_interval_m[1])}
            config = mapconfig.resolve(sensor, program=program)
            if not config.sensor.raw:
                # bins past the tested range carry no evidence: profiles only as long as the test
                # needs (some sensors' readers learn the count from the data)
                n = int(np.ceil(SELF_TEST_RANGE_M * SELF_TEST_BIN_MARGIN / config.sensor.bin_spacing_m())) + 1
                config = config.for_sensor(config.sensor.with_bins(min(n, config.sensor.n_bins() or n)))
            what = f"sensor {name} ({models.get(model).summary})"
            try:
                problem = _self_test_one(runtime, config, rng)
            except DeviceCapabilityError as exc:
                notes.append(f"{what}: {exc}")
                continue
            ran += 1
            if problem:
                return f"{what}: {problem}"
    if not ran:
        return f"fits none of the built-in sensors: {'; '.join(notes)}"
    return dict(problem=None, notes=notes) if notes else None


def _self_test_one(runtime, config, rng):
    """``self_test`` of one sensor and configuration: None, or where the device and the oracle differ."""
    m = Mapping.from_config(runtime, config=config)
    m.every_node_pair = True                # the interpreter's arrays are compared whole below
    frame = _synthetic_frame(m, rng)
    lattice = m.fusion.lattice
    poses = np.broadcast_to(np.eye(4), (lattice.n_beams, 4, 4)) if m.fusion.per_beam_poses else np.eye(4)
    m.fuse(frame, poses)
    got = m.snapshot()
    it = m.detection.interpreter
    if m.range_fft is not None:
        profiles = m.range_fft.arrays["profiles"].get()
        flags = m.range_fft.arrays["flags"].get()
        want = oracle.range_profile(frame, m.range_fft.n_fft, window=m.range_fft.window_kind, output="power")
        err = np.nanmax(np.abs(profiles - want)) / np.nanmax(want)
        if not err <= SELF_TEST_PROFILE_RTOL:
            return f"the range FFT is off by {err:.2g} of the peak (float64 oracle)"
    else:
        profiles, flags = frame, None
    n_beams = lattice.n_beams
    evidence = it.arrays["evidence"].get().reshape(n_beams, *it.arrays["evidence"].shape[len(it.batch):])
    rows = np.unique(np.linspace(0, n_beams - 1, SELF_TEST_BEAMS).astype(int))
    p = profiles.reshape(n_beams, -1)[rows]
    noise, _, mask = oracle.cfar(p, m.detection.cfar.config)
    row_flags = None if flags is None else flags.reshape(-1)[rows]
    want_ev = it.model.oracle(p, noise, mask, it.config, it.bin_spacing_m, it.bin_model, row_flags)
    if it.classes is not None:               # node pairs of the classes the scene has: the others must be 0
        try:
            node_pairs.kept_classes(want_ev, it.classes)
        except ValueError as exc:
            return f"the float64 oracle's nodes contradict the interpreter's classes: {exc}"
    got_ev = it.model.comparable(evidence[rows])          # the classes dropped as the 0 they are
    share = float((np.abs(got_ev.astype(np.int64) - want_ev) <= 1).mean())
    if share < SELF_TEST_MATCH or not (want_ev != 0).any():
        return f"CFAR and the interpreter agree with the float64 oracle on only {share:.1%} of the bins"
    nodes = it.model.nodes(evidence)
    sums, updates, ambiguous = oracle.fusion(m.grid.spec, None if nodes is not None else evidence.reshape(n_beams, -1),
                                             lattice, m.fusion.model, poses, m.fusion.bin_spacing_m, m.fusion.first_bin,
                                             m.fusion.last_bin, margin=1e-3, nodes=nodes,
                                             terrain_dz=m.fusion.terrain_dz)[:3]
    clear = (updates > 0) & ~ambiguous
    share = float((np.abs(got[clear] - sums[clear]) <= updates[clear]).mean()) if clear.any() else 0.0
    if share < SELF_TEST_MATCH or not (got != 0).any():
        return f"the fused map agrees with the float64 oracle on only {share:.1%} of the voxels"
    return None


def _synthetic_frame(mapping, rng):
    """Noise with one strong echo per beam, in the frame's shape and dtype."""
    shape = mapping.frame_shape
    if mapping.range_fft is None:                        # power profiles
        frame = rng.exponential(1.0, shape).astype(np.float32)
        bins = rng.integers(shape[-1] // 8, shape[-1] // 2, shape[:-1])
        np.put_along_axis(frame, bins[..., None], 1e4, axis=-1)
        return frame
    n = shape[-1]
    t = np.arange(n)
    tone = rng.uniform(0.05, 0.3, shape[:-1])[..., None] * t
    dtype = mapping.range_fft.dtype
    if dtype == np.complex64:
        x = 2000 * np.exp(2j * np.pi * tone) + rng.normal(0, 20, shape) + 1j * rng.normal(0, 20, shape)
        return x.astype(np.complex64)
    x = 2000 * np.cos(2 * np.pi * tone) + rng.normal(0, 20, shape)
    return np.rint(x).astype(dtype)


def register():
    """Have every device this process chooses checked with ``self_test`` first (in a child
    process, the verdict cached by the device and by radarcl's own sources: the check, the
    pipeline it builds and all that the pipeline imports, so a verdict a bug in any of them gave
    does not outlive the fix); registering twice is once."""
    register_device_check(self_test, covers=("radarcl",))
