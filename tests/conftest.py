"""Shared fixtures: an OpenCL runtime per device under test, and the shared data.

Devices: the one radarcl chooses (RADARCL_DEVICE overrides; PoCL's CPU device in CI), or with
RADARCL_TEST_DEVICES=all every OpenCL device present that can build a kernel, so a GPU machine tests PoCL too (as
PyOpenCL's own tests parametrise over devices). Each kernel test then runs once per device,
named after it.
"""

import os
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
DEVICES_ENV = "RADARCL_TEST_DEVICES"


def _devices():
    from radarcl import self_test
    from radarcl.cl.devices import _all_devices, build_problem, choose_device

    self_test.register()          # the device check every radarcl application runs before it uses a device

    wanted = os.environ.get(DEVICES_ENV, "").strip().lower()
    if wanted == "all":
        return [device for _, _, _, device in _all_devices() if build_problem(device) is None]
    if wanted:
        raise pytest.UsageError(f"{DEVICES_ENV} must be 'all' or unset, got {wanted!r}")
    return [choose_device()]


def _device_id(device):
    return f"{device.platform.name.split()[0]}-{device.name}".replace(" ", "_")


DEVICES = _devices()


@pytest.fixture(scope="session", params=DEVICES, ids=[_device_id(d) for d in DEVICES])
def runtime(request):
    """A runtime on each device under test; with ``RADARCL_TEST_LIMITS=<class>`` narrowed to that
    GPU class (tests/device_classes.py), so the suite runs the GPU code paths."""
    from device_classes import DEVICE_CLASSES, LIMITS_ENV, narrowed
    from radarcl.cl import Runtime

    cls = os.environ.get(LIMITS_ENV, "").strip()
    if not cls:
        return Runtime(request.param)
    if cls not in DEVICE_CLASSES:
        raise pytest.UsageError(f"{LIMITS_ENV} must be one of {sorted(DEVICE_CLASSES)}, got {cls!r}")
    return Runtime(request.param, limits=narrowed(request.param, cls))


@pytest.fixture(scope="session")
def shared_data():
    """../shared/data beside the checkout (present in CI); its absence is a setup error."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared data not found at {SHARED_DATA}; tests expect ../shared/data beside the checkout")
    return SHARED_DATA


def interactive_signals():
    """``preexec_fn`` for a child that is sent Ctrl-C: SIGINT delivered as a terminal delivers it.
    A harness that starts the suite in the background (make, nohup) may hand it SIGINT ignored,
    which every child would inherit and Python would keep, so a Ctrl-C test would test nothing."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
