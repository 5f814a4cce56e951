"""CFAR calibration on simulated noise: the measured false-alarm rate is the design P_fa within
+-10 %, and a Swerling 1 target is detected as often as theory says (radarcl.cfar_theory).

Statistics. Noise is independent exponential power (a square-law detector in Gaussian noise),
8192 beams x 512 bins = 4.19 M decisions per case. Decisions in one beam share training cells,
so the standard error is measured from the spread of the per-beam rates across the independent
beams rather than assumed binomial; each test first asserts that its +-10 % bound is at least
4 of those standard errors wide (a correct detector fails by chance less than once in 15,000
runs), then that the measured rate lies inside it. Seeds are fixed: the outcome is reproducible.
"""

import numpy as np
import pytest

from radarcl import cfar_theory
from radarcl.config.stage_config import CfarConfig
from radarcl.stages.cfar import Cfar

N_BEAMS, N_BINS = 8192, 512
Z = 4.0          # standard errors the +-10 % bound must span


@pytest.fixture(scope="module")
def noise():
    return np.random.default_rng(2026).exponential(size=(N_BEAMS, N_BINS)).astype(np.float32)


CONFIGS = [CfarConfig(kind=k, guard=2, train=8, pfa=p) for k in cfar_theory.CFAR_KINDS for p in (1e-2, 1e-3)]
CONFIGS += [CfarConfig(pfa=1e-2), CfarConfig(pfa=1e-3)]   # the paper's defaults: CA, 16 + 16 cells


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: f"{c.kind}-t{c.train}-pfa{c.pfa:g}")
def test_false_alarm_rate_within_10_percent(runtime, noise, config):
    mask = Cfar(runtime, (N_BEAMS,), N_BINS, config)(noise).mask
    per_beam = mask.mean(axis=1)
    measured = per_beam.mean()
    standard_error = per_beam.std(ddof=1) / np.sqrt(N_BEAMS)
    print(f"{config.kind} train {config.train} pfa {config.pfa:g}: measured {measured:.5g} "
          f"(+-{standard_error:.2g}), {mask.sum()} false alarms in {mask.size} cells")
    assert 0.1 * config.pfa >= Z * standard_error, "too few trials for a sound +-10 % bound"
    assert abs(measured - config.pfa) <= 0.1 * config.pfa


def test_edge_bins_keep_the_design_rate(runtime, noise):
    """The shift edge rule gives the same statistics at the ends: the first and last
    guard + train bins of every profile alarm at the design rate too (+-20 %, 4 SE)."""
    config = CfarConfig(guard=2, train=8, pfa=1e-2)
    mask = Cfar(runtime, (N_BEAMS,), N_BINS, config)(noise).mask
    edge = np.r_[0:10, N_BINS - 10:N_BINS]
    per_beam = mask[:, edge].mean(axis=1)
    standard_error = per_beam.std(ddof=1) / np.sqrt(N_BEAMS)
    assert 0.2 * config.pfa >= Z * standard_error
    assert abs(per_beam.mean() - config.pfa) <= 0.2 * config.pfa


SNR_DB = (0.0, 6.0, 10.0, 13.0, 16.0, 20.0)


@pytest.mark.parametrize("kind", cfar_theory.CFAR_KINDS)
def test_swerling1_detection_probability(runtime, noise, kind):
    """A Swerling 1 target (exponential power of mean 1 + SNR) every 32 bins, 16 per beam, so
    no target lies in another's window (guard 2 + train 8). 131,072 trials per SNR;
    P_d = P_fa(alpha / (1 + SNR)), for CA (1 + alpha / (N (1 + SNR)))^-N. Trials are
    independent (disjoint windows), so the binomial standard error holds; bound: 4.4 SE
    (two-sided 1e-5 per comparison, 24 comparisons)."""
    config = CfarConfig(kind=kind, guard=2, train=8, pfa=1e-3)
    plan = Cfar(runtime, (N_BEAMS,), N_BINS, config)
    rng = np.random.default_rng(7)
    bins = np.arange(16, N_BINS, 32)
    for snr_db in SNR_DB:
        snr = 10 ** (snr_db / 10)
        x = noise.copy()
        x[:, bins] = rng.exponential(1 + snr, size=(N_BEAMS, len(bins)))
        detected = plan(x).mask[:, bins]
        want = cfar_theory.detection_probability_swerling1(kind, config.alpha, config.n_train, snr, config.rank)
        got = detected.mean()
        se = np.sqrt(want * (1 - want) / detected.size)
        print(f"{kind} SNR {snr_db:4.1f} dB: P_d measured {got:.4f}, theory {want:.4f} (+-{se:.4f})")
        assert abs(got - want) <= 4.4 * se + 1.0 / detected.size
