"""kernels/cfar.cl <-> radarcl/stages/cfar.py against radarcl.oracle.cfar (edge rule "shift")."""

import numpy as np
import pytest
from tolerances import CFAR_RTOL, DECISION_MARGIN

from radarcl import oracle
from radarcl.config.stage_config import CfarConfig
from radarcl.errors import ConfigError, ShapeError
from radarcl.stages.cfar import Cfar


def check_against_oracle(got, profiles, config):
    """noise and ratio within CFAR_RTOL (NaN where the oracle has NaN); masks identical outside
    DECISION_MARGIN of the threshold, and bins inside it rare."""
    noise, ratio, mask = oracle.cfar(profiles, config)
    assert np.array_equal(np.isnan(got.noise), np.isnan(noise))
    assert np.array_equal(np.isnan(got.ratio), np.isnan(ratio))
    finite = np.isfinite(noise)
    np.testing.assert_allclose(got.noise[finite], noise[finite], rtol=CFAR_RTOL, atol=0)
    np.testing.assert_allclose(got.ratio[finite], ratio[finite], rtol=CFAR_RTOL, atol=0)
    threshold = config.alpha * noise
    with np.errstate(invalid="ignore"):
        near = np.isfinite(threshold) & (np.abs(profiles - threshold) <= DECISION_MARGIN * threshold)
    assert near.sum() <= max(2, 1e-4 * near.size), f"{near.sum()} bins within the decision margin"
    assert np.array_equal(got.mask[~near], mask[~near])
    return mask


def exponential(shape, seed=0):
    return np.random.default_rng(seed).exponential(size=shape).astype(np.float32)


CONFIGS = [
    CfarConfig(),                                    # the paper's CA, defaults
    CfarConfig(kind="ca", guard=0, train=1, pfa=0.1),
    CfarConfig(kind="go", guard=2, train=8, pfa=1e-2),
    CfarConfig(kind="so", guard=3, train=5, pfa=1e-3),
    CfarConfig(kind="os", guard=2, train=8, pfa=1e-3),
    CfarConfig(kind="os", guard=1, train=4, rank=1, pfa=1e-2),
]


# Every config on 512 bins, and on 93 where its window fits (shorter profiles are refused:
# test_refuses_bad_input).
CASES = [(c, n) for c in CONFIGS for n in (512, 93) if n >= c.window]


@pytest.mark.parametrize("config,n_bins", CASES, ids=lambda v: f"{v.kind}-g{v.guard}-t{v.train}"
                         if isinstance(v, CfarConfig) else str(v))
def test_matches_oracle(runtime, config, n_bins):
    x = exponential((16, 4, n_bins), seed=n_bins)
    x[3, 1, 40] = 1e4                 # detections, and a target inside other cells' windows
    x[5, 2, 60:75] = 300.0            # an extended echo
    got = Cfar(runtime, (16, 4), n_bins, config)(x)
    mask = check_against_oracle(got, x, config)
    assert mask[3, 1, 40] and got.mask[3, 1, 40]


@pytest.mark.parametrize("local_size", [1, 7, 32, 64, 256])
@pytest.mark.parametrize("vector_width", [1, 2, 4, 8, 16])
def test_local_sizes_and_vector_widths_agree(runtime, local_size, vector_width):
    """Vector and edge paths, partial groups and tails give the oracle's results."""
    x = exponential((8, 509), seed=3)
    config = CfarConfig(guard=3, train=6)
    got = Cfar(runtime, (8,), 509, config, local_size=local_size, vector_width=vector_width)(x)
    check_against_oracle(got, x, config)


@pytest.mark.parametrize("kind", ["ca", "go", "so"])
def test_vector_edge_groups_sum_as_the_lane_by_lane_path(runtime, kind):
    """The edge groups' vector sums add the same cells in the same order as one bin at a time
    (vector_width 1): identical floats, on a profile with 120 dB between its cells."""
    x = exponential((6, 200), seed=5)
    x[:, ::7] *= 1e12
    config = CfarConfig(kind=kind, guard=4, train=9, pfa=1e-3)
    one = Cfar(runtime, (6,), 200, config, vector_width=1)(x)
    for width in (2, 8, 16):
        got = Cfar(runtime, (6,), 200, config, vector_width=width)(x)
        for a, b in ((one.noise, got.noise), (one.ratio, got.ratio), (one.mask, got.mask)):
            assert np.array_equal(a, b), width
    check_against_oracle(one, x, config)


def test_shift_edge_rule_cells():
    """Every bin has 2 train distinct cells inside the profile, none within the guard band,
    and the interior uses the textbook symmetric window."""
    n, guard, train = 40, 2, 5
    cells = oracle.training_cells(n, guard, train)
    for i in range(n):
        row = cells[i]
        assert len(set(row)) == 2 * train and row.min() >= 0 and row.max() < n
        assert np.all(np.abs(row - i) > guard) and np.all(np.diff(row) > 0)
    i = 20
    assert list(cells[i]) == list(range(i - guard - train, i - guard)) + list(range(i + guard + 1, i + guard + 1 + train))
    assert list(cells[0]) == list(range(guard + 1, guard + 1 + 2 * train))


def test_exact_on_integer_valued_profiles(runtime):
    """With small integers the float32 sums are exact, so the kernel equals the oracle to the bit
    and the masks match everywhere."""
    x = np.random.default_rng(5).integers(0, 50, (32, 128)).astype(np.float32)
    config = CfarConfig(guard=2, train=4, pfa=0.05)
    got = Cfar(runtime, (32,), 128, config)(x)
    noise, ratio, mask = oracle.cfar(x, config)
    assert np.array_equal(got.noise, noise.astype(np.float32))
    # r / n of exact float32 operands, correctly rounded once: the float64 quotient rounded to float32
    assert np.array_equal(got.ratio, ratio.astype(np.float32))
    assert np.array_equal(got.mask, mask) and 0 < mask.sum() < mask.size


# -- numerical stability: defined, finite, documented results that agree with the oracle ------

def test_all_zero_windows_use_the_noise_floor(runtime):
    config = CfarConfig(guard=1, train=4)
    x = np.zeros((2, 64), np.float32)
    x[1, 30] = 1e-3                   # a lone echo in silence: its ratio is 1e-3 / floor
    got = Cfar(runtime, (2,), 64, config)(x)
    check_against_oracle(got, x, config)
    assert np.all(got.noise[0] == np.float32(config.noise_floor)) and not got.mask[0].any()
    assert got.noise[1, 30] == np.float32(config.noise_floor)   # its own window is silent
    assert np.all(np.isfinite(got.ratio)) and got.mask.sum() == 1 and got.mask[1, 30]


def test_120_db_dynamic_range(runtime):
    """A 120 dB echo beside weak noise: direct sums keep the weak windows exact (a float32
    prefix sum would leave nothing of them)."""
    config = CfarConfig(guard=2, train=8)
    x = exponential((4, 256), seed=9)
    x[:, 100] = 1e12
    x[:, 180] = 30.0                  # weak target 108 dB below the strong one
    got = Cfar(runtime, (4,), 256, config)(x)
    mask = check_against_oracle(got, x, config)
    assert mask[:, 180].all() and got.mask[:, 180].all() and got.mask[:, 100].all()


def test_huge_ratio_saturates_instead_of_overflowing(runtime):
    config = CfarConfig(guard=1, train=2)
    x = np.zeros((1, 32), np.float32)
    x[0, 10] = 3e38                   # over a floored noise of 1e-30: 3e68 does not fit float32
    got = Cfar(runtime, (1,), 32, config)(x)
    check_against_oracle(got, x, config)
    assert got.ratio[0, 10] == np.finfo(np.float32).max and got.mask[0, 10]


def test_denormals_clipped_and_nan(runtime):
    config = CfarConfig(guard=1, train=3)
    x = exponential((4, 64), seed=11)
    x[0] = 1e-42                      # denormal everywhere: below the floor either way
    x[1, 20:30] = 5.0                 # clipped: a flat plateau at full scale
    x[2, 33] = np.nan
    x[3, 40] = np.inf
    got = Cfar(runtime, (4,), 64, config)(x)
    check_against_oracle(got, x, config)
    assert np.all(got.noise[0] == np.float32(config.noise_floor)) and not got.mask[0].any()
    assert np.isnan(got.noise[2, 33 - 4:33 + 5]).sum() > 0 and not got.mask[2, 33]


# -- bad input --------------------------------------------------------------------------------

def test_refuses_bad_input(runtime):
    with pytest.raises(ConfigError, match="at least 41 bins"):
        Cfar(runtime, (4,), 40, CfarConfig(guard=4, train=16))
    with pytest.raises(ConfigError, match="pfa must lie strictly between 0 and 1"):
        CfarConfig(pfa=1.5)
    with pytest.raises(ConfigError, match="pfa must lie strictly between 0 and 1"):
        CfarConfig(pfa=0.0)
    with pytest.raises(ConfigError, match="rank must be in"):
        CfarConfig(kind="os", train=4, rank=9)
    with pytest.raises(ConfigError, match="rank applies to OS-CFAR only"):
        CfarConfig(kind="ca", rank=3)
    with pytest.raises(ConfigError, match="CFAR kind must be one of"):
        CfarConfig(kind="median")
    plan = Cfar(runtime, (4,), 64, CfarConfig(guard=1, train=2))
    with pytest.raises(ShapeError, match=r"expected power profiles of shape \(4, 64\) float32, got \(4, 63\) float32"):
        plan(np.zeros((4, 63), np.float32))
    with pytest.raises(ShapeError, match="float64"):
        plan(np.zeros((4, 64)))
    with pytest.raises(ConfigError, match="local_size"):
        Cfar(runtime, (4,), 64, CfarConfig(guard=1, train=2), local_size=0)
    import pyopencl.array as cla

    with pytest.raises(ShapeError, match=r"expected power profiles of shape \(4, 64\) float32 on the device"):
        plan.enqueue(cla.to_device(runtime.queue, np.zeros(8, np.float32)))     # once 1,470 "targets"


def test_the_stage_alone_flags_beams_it_cannot_judge(runtime):
    """Above PROFILE_LIMIT the training sums overflow float32 and the noise is infinite: the
    target there is missed. The stage used on its own says which beams (as the interpreter does
    in a pipeline); the others are judged as usual."""
    from radarcl import oracle

    profiles = np.ones((3, 256), np.float32)
    profiles[:, 100] = 1e3                                  # a target in every beam
    profiles[1, 40:60] = 3e37                               # beam 1: bins beyond PROFILE_LIMIT
    profiles[2] = 0.0                                       # beam 2: the receiver measured nothing
    result = Cfar(runtime, (3,), 256, CfarConfig(guard=2, train=8))(profiles)
    assert result.flags.tolist() == [0, oracle.FLAG_BAD_PROFILE, oracle.FLAG_SILENT]
    assert result.mask[0, 100] and not np.isfinite(result.noise[1]).all()
    assert np.array_equal(result.flags, oracle.profile_flags(profiles))
