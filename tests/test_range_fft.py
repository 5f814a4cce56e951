"""kernels/range_fft.cl <-> radarcl/stages/range_fft.py against radarcl.oracle.range_profile."""

import numpy as np
import pytest
from device_classes import KIB, MIB, narrowed
from tolerances import RANGE_FFT_RTOL, WEAK_TONE_RTOL

from radarcl import oracle
from radarcl.cl import Runtime
from radarcl.cl.limits import DeviceLimits
from radarcl.errors import ConfigError, DeviceCapabilityError, ShapeError
from radarcl.stages.range_fft import MAX_FFT, RangeFFT


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


# Work buffers in global memory where local memory is short: GPU classes faked on the device
# under test (tests/device_classes.py), every result against the float64 oracle.

@pytest.fixture(scope="module")
def as_class(runtime):
    """``as_class(name)``: a runtime on the device under test with the limits of GPU class
    ``name``, made once per module (each runtime builds its kernels once)."""
    made = {}

    def make(name):
        if name not in made:
            made[name] = Runtime(runtime.device, limits=narrowed(runtime.device, name))
        return made[name]
    return make


def with_bad_samples(x):
    """A NaN (floats) or clipped (int16) sample in the first beam, and in the last one of more
    than two, so that the flags travel through the path too and a valid beam is left."""
    x = x.copy()
    beams = x.reshape(-1, x.shape[-1])
    bad = np.iinfo(np.int16).max if x.dtype == np.int16 else np.nan
    beams[0, 3] = bad
    if len(beams) > 2:
        beams[-1, -1] = bad
    return x


GLOBAL_CASES = [  # (class, n_samples, n_fft, batch)
    ("gpu-32k", 512, 2048, (5, 3)),         # 2 x 2048 complex + flags is just past 32 KiB; log2 M odd
    ("gpu-16k", 4096, 4096, (5, 3)),        # no padding: every pass in global memory
    ("embedded-32k", 200, 4096, (3, 1)),    # P = 16 pruned blocks
    ("gpu-16k", 40000, MAX_FFT, (2, 1)),    # the longest transform, M = n_fft
    ("gpu-16k", 256, MAX_FFT, (2, 1)),      # the longest transform, P = 256
]


@pytest.mark.parametrize("dtype", [np.int16, np.float32, np.complex64])
@pytest.mark.parametrize("cls,n,n_fft,batch", GLOBAL_CASES)
def test_global_work_buffers_match_oracle(as_class, cls, n, n_fft, batch, dtype):
    rt = as_class(cls)
    x = with_bad_samples(make_samples(np.random.default_rng(n_fft + n), (*batch, n), dtype))
    plan = RangeFFT(rt, batch, n, n_fft, dtype=dtype)
    assert plan.scratch_space == "global" and plan.scratch_bytes > 0
    assert plan.local_bytes <= rt.limits.local_mem_size
    got = plan(x)
    want = oracle.range_profile(x, n_fft)
    assert np.array_equal(got.flags, oracle.beam_flags(x, plan.clip_level))
    assert np.array_equal(np.isnan(got.profiles), np.isnan(want))
    valid = got.valid
    assert valid.any()
    assert rel_err(got.profiles[valid], want[valid]) <= RANGE_FFT_RTOL


@pytest.mark.parametrize("cls,n_fft,space", [
    ("gpu-16k", 512, "local"),      # 8 KiB of buffers + flags fit
    ("gpu-16k", 1024, "global"),    # 16 KiB of buffers + 16 bytes of flags do not
    ("gpu-32k", 1024, "local"),
    ("gpu-32k", 2048, "global"),
    ("gpu-48k", 2048, "local"),
    ("embedded-32k", 1024, "local"),
])
def test_local_work_buffers_wherever_they_fit(as_class, cls, n_fft, space):
    rt = as_class(cls)
    x = make_samples(np.random.default_rng(4), (4, 4, 256), np.int16)
    plan = RangeFFT(rt, (4, 4), 256, n_fft)
    assert plan.scratch_space == space
    assert plan.vector_width == 1                          # a GPU class: one job per work-group
    assert plan.local_bytes <= rt.limits.local_mem_size
    assert plan.scratch_bytes == (0 if space == "local" else plan.n_groups * 2 * n_fft * 8)
    assert rel_err(plan(x).profiles, oracle.range_profile(x, n_fft)) <= RANGE_FFT_RTOL


@pytest.mark.parametrize("dtype,flag_bytes", [(np.int16, 16), (np.float32, 16), (np.complex64, 8)])
def test_local_memory_counts_every_beams_flags(runtime, dtype, flag_bytes):
    """job_flags and job_peak hold one int each per beam: two beams per job for real input, one
    for complex. Local memory of exactly the buffers and one complex job's flags takes complex
    input on the local path, real input on the global one."""
    buffers = 2 * 1024 * 8
    x = make_samples(np.random.default_rng(15), (2, 1, 256), dtype)
    roomy = RangeFFT(Runtime(runtime.device, limits=narrowed(runtime.device, "gpu-32k")), (2, 1), 256, 1024,
                     dtype=dtype)
    assert roomy.scratch_space == "local" and roomy.local_bytes == buffers + flag_bytes
    limits = DeviceLimits.of(runtime.device).narrowed(label="buffers + 8 bytes", is_cpu=False,
                                                      local_mem_size=buffers + 8)
    tight = RangeFFT(Runtime(runtime.device, limits=limits), (2, 1), 256, 1024, dtype=dtype)
    assert tight.scratch_space == ("local" if flag_bytes <= 8 else "global")
    assert tight.local_bytes <= limits.local_mem_size
    assert rel_err(tight(x).profiles, oracle.range_profile(x, 1024)) <= RANGE_FFT_RTOL


@pytest.mark.parametrize("vector_width", [1, 2, 4, 8])
@pytest.mark.parametrize("local_size", [1, 16, 64])
def test_global_work_buffers_at_every_vector_width(runtime, vector_width, local_size):
    """A CPU with little local memory: the lanes of the vectorised load and the butterflies
    work in global memory, full groups and a partial last one (17 beams) alike."""
    limits = DeviceLimits.of(runtime.device).narrowed(label="cpu-16k", local_mem_size=16 * KIB)
    rt = Runtime(runtime.device, limits=limits)
    x = with_bad_samples(make_samples(np.random.default_rng(12), (17, 1, 256), np.float32))
    plan = RangeFFT(rt, (17, 1), 256, 1024, dtype=np.float32, vector_width=vector_width, local_size=local_size)
    assert plan.scratch_space == "global"
    got = plan(x)
    want = oracle.range_profile(x, 1024)
    assert np.array_equal(got.flags, oracle.beam_flags(x, plan.clip_level))
    valid = got.valid
    assert rel_err(got.profiles[valid], want[valid]) <= RANGE_FFT_RTOL


def test_a_cpu_without_room_for_any_width_keeps_its_lanes(runtime):
    limits = DeviceLimits.of(runtime.device).narrowed(label="cpu-16k", local_mem_size=16 * KIB)
    plan = RangeFFT(Runtime(runtime.device, limits=limits), (4, 4), 256, 2048)
    lanes = 8 if limits.is_cpu else 1                         # a GPU under test takes one job per group
    assert plan.scratch_space == "global" and plan.vector_width == lanes
    assert plan.local_bytes == 2 * 4 * 2 * lanes              # the flags of the group's beam pairs


def test_scratch_is_held_against_global_memory(as_class):
    rt = as_class("gpu-16k")
    before = rt.held_bytes
    plan = RangeFFT(rt, (8, 4), 256, 4096)
    assert plan.scratch_space == "global" and plan.scratch_bytes == 16 * 2 * 4096 * 8
    ports = sum(a.nbytes for a in plan.arrays.values())          # the frame, profiles and flags
    assert rt.held_bytes == before + plan.scratch_bytes + ports


def test_scratch_beyond_the_largest_buffer_is_refused(runtime):
    """What the global path needs and what the device has, in one sentence."""
    limits = narrowed(runtime.device, "gpu-16k").narrowed(max_mem_alloc_size=1 * MIB)
    said = (r"n_fft = 4096 with vector_width 1 needs 65552 bytes of local memory per work-group, more than the "
            r"16384 of .*, so its work buffers go to global memory: 32 work-groups x 65536 bytes = 2 MiB in one "
            r"buffer, more than the largest buffer the device allows, 1 MiB")
    with pytest.raises(DeviceCapabilityError, match=said):
        RangeFFT(Runtime(runtime.device, limits=limits), (16, 4), 256, 4096)


def test_work_group_size_within_the_device_limit(runtime):
    limits = narrowed(runtime.device, "gpu-16k").narrowed(max_work_group_size=64)
    rt = Runtime(runtime.device, limits=limits)
    x = make_samples(np.random.default_rng(13), (4, 2, 256), np.int16)
    plan = RangeFFT(rt, (4, 2), 256, 1024)                   # n_fft / 4 = 256 workers wanted
    assert plan.local_size == 64
    assert rel_err(plan(x).profiles, oracle.range_profile(x, 1024)) <= RANGE_FFT_RTOL
    with pytest.raises(ConfigError, match="local_size must be a power of two <= 64"):
        RangeFFT(rt, (4, 2), 256, 1024, local_size=128)


def test_work_group_size_within_the_built_kernels_limit(as_class, monkeypatch):
    """The built kernel may run fewer work-items than the device (its registers, its local
    memory; CL_KERNEL_WORK_GROUP_SIZE): a defaulted size is rebuilt at the largest power of
    two within it, a requested one is refused with a sentence."""
    rt = as_class("gpu-16k")
    monkeypatch.setattr(rt, "max_local_size", lambda kernel: 100)
    x = make_samples(np.random.default_rng(14), (4, 2, 256), np.float32)
    plan = RangeFFT(rt, (4, 2), 256, 1024, dtype=np.float32)
    assert plan.local_size == 64
    assert rel_err(plan(x).profiles, oracle.range_profile(x, 1024)) <= RANGE_FFT_RTOL
    with pytest.raises(ConfigError, match=r"local_size 128 is more than the 100 work-items .* runs this build"):
        RangeFFT(rt, (4, 2), 256, 1024, dtype=np.float32, local_size=128)
