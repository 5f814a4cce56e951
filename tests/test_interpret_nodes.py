"""kernels/interpret_nodes.cl <-> radarcl/stages/interpret_nodes.py: "snr" evidence's node pairs
after the beam walk, against radarcl.oracle.interpret_detstats (the walk's own checks, the
"detection" evidence and the noise floor are tests/test_interpret.py's)."""

import dataclasses
import math

import numpy as np
import pytest
from test_interpret import SPACING, detstats_model, oracle_kept
from tolerances import EVIDENCE_UNITS_TOL

from radarcl import logodds, node_pairs, oracle
from radarcl import sensor_model as sm
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.pipeline import Detection
from radarcl.stages.interpret import Interpreter
from radarcl.stages.interpret_nodes import LANE_CHOICES, InterpretNodes, classes_needed

CONFIG = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
CFAR = CfarConfig(guard=16, train=8)


def scene(seed=0, n_beams=12, n_bins=256):
    """Exponential noise with pulses of every kind the nodes meet: a strong blocker with an echo
    behind it, a weak partial blocker, a huge echo, a silent and a NaN beam."""
    x = np.random.default_rng(seed).exponential(size=(n_beams, n_bins)).astype(np.float32)
    x[0, 40:42] = 1e7
    x[0, 120:122] = 1e4
    x[1, 50:53] = 30.0
    x[2, 60:63] = 1e30
    x[3] = 0.0
    x[4, 7] = np.nan
    x[5, 100:116] = 1e3
    return x


def run(runtime, x, model, config=CONFIG, classes=None, **nodes_options):
    """(the interpreter's node values (e, d), the oracle's (e, d) of the classes it keeps (whose
    others it checks are 0), the interpreter's nodes plan)"""
    det = Detection(runtime, x.shape[:-1], x.shape[-1], SPACING, CFAR, config, bin_model=model)
    if nodes_options or classes is not None:
        det.interpreter = Interpreter(runtime, x.shape[:-1], x.shape[-1], SPACING, config, bin_model=model,
                                      nodes_options=nodes_options, classes=classes)
    got = det(x)
    e, d = oracle.interpret_detstats(x, got.cfar.noise, got.cfar.mask, config, SPACING, model)[:2]
    return node_pairs.unpack_nodes(got.interpret.evidence), oracle_kept((e, d), det.interpreter.classes), det.interpreter.nodes


@pytest.mark.parametrize("lanes", LANE_CHOICES)
@pytest.mark.parametrize("local_size", [1, 7, 64])
def test_lanes_and_local_sizes_give_the_same_nodes(runtime, lanes, local_size):
    """Every bins-per-work-item choice and work-group size gives the same node pairs, bit for bit
    (each lane computes one bin's scalar floats), within EVIDENCE_UNITS_TOL of the float64
    oracle, with both classes computed where the scene has terrain."""
    x = scene(seed=lanes + local_size)
    model = detstats_model()
    (ge, gd), (e, d), nodes = run(runtime, x, model, lanes=lanes, local_size=local_size)
    assert (nodes.lanes, nodes.local_size, nodes.classes) == (lanes, local_size, 2)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    assert (gd[..., 1, :] > 0).any() and (gd[..., 0, :] > 0).any()
    (ref_e, ref_d), _, _ = run(runtime, x, model, lanes=8, local_size=64)
    assert np.array_equal(ge, ref_e) and np.array_equal(gd, ref_d)


def test_a_scene_without_terrain_computes_the_upright_class_only(runtime):
    """No ground plane (ground_below_m = 0, sensor_model.terrain_dz = -inf): the terrain class has
    no opportunity at any bin, so the kernel computes and stores one class (the oracle's terrain
    nodes are all 0: a node without knowledge carries no evidence); the upright class's nodes are
    the oracle's within EVIDENCE_UNITS_TOL, bit for bit those of the same interpreter made to keep
    both classes (whose terrain nodes are then 0), and those of a model with terrain wherever the
    upright tables agree."""
    flat = detstats_model(ground_below_m=0.0)
    assert not flat.opportunity[:, 1].any() and classes_needed(flat.opportunity) == 1
    x = scene(seed=3)
    (ge, gd), (e, d), nodes = run(runtime, x, flat)
    assert nodes.classes == 1 and ge.shape == e.shape == (12, 256, 1, 5)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    (we, wd), _, wide = run(runtime, x, flat, classes=2)
    assert wide.classes == 2 and we.shape == (12, 256, 2, 5) and not we[..., 1, :].any() and not wd[..., 1, :].any()
    assert np.array_equal(we[..., :1, :], ge) and np.array_equal(wd[..., :1, :], gd)
    assert (gd[..., 0, :] > 0).any() and (ge[..., 0, :] != 0).any()
    # the same upright tables with a terrain class beside them: two classes, the same upright nodes
    terrain = np.array(flat.opportunity)
    terrain[:, 1] = 0.5
    both = dataclasses.replace(flat, opportunity=terrain, miss=1.0 - terrain)
    assert classes_needed(both.opportunity) == 2
    (be, bd), _, plan = run(runtime, x, both)
    assert plan.classes == 2 and (bd[..., 1, :] > 0).any()
    assert np.array_equal(be[..., 0, :], ge[..., 0, :]) and np.array_equal(bd[..., 0, :], gd[..., 0, :])



@pytest.mark.parametrize("lanes", LANE_CHOICES)
def test_node_use_makes_only_the_classes_a_chunk_reads(runtime, lanes):
    """With ``node_use`` (a still plan's table: bit c where some voxel reads class c's pairs of a
    bin) a chunk of ``lanes`` bins makes the classes one of its bins has, the same integers as
    making every pair, and leaves the others' pairs as they were (a sentinel here): the work
    saved is the chunks and classes no voxel reads."""
    import pyopencl.array as cla

    x = scene(seed=9)
    det = Detection(runtime, x.shape[:-1], x.shape[-1], SPACING, CFAR, CONFIG, bin_model=detstats_model())
    det.interpreter = it = Interpreter(runtime, x.shape[:-1], x.shape[-1], SPACING, CONFIG,
                                       bin_model=detstats_model(), nodes_options=dict(lanes=lanes))
    every = det(x).interpret.evidence                       # (beams, bins, classes x segments, 2)
    n_beams, n_bins = x.shape
    use = np.zeros((n_beams, n_bins), np.uint32)
    rng = np.random.default_rng(lanes)
    use[rng.random(use.shape) < 0.02] |= 1                  # sparse: most chunks read no upright pair
    use[:, 150:170] |= 2                                    # a run of terrain bins in every beam
    sentinel = np.int32(0x5A5A5A5A)
    q = runtime.queue
    it.arrays["evidence"].set(np.full(it.arrays["evidence"].shape, sentinel, np.int32), queue=q)
    det.enqueue(node_use=cla.to_device(q, use)).wait()
    got = it.arrays["evidence"].get(q)
    assert it.classes == 2
    pairs = lambda a: a.reshape(n_beams, n_bins, 2, -1)       # (beam, bin, class, the class's words)
    g, w = pairs(got), pairs(every)
    flags = it.arrays["flags_out"].get(q)
    valid = (flags & oracle.NO_EVIDENCE_FLAGS) == 0
    lo, first, last = it.first_bin & ~(lanes - 1), it.first_bin, it.last_bin
    made = skipped = 0
    for b in np.flatnonzero(valid):
        for j0 in range(lo, last + 1, lanes):
            window = np.arange(max(j0, first), min(j0 + lanes - 1, last, n_bins - 1) + 1)
            chunk_use = np.bitwise_or.reduce(use[b, window])
            for c in range(2):
                if chunk_use >> c & 1:
                    assert np.array_equal(g[b, window, c], w[b, window, c]), (b, j0, c)
                    made += 1
                else:
                    assert (g[b, window, c] == sentinel).all(), (b, j0, c)
                    skipped += 1
    assert made > 50 and skipped > made                     # both kinds of chunk, most of them skipped
    inside = slice(first, last + 1)
    assert (~valid).any() and np.array_equal(g[~valid, inside], w[~valid, inside])   # a flagged beam's: zeroed
    for bad in (use, cla.to_device(q, use.astype(np.int32)), cla.to_device(q, use[:, :-1].copy())):
        with pytest.raises(ShapeError, match="node_use must be a device array of uint32"):
            det.enqueue(node_use=bad)


def test_a_terrain_class_below_half_a_knowledge_unit_is_not_computed():
    """The class test is the kernels' own, in float32, and the host's exact nodes', in float64: an
    opportunity whose knowledge rounds to 0 (at most half a unit) everywhere in both is no class to
    compute; one bin above it in either is."""
    half = np.float32(0.5) / np.float32(logodds.KNOWLEDGE_SCALE)
    opportunity = np.zeros((64, node_pairs.N_CLASSES, node_pairs.NODES), np.float32)
    opportunity[:, 0] = 1.0
    opportunity[10:, 1] = half
    assert classes_needed(opportunity) == 1
    opportunity[40, 1, 3] = np.nextafter(half, np.float32(1.0))
    assert classes_needed(opportunity) == 2
    # a float64 table (the bin model's) just above half a unit, which float32 rounds down to half:
    # the host's exact nodes give it a unit of knowledge, so the class is kept
    exact = np.zeros((64, node_pairs.N_CLASSES, node_pairs.NODES))
    exact[10:, 1] = float(half)
    assert classes_needed(exact) == 1
    exact[40, 1, 3] = float(half) * (1 + 1e-12)
    assert np.float32(exact[40, 1, 3]) == half and classes_needed(exact) == 2



@pytest.mark.parametrize("evidence", ["snr", "detection"])
def test_live_segments_are_those_a_node_with_knowledge_ends(runtime, evidence):
    """``node_pairs.live_segments``: bit s of a bin and class is set where node s or s + 1 has more
    than half a knowledge unit of opportunity, in float32 (the kernels') or float64 (the host's exact
    nodes). The premise a still table leaves entries out on: a node at most half a unit is (0, 0)
    in every frame, from the node kernel ("snr") and from the walk ("detection") alike."""
    half = np.float32(0.5) / np.float32(logodds.KNOWLEDGE_SCALE)
    opportunity = np.zeros((5, node_pairs.N_CLASSES, node_pairs.NODES))
    opportunity[0] = 1.0                                     # every segment of both classes
    opportunity[1, 1, 2] = 0.6 / logodds.KNOWLEDGE_SCALE     # node 2: segments 1 and 2 of the terrain class
    opportunity[2, 0, 4] = float(half)                      # half a unit: nothing
    opportunity[3, 0, 0] = float(half) * (1 + 1e-12)         # float32 rounds it to half; float64's rint gives 1
    live = node_pairs.live_segments(opportunity)
    assert live.dtype == np.uint8 and live.tolist() == [[15, 15], [0, 6], [0, 0], [1, 0], [0, 0]]
    assert node_pairs.live_segments(opportunity, classes=1).tolist() == [[15], [0], [0], [1], [0]]
    with pytest.raises(ShapeError):
        node_pairs.live_segments(opportunity[:, :1])
    with pytest.raises(ConfigError):
        node_pairs.live_segments(opportunity, classes=3)
    model = detstats_model(evidence=evidence)
    opp = np.array(model.opportunity)
    opp[150:200, 1] = 0.4 / logodds.KNOWLEDGE_SCALE         # looks that can hardly see: below half a unit
    opp[200:, 0, 3:] = 0.0
    model = dataclasses.replace(model, opportunity=opp, miss=1.0 - opp)
    units = np.asarray(model.opportunity, np.float32) * np.float32(logodds.KNOWLEDGE_SCALE)
    never = (units <= 0.5) & (np.asarray(model.opportunity) * logodds.KNOWLEDGE_SCALE <= 0.5)
    assert never.any() and not never.all()
    (ge, gd), _, _ = run(runtime, scene(seed=11), model)
    assert not ge[:, never].any() and not gd[:, never].any()
    assert gd[:, ~never].any()



def test_a_model_hook_without_node_use_gets_none():
    """A model's ``after_kernel`` written before ``node_use`` (three arguments) is called without
    it, and so makes every node; one that names it, or takes **kwargs, gets it."""
    from radarcl.stages.interpret import _takes_keyword

    def old(interpreter, event, profiles):
        return event

    def named(interpreter, event, profiles, node_use=None):
        return event

    def open_ended(interpreter, event, profiles, **options):
        return event

    assert not _takes_keyword(old, "node_use")
    assert _takes_keyword(named, "node_use") and _takes_keyword(open_ended, "node_use")
    from radarcl.models.detstats import DetStats

    assert _takes_keyword(DetStats().after_kernel, "node_use")


def test_refuses_bad_input(runtime):
    model = detstats_model(n_bins=64)
    with pytest.raises(ConfigError, match=r"lanes must be one of \(8, 16\), got 12"):
        InterpretNodes(runtime, 4, 64, 8, 60, model, 2, lanes=12)
    with pytest.raises(ConfigError, match="needs a sensor_model.BinModel with 'snr' evidence"):
        InterpretNodes(runtime, 4, 64, 8, 60, detstats_model(n_bins=64, evidence="detection"), 2)
    with pytest.raises(ConfigError, match=r"must both be \(128, 2, 5\)"):
        InterpretNodes(runtime, 4, 128, 8, 60, model, 2)
    with pytest.raises(ConfigError, match=r"classes must be 1 or 2, got 0"):
        InterpretNodes(runtime, 4, 64, 8, 60, model, 0)
    with pytest.raises(ConfigError, match=r"local_size must be an integer in \[1, "):
        InterpretNodes(runtime, 4, 64, 8, 60, model, 2, local_size=0)
    with pytest.raises(ConfigError, match="the detection statistics interpreter with detection evidence has no node"):
        Interpreter(runtime, (4,), 64, SPACING, CONFIG, bin_model=detstats_model(n_bins=64, evidence="detection"),
                    nodes_options=dict(lanes=8))


@pytest.mark.parametrize("n_bins", [253, 264])
def test_snr_nodes_of_any_bin_count_and_window(runtime, n_bins):
    """"snr" evidence's nodes are computed LANES bins at a time (8 or 16): a profile whose bins are
    not a multiple of eight (the last chunk's lanes past the end), a window whose ends fall inside a
    chunk, pulses and blocking across chunk edges, give the oracle's nodes within
    EVIDENCE_UNITS_TOL, and 0 outside the window, on flagged beams and past the profile's end."""
    rng = np.random.default_rng(n_bins)
    x = rng.exponential(size=(6, n_bins)).astype(np.float32)
    x[0, 14:18] = 1e3                                # a pulse across the chunk edge at bin 16
    x[1, n_bins - 12:n_bins - 9] = 40.0              # a weak pulse near the window's end
    x[2, 30] = 1e30                                  # blocked behind it
    x[3] = np.nan                                    # a bad beam: no evidence
    cfg = InterpretConfig(range_min_m=1.1, range_max_m=(n_bins - 5) * SPACING, wide_pulse_m=2.0, max_pulses=4,
                          model="detstats")
    model = detstats_model(n_bins)
    det = Detection(runtime, (6,), n_bins, SPACING, CfarConfig(guard=16, train=8), cfg, bin_model=model)
    got = det(x)
    e, d, pulses, n_pulses, flags = oracle.interpret_detstats(x, got.cfar.noise, got.cfar.mask, cfg, SPACING, model)
    assert np.array_equal(got.interpret.pulses, pulses) and np.array_equal(got.interpret.flags, flags)
    ge, gd = node_pairs.unpack_nodes(got.interpret.evidence)
    assert ge.shape == e.shape == (6, n_bins, 2, 5)
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
    first, last = cfg.bin_interval(SPACING, n_bins)
    assert first % 8 and (last + 1) % 8 and last < n_bins - 1        # the window's ends inside chunks
    assert not ge[:, :first].any() and not gd[:, last + 1:].any() and not ge[3].any() and not gd[3].any()
    assert (gd[:, first] > 0).any() and (gd[:, last] > 0).any() and (ge[2, 30, 0] > 0).all()


def test_a_gap_in_a_blocker_lets_the_echo_behind_it_count(runtime):
    """sensor_model.blocker_gap: behind a strong echo, a second echo is evidence of occupancy and
    knowledge with a gap (the mixture of the blocked and the unblocked target's likelihoods), and
    none with hard blocking; the noise behind the blocker gives no knowledge either way. The
    kernel matches its oracle in both."""
    x = np.random.default_rng(5).exponential(size=(2, 256)).astype(np.float32)
    x[:, 40:42] = 1e7                             # the blocker: x ~ 1e7, far beyond the blocking unit
    x[:, 120:122] = 1e4                           # an echo behind it
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
    got = {}
    for gap in (0.0, 0.01):
        model = detstats_model(blocker_gap=gap)
        det = Detection(runtime, (2,), 256, SPACING, CfarConfig(guard=16, train=8), cfg, bin_model=model)
        out = det(x)
        e, d = oracle.interpret_detstats(x, out.cfar.noise, out.cfar.mask, cfg, SPACING, model)[:2]
        ge, gd = node_pairs.unpack_nodes(out.interpret.evidence)
        assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.abs(gd - d).max() <= EVIDENCE_UNITS_TOL
        assert out.interpret.n_pulses.tolist() == [2, 2]
        got[gap] = ge[:, 120:122, 0], gd[:, 120:122, 0], gd[:, 60:110]
    (e0, d0, n0), (e1, d1, n1) = got[0.0], got[0.01]
    assert np.abs(e0).max() <= 1 and not d0.any()                  # hard blocking: nothing behind the blocker
    assert (e1 > 2 * logodds.SCALE).all() and (d1 > 0).all()        # a gap: the echo counts, and is known
    assert not n0.any() and not n1.any()                             # noise behind the blocker: still unknown


def test_a_look_that_could_hardly_see_says_at_most_what_a_detection_would_either_way(runtime):
    """A look says of an occupied voxel no more than a CFAR detection would at its opportunity
    delta, ln(1 + delta (1 - q) / q) (snr_evidence.bounded): a 40 dB echo where the typical
    target's opportunity is 0.02 gives that (about 0.89 nat), not the ln(1 / q) of the table it
    gives where the look sees the voxel; a bin far under the noise no more either way (and where the
    look sees, no more than -ln(1 / q) though the table says more). Kernel and oracle alike."""
    from radarcl.snr_evidence import detection_cap

    base = detstats_model(ground_below_m=0.0)
    at = 100
    opportunity = np.array(base.opportunity)
    ln_snr = np.array(base.ln_snr)
    opportunity[at, 0] = [1.0, 0.02, 0.02, 0.02, 0.02]            # node 0: a look that sees; 1-4: hardly
    ln_snr[at, 0] = math.log(1e4)                                   # a 40 dB target: the table says all it can
    model = sm.BinModel(opportunity, 1.0 - opportunity, base.blocking, base.pfa, ln_snr, base.snr_table)
    x = np.full((2, 256), math.log(2.0), np.float32)                # the floor: median / ln 2 = 1
    x[0, at] = 1e4                                                  # 40 dB over the floor
    x[1, at] = 1e-3                                                 # far under it
    mask = np.zeros(x.shape, np.uint8)
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, max_pulses=4, model="detstats")
    out = Interpreter(runtime, (2,), 256, SPACING, cfg, bin_model=model)(x, np.ones_like(x), mask)
    ge, gd = node_pairs.unpack_nodes(out.evidence)
    e, d = oracle_kept(oracle.interpret_detstats(x, np.ones_like(x), mask, cfg, SPACING, model)[:2], 1)
    assert ge.shape == e.shape == (2, 256, 1, 5)                    # no ground plane: the upright class alone
    assert np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL and np.array_equal(gd, d)
    q = model.snr_table.q
    most = detection_cap(0.02, q) * logodds.SCALE
    assert 0.8 * logodds.SCALE < most < 0.9 * logodds.SCALE
    assert abs(e[0, at, 0, 0] + math.log(q) * logodds.SCALE) <= EVIDENCE_UNITS_TOL     # sees: the table's ln(1 / q)
    assert np.all(np.abs(e[0, at, 0, 1:] - most) <= EVIDENCE_UNITS_TOL)
    assert model.snr_table(math.log(1e-3), math.log(1e4)) < -5.0                        # the table's free evidence
    assert abs(e[1, at, 0, 0] - math.log(q) * logodds.SCALE) <= EVIDENCE_UNITS_TOL
    assert np.all(np.abs(e[1, at, 0, 1:] + most) <= EVIDENCE_UNITS_TOL)
    # sensor_model.evidence_bound = "none": the table's evidence as it is, in the kernel as in the oracle
    free = dataclasses.replace(model, bounded=False)
    ge = node_pairs.unpack_nodes(Interpreter(runtime, (2,), 256, SPACING, cfg, bin_model=free)(x, np.ones_like(x), mask).evidence)[0]
    e = oracle_kept(oracle.interpret_detstats(x, np.ones_like(x), mask, cfg, SPACING, free)[:2], 1)[0]
    assert ge.shape == e.shape and np.abs(ge - e).max() <= EVIDENCE_UNITS_TOL
    table = model.snr_table(np.log(x[:, at])[:, None], np.full((2, 5), math.log(1e4))) * logodds.SCALE
    assert np.all(np.abs(e[:, at, 0] - np.rint(table)) <= EVIDENCE_UNITS_TOL)
