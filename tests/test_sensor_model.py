"""The detection-statistics model (radarcl.sensor_model, radarcl.cfar_theory's correlated
cells): evidence pinned against hand-computed values, the physical ranges refused, the reading.

Hand values (CA-CFAR, 32 training cells, design P_fa 1e-3, alpha = 7.7098; Swerling 1):
- independent cells: P_d(S) = (1 + alpha / (32 (1 + S)))^-32; at 20 dB 0.926588, at 20 dB - 6.02 dB
  (the half-power edge, two-way 4^-1) 0.744403;
- the paper's cells (Hann, 256 samples padded to 1024, guard 16, train 16) are correlated: P_fa
  8.4711e-3, P_d(20 dB) 0.927055, P_d(edge) 0.749857 (eigenvalues of the cells' correlation).
A miss is worth ln((1 - P_d) / (1 - P_fa)), a detection ln(P_d / P_fa).

"snr" evidence (the default), by hand for a point target of SNR s with no spread, a bin measuring
x times its noise floor and q = 8.4711e-3 (the correlated cells' P_fa): ln L = x s / (1 + s) -
ln(1 + s), e = ln L - ln(1 - q + q L). On the axis (s = 100, 20 dB) and at the half-power edge
(s = 25): x = 1 (noise) -3.616742 and -2.288910 nat; x = 5 (an echo under the threshold)
+0.332005 and +1.518655 (a typical target on the axis would have been brighter); x = 50
+4.771095 at both (bounded by ln(1 / q)).
"""

import itertools
import math

import numpy as np
import pytest

from radarcl import cfar_theory, logodds, node_pairs, oracle
from radarcl import sensor_model as sm
from radarcl import snr_evidence as se
from radarcl.config import keys, mapconfig, sensors
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.errors import ConfigError

SPACING = 0.125
CA = CfarConfig(guard=16, train=16)           # the paper's CFAR
HAND = {  # (cells, rho2): (P_d, e_miss [nat], e_det [nat], P_fa)
    ("independent", 0.0): (0.926588, -2.6107, 6.8315, 1e-3),
    ("independent", 1.0): (0.744403, -1.3632, 6.6126, 1e-3),
    ("correlated", 0.0): (0.927055, -2.6095, 4.6954, 8.4711e-3),
    ("correlated", 1.0): (0.749857, -1.3772, 4.4832, 8.4711e-3),
}


def point_model(cells, snr_db, n_bins, at):
    """A BinModel whose bin ``at`` holds a point target (kappa 1) of ``snr_db`` on the axis, with
    no spread, built by hand from the CFAR's table; nothing blocks."""
    table = sm.DetectionTable.build("ca", CA.alpha, CA.n_train, None, None if cells == "independent" else 4.0, 0.0)
    t = np.arange(node_pairs.NODES) / (node_pairs.NODES - 1)
    opportunity = np.zeros((n_bins, node_pairs.N_CLASSES, node_pairs.NODES))
    opportunity[at, 0] = table(math.log(10 ** (snr_db / 10)) - t * math.log(4.0))
    return sm.BinModel(opportunity, 1.0 - opportunity, np.zeros(n_bins), table.pfa)


def test_hand_values_of_the_statistics():
    for cells in ("independent", "correlated"):
        corr = None if cells == "independent" else cfar_theory.training_correlation(sm.hann(256), 4, 16, 16)
        for rho2 in (0.0, 1.0):
            pd, e_miss, e_det, pfa = HAND[(cells, rho2)]
            s = 100.0 * 4.0 ** -rho2
            got = cfar_theory.detection_curve("ca", CA.alpha, 32, [0.0, s], corr=corr)
            assert got[0] == pytest.approx(pfa, rel=1e-4) and got[1] == pytest.approx(pd, abs=2e-6)
            assert math.log((1 - got[1]) / (1 - got[0])) == pytest.approx(e_miss, abs=2e-4)
            assert math.log(got[1] / got[0]) == pytest.approx(e_det, abs=2e-4)


@pytest.mark.parametrize("cells", ["independent", "correlated"])
def test_point_target_on_the_axis_and_at_the_half_power_edge(cells):
    """A bin holding a 20 dB point target: the oracle's nodes at rho2 = 0 and 1 equal the hand
    values (within 2 units: the table's interpolation in ln S), for a miss and a detection."""
    n_bins, at = 64, 30
    model = point_model(cells, 20.0, n_bins, at)
    noise = np.ones((2, n_bins))
    profiles = noise.copy()
    mask = np.zeros((2, n_bins), bool)
    mask[1, at] = True                                  # beam 1 detects in that bin (a one-bin pulse)
    profiles[1, at] = 50.0
    cfg = InterpretConfig(range_min_m=0.0, range_max_m=7.0, wide_pulse_m=1.0)
    e, d, *_ = oracle.interpret_detstats(profiles, noise, mask, cfg, SPACING, model)
    for node, rho2 in ((0, 0.0), (node_pairs.NODES - 1, 1.0)):
        pd, e_miss, e_det, pfa = HAND[(cells, rho2)]
        assert abs(e[0, at, 0, node] - e_miss * logodds.SCALE) <= 2
        assert abs(e[1, at, 0, node] - e_det * logodds.SCALE) <= 2
        assert abs(d[0, at, 0, node] - (pd - pfa) / (1 - pfa) * logodds.KNOWLEDGE_SCALE) <= 2
    # no-detection evidence is weaker at the beam edge than on the axis, node by node
    assert np.all(np.diff(e[0, at, 0]) > 0) and e[0, at, 0, -1] < 0


def test_a_voxel_behind_a_strong_echo_stays_unknown():
    """A 1 m^2 target at 10 m (SNR 50 dB) blocks the beam: behind it a 40 dB typical target gives
    evidence within +-0.2 nat of 0, detected or not."""
    params = sm.ModelParams(50.28)
    n_bins = 512
    model = sm.BinModel.build(params, CA, n_bins, SPACING, 4.0, math.radians(0.5), math.radians(1.0), 0.2)
    opp = np.array(model.opportunity)
    behind = 120                                       # 15 m
    opp[behind, 0] = sm.DetectionTable.build("ca", CA.alpha, 32, None, 4.0, 0.0)(math.log(1e4))   # 40 dB
    model = sm.BinModel(opp, 1.0 - opp, model.blocking, model.pfa)
    noise = np.ones((2, n_bins))
    profiles = noise.copy()
    mask = np.zeros((2, n_bins), bool)
    peak = 80                                          # 10 m
    psf = 10.0 ** (5.028 - np.abs(np.arange(-3, 4)) ** 2 / 6)   # a pulse of 7 bins, 50 dB at its peak
    profiles[:, peak - 3:peak + 4] += psf
    mask[:, peak - 3:peak + 4] = True
    mask[1, behind] = True                             # beam 1: a detection behind the echo
    profiles[1, behind] = 30.0
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=60.0, wide_pulse_m=1.0)
    e, d, *_ = oracle.interpret_detstats(profiles, noise, mask, cfg, SPACING, model)
    limit = 0.2 * logodds.SCALE
    assert np.abs(e[:, behind, 0]).max() <= limit
    assert e[0, 60, 0, 0] < -logodds.SCALE             # in front of it: a miss of a 40 dB-class target is free
    assert d[:, behind].max() <= 0.01 * logodds.KNOWLEDGE_SCALE     # and the radar knows nothing behind


def test_tables_for_every_kind_start_at_the_achieved_false_alarm_rate():
    for kind, pfa in (("ca", 8.47e-3), ("go", 5.9e-3), ("so", 2.85e-2), ("os", 8.0e-3)):
        rank = cfar_theory.default_rank(32) if kind == "os" else None
        alpha = cfar_theory.threshold_factor(kind, 1e-3, 32, rank)
        table = sm.DetectionTable.build(kind, alpha, 32, rank, 4.0, 5.0)
        assert table.pfa == pytest.approx(pfa, rel=0.03)
        assert table.delta[0] < 1e-3 and np.all(np.diff(table.delta) >= -1e-9) and table.delta[-1] > 0.99


def test_the_radar_equation():
    """S of a beam-filling -10 dB surface: 25.66 dB at 10 m and 10.10 at 60 m for the simulator's
    50.28 dB sensitivity (the untruncated Gaussian pattern, pi h_az h_el / ln 4: 0.20 dB above the
    issue's 25.46 / 9.90, which integrate the pattern to the simulator's 1.5 half-widths only)."""
    params = sm.ModelParams(50.28, block_gamma_db=-10.0)
    s = sm.block_snr(params, [10.0, 60.0], math.radians(0.5), math.radians(1.0))
    assert 10 * np.log10(s) == pytest.approx([25.660, 10.097], abs=0.002)
    ln_s, kappa = sm.upright_snr(sm.ModelParams(50.28, target_extent_m=0.01), [10.0], math.radians(0.5),
                                 math.radians(1.0))
    assert kappa[0] > 0.99                              # a small patch is a point: the whole pattern applies


def test_parameters_outside_their_physical_range_are_refused():
    with pytest.raises(ConfigError, match=r"sensor_model.target_spread_db = -1.0 is outside its physical range "
                                          r"\[0, 15\] dB"):
        sm.ModelParams(50.0, target_spread_db=-1.0)
    with pytest.raises(ConfigError, match=r"sensor_model.prior_nats = 0.5 is outside its physical range \[-10, 0\]"):
        sm.ModelParams(50.0, prior_nats=0.5)
    with pytest.raises(ConfigError, match=r"sensor_model.blocker_gap = 0.9 is outside its physical range \[0, 0.5\]"):
        sm.ModelParams(50.0, blocker_gap=0.9)
    with pytest.raises(ConfigError, match=r"sensor_model.target_extent_m .* -0.2"):
        keys.check_value("sensor_model.target_extent_m", -0.2)
    with pytest.raises(ConfigError, match=r"sensor_model.look_limit must lie in \[0.5, 10000.0\].*got 0"):
        mapconfig.resolve("paper", flags={"sensor_model.look_limit": 0})


def test_a_profile_without_sensitivity_says_which_figure_and_the_default():
    """A profile that gives no sensitivity says so and what it uses; no built-in Navtech profile
    guesses (each carries a chosen figure and says where it came from); the polar-png template, which
    a new radar's profile extends, gives none, so such a profile is told."""
    for name in ("navtech-cts350x", "radiate-cts350x", "boreas-cir204", "mulran"):
        assert mapconfig.resolve(name).origins["sensor_model.snr_1m2_at_10m_db"].endswith("[sensitivity]")
    assert mapconfig.resolve("polar-png").origins["sensor_model.snr_1m2_at_10m_db"].endswith(
        sensors.missing_sensitivity(sensors.load("polar-png")))
    config = mapconfig.resolve("ti-xwr18xx-uart")
    why = config.origins["sensor_model.snr_1m2_at_10m_db"]
    assert "has no [sensitivity] snr_1m2_at_10m_db" in why and f"using {sm.DEFAULT_SNR_DB:g} dB" in why
    assert "--set sensor_model.snr_1m2_at_10m_db=" in why                 # and how to give it
    assert config["sensor_model.snr_1m2_at_10m_db"] == sm.DEFAULT_SNR_DB   # the default it names is the one used
    assert why.endswith(sensors.missing_sensitivity(config.sensor))
    assert mapconfig.resolve("paper").origins["sensor_model.snr_1m2_at_10m_db"].endswith("[sensitivity]")


def test_the_reading():
    e = np.array([8 * logodds.SCALE, -8 * logodds.SCALE, 0, 3 * logodds.SCALE, -logodds.SCALE])
    k = np.array([16, 2, 0, 1, 0.25]) * logodds.KNOWLEDGE_SCALE
    n = np.array([16, 2, 0, 1, 100])                  # the last: 100 looks of a voxel a blocker hides
    reading = dict(look_limit=4.0, prior_nats=0.0, prior_looks=0.5)
    assert np.allclose(sm.read_log_odds(e, k, n, reading), [2.0, -8.0, 0.0, 3.0, -0.04])   # 16 looks count as 4
    reading["prior_nats"] = -2.0
    assert np.allclose(sm.read_log_odds(e, k, n, reading), [0.0, -10.0, 0.0, 1.0, -1.04])  # never observed: still 0
    reading["prior_looks"] = 0.0          # the default: the prior everywhere, never observed reads the base rate
    assert np.allclose(sm.read_log_odds(e, k, n, reading), [0.0, -10.0, -2.0, 1.0, -2.04])
    reading["known_looks"] = sm.KNOWN_LOOKS   # the default: less knowledge than that reads the prior alone
    assert np.allclose(sm.read_log_odds(e, k, n, reading), [0.0, -10.0, -2.0, 1.0, -2.0])
    assert sm.ModelParams().reading["known_looks"] == sm.KNOWN_LOOKS


def test_the_default_reading_puts_the_prior_everywhere_and_an_old_map_reads_as_it_did():
    """The default reading: the prior is the base rate, everywhere (prior_looks 0), so a voxel never
    observed reads it; a map saved by the last release (prior_looks 0.5, prior 0) reads 0 there."""
    default = sm.ModelParams().reading
    assert default["prior_looks"] == 0.0 and default["prior_nats"] < 0
    never = sm.read_log_odds(0, 0, 0, default)
    assert never == pytest.approx(default["prior_nats"])
    assert sm.read_log_odds(0, 0, 0, dict(look_limit=4.0, prior_nats=0.0, prior_looks=0.5)) == 0.0
    with pytest.raises(ConfigError, match=r"sensor_model.prior_looks = -1 is outside its physical range \[0, 100\]"):
        sm.ModelParams(prior_looks=-1)


def test_node_packing_round_trips_and_interpolates():
    rng = np.random.default_rng(0)
    e = rng.integers(-logodds.EVIDENCE_LIMIT, logodds.EVIDENCE_LIMIT + 1, (7, node_pairs.N_CLASSES, node_pairs.NODES))
    d = rng.integers(0, logodds.KNOWLEDGE_SCALE + 1, e.shape)
    packed = node_pairs.pack_nodes(e, d)
    assert packed.shape == (7, *node_pairs.node_shape()) and packed.dtype == np.int32
    back = node_pairs.unpack_nodes(packed)
    assert np.array_equal(back[0], e) and np.array_equal(back[1], d)
    q = np.array([0, 4096, 2048, node_pairs.Q_ONE, node_pairs.Q_MAX])
    assert np.array_equal(node_pairs.node_lerp(np.array([[0, 100, 200, 300, 400]] * 5), q), [0, 100, 50, 400, 400])
    # the beam's edge and beyond quantise into the last segment, within 1 unit of the last node
    assert np.array_equal(node_pairs.quantised_rho2([0.0, 0.25, 1.0 - 2 ** -15, 1.0, 2.0]), [0, 4096, 16383, 16383, 16383])
    with pytest.raises(ConfigError, match="node values out of range"):
        node_pairs.pack_nodes(e + logodds.EVIDENCE_LIMIT, d)


def test_a_pipeline_without_a_terrain_class_keeps_the_upright_class_alone():
    """node_shape: one class or both; all_classes puts a dropped class back as the 0 it is;
    kept_classes refuses an oracle whose dropped class is not all 0 (the premise of dropping it)."""
    assert node_pairs.node_shape(1) == (1, node_pairs.SEGMENTS, 2) and node_pairs.node_shape() == node_pairs.node_shape(2) == (2, node_pairs.SEGMENTS, 2)
    with pytest.raises(ConfigError, match="classes must be 1 or 2, got 3"):
        node_pairs.node_shape(3)
    rng = np.random.default_rng(1)
    e = rng.integers(-100, 100, (3, 4, node_pairs.N_CLASSES, node_pairs.NODES))
    e[..., 1, :] = 0
    kept = node_pairs.kept_classes(e, 1)
    assert kept.shape == (3, 4, 1, node_pairs.NODES) and np.array_equal(kept[..., 0, :], e[..., 0, :])
    assert np.array_equal(node_pairs.all_classes(kept), e) and np.array_equal(node_pairs.kept_classes(e, 2), e)
    e[2, 1, 1, 4] = -1
    with pytest.raises(ValueError, match=r"a dropped class has 1 nonzero nodes \(up to 1\)"):
        node_pairs.kept_classes(e, 1)
    packed = node_pairs.pack_nodes(kept, np.abs(kept))
    assert packed.shape == (3, 4, *node_pairs.node_shape(1))


def test_a_false_alarm_rate_that_leaves_pd_outside_pfa_to_1_is_refused():
    """A measured false-alarm rate at or above the best P_d of the typical target would make
    every look worthless: refused naming the key, the value and the range of P_d."""
    args = (CA, 256, SPACING, 4.0, math.radians(0.5), math.radians(1.0), 0.2, 1.0)     # read from 1 m
    weak = dict(snr_1m2_at_10m_db=0.0, target_gamma_db=-40.0, target_extent_m=0.01)
    with pytest.raises(ConfigError, match=r"sensor_model.false_alarm = 0.3 leaves P_d outside \(P_fa, 1\): the typical "
                                          r"target's P_d is at most 0\.\d+ .* expected a false-alarm rate in \[0, "):
        sm.BinModel.build(sm.ModelParams(false_alarm=0.3, **weak), *args)
    ok = sm.BinModel.build(sm.ModelParams(false_alarm=0.05), *args)     # the simulator's sensitivity: P_d reaches ~1
    assert ok.pfa == 0.05 and ok.opportunity.max() > 0.9


# -- "snr" evidence: the measured power's likelihood ratio ------------------------------------------------------------
Q_CORR = 8.4711e-3
SNR_HAND = {  # (x, s): e [nat]
    (1.0, 100.0): -3.616742, (1.0, 25.0): -2.288910,
    (5.0, 100.0): 0.332005, (5.0, 25.0): 1.518655,
    (50.0, 100.0): 4.771095, (50.0, 25.0): 4.771095,
}
# The table is read bilinearly: against its own quadrature (se.snr_evidence) it is within
# SNR_TABLE_P99_NATS at 99 % of random points and within SNR_TABLE_MAX_NATS everywhere a target
# lies no more than 43 dB under the noise (v >= -10); below that, where a huge echo meets a target
# the log-normal prior's far tail alone could make bright, the transition in v is too steep for
# the grid (measured: up to 0.57 nat, on 0.5 % of the points).
SNR_TABLE_P99_NATS = 0.01
SNR_TABLE_MAX_NATS = 0.12


def test_snr_evidence_hand_values():
    """The quadrature (no spread) and the table (within SNR_TABLE_MAX_NATS of it) against the
    hand values of the module docstring: a point target on the axis and at the half-power edge."""
    table = se.SnrTable.build(0.0, Q_CORR)
    for (x, s), e in SNR_HAND.items():
        assert se.snr_evidence(x, math.log(s), 0.0, Q_CORR) == pytest.approx(e, abs=1e-6)
        assert table(math.log(x), math.log(s)) == pytest.approx(e, abs=SNR_TABLE_MAX_NATS)
    # no-detection evidence (a noise-like bin) is weaker at the beam edge than on the axis
    assert SNR_HAND[(1.0, 100.0)] < SNR_HAND[(1.0, 25.0)] < 0


@pytest.mark.parametrize("spread_db", [0.0, 7.0, 10.0])
def test_the_snr_table_against_its_quadrature(spread_db):
    rng = np.random.default_rng(int(spread_db))
    u = rng.uniform(se.SNR_U[0], se.SNR_U[1], 20000)
    v = rng.uniform(se.SNR_V[0], se.SNR_V[1], 20000)
    table = se.SnrTable.build(spread_db, Q_CORR)
    err = np.abs(table(u, v) - se.snr_evidence(np.exp(u), v, spread_db, Q_CORR))
    assert np.quantile(err, 0.99) <= SNR_TABLE_P99_NATS
    assert err[v >= -10.0].max() <= SNR_TABLE_MAX_NATS
    assert np.all(table.values[:, 0] == 0.0) and table.values.max() <= -math.log(Q_CORR) + 1e-9   # bounded by ln(1 / q)
    # monotone in the measured power: a stronger echo is never less evidence of a target
    assert np.all(np.diff(table.values, axis=0) >= -1e-9)


def test_clutter_explains_an_echo_a_weak_target_could_not_give():
    """With a background that holds clutter (a fifth of the bins, 15 dB median, 10 dB spread), a
    bright bin where the typical target is weak is explained by the background (about 0 nat; noise
    alone calls it the most a look says), a bright bin where the target is strong is still
    evidence of it, and a noise-like bin is still free evidence. The table holds to its quadrature."""
    clutter = se.Clutter(0.2, 15.0, 10.0)
    weak, strong = math.log(0.1), math.log(1e4)                     # -10 dB and 40 dB targets
    assert se.snr_evidence(1e3, weak, 0.0, Q_CORR) == pytest.approx(-math.log(Q_CORR), abs=0.01)
    assert abs(se.snr_evidence(1e3, weak, 7.0, Q_CORR, clutter)) < 0.02
    assert se.snr_evidence(1e4, strong, 7.0, Q_CORR, clutter) > 2.0
    assert se.snr_evidence(1.0, math.log(100.0), 7.0, Q_CORR, clutter) < -2.0
    # the background law is a density: it integrates to 1 over x (trapezoid on a log grid)
    u = np.linspace(-12.0, 14.0, 20001)
    x = np.exp(u)
    assert np.trapezoid(np.exp(clutter.ln_density(x)) * x, u) == pytest.approx(1.0, abs=1e-3)
    table = se.SnrTable.build(7.0, Q_CORR, clutter)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(*se.SNR_U[:2], 5000), rng.uniform(-10.0, se.SNR_V[1], 5000)
    err = np.abs(table(u, v) - se.snr_evidence(np.exp(u), v, 7.0, Q_CORR, clutter))
    assert np.quantile(err, 0.99) <= SNR_TABLE_P99_NATS and err.max() <= SNR_TABLE_MAX_NATS
    with pytest.raises(ConfigError, match=r"sensor_model.clutter_share = 1 is outside its physical range"):
        sm.ModelParams(clutter_share=1)
    with pytest.raises(ConfigError, match="sensor_model.evidence_bound = 'soft': expected one of detection, none"):
        sm.ModelParams(evidence_bound="soft")


def snr_beams(profiles, noise_floor_power=1.0):
    """profiles (beams, bins) with every bin not set by the caller at the noise floor: the floor
    (median / ln 2) comes out at ``noise_floor_power``."""
    return np.where(np.isnan(profiles), noise_floor_power * math.log(2.0), profiles)


def test_snr_evidence_of_a_point_target_through_the_oracle():
    """A BinModel whose bin holds a 20 dB point target (no spread, nothing blocks): beam 0 measures
    x = 1 there, beam 1 x = 5 (under any CFAR threshold: no detection), beam 2 x = 50 (detected);
    the oracle's nodes at rho2 = 0 and 1 are the hand values."""
    n_bins, at = 64, 30
    t = np.arange(node_pairs.NODES) / (node_pairs.NODES - 1)
    ln_snr = np.full((n_bins, node_pairs.N_CLASSES, node_pairs.NODES), -np.inf)
    ln_snr[at, 0] = math.log(100.0) - t * math.log(4.0)
    opportunity = np.zeros(ln_snr.shape)
    opportunity[at, 0] = 1.0                          # the look sees the target (no evidence without)
    model = sm.BinModel(opportunity, 1.0 - opportunity, np.zeros(n_bins), Q_CORR, ln_snr,
                        se.SnrTable.build(0.0, Q_CORR))
    profiles = snr_beams(np.full((3, n_bins), np.nan))
    profiles[:, at] = np.array([1.0, 5.0, 50.0]) * math.log(2.0) / math.log(2.0)
    mask = np.zeros((3, n_bins), bool)
    mask[2, at] = True
    cfg = InterpretConfig(range_min_m=0.0, range_max_m=7.0, wide_pulse_m=1.0)
    e, d, *_ = oracle.interpret_detstats(profiles, np.ones((3, n_bins)), mask, cfg, SPACING, model)
    for beam, x in enumerate((1.0, 5.0, 50.0)):
        for node, s in ((0, 100.0), (node_pairs.NODES - 1, 25.0)):
            assert abs(e[beam, at, 0, node] - SNR_HAND[(x, s)] * logodds.SCALE) <= SNR_TABLE_MAX_NATS * logodds.SCALE
    assert not e[:, at, 1].any()                       # no terrain class without a ground plane: nothing
    assert np.all(np.diff(e[0, at, 0]) > 0)            # a noise-like bin: weaker free evidence towards the edge


def test_snr_evidence_behind_a_strong_echo_stays_unknown():
    """A 50 dB pulse at 10 m blocks the beam: behind it a 40 dB typical target gets evidence within
    +-0.2 nat of 0 whether its bin measures noise or a 15 dB echo, and no knowledge; in front of it a
    noise-like bin is free evidence."""
    params = sm.ModelParams(50.28)
    n_bins = 512
    model = sm.BinModel.build(params, CA, n_bins, SPACING, 4.0, math.radians(0.5), math.radians(1.0), 0.2)
    assert model.graded
    ln_snr = np.array(model.ln_snr)
    behind = 120                                       # 15 m
    ln_snr[behind, 0] = math.log(1e4)                  # 40 dB
    model = sm.BinModel(model.opportunity, model.miss, model.blocking, model.pfa, ln_snr, model.snr_table)
    profiles = snr_beams(np.full((2, n_bins), np.nan))
    mask = np.zeros((2, n_bins), bool)
    peak = 80                                          # 10 m
    psf = 10.0 ** (5.028 - np.abs(np.arange(-3, 4)) ** 2 / 6)   # a pulse of 7 bins, 50 dB at its peak
    profiles[:, peak - 3:peak + 4] += psf
    mask[:, peak - 3:peak + 4] = True
    profiles[1, behind] = 30.0 * math.log(2.0)         # beam 1: 15 dB over the floor behind the echo
    mask[1, behind] = True
    cfg = InterpretConfig(range_min_m=1.0, range_max_m=60.0, wide_pulse_m=1.0)
    e, d, *_ = oracle.interpret_detstats(profiles, np.ones((2, n_bins)), mask, cfg, SPACING, model)
    assert np.abs(e[:, behind, 0]).max() <= 0.2 * logodds.SCALE
    assert d[:, behind].max() <= 0.01 * logodds.KNOWLEDGE_SCALE
    assert e[0, 60, 0, 0] < -logodds.SCALE             # in front of it: a noise-like bin is free


def test_the_noise_floor_is_the_median_over_ln2():
    r = np.arange(1.0, 12.0)[None, :] * np.ones((2, 1))
    assert se.noise_floor(r, 2, 8) == pytest.approx([6.0 / math.log(2.0)] * 2)       # bins 3..9: the 4th smallest
    assert se.noise_floor(np.zeros((1, 9)), 0, 8, floor=1e-30)[0] == 1e-30
    with pytest.raises(ConfigError, match="sensor_model.evidence = 'cfar': expected one of snr, detection"):
        sm.ModelParams(evidence="cfar")
    with pytest.raises(ConfigError, match="sensor_model.evidence"):
        mapconfig.resolve("paper", flags={"sensor_model.evidence": "binary"})


def test_a_default_prior_is_the_base_rate_at_the_grids_voxel(tmp_path):
    """Surfaces fill a share of space in proportion to the voxel's edge: a default prior (fitted at
    PRIOR_VOXEL_M) is moved by ln(voxel / PRIOR_VOXEL_M), the profile's as radarcl's; a prior the
    user gives is kept; changing the voxel again starts from the default, not the moved value."""
    base = sm.DEFAULTS["prior_nats"]
    at = {v: mapconfig.resolve("paper", flags={"grid.voxel_m": v}) for v in (0.1, 0.2, 0.4)}
    assert at[0.2]["sensor_model.prior_nats"] == pytest.approx(base)
    assert at[0.4]["sensor_model.prior_nats"] == pytest.approx(base + math.log(2.0))
    assert at[0.1]["sensor_model.prior_nats"] == pytest.approx(base - math.log(2.0))
    assert "ln(0.4 / 0.2)" in at[0.4].origins["sensor_model.prior_nats"]
    again = at[0.4].replaced(grid__voxel_m=0.1).replaced(grid__voxel_m=0.4)
    assert again["sensor_model.prior_nats"] == pytest.approx(base + math.log(2.0))
    spinning = mapconfig.resolve("spinning-sim", flags={"grid.voxel_m": 0.4})
    assert spinning["sensor_model.prior_nats"] == pytest.approx(-5.0 + math.log(2.0))
    given = mapconfig.resolve("paper", flags={"grid.voxel_m": 0.4, "sensor_model.prior_nats": -3.0})
    assert given["sensor_model.prior_nats"] == -3.0 and given.origins["sensor_model.prior_nats"] == "flag"
    assert given.model_params().reading["prior_nats"] == -3.0
    assert at[0.4].model_params().reading["prior_nats"] == pytest.approx(base + math.log(2.0))
    # a saved configuration leaves the default prior out (and says so), so it follows the voxel it is used at
    at[0.1].save(tmp_path / "c.toml")
    text = (tmp_path / "c.toml").read_text()
    assert "prior_nats is left out" in text and "\nprior_nats =" not in text
    back = mapconfig.resolve(path=tmp_path / "c.toml", flags={"grid.voxel_m": 0.4})
    assert back["sensor_model.prior_nats"] == pytest.approx(base + math.log(2.0))
    assert mapconfig.resolve(path=tmp_path / "c.toml").values == at[0.1].values          # the round trip holds
    given.save(tmp_path / "g.toml")                                                      # a given prior is written
    assert mapconfig.resolve(path=tmp_path / "g.toml", flags={"grid.voxel_m": 0.1})["sensor_model.prior_nats"] == -3.0


def test_the_reading_fit_takes_the_best_reading_that_meets_the_goals():
    """``detstats_fit.fit_reading``: the best pooled likelihood of the visible voxels, or, with a
    constraint, the best of the readings that meet it, tried in order of likelihood."""
    from radarcl.evaluation import detstats_fit as fit

    rng = np.random.default_rng(3)
    y = rng.random(4000) < 0.04                                      # 4 % occupied, as the scenes' visible voxels
    n = rng.integers(1, 12, y.size).astype(float)
    e = np.where(y, rng.normal(3.0, 2.0, y.size), rng.normal(-1.5, 1.0, y.size)) * n
    k = n.copy()
    best, ll, _ = fit.fit_reading([(e, k, n, y)])
    tried = []

    def meets(reading):
        tried.append(reading)
        return reading["look_limit"] >= 4.0 and reading["prior_nats"] >= -3.0

    chosen, ll_chosen, _ = fit.fit_reading([(e, k, n, y)], meets)
    assert chosen["look_limit"] >= 4.0 and chosen["prior_nats"] >= -3.0 and ll_chosen <= ll
    assert tried[-1] == chosen and all(not meets(r) for r in tried[:-1])
    every = [dict(look_limit=a, prior_nats=b, prior_looks=c) for a, b, c in
             itertools.product(*fit.READING_GRID.values()) if b != 0.0 or c == fit.READING_GRID["prior_looks"][0]]
    better = [r for r in every if meets(r) and fit.log_likelihood(e, k, n, y, r) > ll_chosen + 1e-12]
    assert not better and (best == chosen) == meets(best)
    assert fit.fit_reading([(e, k, n, y)], lambda r: False) is None
