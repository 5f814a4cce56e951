"""kernels/range_fft.cl <-> radarcl/stages/range_fft.py against radarcl.oracle.range_profile."""

import numpy as np
import pytest
from tolerances import RANGE_FFT_RTOL, WEAK_TONE_RTOL

from radarcl import oracle
from radarcl.errors import ConfigError, ShapeError
from radarcl.stages.range_fft import RangeFFT


def make_samples(rng, shape, dtype):
    if dtype == np.complex64:
        return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64) * 100
    if dtype == np.int16:
        return rng.integers(-3000, 3000, shape).astype(np.int16)
    return rng.standard_normal(shape).astype(np.float32)


def rel_err(got, want):
    return np.abs(got.astype(np.float64) - want).max() / np.abs(want).max()


CASES = [  # (dtype, n_samples, n_fft, window, output)
    (np.int16, 256, 256, "hann", "magnitude"),      # N = n: no padding
    (np.int16, 256, 1024, "hann", "magnitude"),     # N = 4n: the paper's 768 zeros
    (np.float32, 256, 512, "rect", "power"),
    (np.float32, 200, 512, "hann", "magnitude"),    # n not a power of two
    (np.float32, 3, 4, "hann", "magnitude"),        # local size 1
    (np.float32, 2, 8, "rect", "magnitude"),        # M = 2: radix-2 only, P = 4
    (np.complex64, 128, 128, "hann", "magnitude"),  # I/Q, all N bins kept
    (np.complex64, 100, 512, "rect", "power"),
    (np.int16, 256, 4096, "hann", "power"),
]


@pytest.mark.parametrize("dtype,n,n_fft,window,output", CASES)
def test_matches_oracle(runtime, dtype, n, n_fft, window, output):
    x = make_samples(np.random.default_rng(n_fft + n), (5, 3, n), dtype)  # 15 beams: odd pair count
    plan = RangeFFT(runtime, (5, 3), n, n_fft, dtype=dtype, window=window, output=output)
    got = plan(x)
    want = oracle.range_profile(x, n_fft, window=window, output=output)
    assert got.profiles.shape == want.shape == (5, 3, n_fft if dtype == np.complex64 else n_fft // 2)
    assert got.profiles.dtype == np.float32
    assert rel_err(got.profiles, want) <= RANGE_FFT_RTOL
    assert np.array_equal(got.flags, oracle.beam_flags(x, plan.clip_level))


@pytest.mark.parametrize("local_size", [1, 2, 16, 64, 256])
@pytest.mark.parametrize("vector_width", [1, 2, 4, 8])
def test_local_sizes_and_vector_widths_agree(runtime, local_size, vector_width):
    x = make_samples(np.random.default_rng(7), (64, 4, 256), np.int16)
    want = oracle.range_profile(x, 1024)
    got = RangeFFT(runtime, (64, 4), 256, 1024, local_size=local_size, vector_width=vector_width)(x)
    assert rel_err(got.profiles, want) <= RANGE_FFT_RTOL


@pytest.mark.parametrize("dtype", [np.float32, np.complex64])
@pytest.mark.parametrize("batch", [(1, 1), (3, 5), (17, 1)])
def test_partial_last_group(runtime, dtype, batch):
    # Beam counts that leave lanes of the last work-group empty (and an unpaired last beam).
    x = make_samples(np.random.default_rng(8), (*batch, 64), dtype)
    x[0, 0, 5] = np.nan
    got = RangeFFT(runtime, batch, 64, 256, dtype=dtype, vector_width=8)(x)
    want = oracle.range_profile(x, 256)
    valid = got.valid
    assert got.n_invalid == 1 and np.isnan(got.profiles[0, 0]).all()
    if valid.any():
        assert rel_err(got.profiles[valid], want[valid]) <= RANGE_FFT_RTOL


def test_repeatable_bit_for_bit(runtime):
    x = make_samples(np.random.default_rng(3), (64, 4, 256), np.int16)
    plan = RangeFFT(runtime, (64, 4), 256, 512)
    first = plan(x).profiles
    assert np.array_equal(first, plan(x).profiles)


def test_all_zero_frame_gives_exact_zeros(runtime):
    got = RangeFFT(runtime, (4, 4), 256, 512)(np.zeros((4, 4, 256), np.int16))
    assert np.array_equal(got.profiles, np.zeros((4, 4, 256), np.float32))
    assert not got.flags.any()


def test_full_scale_clipped_frame(runtime):
    # A square wave at the int16 rails: every beam saturates; values stay finite and exact-ish.
    j = np.arange(256)
    square = np.where((j // 8) % 2 == 0, 32767, -32768).astype(np.int16)
    x = np.broadcast_to(square, (8, 4, 256)).copy()
    got = RangeFFT(runtime, (8, 4), 256, 1024)(x)
    assert np.isfinite(got.profiles).all()
    assert rel_err(got.profiles, oracle.range_profile(x, 1024)) <= RANGE_FFT_RTOL
    assert got.n_clipped == 32 and got.n_invalid == 0


def test_single_impulse_is_flat(runtime):
    # An impulse at sample j0 transforms to a flat magnitude w[j0] / sum(w) at every bin.
    x = np.zeros((2, 1, 256), np.float32)
    x[:, :, 100] = 1.0
    got = RangeFFT(runtime, (2, 1), 256, 1024, dtype=np.float32)(x)
    w = oracle.window_coefficients("hann", 256)
    np.testing.assert_allclose(got.profiles, w[100] / w.sum(), rtol=RANGE_FFT_RTOL)


def test_120_db_spread_between_two_tones(runtime):
    n, n_fft = 256, 256
    j = np.arange(n)
    x = (1.0 * np.exp(2j * np.pi * 40 * j / n) + 1e-6 * np.exp(2j * np.pi * 200 * j / n))
    x = x.astype(np.complex64)[None, None, :]
    got = RangeFFT(runtime, (1, 1), n, n_fft, dtype=np.complex64, window="rect")(x).profiles[0, 0]
    want = oracle.range_profile(x, n_fft, window="rect")[0, 0]
    assert want[40] == pytest.approx(1.0, rel=1e-6)
    assert abs(got[200] - want[200]) / want[200] <= WEAK_TONE_RTOL   # the -120 dB tone survives
    assert rel_err(got, want) <= RANGE_FFT_RTOL


def test_range_gain_compensation(runtime):
    x = make_samples(np.random.default_rng(11), (4, 4, 256), np.int16)
    gain = oracle.range_gain(256, 0.25, 2.0)
    got = RangeFFT(runtime, (4, 4), 256, 512, gain=gain)(x)
    assert rel_err(got.profiles, oracle.range_profile(x, 512, gain=gain)) <= RANGE_FFT_RTOL
    assert np.array_equal(got.profiles[..., 0], np.zeros((4, 4), np.float32))   # r = 0 gets gain 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_beams_flagged_and_partner_untouched(runtime, bad):
    x = make_samples(np.random.default_rng(5), (4, 2, 256), np.float32)
    x[1, 0, 17] = bad                      # beam 2 is paired with beam 3 in one FFT
    got = RangeFFT(runtime, (4, 2), 256, 512, dtype=np.float32)(x)
    want = oracle.range_profile(x, 512)
    assert np.isnan(got.profiles[1, 0]).all() and np.isnan(want[1, 0]).all()
    valid = got.valid
    assert valid.sum() == 7 and not valid[1, 0] and got.n_invalid == 1
    assert rel_err(got.profiles[valid], want[valid]) <= RANGE_FFT_RTOL
    assert got.flags[1, 0] == oracle.FLAG_NONFINITE


@pytest.mark.parametrize("huge", [1e10, 1e30, 3e38])
def test_paired_beams_never_pollute_each_other(runtime, huge):
    """One real beam with a huge sample, paired in one FFT with a normal beam. 1e10 is within
    the float input range but 1e10 times its partner: the partner is flagged CROSSTALK (it once
    took 419 wrong evidence bins silently); 1e30 and 3e38 are beyond sample_limit (their power
    would overflow float32): that beam is flagged OVERRANGE and written NaN, and its partner,
    which took none of it, is exact. Flags equal the oracle's."""
    x = make_samples(np.random.default_rng(5), (4, 2, 256), np.float32)
    x[1, 0, 17] = huge                     # beam 2 is paired with beam 3
    plan = RangeFFT(runtime, (4, 2), 256, 512, dtype=np.float32, output="power")
    got = plan(x)
    want = oracle.range_profile(x, 512, output="power")
    assert np.array_equal(got.flags, oracle.beam_flags(x, plan.clip_level))
    others = np.ones((4, 2), bool)
    others[1] = False
    assert rel_err(got.profiles[others], want[others]) <= RANGE_FFT_RTOL
    if huge > oracle.sample_limit(256):
        assert got.flags[1, 0] == oracle.FLAG_OVERRANGE and np.isnan(got.profiles[1, 0]).all()
        assert got.flags[1, 1] == 0 and rel_err(got.profiles[1, 1], want[1, 1]) <= RANGE_FFT_RTOL
    else:
        assert got.flags[1, 1] == oracle.FLAG_CROSSTALK and got.flags[1, 0] == 0
        assert np.isfinite(got.profiles[1]).all()
    assert got.n_invalid == 1 and not got.valid[1].all()


def test_pairing_below_the_ratio_leaks_little(runtime):
    """Peaks PAIR_RATIO / 2 apart: not flagged, and the weaker beam's profile is within 1e-2 of
    its own peak bin of the float64 oracle (the bound the flag's threshold promises)."""
    n = 256
    t = np.arange(n)
    strong = (0.5 * oracle.PAIR_RATIO * np.cos(2 * np.pi * 40.3 * t / n)).astype(np.float32)
    weak = np.random.default_rng(1).uniform(-1, 1, n).astype(np.float32)
    x = np.stack([strong, weak]).reshape(1, 2, n)
    got = RangeFFT(runtime, (1, 2), n, 1024, dtype=np.float32)(x)
    want = oracle.range_profile(x, 1024)
    assert not got.flags.any()
    leak = np.abs(got.profiles[0, 1] - want[0, 1]).max() / want[0, 1].max()
    assert leak < 1e-2, leak


def test_a_silent_beam_beside_a_live_one_is_flagged(runtime):
    """int16: a beam of zeros paired with a live beam would take the live beam's rounding as
    signal; it is flagged (and gives no evidence), whatever the live beam's level."""
    x = make_samples(np.random.default_rng(2), (1, 2, 256), np.int16)
    x[0, 1] = 0
    got = RangeFFT(runtime, (1, 2), 256, 512)(x)
    assert got.flags[0, 1] == oracle.FLAG_CROSSTALK and got.flags[0, 0] == 0
    assert np.array_equal(got.flags, oracle.beam_flags(x, 32767.0))


def test_nonfinite_complex_sample(runtime):
    x = make_samples(np.random.default_rng(6), (2, 1, 64), np.complex64)
    x[0, 0, 3] = complex(1.0, np.nan)
    got = RangeFFT(runtime, (2, 1), 64, 128, dtype=np.complex64)(x)
    assert got.n_invalid == 1 and np.isnan(got.profiles[0, 0]).all()
    assert rel_err(got.profiles[1], oracle.range_profile(x, 128)[1]) <= RANGE_FFT_RTOL


def test_wrong_shape_or_dtype_is_refused(runtime):
    plan = RangeFFT(runtime, (64, 4), 256, 512)
    with pytest.raises(ShapeError, match=r"expected a frame of shape \(64, 4, 256\) int16, got \(256, 256\) float64"):
        plan(np.zeros((256, 256)))
    with pytest.raises(ShapeError, match="int16"):
        plan(np.zeros((64, 4, 256), np.float32))


@pytest.mark.parametrize("kwargs,match", [
    (dict(n_samples=256, n_fft=128), "n_fft must be a power of two >= "),
    (dict(n_samples=256, n_fft=768), "power of two"),
    (dict(n_samples=256, n_fft=512, dtype=np.float64), "dtype must be one of"),
    (dict(n_samples=256, n_fft=512, window="kaiser"), "window must be one of"),
    (dict(n_samples=256, n_fft=512, output="db"), "output must be one of"),
    (dict(n_samples=256, n_fft=512, local_size=3), "local_size must be a power of two"),
    (dict(n_samples=256, n_fft=512, local_size=256), "local_size must be a power of two"),
    (dict(n_samples=256, n_fft=512, clip_level=-1.0), "clip_level must be positive"),
    (dict(n_samples=1, n_fft=4), "n_samples must be an integer >= 2"),
    (dict(n_samples=64.7, n_fft=128), "n_samples must be an integer >= 2, got 64.7"),
    (dict(n_samples=True, n_fft=4), "n_samples must be an integer >= 2, got True"),
    (dict(n_samples=256, n_fft=512, vector_width=3), "vector_width must be one of"),
])
def test_impossible_plans_are_refused(runtime, kwargs, match):
    with pytest.raises(ConfigError, match=match):
        RangeFFT(runtime, (64, 4), **kwargs)


def test_gain_of_wrong_length_is_refused(runtime):
    with pytest.raises(ShapeError, match=r"gain must be finite with shape \(256,\)"):
        RangeFFT(runtime, (64, 4), 256, 512, gain=np.ones(10))


@pytest.mark.parametrize("dtype", [np.float32, np.int16])
def test_full_groups_check_samples_as_vectors(runtime, dtype):
    """Groups whose beams all exist load each sample row as vectors (the even and the odd
    beams) with their checks per lane: the same flags as the oracle, and the same profiles as
    one job per group (vector_width 1, the lane-by-lane path), for NaN, Inf, over-range,
    clipped and silent beams in the first and last lanes of a group."""
    x = make_samples(np.random.default_rng(9), (16, 2, 256), dtype)
    if dtype == np.float32:
        x[0, 0, 3], x[3, 1, 200], x[7, 1, 0] = np.nan, -np.inf, 1e30     # lanes 0, 7 and 15 of group 0
        x[8, 0, 255] = np.inf
    x[12, 1, 40] = np.iinfo(np.int16).max if dtype == np.int16 else 32767.0   # clipped
    x[15, 1] = 0                                                            # the last lane: silent
    vector = RangeFFT(runtime, (16, 2), 256, 512, dtype=dtype, vector_width=8)
    got = vector(x)
    one = RangeFFT(runtime, (16, 2), 256, 512, dtype=dtype, vector_width=1)(x)
    assert np.array_equal(got.flags, oracle.beam_flags(x, vector.clip_level))
    assert np.array_equal(got.flags, one.flags)
    assert np.array_equal(np.isnan(got.profiles), np.isnan(one.profiles))
    valid = got.valid
    assert 0 < valid.sum() < 32
    assert rel_err(got.profiles[valid], one.profiles[valid]) <= RANGE_FFT_RTOL
    assert rel_err(got.profiles[valid], oracle.range_profile(x, 512)[valid]) <= RANGE_FFT_RTOL
