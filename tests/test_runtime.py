"""OpenCL runtime: device choice, memoised builds, clear errors."""

import numpy as np
import pytest

from radarcl.cl import Runtime, choose_device, device_report, kernels_dir
from radarcl.cl import devices as dev_module
from radarcl.cl import runtime as rt_module
from radarcl.errors import KernelBuildError, NoOpenCLError


def test_device_override_by_name_and_index(monkeypatch):
    default = choose_device()
    monkeypatch.setenv("RADARCL_DEVICE", default.name[:6])
    assert choose_device().int_ptr == default.int_ptr
    monkeypatch.setenv("RADARCL_DEVICE", "0:0")
    assert choose_device() is not None
    monkeypatch.setenv("RADARCL_DEVICE", "no-such-device")
    with pytest.raises(NoOpenCLError, match="matches no device; available: 0:0"):
        choose_device()


def test_a_device_that_cannot_build_is_passed_over_and_named(monkeypatch):
    """PyPI's PoCL 3.0 lists itself on CPUs its LLVM 14 does not know, then fails every build
    ("unknown target CPU 'generic'"): the default choice passes over it, asking for it by name
    says why not, and `radarcl info` marks it."""
    default = choose_device()
    reason = "cannot build kernels (error: unknown target CPU 'generic'); install a newer PoCL"
    monkeypatch.setattr(dev_module, "_probed", {default.int_ptr: dict(problem=reason, notes=[])})
    chosen = [dev for _, _, _, dev in dev_module._all_devices() if dev_module.build_problem(dev) is None]
    if chosen:
        assert choose_device(spec="").int_ptr == chosen[0].int_ptr != default.int_ptr
    else:
        with pytest.raises(NoOpenCLError, match="no OpenCL device can run radarcl's kernels: .*unknown target CPU"):
            choose_device(spec="")
    with pytest.raises(NoOpenCLError, match="which cannot build kernels .*unknown target CPU 'generic'"):
        choose_device(spec=default.name)
    assert any(line.strip() == f"UNUSABLE       {reason}" for line in device_report())


def test_the_probe_reports_a_failed_build(monkeypatch):
    monkeypatch.setattr(dev_module, "_probed", {})
    monkeypatch.setattr(dev_module, "_PROBE_SOURCE", "__kernel void probe(__global float *x) { x[0] = nope; }")
    problem = dev_module.build_problem(dev_module._all_devices()[0][3])
    assert problem.startswith("cannot build kernels (") and "nope" in problem


def test_no_platform_says_how_to_get_pocl(monkeypatch):
    import pyopencl as cl

    def no_platforms():
        raise cl.Error("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")

    monkeypatch.setattr(cl, "get_platforms", no_platforms)
    with pytest.raises(NoOpenCLError, match="pip install pocl-binary-distribution"):
        choose_device(spec="")


def test_builds_are_memoised_and_kernels_fetched_once(runtime):
    a = runtime.kernels("range_fft", _defines())
    b = runtime.kernels("range_fft", _defines())
    assert a is b and a["range_fft"] is b["range_fft"]
    other = runtime.kernels("range_fft", {**_defines(), "POWER": 1})
    assert other is not a


def test_build_failure_names_file_options_and_log(runtime, tmp_path, monkeypatch):
    (tmp_path / "radarcl_common.h").write_text("")
    (tmp_path / "broken.cl").write_text("__kernel void broken(__global float *x) { x[0] = undefined_name; }\n")
    monkeypatch.setattr(rt_module, "kernels_dir", lambda: tmp_path)
    with pytest.raises(KernelBuildError) as info:
        Runtime(runtime.device).kernels("broken", {"ANSWER": 42})
    message = str(info.value)
    assert "broken.cl" in message and "-DANSWER=42" in message and "undefined_name" in message


def test_shared_constants_have_one_source(runtime):
    """The header holds no values: a build without radarcl's -D constants stops with a sentence,
    and the kernels see exactly the Python values (interpret flags a silent beam with
    oracle.FLAG_SILENT and clamps evidence at logodds.EVIDENCE_LIMIT)."""
    from radarcl import logodds, oracle
    from radarcl.config.stage_config import CfarConfig, InterpretConfig
    from radarcl.pipeline import Detection
    from radarcl.stages import COMMON_DEFINES

    bare = {k: v for k, v in _defines().items() if k not in COMMON_DEFINES}
    with pytest.raises(KernelBuildError, match="come from radarcl.stages.COMMON_DEFINES"):
        runtime.kernels("range_fft", bare)
    profiles = np.ones((2, 64), np.float32)
    profiles[0] = 0.0                                     # silent beam
    profiles[1, 30] = 1e30                                # a pulse beyond 16 nat
    detection = Detection(runtime, (2,), 64, 0.5, CfarConfig(guard=2, train=4),
                          InterpretConfig(k_occ=10.0, range_min_m=0.0, range_max_m=31.5))
    result = detection(profiles).interpret
    assert result.flags[0] == oracle.FLAG_SILENT
    assert result.evidence[1].max() == logodds.EVIDENCE_LIMIT


def test_kernels_are_called_by_name_as_their_source_declares(runtime):
    """The signature is read from the .cl file: a missing, unknown or ill-typed argument is a
    sentence, not a wrong launch."""
    import pyopencl.array as cla

    from radarcl.errors import ConfigError, ShapeError

    f = runtime.kernels("range_fft", _defines())["range_fft"]
    assert f.names == ("samples", "window", "twiddle", "scale", "clip_level", "n_beams", "profiles", "flags",
                       "scratch")
    q = runtime.queue
    bufs = {n: cla.empty(q, 64, np.float32)
            for n in ("samples", "window", "twiddle", "scale", "profiles", "flags", "scratch")}
    with pytest.raises(ConfigError, match="missing \\['n_beams'\\]"):
        f(q, (2,), (2,), clip_level=1.0, **bufs)
    with pytest.raises(ConfigError, match="unknown \\['beams'\\]"):
        f(q, (2,), (2,), clip_level=1.0, n_beams=1, beams=2, **bufs)
    with pytest.raises(ConfigError, match="n_beams = 4294967296 does not fit int"):
        f(q, (2,), (2,), clip_level=1.0, n_beams=2 ** 32, **bufs)
    with pytest.raises(ShapeError, match="samples must be a device array"):
        f(q, (2,), (2,), clip_level=1.0, n_beams=1, **{**bufs, "samples": np.zeros(8, np.float32)})


def test_missing_kernel_name_is_explained(runtime):
    with pytest.raises(KeyError, match="range_fft.cl has no kernel 'nope'"):
        runtime.kernels("range_fft", _defines())["nope"]


def test_info_lists_the_chosen_device():
    lines = device_report()
    assert any(line.startswith("* ") for line in lines)
    assert any("int32 atomics  yes" in line for line in lines)


def test_kernels_dir_has_the_common_header():
    assert (kernels_dir() / "radarcl_common.h").is_file()


def _defines():
    from radarcl.stages import COMMON_DEFINES

    return dict(COMMON_DEFINES, N_FFT=8, N_SAMPLES=8, M=8, LOG2_M=3, P=1, LOG2_P=0, N_BINS=4, LOCAL_SIZE=2,
                INPUT_KIND=0, WINDOWED=1, POWER=0, CHECK_FINITE=1, VEC=1, SAMPLE_LIMIT=1e16)


def test_float_defines_are_exact():
    assert rt_module._define("X", 0.1) == "-DX=0.1f" and rt_module._define("B", True) == "-DB=1"
    assert float(rt_module._define("X", 1e-7)[4:-1]) == np.float64(1e-7)


def test_kernel_tests_run_on_every_device_when_asked():
    """RADARCL_TEST_DEVICES=all parametrises the runtime fixture over every OpenCL device that
    can build a kernel."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    from radarcl.cl.devices import _all_devices, build_problem

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "RADARCL_TEST_DEVICES": "all"}
    out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                          "tests/test_cfar.py::test_exact_on_integer_valued_profiles"],
                         cwd=root, env=env, capture_output=True, text=True).stdout
    collected = [line for line in out.splitlines() if line.startswith("tests/test_cfar.py::")]
    assert len(collected) == len([d for *_, d in _all_devices() if build_problem(d) is None]) >= 1
    env["RADARCL_TEST_DEVICES"] = "some"
    bad = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                          "tests/test_cfar.py"], cwd=root, env=env, capture_output=True, text=True)
    assert bad.returncode != 0 and "must be 'all' or unset" in bad.stdout + bad.stderr


def test_pocl_workers_are_pinned_only_where_safe(monkeypatch):
    """POCL_AFFINITY=1 by default; never over the user's value, never with a limited worker
    count (one-thread workers would all be pinned to CPU 0), never where some CPU is not
    allowed to the process (PoCL stops the process when a pin is refused)."""
    from radarcl.cl.devices import pin_pocl_workers

    n = 4
    monkeypatch.setattr("os.cpu_count", lambda: n)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(n)), raising=False)
    env = {}
    assert pin_pocl_workers(env) == "1" and env == {"POCL_AFFINITY": "1"}
    env = {"POCL_AFFINITY": "0"}
    assert pin_pocl_workers(env) == "0" and env == {"POCL_AFFINITY": "0"}
    env = {"POCL_MAX_PTHREAD_COUNT": "1"}
    assert pin_pocl_workers(env) is None and "POCL_AFFINITY" not in env
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {2, 3}, raising=False)
    env = {}
    assert pin_pocl_workers(env) is None and env == {}
