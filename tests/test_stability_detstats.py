"""The stability suite of the default model (detection statistics, ``radarcl.sensor_model``):
its stiff and extreme cases against float64, each named, each with an assertion at a named
tolerance (tests/tolerances.py). The kernel's own series (``exp_nb``, ``log10_nb``) over their
whole range; the SNR from -30 to +150 dB over the floor; the gap mixture behind a blocker at
extreme powers; 10^6 looks of one voxel (the reading's look limit, the knowledge channel at its
integer limit); knowledge at 0; all-zero, clipped and NaN frames; a 120 dB reflector beside a
weak target."""

import math

import numpy as np
import pytest
from test_interpret import SPACING, detstats_model
from tolerances import EVIDENCE_UNITS_TOL, EXP_NB_RTOL, LIKELIHOOD_RATIO_RTOL, LOG10_NB_DECADES, READ_NATS_TOL

from radarcl import logodds, node_pairs, oracle
from radarcl import sensor_model as sm
from radarcl.config.stage_config import PAPER_RADAR, CfarConfig, InterpretConfig
from radarcl.errors import ConfigError
from radarcl.geometry import BeamLattice, BeamModel
from radarcl.grid import EvidenceGrid
from radarcl.gridspec import GRID_LIMIT, GridSpec
from radarcl.pipeline import Detection
from radarcl.scene.fmcw import simulate_beams
from radarcl.snr_evidence import GAP_CAP, SNR_U, SNR_V, likelihood_ratio
from radarcl.stages.fusion import Fusion

CONFIG = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
CFAR = CfarConfig(guard=16, train=8)

PROBE = """
#include "interpret_nodes.cl"
#define vstoreV CAT(vstore, LANES)

/* test only: the detection-statistics model's own series and likelihood ratio, as the kernel has
 * them: LANES lanes a work-item, as interpret_nodes computes them (log10_nb also scalar) */
__kernel void probe(const __global float *x, const float q, __global float *e, __global float *l,
                    __global float *lr, __global float *l1)
{
    const int i = get_global_id(0);
    const floatV v = vloadV(i, x);
    vstoreV(exp_nb(v), i, e);
    vstoreV(LOG10_NB(v), i, l);
    vstoreV(likelihood_ratio(v, q), i, lr);
    for (int k = 0; k < LANES; ++k)
        l1[LANES * i + k] = log10_nb(x[LANES * i + k]);
}
"""


def probe(runtime, x, q):
    """(exp_nb(x), log10_nb(x), likelihood_ratio(x, q)) computed on the device, float32, lane by
    lane as kernels/interpret_nodes.cl computes them (its default lanes; log10_nb's lanes checked
    equal to the scalar log10_nb)."""
    import pyopencl as cl
    import pyopencl.array as cla

    from radarcl.cl.devices import kernels_dir
    from radarcl.cl.runtime import _define
    from radarcl.stages import COMMON_DEFINES
    from radarcl.stages.interpret_nodes import DEFAULT_LANES

    LANES = DEFAULT_LANES["cpu" if runtime.is_cpu else "other"]

    defines = dict(COMMON_DEFINES, N_BINS=64, CLASSES=2, LANES=LANES, SNR_NU=SNR_U[2],
                   SNR_NV=SNR_V[2], SNR_U0=float(SNR_U[0]), SNR_V0=float(SNR_V[0]),
                   SNR_U_SCALE=(SNR_U[2] - 1) / (SNR_U[1] - SNR_U[0]), SNR_V_SCALE=(SNR_V[2] - 1) / (SNR_V[1] - SNR_V[0]),
                   GAP_CAP=GAP_CAP, NODES=node_pairs.NODES)
    program = cl.Program(runtime.context, PROBE).build(
        options=[f"-I{kernels_dir()}"] + [_define(k, v) for k, v in sorted(defines.items())])
    qu = runtime.queue
    x = np.asarray(x, np.float32)
    n = len(x)
    xd = cla.to_device(qu, np.concatenate([x, np.ones(-n % LANES, np.float32)]))     # whole work-items
    outs = [cla.empty(qu, xd.shape, np.float32) for _ in range(4)]
    program.probe(qu, (xd.shape[0] // LANES,), None, xd.data, np.float32(q), *(o.data for o in outs))
    e, l, lr, l1 = (o.get()[:n] for o in outs)
    assert np.array_equal(l, l1, equal_nan=True)               # the lanes compute what the scalar does
    return e, l, lr


def test_exp_nb_against_float64_over_its_range(runtime):
    """exp_nb on [-87, 88] (every float32 input it takes unclamped, sampled densely, the points
    where its reduction n = rint(x / ln 2) steps) within EXP_NB_RTOL of float64's exp of the same
    float; outside, clamped to its ends (finite, never 0 or inf)."""
    rng = np.random.default_rng(1)
    steps = (np.arange(-125, 127) + 0.5) * math.log(2.0)
    x = np.concatenate([np.linspace(-87.0, 88.0, 200001), rng.uniform(-87, 88, 100000), steps, np.nextafter(steps, 0),
                        [0.0, -0.0, 1e-30, -1e-30]]).astype(np.float32)
    got = probe(runtime, x, 0.1)[0].astype(np.float64)
    exact = np.exp(x.astype(np.float64))
    assert np.abs(got / exact - 1).max() <= EXP_NB_RTOL
    ends = probe(runtime, np.array([88.0, 89.0, 1e30, np.inf, -87.0, -88.0, -1e30, -np.inf], np.float32), 0.1)[0]
    assert np.isfinite(ends).all() and (ends > 0).all()
    assert ends[:4].tolist() == [ends[0]] * 4 and ends[4:].tolist() == [ends[4]] * 4


def test_log10_nb_against_float64_over_its_range(runtime):
    """log10_nb over every float32 exponent, subnormals included, and the arguments the model gives
    it (1 + delta c_det up to 1e6, the mixture's L / (1 - q + q L) in (0, 1 / q)) within
    LOG10_NB_DECADES of float64's log10; log10(0) = -inf."""
    rng = np.random.default_rng(2)
    x = np.concatenate([np.ldexp(1.0, np.arange(-149, 128)), rng.uniform(0.5, 2.0, 50000),
                        10.0 ** rng.uniform(-45, 38, 50000), 1 + 10.0 ** rng.uniform(-7, 6, 50000)]).astype(np.float32)
    x = x[(x > 0) & np.isfinite(x)]
    got = probe(runtime, x, 0.1)[1].astype(np.float64)
    assert np.abs(got - np.log10(x.astype(np.float64))).max() <= LOG10_NB_DECADES
    assert probe(runtime, np.zeros(1, np.float32), 0.1)[1].tolist() == [-np.inf]


@pytest.mark.parametrize("q", [1e-6, 1e-3, 0.1, 0.5])
def test_the_likelihood_ratio_against_float64_at_extreme_evidence(runtime, q):
    """L of e = ln(L / (1 - q + q L)) (the gap mixture's first step) for e from -80 nat to
    ln(1 / q) and past it: finite and positive everywhere (capped below 1 / q by GAP_CAP), within
    LIKELIHOOD_RATIO_RTOL of float64 where e^e is at least a part in 10^3 below its cap (at the cap
    L's denominator 1 - q e^e cancels, but the mixture's evidence there is ln(1 / q) whatever L)."""
    e = np.concatenate([np.linspace(-80.0, -math.log(q) + 5.0, 20001), [-math.log(q), 88.0, 200.0]]).astype(np.float32)
    got = probe(runtime, e, q)[2].astype(np.float64)
    exact = likelihood_ratio(e.astype(np.float64), q)
    assert np.isfinite(got).all() and (got > 0).all() and np.isfinite(exact).all()
    away = np.exp(e.astype(np.float64)) * q < 1 - 1e-3
    assert away.sum() > 10000 and np.abs(got[away] / exact[away] - 1).max() <= LIKELIHOOD_RATIO_RTOL



def detect(runtime, x, model, flags=None):
    """CFAR and the default model's interpreter on profiles ``x`` (n, 256), and the float64 oracle
    on the same CFAR output: (kernel nodes e, d, oracle nodes e, d, kernel result)."""
    det = Detection(runtime, x.shape[:-1], x.shape[-1], SPACING, CFAR, CONFIG, bin_model=model)
    got = det(x, flags) if flags is not None else det(x)
    e, d, pulses, n_pulses, oflags = oracle.interpret_detstats(x, got.cfar.noise, got.cfar.mask, CONFIG, SPACING, model,
                                                               flags)
    ge, gd = node_pairs.unpack_nodes(got.interpret.evidence)
    classes = det.interpreter.classes               # the oracle's other classes must be 0: kept_classes checks
    e, d = node_pairs.kept_classes(e, classes), node_pairs.kept_classes(d, classes)
    assert ge.shape == e.shape
    assert np.array_equal(got.interpret.flags, oflags) and np.array_equal(got.interpret.n_pulses, n_pulses)
    return ge, gd, e, d, got


@pytest.mark.parametrize("evidence", ["snr", "detection"])
def test_snr_from_minus_30_to_plus_150_db(runtime, evidence):
    """One echo per beam, from 30 dB under the noise to 150 dB over it (float32 power up to 1e15):
    the nodes within EVIDENCE_UNITS_TOL of the float64 oracle, none past the update limit, an
    echo 20 dB over the noise or more says "occupied" at the node that sees it, and behind a
    150 dB echo the beam knows nothing (no knowledge, no evidence)."""
    snr_db = np.arange(-30, 151, 5, dtype=np.float64)
    x = np.random.default_rng(3).exponential(size=(len(snr_db), 256)).astype(np.float32)
    x[:, 100:102] = (10.0 ** (snr_db / 10))[:, None]
    ge, gd, e, d, _ = detect(runtime, x, detstats_model(evidence=evidence))
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    assert np.abs(ge).max() <= logodds.EVIDENCE_LIMIT
    strong = snr_db >= 20
    assert (ge[strong, 100, 0, 0] > 0).all() and (e[strong, 100, 0, 0] > 0).all()
    assert not gd[-1, 110:].any() and not ge[-1, 110:].any()


@pytest.mark.parametrize("gap", [sm.BLOCKER_GAP_MIN, 0.01, 0.5])
def test_the_gap_mixture_at_extreme_snr(runtime, gap):
    """Behind a blocker of 40 to 150 dB, an echo of -10 to 150 dB, with a gap of chance 1e-4 to
    0.5 (a smaller one but 0 is refused: ``test_a_gap_float32_cannot_resolve_is_refused``): the nodes within EVIDENCE_UNITS_TOL of the float64 oracle (``snr_evidence.gap_mixture``
    in float64), finite, and an echo 60 dB or more behind a gap of 1 % or more counts as occupied."""
    blockers = np.array([1e4, 1e8, 1e12, 1e15])
    echoes = np.array([1e-1, 1e2, 1e6, 1e10, 1e15])
    x = np.random.default_rng(4).exponential(size=(len(blockers) * len(echoes), 256)).astype(np.float32)
    x[:, 40:42] = np.repeat(blockers, len(echoes))[:, None]
    x[:, 120:122] = np.tile(echoes, len(blockers))[:, None]
    ge, gd, e, d, _ = detect(runtime, x, detstats_model(blocker_gap=gap))
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    assert np.abs(ge).max() <= logodds.EVIDENCE_LIMIT
    loud = np.tile(echoes >= 1e6, len(blockers))
    if gap >= 0.01:
        assert (ge[loud, 120, 0, 0] > 0).all() and (gd[loud, 120, 0, 0] > 0).all()


def test_a_gap_float32_cannot_resolve_is_refused():
    """At a gap of 1e-6 the mixture's posterior w = g L_0 / L rests on L_0 at its cap, whose float32
    rounding the kernel's nodes amplify by up to 1 / GAP_CAP (several units from float64): such a
    gap is refused with the least one allowed; 0 (no gap) stays allowed."""
    with pytest.raises(ConfigError, match=r"blocker_gap = 1e-06: expected 0 \(no gap\) or at least 0.0001"):
        sm.ModelParams(blocker_gap=1e-6)
    assert sm.ModelParams(blocker_gap=0.0).blocker_gap == 0.0


def looks_grid(runtime, e_units, frames, still="auto"):
    """A one-voxel grid with the knowledge channel looked at by 10^4 beams a frame, every node
    ``e_units`` of evidence and a full look (KNOWLEDGE_SCALE), ``frames`` times (``still``: the
    fusion's; "auto" fuses the repeated pose from its still table, False by the gather)."""
    spec = GridSpec((4.5, -0.5, -0.5), 1.0, (1, 1, 1))                 # one voxel around (5, 0, 0)
    lattice = BeamLattice(250, 40, -1e-4, 1e-6, -1e-4, 5e-6)           # 10^4 beams, all through it
    model = BeamModel(0.1, 0.1, 0.0, 0.0, near_field=False, gaussian=False)
    grid = EvidenceGrid(runtime, spec, knowledge=True)
    fusion = Fusion(runtime, grid, lattice, model, 64, 0.1, 1, 63, detstats=True, still=still)
    shape = (lattice.n_beams, 64, node_pairs.N_CLASSES, node_pairs.NODES)
    packed = node_pairs.pack_nodes(np.full(shape, e_units), np.full(shape, logodds.KNOWLEDGE_SCALE))
    fusion(packed, np.eye(4))
    for _ in range(frames - 1):                # the same frame again: checked and uploaded once
        fusion.enqueue(plan=fusion.plan(np.eye(4)))
    runtime.queue.finish()
    return grid.snapshot().item(), grid.knowledge_snapshot().item(), grid.knowledge_snapshot("looks").item()


def test_a_million_looks_of_one_voxel_read_at_the_look_limit(runtime):
    """10^6 full looks of one voxel at +1000 units each: the looks counted exactly, the evidence
    summed exactly (10^9 units, under GRID_LIMIT), the knowledge saturated at its integer limit
    GRID_LIMIT exactly (4096 x 10^6 would wrap int32), and the reading (E / (n / look_limit) plus
    the prior where known) within READ_NATS_TOL of float64 on the unsaturated sums."""
    evidence, knowledge, looks = looks_grid(runtime, 1000, 100)
    assert looks == 10 ** 6 and evidence == 1000 * 10 ** 6 and knowledge == GRID_LIMIT
    reading = dict(look_limit=2.0, prior_nats=-2.0, prior_looks=0.0, known_looks=0.5)
    got = sm.read_log_odds(evidence, knowledge, looks, reading)
    exact = 1000 * 1e6 / logodds.SCALE / (1e6 / 2.0) - 2.0
    assert abs(float(got) - exact) <= READ_NATS_TOL


@pytest.mark.parametrize("still", ["auto", False], ids=["still table", "gather"])
def test_strong_looks_past_saturation_keep_their_mean_evidence(runtime, still):
    """2 x 10^5 looks of +16 nat (three times what saturates the sum): the float64 reading is 2
    looks' worth, 32 nat (the update limit times look_limit). The stored sum saturates after
    65,536 of them; the looks stop counting there (the frame that saturates it counts whole), so
    the reading stays at its mean, within one frame's share of the looks (10^4 of the 7 x 10^4
    counted), rather than fading as 1 / n (to 2.1 nat at 10^6 looks, as it did)."""
    evidence, knowledge, looks = looks_grid(runtime, logodds.EVIDENCE_LIMIT, 20, still)      # 2 x 10^5 looks
    reading = dict(look_limit=2.0, prior_nats=0.0, prior_looks=0.0, known_looks=0.5)
    got = float(sm.read_log_odds(evidence, knowledge, looks, reading))
    assert evidence == GRID_LIMIT and looks == 10 ** 4 * math.ceil(GRID_LIMIT / (10 ** 4 * logodds.EVIDENCE_LIMIT))
    exact = 2.0 * logodds.EVIDENCE_LIMIT_NATS
    assert exact * (1 - 10 ** 4 / looks) <= got <= exact


def test_knowledge_at_zero_reads_the_prior(runtime):
    """Looks whose opportunity is 0 (the nodes' d = 0) are no looks: knowledge and looks stay
    exactly 0, the interpreter gives such nodes no evidence (kernel and oracle), and the voxel
    reads exactly the prior."""
    spec = GridSpec((4.5, -0.5, -0.5), 1.0, (1, 1, 1))
    lattice = BeamLattice(10, 10, -1e-4, 2e-5, -1e-4, 2e-5)
    grid = EvidenceGrid(runtime, spec, knowledge=True)
    fusion = Fusion(runtime, grid, lattice, BeamModel(0.1, 0.1, 0.0, 0.0, near_field=False, gaussian=False), 64, 0.1,
                    1, 63, detstats=True)
    shape = (lattice.n_beams, 64, node_pairs.N_CLASSES, node_pairs.NODES)
    fusion(node_pairs.pack_nodes(np.zeros(shape, int), np.zeros(shape, int)), np.eye(4))
    assert (grid.snapshot().item(), grid.knowledge_snapshot().item(), grid.knowledge_snapshot("looks").item()) == (0, 0, 0)
    reading = dict(look_limit=2.0, prior_nats=-2.5, prior_looks=0.0, known_looks=0.5)
    assert float(sm.read_log_odds(0, 0, 0, reading)) == -2.5
    # the interpreter: behind a 150 dB echo the nodes have d = 0, and then e = 0 exactly
    x = np.random.default_rng(6).exponential(size=(4, 256)).astype(np.float32)
    x[:, 60:62] = 1e15
    ge, gd, e, d, _ = detect(runtime, x, detstats_model())
    assert (gd == 0).any() and not ge[gd == 0].any() and not e[d == 0].any()


def test_all_zero_frame(runtime):
    """Zeros: nothing detected, no knowledge and no evidence anywhere, as the oracle says."""
    ge, gd, e, d, got = detect(runtime, np.zeros((8, 256), np.float32), detstats_model())
    assert np.array_equal(ge, e) and np.array_equal(gd, d) and not ge.any() and not got.cfar.mask.any()


def test_clipped_frame(runtime):
    """Every bin at a Navtech level's full scale (255 at 1 dB per level: 3.2e25), and half the bins
    of some beams there: within EVIDENCE_UNITS_TOL of float64, inside the update limit."""
    full = np.float32(10.0 ** 25.5)
    x = np.random.default_rng(7).exponential(size=(8, 256)).astype(np.float32)
    x[:4] = full
    x[4:, 128:] = full
    ge, gd, e, d, _ = detect(runtime, x, detstats_model())
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    assert np.abs(ge).max() <= logodds.EVIDENCE_LIMIT and (ge[4:, 128:, 0, 0] > 0).any()


def test_nan_and_inf_beams(runtime):
    """Beams flagged non-finite by their reader (a NaN, +inf or -inf in them, read as 0 so the
    check lets them by) give no evidence and no knowledge; the other beams give exactly what
    they give without the bad ones, and the oracle agrees."""
    x = np.random.default_rng(8).exponential(size=(8, 256)).astype(np.float32)
    x[:, 90:92] = 1e5
    clean = detect(runtime, x, detstats_model())
    flags = np.zeros(8, np.uint8)
    flags[[1, 4, 6]] = oracle.FLAG_NONFINITE
    bad = x.copy()
    bad[[1, 4, 6]] = 0.0
    ge, gd, e, d, _ = detect(runtime, bad, detstats_model(), flags)
    assert not ge[[1, 4, 6]].any() and not gd[[1, 4, 6]].any() and not e[[1, 4, 6]].any()
    keep = [0, 2, 3, 5, 7]
    assert np.array_equal(ge[keep], clean[0][keep]) and np.array_equal(gd[keep], clean[1][keep])
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL


def test_120_db_reflector_beside_a_weak_target(runtime):
    """A corner reflector 120 dB over the noise at 12 m and a target 80 dB weaker at 30 m (the
    eq. 12 stability case's scene, through the default model): nodes within EVIDENCE_UNITS_TOL
    of float64; the weak target is detected and its bins carry evidence of occupancy at the
    node that sees it, kernel and oracle alike."""
    samples = simulate_beams(PAPER_RADAR, np.array([[1.0, 1e-4]]), np.array([[12.0, 30.0]]),
                             noise_rms=1e-6, seed=1).samples.astype(np.float64)
    profiles = oracle.range_profile(samples, 512, output="power").astype(np.float32)
    spacing = PAPER_RADAR.bin_spacing_m(512)
    model = sm.BinModel.build(sm.ModelParams(50.28, ground_below_m=0.0), CFAR, 256, spacing, 4.0, math.radians(0.5),
                              math.radians(1.0), 0.2)
    config = InterpretConfig(range_min_m=1.0, range_max_m=40.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
    det = Detection(runtime, (1,), 256, spacing, CFAR, config, bin_model=model)
    got = det(profiles)
    e, d = oracle.interpret_detstats(profiles, got.cfar.noise, got.cfar.mask, config, spacing, model)[:2]
    e, d = node_pairs.kept_classes(e, 1), node_pairs.kept_classes(d, 1)           # no ground plane: the upright class alone
    ge, gd = node_pairs.unpack_nodes(got.interpret.evidence)
    assert ge.shape == e.shape == (1, 256, 1, 5)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    hits = np.flatnonzero(got.cfar.mask[0]) * spacing
    assert (np.abs(hits - 12.0) < 1).any() and (np.abs(hits - 30.0) < 1).any()
    weak = [b for b in np.flatnonzero(got.cfar.mask[0]) if abs(b * spacing - 30.0) < 1]
    assert (ge[0, weak, 0, 0] > 0).any() and (e[0, weak, 0, 0] > 0).any()
