"""Put on PYTHONPATH by tests/test_device_check.py: in the device-check child, device P:D named by
RADARCL_TEST_ABORT_ON dies as PyPI's PoCL 3.0 did on AMD Zen 4 ("LLVM ERROR: Cannot emit physreg
copy instruction", SIGABRT) while its kernel is built. The test makes its crashing device itself,
so it does not depend on which PoCL crashes, fails or builds on this CPU (on Zen 5 PyPI's PoCL
fails every build before any check could abort)."""

import os

VICTIM = os.environ.get("RADARCL_TEST_ABORT_ON")

if VICTIM:
    import sys

    from radarcl.cl import devices

    real_probe = devices.probe

    def probe(device):
        place = next(f"{p}:{d}" for p, d, _, dev in devices._all_devices() if dev.int_ptr == device.int_ptr)
        if place == VICTIM:
            sys.stderr.write("LLVM ERROR: Cannot emit physreg copy instruction\n")
            sys.stderr.flush()
            os.abort()
        return real_probe(device)

    devices.probe = probe
