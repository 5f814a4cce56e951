"""Every device's limits honoured, shown on PoCL's CPU device narrowed to GPU classes
(tests/device_classes.py): the device self-test (radarcl.self_test.self_test: every built-in
sensor's pipeline against the float64 oracle) passes on each class; a sensor a device cannot fit
is refused alone, with a sentence, and the device stays usable for the rest; work-group sizes
come from the compiled kernels; a device without 64-bit integers gets kernels that use none; the
buffers of a whole pipeline are counted against global memory.

The kernel tests themselves run under any class with RADARCL_TEST_LIMITS=<class> (conftest)."""

import gc
import re
import shutil
import subprocess

import numpy as np
import pytest
from device_classes import DEVICE_CLASSES, MIB, narrowed

from radarcl.cl import devices as dev_module
from radarcl.cl.runtime import Runtime
from radarcl.config import mapconfig
from radarcl.errors import DeviceCapabilityError
from radarcl.pipeline import Mapping
from radarcl.self_test import self_test

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def as_class(runtime, name, **more):
    """A fresh runtime on ``runtime``'s device, narrowed to class ``name`` and further by ``more``."""
    return Runtime(runtime.device, limits=narrowed(runtime.device, name, **more))


@pytest.mark.parametrize("name", sorted(DEVICE_CLASSES))
def test_every_gpu_class_runs_every_builtin_sensor_against_the_oracle(runtime, name):
    """No sensor refused: the range FFT fits any local memory of 16 KiB or more (global-memory
    scratch beyond it), and the self-test sizes its profiles by the range it tests."""
    narrow = as_class(runtime, name)
    assert not narrow.is_cpu and narrow.limits.max_work_group_size == 256
    assert self_test(narrow) is None


def test_a_largest_buffer_of_64_mib_runs_every_builtin_sensor(runtime):
    """The self-test once sized a profile sensor's interpreter by every bin the sensor has (400
    azimuths x 3,355 bins x 16 int32 = 86 MB) and refused such a device whole."""
    assert self_test(as_class(runtime, "gpu-48k", max_mem_alloc_size=64 * MIB)) is None


def test_a_sensor_that_does_not_fit_is_refused_alone_with_a_sentence(runtime):
    """A largest buffer of 1 MiB holds the paper radar's eq. 12 buffers and a TI board's, but not
    a spinning radar's 400-azimuth frames: each refused sensor is named with what it needs and
    what the device has, the device stays usable, and asking for such a sensor says the same."""
    narrow = as_class(runtime, "gpu-32k", max_mem_alloc_size=1 * MIB)
    verdict = self_test(narrow)
    assert isinstance(verdict, dict) and verdict["problem"] is None
    refused = {re.match(r"sensor (\S+ \([^)]*\)): ", note).group(1) for note in verdict["notes"]}
    assert {"spinning-sim (eq. 12)", "spinning-sim (detection statistics)"} <= refused
    assert "paper (eq. 12)" not in refused and "ti-xwr-openradar (eq. 12)" not in refused
    for note in verdict["notes"]:
        assert "(as gpu-32k, max_mem_alloc_size=1048576)" in note and "more than the largest buffer" in note, note
        assert re.search(r" [\d.]+ (KiB|MiB)\b", note) and re.search(r", 1 MiB \((radarcl info|process fewer beams)", note)
    config = mapconfig.resolve("spinning-sim", program={"grid.voxel_m": 2.0, "interpret.range_max_m": 24.0})
    with pytest.raises(DeviceCapabilityError, match=r"= 6.25 MiB in one buffer, more than the largest buffer"):
        Mapping.from_config(narrow, config=config)


def test_a_device_that_fits_no_sensor_is_unusable(runtime):
    verdict = self_test(as_class(runtime, "gpu-32k", max_mem_alloc_size=16))
    assert isinstance(verdict, str) and verdict.startswith("fits none of the built-in sensors: sensor ")


def test_info_names_what_a_usable_device_cannot_run(runtime, monkeypatch):
    """A device with notes is still usable and chosen; `radarcl info` lists what it cannot run."""
    notes = self_test(as_class(runtime, "gpu-32k", max_mem_alloc_size=1 * MIB))["notes"]
    monkeypatch.setattr(dev_module, "_probed", {runtime.device.int_ptr: dict(problem=None, notes=notes)})
    lines = dev_module.device_report()
    assert all(f"      cannot run     {note}" in lines for note in notes) and notes
    place = next(f"{p}:{d}" for p, d, _, dev in dev_module._all_devices() if dev.int_ptr == runtime.device.int_ptr)
    assert dev_module.choose_device(spec=place).int_ptr == runtime.device.int_ptr


def test_work_group_sizes_come_from_the_device_class(runtime):
    """A class allowing 16 work-items per group: every stage launches within it, and the map is
    the same integers as on the unnarrowed device."""
    config = mapconfig.resolve("paper", program={"grid.voxel_m": 0.5, "interpret.range_max_m": 20.0})
    narrow = as_class(runtime, "gpu-48k", max_work_group_size=16)
    maps = []
    for rt in (as_class(runtime, "gpu-48k"), narrow):
        m = Mapping.from_config(rt, config=config)
        frame = np.random.default_rng(3).normal(0, 30, m.frame_shape).round().astype(m.range_fft.dtype)
        m.fuse(frame, np.eye(4))
        maps.append(m.snapshot())
        stages = (m.range_fft, m.detection.cfar, m.detection.interpreter, m.fusion)
        if rt is narrow:
            assert all(s.local_size <= 16 for s in stages)
    assert np.array_equal(maps[0], maps[1]) and (maps[0] != 0).any()


LONG_TYPE = r"(?<![A-Za-z0-9])(u?long\d*)\b"     # also inside as_ulong(...), convert_long4(...)


def test_the_long_type_pattern_finds_casts_and_conversions():
    assert re.findall(LONG_TYPE, "as_ulong(x) + convert_long4(y); ulong8 z; long w; longer; along") == \
        ["ulong", "long4", "ulong8", "long"]


def test_a_device_without_64_bit_integers_gets_kernels_without_them(runtime):
    """Embedded-profile devices may lack 64-bit integers: every kernel the detection-statistics
    pipeline builds for such a class, preprocessed with its own options, names no long type."""
    assert shutil.which("gcc"), "this test reads the built sources through gcc's preprocessor (apt-get install gcc)"
    narrow = as_class(runtime, "embedded-32k")
    assert not narrow.limits.int64
    config = mapconfig.resolve("paper", program={"grid.voxel_m": 1.0, "interpret.model": "detstats"})
    Mapping.from_config(narrow, config=config)
    assert narrow._programs
    for kernels in narrow._programs.values():
        options = [o for o in kernels.options if o.startswith(("-D", "-I"))]
        done = subprocess.run(["gcc", "-E", "-P", "-x", "c", *options, str(kernels.source_path)],
                              capture_output=True, text=True, check=True)
        used = set(re.findall(LONG_TYPE, done.stdout))
        assert not used, f"{kernels.source_path.name} uses {sorted(used)} with {' '.join(options)}"


def test_the_pipeline_and_its_map_are_counted_against_global_memory(runtime):
    """The stages' buffers are held against global memory, the grid grows only into what is
    left, and a pipeline let go gives its share back."""
    config = mapconfig.resolve("paper", program={"grid.voxel_m": 0.5, "interpret.range_max_m": 20.0})
    roomy = as_class(runtime, "gpu-48k")
    m = Mapping.from_config(roomy, config=config)
    held = roomy.held_bytes
    assert held >= m.detection.cfar.arrays["profiles"].nbytes + m.detection.interpreter.arrays["evidence"].nbytes
    del m
    gc.collect()
    assert roomy.held_bytes == 0
    tight = as_class(runtime, "gpu-48k", global_mem_size=held + 4096)
    m = Mapping.from_config(tight, config=config)
    frame = np.zeros(m.frame_shape, m.range_fft.dtype)
    with pytest.raises(DeviceCapabilityError, match="beside the pipeline's buffers"):
        m.fuse(frame, np.eye(4))
    with pytest.raises(DeviceCapabilityError, match=r"need [\d.]+ KiB of device memory beside the .* radarcl already holds"):
        Mapping.from_config(tight, config=config)
