"""Shared fixtures: one OpenCL runtime per session, on the device radarcl chooses
(RADARCL_DEVICE overrides; PoCL's CPU device in CI)."""

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def runtime():
    from radarcl.cl import Runtime

    return Runtime()


@pytest.fixture(scope="session")
def shared_data():
    """../shared/data beside the checkout (present in CI); its absence is a setup error."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared data not found at {SHARED_DATA}; tests expect ../shared/data beside the checkout")
    return SHARED_DATA
