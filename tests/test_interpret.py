"""kernels/interpret.cl <-> radarcl/stages/interpret.py against radarcl.oracle.interpret (eq. 12)."""

import math

import numpy as np
import pytest
from tolerances import EVIDENCE_UNITS_TOL

from radarcl import logodds, node_pairs, oracle
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.pipeline import Detection
from radarcl.stages.interpret import Interpreter

SPACING = 0.125


def check_against_oracle(got, profiles, noise, mask, config, flags=None):
    """Pulses, counts and flags identical; evidence identical off pulses, within one unit on them."""
    evidence, pulses, n_pulses, flags_out = oracle.interpret(profiles, noise, mask, config, SPACING, flags)
    assert np.array_equal(got.flags, flags_out)
    assert np.array_equal(got.n_pulses, n_pulses)
    assert np.array_equal(got.pulses, pulses)
    on_pulse = np.asarray(mask, bool)
    assert np.array_equal(got.evidence[~on_pulse], evidence[~on_pulse])
    assert np.abs(got.evidence[on_pulse].astype(np.int64) - evidence[on_pulse]).max(initial=0) <= EVIDENCE_UNITS_TOL
    return evidence, pulses, n_pulses, flags_out


def frame(seed=0, shape=(16, 4, 256)):
    rng = np.random.default_rng(seed)
    x = rng.exponential(size=shape).astype(np.float32)
    beams = x.reshape(-1, shape[-1])
    beams[0, 50:53] = 1e3             # narrow pulse
    beams[0, 100:116] = 1e3           # wide pulse (16 bins = 2 m): E_l behind it
    beams[1, 60] = 1e30               # huge ratio: evidence clamped at the limit
    beams[2, 30:240:40] = 1e4         # six pulses: more than max_pulses = 4
    return x


def run_both(runtime, x, config=InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4),
             cfar=CfarConfig(guard=16, train=8), flags=None, **options):
    det = Detection(runtime, x.shape[:-1], x.shape[-1], SPACING, cfar, config)
    if options:
        det.interpreter = Interpreter(runtime, x.shape[:-1], x.shape[-1], SPACING, config, **options)
    got = det(x, flags)
    return got, check_against_oracle(got.interpret, x, got.cfar.noise, got.cfar.mask, config, flags)


def test_matches_oracle(runtime):
    got, (evidence, pulses, n_pulses, _) = run_both(runtime, frame())
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4)
    first, last = cfg.bin_interval(SPACING, 256)
    assert (first, last) == (8, 240)
    ev = got.interpret.evidence
    assert np.all(ev[..., :first] == 0) and np.all(ev[..., last + 1:] == 0)
    # the wide pulse: E_h before it, positive on it, E_l after it (off later pulses)
    e_high, e_low = logodds.to_fixed([-1.0, -0.1])
    beam = ev[0, 0]
    wide = [p for p in got.interpret.pulses[0, 0] if p[3] == 1]
    assert wide and wide[0][0] <= 100 and wide[0][1] >= 115
    start, end = wide[0][:2]
    noise_bins = ~got.cfar.mask[0, 0]
    assert np.all(beam[first:start][noise_bins[first:start]] == e_high)
    assert np.all(beam[end + 1:last + 1][noise_bins[end + 1:last + 1]] == e_low)
    assert np.all(beam[start:end + 1] > 0)
    assert ev[0, 1, 60] == logodds.EVIDENCE_LIMIT
    assert n_pulses[0, 2] == 6 and np.all(pulses[0, 2, :, 0] >= 0)


@pytest.mark.parametrize("local_size", [1, 3, 16, 64])
def test_local_sizes_agree(runtime, local_size):
    run_both(runtime, frame(seed=local_size, shape=(13, 97)), local_size=local_size)


def test_flags_and_invalid_beams_give_no_evidence(runtime):
    x = frame(seed=4, shape=(6, 128))
    x[1] = 0.0                        # silent receiver
    x[2, 70] = np.nan                 # bad profile
    x[3, 10] = -1.0                   # negative power: not a power profile
    flags = np.zeros(6, np.uint8)
    flags[4] = oracle.FLAG_NONFINITE   # invalid upstream
    flags[5] = oracle.FLAG_CLIPPED     # clipped upstream: still gives evidence
    got, (evidence, _, n_pulses, flags_out) = run_both(runtime, x, flags=flags)
    assert list(flags_out) == [0, oracle.FLAG_SILENT, oracle.FLAG_BAD_PROFILE,
                               oracle.FLAG_BAD_PROFILE, oracle.FLAG_NONFINITE, oracle.FLAG_CLIPPED]
    assert np.all(evidence[1:5] == 0) and np.all(n_pulses[1:5] == 0)
    assert np.all(got.interpret.pulses[1:5] == -1)
    assert np.any(evidence[5] != 0) and list(got.interpret.valid) == [True, False, False, False, False, True]


def test_strong_echo_never_overflows(runtime):
    """Echoes up to oracle.PROFILE_LIMIT over floored noise: evidence clamped, never wrapped;
    beyond it (where CFAR's float32 sums could overflow) the beam is flagged and gives none."""
    x = np.zeros((4, 64), np.float32)
    x[0, 20] = oracle.PROFILE_LIMIT
    x[1, 20] = 1e-20
    x[2, 20] = 1e-28                  # 100 x the noise floor
    x[3, 20] = np.finfo(np.float32).max
    cfg = InterpretConfig(range_min_m=0.0, range_max_m=8.0, k_occ=3.0)
    got, (evidence, _, _, flags) = run_both(runtime, x, cfg, CfarConfig(guard=1, train=2))
    assert got.cfar.mask[:3, 20].all()
    assert evidence[0, 20] == logodds.EVIDENCE_LIMIT
    assert 0 < got.interpret.evidence[1, 20] <= logodds.EVIDENCE_LIMIT
    assert 0 < got.interpret.evidence[2, 20] <= logodds.EVIDENCE_LIMIT
    assert flags[3] == oracle.FLAG_BAD_PROFILE == got.interpret.flags[3]
    assert not got.interpret.evidence[3].any()


def test_k_occ_zero_and_empty_interval(runtime):
    x = frame(seed=5, shape=(4, 64))
    got, (evidence, _, _, _) = run_both(runtime, x, InterpretConfig(k_occ=0.0, range_min_m=0.0, range_max_m=8.0))
    assert np.all(evidence[got.cfar.mask] == 0)
    got, (evidence, _, n_pulses, _) = run_both(runtime, x, InterpretConfig(range_min_m=10.0, range_max_m=20.0))
    assert np.all(evidence == 0) and np.all(n_pulses == 0)   # 64 bins reach 7.9 m only


def test_refuses_bad_input(runtime):
    with pytest.raises(ConfigError, match="E_h and E_l are evidence of emptiness"):
        InterpretConfig(e_high=0.5)
    with pytest.raises(ConfigError, match="k_occ must be >= 0"):
        InterpretConfig(k_occ=-1.0)
    with pytest.raises(ConfigError, match="range_min_m < range_max_m"):
        InterpretConfig(range_min_m=5.0, range_max_m=5.0)
    with pytest.raises(ConfigError, match="must be a finite number"):
        InterpretConfig(e_low=float("nan"))
    plan = Interpreter(runtime, (4,), 64, SPACING)
    ok = np.ones((4, 64), np.float32)
    with pytest.raises(ShapeError, match=r"expected noise of shape \(4, 64\) float32"):
        plan(ok, ok[:, :32], ok > 0)
    with pytest.raises(ShapeError, match=r"expected flags of shape \(4,\) uint8"):
        plan(ok, ok, ok > 0, flags=np.zeros(4, np.int32))
    import pyopencl.array as cla

    detection = Detection(runtime, (4,), 64, SPACING, CfarConfig(guard=1, train=2), InterpretConfig())
    with pytest.raises(ShapeError, match=r"expected power profiles of shape \(4, 64\) float32 on the device, "
                                         r"got \(4, 64\) float64"):
        detection.enqueue(cla.to_device(runtime.queue, np.ones((4, 64))))     # once read the wrong bytes


def test_the_occlusion_aware_variant_matches_its_oracle(runtime):
    """OCCLUSION=1: a strong narrow pulse (a post, a trunk) is a surface, so the noise behind it
    gets E_l, not the paper's E_h; before the first surface E_h runs from e_high at the first
    bin to e_high_far at the last, in integers exactly as the oracle computes them."""
    occ = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="occlusion",
                          surface_db=20.0, e_high=-1.0, e_high_far=-0.25, e_low=0.0)
    x = frame(seed=7)
    got, (evidence, pulses, n_pulses, _) = run_both(runtime, x, config=occ)
    # no pulse peak lies within 1e-3 decades of the surface test (float32 vs float64 could differ there)
    noise = got.cfar.noise.astype(np.float64)
    decades = np.log10(np.maximum(x, 1e-30)) - np.log10(noise)
    assert np.all(np.abs(decades[got.cfar.mask.astype(bool)] - 2.0) > 1e-3)
    ev = got.interpret.evidence
    first, last = occ.bin_interval(SPACING, 256)
    e_high, e_far = logodds.to_fixed([-1.0, -0.25])
    beam, noise_bins = ev[0, 0], ~got.cfar.mask[0, 0].astype(bool)
    narrow = [p for p in got.interpret.pulses[0, 0] if p[0] >= 0 and p[3] == 0 and p[0] <= 52 <= p[1]]
    assert narrow, "the narrow pulse at bins 50-52 was detected"
    end = narrow[0][1]
    behind = np.arange(end + 1, 100)[noise_bins[end + 1:100]]
    assert len(behind) and np.all(beam[behind] == 0)                    # E_l = 0 behind the surface
    paper = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4)
    paper_ev = oracle.interpret(x, got.cfar.noise, got.cfar.mask, paper, SPACING)[0]
    assert np.all(paper_ev[0, 0][behind] == logodds.to_fixed(-1.0))    # the paper: strongly free
    # a beam with no detection: the ramp, exactly
    quiet = [b for b in range(ev.shape[0] * ev.shape[1]) if not got.cfar.mask.reshape(-1, 256)[b, first:last + 1].any()]
    assert quiet
    ramp = ev.reshape(-1, 256)[quiet[0], first:last + 1].astype(np.int64)
    assert ramp[0] == e_high and ramp[-1] == e_far and np.all(np.diff(ramp) >= 0)
    j = np.arange(last - first + 1)
    step = (int(e_far) - int(e_high)) * j
    assert np.array_equal(ramp, int(e_high) + np.sign(step) * (np.abs(step) // (last - first)))


def test_the_occlusion_keys_are_checked():
    with pytest.raises(ConfigError, match="model must be one of"):
        InterpretConfig(model="magic")
    with pytest.raises(ConfigError, match="e_high_far is evidence of emptiness"):
        InterpretConfig(model="occlusion", e_high_far=0.5)
    assert InterpretConfig(e_high=-0.3).e_high_far == -0.3            # defaults to E_h: no ramp


LOG10_PROBE = """
#include "interpret_common.h"

/* test only: log10_nb and log10_nb8 / log10_nb16 of the same floats, for a bit-for-bit comparison */
__kernel void probe_log10(const __global float *x, __global float *scalar, __global float *vector8,
                          __global float *vector16)
{
    const int g = get_global_id(0);
    for (int l = 0; l < 16; ++l)
        scalar[16 * g + l] = log10_nb(x[16 * g + l]);
    vstore8(log10_nb8(vload8(2 * g, x)), 2 * g, vector8);
    vstore8(log10_nb8(vload8(2 * g + 1, x)), 2 * g + 1, vector8);
    vstore16(log10_nb16(vload16(g, x)), g, vector16);
}
"""


@pytest.mark.parametrize("lanes", [8, 16])
def test_log10_nb_vectors_are_log10_nb_lane_for_lane(runtime, lanes):
    """docs/guide/pipeline.md ("Eq. 12"): a chunk of eight bins takes its logs as one vector, ``log10_nb8``, lane
    for lane the same floats as the scalar ``log10_nb`` the other bins take; the nodes kernel's
    sixteen bins take theirs as ``log10_nb16``, the same floats again. Both on the device,
    compared bit for bit: every exponent of the float range, subnormals, 0, the mantissa around
    sqrt(2) where the reduction switches, random bit patterns, in every lane; NaN for negatives in
    both (a profile's NaN and Inf never reach the logs: the beam is flagged first, yet even their
    garbage agrees). The logs agree with float64's log10 to 4e-6 decades (the kernel's note)."""
    import pyopencl as cl
    import pyopencl.array as cla

    from radarcl.cl.devices import kernels_dir
    from radarcl.cl.runtime import _define
    from radarcl.stages import COMMON_DEFINES

    rng = np.random.default_rng(7)
    special = np.array([0.0, 1.0, 10.0, 1.1754944e-38, 1.1754942e-38, 1e-45, 3.4028235e38, np.inf, -1.0, np.nan,
                        1.41421350, 1.41421356, 1.41421362, 0.70710677, 0.70710683], np.float32)
    powers = np.ldexp(np.float32(1.0), np.arange(-149, 128)).astype(np.float32)
    bits = rng.integers(0, 0x7F800000, 40000, dtype=np.uint32).view(np.float32)             # every finite x >= 0
    near = (np.float32(1.41421356) * (1 + rng.uniform(-1e-6, 1e-6, 2000))).astype(np.float32)
    x = np.concatenate([special, powers, powers * np.float32(1.5), bits, near])
    x = np.concatenate([x, np.roll(x, 3)])                       # every value in another lane too
    x = np.concatenate([x, np.zeros(-len(x) % 16, np.float32)])
    defines = dict(COMMON_DEFINES, N_BINS=64, MAX_PULSES=4, OCCLUSION=0)
    program = cl.Program(runtime.context, LOG10_PROBE).build(
        options=[f"-I{kernels_dir()}"] + [_define(k, v) for k, v in sorted(defines.items())])
    q = runtime.queue
    xd = cla.to_device(q, x)
    scalar, vector8, vector16 = (cla.empty(q, x.shape, np.float32) for _ in range(3))
    program.probe_log10(q, (len(x) // 16,), None, xd.data, scalar.data, vector8.data, vector16.data)
    s, v = scalar.get(), (vector8 if lanes == 8 else vector16).get()
    both_nan = np.isnan(s) & np.isnan(v)
    assert np.array_equal(np.isnan(s), np.isnan(v)) and np.array_equal(both_nan, x < 0)   # -1.0, in two lanes
    assert np.array_equal(s.view(np.uint32)[~both_nan], v.view(np.uint32)[~both_nan])      # NaN and Inf in too
    finite = (x > 0) & np.isfinite(x)
    assert np.abs(s[finite] - np.log10(x[finite].astype(np.float64))).max() < 4e-6
    assert s[x == 0].tolist() == [-np.inf] * int((x == 0).sum())


# -- the detection-statistics model (DETSTATS=1) ------------------------------------------------------------------
def detstats_model(n_bins=256, ground_below_m=1.5, evidence="snr", **params):
    from radarcl import sensor_model as sm

    params = sm.ModelParams(50.28, ground_below_m=ground_below_m, evidence=evidence, **params)
    return sm.BinModel.build(params, CfarConfig(guard=16, train=8), n_bins, SPACING, 4.0, math.radians(0.5),
                             math.radians(1.0), 0.2)


def oracle_kept(nodes, classes):
    """The float64 oracle's (e, d) nodes of the classes an interpreter keeps; fails unless the
    others are all 0 (the premise of dropping them)."""
    return tuple(node_pairs.kept_classes(v, classes) for v in nodes)


@pytest.mark.parametrize("local_size", [1, 16, 64])
@pytest.mark.parametrize("evidence", ["snr", "detection"])
@pytest.mark.parametrize("ground_below_m, classes", [(1.5, 2), (0.0, 1)])
def test_detstats_matches_its_oracle(runtime, local_size, evidence, ground_below_m, classes):
    """Node values within EVIDENCE_UNITS_TOL of the float64 oracle (float32 logs, blocking and,
    with "snr", the table's bilinear read), and identical to it until a beam's first pulse with
    "detection" (the host's exact table); pulses, counts and flags identical; flagged beams and
    bins outside the window give 0. Without a ground plane the node array holds the upright class
    alone, and the oracle's terrain nodes are all 0."""
    x = frame(seed=11 + local_size)
    beams = x.reshape(-1, 256)
    beams[3, 40:44] = 30.0                       # a weak pulse: partial blocking behind it
    beams[4] = 0.0                               # silent
    beams[5, 100:] = 0.0                         # "snr": a floor from a window half of zeros
    beams[6, 60:63] = 1e30                       # a huge echo: x beyond the table, blocking without overflow
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
    model = detstats_model(evidence=evidence, ground_below_m=ground_below_m)
    det = Detection(runtime, x.shape[:-1], 256, SPACING, CfarConfig(guard=16, train=8), cfg, bin_model=model)
    det.interpreter = Interpreter(runtime, x.shape[:-1], 256, SPACING, cfg, bin_model=model, local_size=local_size)
    assert det.interpreter.classes == classes
    got = det(x)
    e, d, pulses, n_pulses, flags = oracle.interpret_detstats(x, got.cfar.noise, got.cfar.mask, cfg, SPACING, model)
    assert np.array_equal(got.interpret.pulses, pulses) and np.array_equal(got.interpret.n_pulses, n_pulses)
    assert np.array_equal(got.interpret.flags, flags) and flags.reshape(-1)[4] & oracle.FLAG_SILENT
    assert e.shape == (16, 4, 256, 2, 5)
    e, d = oracle_kept((e, d), classes)
    ge, gd = node_pairs.unpack_nodes(got.interpret.evidence)
    assert ge.shape == e.shape == (16, 4, 256, classes, 5)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    mask = got.cfar.mask.reshape(-1, 256).astype(bool)
    first, last = cfg.bin_interval(SPACING, 256)
    before = np.zeros_like(mask)                 # noise bins before each beam's first pulse: exact
    for b in range(len(mask)):
        hits = np.flatnonzero(mask[b, first:last + 1])
        before[b, first:(first + hits[0]) if len(hits) else last + 1] = True
    before &= ~mask
    assert not ge.reshape(-1, 256, classes, 5)[4].any() and not ge[..., :first, :, :].any()
    assert not ge[..., last + 1:, :, :].any() and (ge != 0).any()
    window = np.zeros_like(mask)
    window[:, first:last + 1] = True
    hit = e.reshape(-1, 256, classes, 5)[mask & window & (flags.reshape(-1)[:, None] == 0)]
    if evidence == "detection":
        assert np.array_equal(ge.reshape(-1, 256, classes, 5)[before], e.reshape(-1, 256, classes, 5)[before])
        # a detection is evidence of occupancy (0 only where nearer echoes block the beam)
        assert len(hit) and (hit >= 0).all() and (hit[:, 0, 0] > 0).mean() > 0.5
    else:
        # behind the huge echo the beam is blocked: no knowledge, so no evidence (the gap's
        # ln(1 - gap) on quiet bins would otherwise add up, uncounted by the look limit, frame after
        # frame): exactly 0
        behind_e, behind_d = ge.reshape(-1, 256, classes, 5)[6, 64:], gd.reshape(-1, 256, classes, 5)[6, 64:]
        assert not behind_d.any() and not behind_e.any()
        assert (ge.reshape(-1, 256, classes, 5)[6, 60:63, 0] > 0).all()
        # anywhere: a node without an opportunity carries no evidence, in the kernel and the oracle
        assert not ge[gd == 0].any() and not e[d == 0].any() and (gd == 0).any()


def test_detstats_needs_its_model(runtime):
    cfg = InterpretConfig(model="detstats")
    with pytest.raises(ConfigError, match="needs its sensor_model.BinModel"):
        Interpreter(runtime, (4,), 256, SPACING, cfg)
    with pytest.raises(ConfigError, match="the bin model has 256 bins; the profiles have 128"):
        Interpreter(runtime, (4,), 128, SPACING, cfg, bin_model=detstats_model(256))
    with pytest.raises(ConfigError, match=r"classes must be 2 \(None: 2\) for this bin model, got 1: its terrain"):
        Interpreter(runtime, (4,), 256, SPACING, cfg, bin_model=detstats_model(256), classes=1)
    with pytest.raises(ConfigError, match=r"classes must be 1 or 2 \(None: 1\) for this bin model, got 3"):
        Interpreter(runtime, (4,), 256, SPACING, cfg, bin_model=detstats_model(256, ground_below_m=0.0), classes=3)
    with pytest.raises(ConfigError, match="classes are for a model with node pairs"):
        Interpreter(runtime, (4,), 256, SPACING, InterpretConfig(), classes=1)


def test_snr_noise_floor_counts_negative_zero_as_zero(runtime):
    """-0.0 passes the profile check; the kernel's median (a bisection on the floats' bits) counts
    it as +0.0, as the oracle's partition does, instead of above +inf."""
    rng = np.random.default_rng(5)
    x = rng.exponential(1.0, (4, 256)).astype(np.float32)
    x[0, ::2] = -0.0                                  # every other bin
    x[1, :200] = -0.0                                 # most of the beam
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
    model = detstats_model()
    det = Detection(runtime, (4,), 256, SPACING, CfarConfig(guard=16, train=8), cfg, bin_model=model)
    got = det(x)
    e, d, *_ = oracle.interpret_detstats(x, got.cfar.noise, got.cfar.mask, cfg, SPACING, model)
    ge, gd = node_pairs.unpack_nodes(got.interpret.evidence)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    assert (got.interpret.flags == 0).all() and (e[0] != 0).any()
