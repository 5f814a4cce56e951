"""Detection theory (radarcl.cfar_theory), the wide-pulse geometry (radarcl.physics) and the
fixed-point log-odds unit (radarcl.logodds)."""

import math

import numpy as np
import pytest

from radarcl import cfar_theory, logodds, physics
from radarcl.config.stage_config import PAPER_WIDE_PULSE_M, CfarConfig, InterpretConfig
from radarcl.errors import ConfigError


@pytest.mark.parametrize("kind", cfar_theory.CFAR_KINDS)
@pytest.mark.parametrize("pfa", [1e-1, 1e-3, 1e-6])
@pytest.mark.parametrize("n", [2, 16, 32])
def test_threshold_factor_inverts_pfa(kind, pfa, n):
    """Every detector reaches every pfa in (0, 1): at factor 0 it alarms on every cell (P_fa = 1)."""
    rank = cfar_theory.default_rank(n) if kind == "os" else None
    alpha = cfar_theory.threshold_factor(kind, pfa, n, rank)
    assert alpha > 0
    assert math.isclose(cfar_theory.false_alarm_probability(kind, alpha, n, rank), pfa, rel_tol=1e-9)


def test_a_pfa_no_factor_reaches_is_refused():
    """P_fa at factor 0 is 1 in exact arithmetic; SO's series sums a few ulp below 1 in float64
    (22 cells a side: 1 - 3.2e-15), and a pfa in that gap is refused, not answered with a factor
    whose P_fa is another. Beyond the far end, a pfa no finite factor reaches is refused too."""
    at_zero = cfar_theory.false_alarm_probability("so", 0.0, 44)
    assert 1 - 1e-13 < at_zero < 1.0
    with pytest.raises(ConfigError, match=r"cannot reach pfa = 0\.99999"):
        cfar_theory.threshold_factor("so", 0.5 * (at_zero + 1.0), 44)
    assert cfar_theory.threshold_factor("so", at_zero * (1 - 1e-9), 44) > 0
    with pytest.raises(ConfigError, match="no finite threshold factor reaches pfa = 1e-300"):
        cfar_theory.threshold_factor("os", 1e-300, 2, 1)     # P_fa = 2 / (2 + a) >= 2e-300 for a <= 1e300


def test_ca_closed_form_and_textbook_pd():
    n, pfa = 16, 1e-3
    alpha = cfar_theory.threshold_factor("ca", pfa, n)
    assert math.isclose(alpha, n * (pfa ** (-1 / n) - 1))
    snr = 10 ** 1.3
    want = (1 + alpha / (n * (1 + snr))) ** -n
    assert math.isclose(cfar_theory.detection_probability_swerling1("ca", alpha, n, snr), want)


def test_go_and_so_split_two_one_sided_detectors():
    """P_go + P_so = P(left alone) + P(right alone): an identity of the order statistics."""
    m, t = 8, 0.9
    total = cfar_theory.false_alarm_probability("go", t * m, 2 * m) + cfar_theory.false_alarm_probability("so", t * m, 2 * m)
    assert math.isclose(total, 2 * (1 + t) ** -m)


def test_refuses_impossible_detectors():
    with pytest.raises(ConfigError, match="strictly between 0 and 1"):
        cfar_theory.threshold_factor("ca", 1.0, 16)
    with pytest.raises(ConfigError, match="even integer"):
        cfar_theory.threshold_factor("go", 1e-3, 7)
    with pytest.raises(ConfigError, match="rank must be an integer in"):
        cfar_theory.threshold_factor("os", 1e-3, 16, 0)
    with pytest.raises(ConfigError, match="snr must be >= 0"):
        cfar_theory.detection_probability_swerling1("ca", 5.0, 16, -1.0)


def test_wide_pulse_rule_from_geometry():
    h, beam = 1.5, math.radians(2.0)
    extent = physics.ground_echo_extent(h, math.radians(-14.0), beam)
    assert math.isclose(extent, h / math.sin(math.radians(13)) - h / math.sin(math.radians(15)))
    assert math.isclose(PAPER_WIDE_PULSE_M, extent + 2.0 * physics.range_resolution(300e6))
    assert physics.ground_echo_extent(h, math.radians(-0.5), beam) == math.inf   # grazing: no end
    # steeper beams light shorter stretches of ground
    assert physics.ground_echo_extent(h, math.radians(-30), beam) < extent
    with pytest.raises(ConfigError, match="point at the ground"):
        physics.ground_echo_extent(h, math.radians(5.0), beam)
    assert InterpretConfig().wide_bins(0.125) == 15


def test_logodds_fixed_point():
    assert logodds.to_fixed(1.0) == 1024 and logodds.to_fixed(-0.1) == -102
    assert logodds.to_fixed(0.5 / 1024) == 0 and logodds.to_fixed(1.5 / 1024) == 2   # ties to even
    assert logodds.to_fixed(np.inf) == logodds.EVIDENCE_LIMIT
    assert logodds.to_fixed(-1e9) == -logodds.EVIDENCE_LIMIT
    assert abs(logodds.probability(logodds.from_probability(0.7)) - 0.7) < 1e-3
    with pytest.raises(ConfigError):
        logodds.to_fixed(np.nan)
    with pytest.raises(ConfigError):
        logodds.from_probability(1.0)
    # a frame of updates cannot approach the int32 range
    assert 256 * logodds.EVIDENCE_LIMIT < 2 ** 31 / 100


def test_cfar_config_derived_values():
    c = CfarConfig()
    assert c.n_train == 32 and c.window == 65
    assert math.isclose(c.alpha, 32 * (1e-3 ** (-1 / 32) - 1))
    assert CfarConfig(kind="os", train=8).rank == 12
