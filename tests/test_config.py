"""Paper §2 physics and the validated radar configuration."""

import math

import numpy as np
import pytest

from radarcl import physics
from radarcl.config.stage_config import PAPER_RADAR, RadarConfig
from radarcl.errors import ConfigError


def test_paper_radar_figures():
    r = PAPER_RADAR
    assert r.wavelength_m == pytest.approx(3.893e-3, rel=1e-3)          # "~3.9 mm", §2.3
    assert r.range_resolution_m == pytest.approx(0.5, rel=1e-3)          # eq. 7 with 300 MHz
    assert r.bin_spacing_m(256) == pytest.approx(r.range_resolution_m)   # no padding: one cell
    assert r.bin_spacing_m(512) == pytest.approx(r.range_resolution_m / 2)
    assert r.n_bins(1024) == 512                                         # "512 range bins", §3.3
    assert r.max_beat_frequency_hz == pytest.approx(500e3, rel=1e-3)     # eq. 10 at 64 m
    assert r.aperture_az_m == pytest.approx(0.2275, rel=1e-3)            # eq. 1 (paper: 224 mm)
    assert r.far_field_m == pytest.approx(13.3, rel=1e-2)                # eq. 2 (paper: ~13.6 m)
    assert r.frame_shape == (64, 4, 256) and r.n_beams == 256


def test_equations_are_consistent():
    b, t = 300e6, 256e-6
    f = physics.beat_frequency(10.0, b, t)
    assert physics.range_of_beat_frequency(f, b, t) == pytest.approx(10.0)
    lam = physics.wavelength(77e9)
    d = physics.aperture_for_beamwidth(lam, math.radians(1.0))
    assert physics.beamwidth(lam, d) == pytest.approx(math.radians(1.0))
    assert physics.far_field_distance(d, lam) == pytest.approx(d * d / lam)
    assert physics.bin_spacing(b, t, 1e6, 256) == pytest.approx(physics.range_resolution(b))


@pytest.mark.parametrize("kwargs,match", [
    (dict(range_max_m=100.0), "above the Nyquist limit"),
    (dict(n_samples=300), "longer than the 256.0 us sweep"),
    (dict(range_min_m=70.0), "range_min_m < range_max_m"),
    (dict(bandwidth_hz=-1.0), "bandwidth_hz must be a positive finite number"),
    (dict(carrier_hz=float("nan")), "carrier_hz must be a positive finite number"),
    (dict(n_azimuth=0), "n_azimuth must be a positive integer"),
    (dict(n_samples=2.5), "n_samples must be a positive integer"),
    (dict(beamwidth_el_deg=200.0), "below 180 deg"),
    (dict(complex_samples="yes"), "complex_samples must be True or False"),
])
def test_impossible_configurations_are_refused(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        RadarConfig(**kwargs)


def test_config_is_frozen():
    with pytest.raises(AttributeError):
        PAPER_RADAR.n_samples = 512


def test_complex_sampling_doubles_the_unambiguous_range():
    iq = RadarConfig(complex_samples=True, range_max_m=120.0)
    assert iq.unambiguous_range_m == pytest.approx(2 * PAPER_RADAR.unambiguous_range_m)
    assert iq.n_bins(512) == 512


@pytest.mark.parametrize("n_fft", [100, 128, 0])
def test_bad_fft_lengths(n_fft):
    with pytest.raises(ConfigError, match="n_fft"):
        PAPER_RADAR.n_bins(n_fft)


def test_bin_ranges():
    r = PAPER_RADAR.bin_ranges_m(512)
    assert r.shape == (256,) and r[0] == 0.0
    np.testing.assert_allclose(np.diff(r), PAPER_RADAR.bin_spacing_m(512))
