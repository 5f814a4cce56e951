"""The FMCW simulator (eq. 3-6): tones where eq. 6a puts them, noise, ADC, reproducibility."""

import numpy as np
import pytest

from radarcl import oracle
from radarcl.config.stage_config import PAPER_RADAR, RadarConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.scene.fmcw import Adc, PointTarget, beat_signal, simulate_beams, simulate_frame


def test_tone_lands_at_its_range():
    for r in (3.0, 17.25, 40.0, 63.0):
        x = beat_signal(PAPER_RADAR, [1.0], [r])
        p = oracle.range_profile(x, 4096)
        assert PAPER_RADAR.bin_ranges_m(4096)[np.argmax(p)] == pytest.approx(r, abs=PAPER_RADAR.bin_spacing_m(4096))


def test_amplitude_is_calibrated():
    # A real tone of amplitude a on a bin centre reads a / 2 after the calibrated range FFT.
    r = 20 * PAPER_RADAR.bin_spacing_m(256)
    p = oracle.range_profile(beat_signal(PAPER_RADAR, [0.8], [r]), 256)
    assert p.max() == pytest.approx(0.4, rel=1e-6)


def test_complex_tone_has_positive_frequency_only():
    iq = RadarConfig(complex_samples=True)
    p = oracle.range_profile(beat_signal(iq, [1.0], [30 * iq.bin_spacing_m(256)]), 256)
    assert np.argmax(p) == 30 and p.max() == pytest.approx(1.0, rel=1e-6)


def test_blocks_of_beams_change_no_bit(monkeypatch):
    """beat_signal sums each beam's tones a block of beams at a time (memory); the sum per beam
    runs over its own targets in the same order whatever the block, so any block size gives
    the same bits, real or I/Q, any leading shape, none or many targets."""
    from radarcl.scene import fmcw

    rng = np.random.default_rng(1)
    for config in (PAPER_RADAR, RadarConfig(complex_samples=True)):
        for shape in ((5, 4, 3), (9, 1), (4, 0)):
            a, r, p = rng.random(shape), rng.random(shape) * 60.0, rng.random(shape)
            whole = fmcw.beat_signal(config, a, r, p)
            monkeypatch.setattr(fmcw, "CHUNK_BYTES", 1)           # one beam per block
            assert whole.shape == shape[:-1] + (config.n_samples,)
            assert np.array_equal(fmcw.beat_signal(config, a, r, p), whole)
            monkeypatch.undo()


def test_seeded_noise_is_reproducible_and_has_its_rms():
    a = simulate_beams(PAPER_RADAR, np.zeros((64, 4, 1)), np.zeros((64, 4, 1)), noise_rms=0.01, seed=4)
    b = simulate_beams(PAPER_RADAR, np.zeros((64, 4, 1)), np.zeros((64, 4, 1)), noise_rms=0.01, seed=4)
    assert np.array_equal(a.samples, b.samples)
    assert a.samples.std() == pytest.approx(0.01, rel=0.02)   # 65536 samples: 1 % standard error


def test_adc_quantises_and_counts_clipping():
    adc = Adc(bits=12, full_scale=1.0)
    codes, n = adc.quantise(np.array([0.0, 0.5, -1.0, 1.0, 3.0, -3.0]))
    assert codes.dtype == np.int16
    assert codes.tolist() == [0, 1024, -2048, 2047, 2047, -2048]
    assert n == 3   # +1.0 rounds to 2048 > 2047, and the two beyond full scale
    assert adc.clip_level == 2047


def test_frame_from_point_targets():
    adc = Adc(bits=16, full_scale=4.0)
    frame = simulate_frame(PAPER_RADAR, [PointTarget(10, 2, 12.0, 1.0), PointTarget(10, 2, 30.0, 0.5)],
                           noise_rms=1e-3, adc=adc, seed=1)
    assert frame.samples.shape == (64, 4, 256) and frame.samples.dtype == np.int16
    assert frame.n_clipped == 0
    p = oracle.range_profile(frame.samples, 1024)
    axis = PAPER_RADAR.bin_ranges_m(1024)
    assert axis[np.argmax(p[10, 2])] == pytest.approx(12.0, abs=0.2)
    assert p[10, 2].max() > 100 * p[0, 0].max()   # an empty beam holds only noise


def test_bad_targets_are_refused():
    with pytest.raises(ShapeError, match="outside the 64 x 4 beam lattice"):
        simulate_frame(PAPER_RADAR, [PointTarget(64, 0, 5.0, 1.0)])
    with pytest.raises(ConfigError, match="ranges must be >= 0"):
        beat_signal(PAPER_RADAR, [1.0], [-1.0])
    with pytest.raises(ConfigError, match="finite"):
        beat_signal(PAPER_RADAR, [np.nan], [1.0])
    with pytest.raises(ConfigError, match="Adc.bits"):
        Adc(bits=24)
    with pytest.raises(ConfigError, match="noise_rms"):
        simulate_beams(PAPER_RADAR, [1.0], [1.0], noise_rms=-1.0)
