"""kernels/levels.cl <-> radarcl/stages/levels.py against its oracle, the host's table lookup
``polar_png.levels_to_power``: the power is compared bit for bit (the same float32 table)."""

import numpy as np
import pytest

from radarcl.errors import ConfigError, FrameFormatError, ShapeError
from radarcl.io.polar_png import levels_to_power
from radarcl.stages.levels import VECTOR_WIDTHS, Levels


def every_level(shape, seed=0):
    """uint8 levels of ``shape`` holding every level 0 .. 255 at least once (where they fit)."""
    x = np.random.default_rng(seed).integers(0, 256, size=shape, dtype=np.uint8)
    flat = x.reshape(-1)
    flat[:min(256, flat.size)] = np.arange(min(256, flat.size), dtype=np.uint8)
    return x


def same_bits(a, b):
    return a.dtype == b.dtype == np.float32 and np.array_equal(a.view(np.uint32), b.view(np.uint32))


@pytest.mark.parametrize("db_per_level", [1.0, 0.5, 0.25, 1.4])
def test_matches_the_host_table_bit_for_bit(runtime, db_per_level):
    levels = every_level((40, 517))
    got = Levels(runtime, levels.shape, db_per_level)(levels)
    assert same_bits(got, levels_to_power(levels, db_per_level))


# The tail past the last whole vector (a frame of 7 x 13 = 91 levels), every width, odd local sizes.
@pytest.mark.parametrize("vector_width", VECTOR_WIDTHS)
@pytest.mark.parametrize("local_size", [1, 7, 64])
def test_every_width_and_local_size(runtime, vector_width, local_size):
    levels = every_level((7, 13), seed=vector_width)
    got = Levels(runtime, levels.shape, local_size=local_size, vector_width=vector_width)(levels)
    assert same_bits(got, levels_to_power(levels))


def test_writes_into_another_stages_array(runtime):
    import pyopencl.array as cla

    levels = every_level((3, 300))
    target = cla.zeros(runtime.queue, levels.shape, np.float32)
    stage = Levels(runtime, levels.shape, power=target)
    stage.enqueue(wait_for=[stage.upload(levels)]).wait()
    assert same_bits(target.get(), levels_to_power(levels))
    assert stage.arrays["power"] is target               # no buffer of its own


def test_a_new_scale_takes_a_new_table(runtime):
    levels = every_level((2, 256))
    stage = Levels(runtime, levels.shape, 1.0)
    assert same_bits(stage(levels), levels_to_power(levels, 1.0))
    stage.set_db_per_level(0.5)
    assert same_bits(stage(levels), levels_to_power(levels, 0.5))


def test_refuses_bad_input(runtime):
    stage = Levels(runtime, (4, 100))
    with pytest.raises(ShapeError, match=r"expected levels of shape \(4, 100\) uint8, got \(4, 100\) float32"):
        stage(np.zeros((4, 100), np.float32))
    with pytest.raises(ShapeError, match=r"got \(4, 99\) uint8"):
        stage(np.zeros((4, 99), np.uint8))
    with pytest.raises(FrameFormatError, match=r"db_per_level must be in \(0, 1.4\]"):
        stage.set_db_per_level(2.0)
    assert stage.db_per_level == 1.0                     # the table it had is kept
    with pytest.raises(ConfigError, match="vector_width must be one of"):
        Levels(runtime, (4, 100), vector_width=3)
    with pytest.raises(ShapeError, match=r"expected power of shape \(4, 100\) float32"):
        import pyopencl.array as cla

        Levels(runtime, (4, 100), power=cla.zeros(runtime.queue, (4, 100), np.float64))


def differences(levels):
    """Each row's differences mod 256, the first its level: a PNG's "Sub" rows."""
    d = levels.copy()
    d[..., 1:] -= levels[..., :-1]
    return d


# Rows whose length is no multiple of the kernel's 16 (13, 517), one shorter than 16 (7), whole
# vectors only (32); every local size; the host's running sums as the oracle.
@pytest.mark.parametrize("shape", [(7, 13), (40, 517), (3, 32), (5, 7)])
@pytest.mark.parametrize("local_size", [1, 7, 64])
def test_differenced_rows_are_summed_as_the_host_sums_them(runtime, shape, local_size):
    from radarcl.io.png import running_sums

    levels = every_level(shape, seed=shape[1])
    coded = differences(levels)
    assert np.array_equal(running_sums(coded), levels)
    stage = Levels(runtime, shape, 0.5, local_size=local_size)
    assert same_bits(stage(coded, differenced=True), levels_to_power(levels, 0.5))
    assert same_bits(stage(levels), levels_to_power(levels, 0.5))      # the same stage, levels as they are
