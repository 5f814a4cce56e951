"""A device is checked in a child process before radarcl uses it: one whose compiler
aborts (PyPI's PoCL 3.0 on some CPUs: "LLVM ERROR: Cannot emit physreg copy instruction", exit
134) is marked unusable by `radarcl info` and never chosen, the verdict is cached per device
and driver, and a program a damaged driver cache hands back without its kernels is never used."""

import json
import os
from pathlib import Path

import pytest

from radarcl.cl import devices as dev_module
from radarcl.cl import runtime as rt_module
from radarcl.cli import main
from radarcl.errors import NoOpenCLError

HERE = Path(__file__).resolve().parent


CRASHING_SITE = HERE / "crashing_device"


@pytest.fixture
def crashing(monkeypatch, tmp_path):
    """The last listed device's check aborts in the child, whatever this CPU's PoCL does
    (``crashing_device/sitecustomize.py``); verdicts go to a private cache."""
    devices = dev_module._all_devices()
    p, d, platform, victim = devices[-1]
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(CRASHING_SITE), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("RADARCL_TEST_ABORT_ON", f"{p}:{d}")
    monkeypatch.setattr(dev_module, "DEVICE_CHECKS", [])
    monkeypatch.setattr(dev_module, "_probed", {})
    return f"{p}:{d}", victim, [dev for _, _, _, dev in devices[:-1]]


def test_a_device_whose_compiler_aborts_is_marked_unusable_and_never_chosen(crashing, capsys, monkeypatch):
    spec, victim, others = crashing
    status = main(["info"])
    usable = [dev for dev in others if dev_module.build_problem(dev) is None]    # checked by info already
    out, err = capsys.readouterr()
    block = out[out.index(f"  {spec}  ") if f"  {spec}  " in out else out.index(f"* {spec}  "):]
    unusable = [ln for ln in block.splitlines() if "UNUSABLE" in ln][0]
    assert "crashes while building or running radarcl's kernels (signal 6 (SIGABRT)" in unusable
    assert "LLVM ERROR: Cannot emit physreg copy instruction" in unusable
    assert status == (0 if usable else 2) and "Traceback" not in err
    monkeypatch.setenv("RADARCL_DEVICE", spec)                 # asked for by index: a sentence, not exit 134
    with pytest.raises(NoOpenCLError, match="crashes while building"):
        dev_module.choose_device()
    monkeypatch.delenv("RADARCL_DEVICE")
    if usable:
        assert dev_module.choose_device().int_ptr != victim.int_ptr
    else:
        with pytest.raises(NoOpenCLError, match="crashes while building"):
            dev_module.choose_device()
    # the verdict is kept per device and driver: a new process asks no child again
    verdicts = json.loads((Path(os.environ["XDG_CACHE_HOME"]) / "radarcl" / "devices.json").read_text())
    assert any("SIGABRT" in (v["problem"] or "") and v["driver"] == victim.driver_version for v in verdicts.values())
    monkeypatch.setattr(dev_module, "_probed", {})
    monkeypatch.setattr(dev_module, "_probe_in_child", lambda device: pytest.fail("the cached verdict was not used"))
    assert "SIGABRT" in dev_module.build_problem(victim)


def test_a_damaged_verdict_cache_is_ignored_and_rewritten(crashing):
    _, victim, _ = crashing
    cache = Path(os.environ["XDG_CACHE_HOME"]) / "radarcl"
    cache.mkdir(parents=True)
    (cache / "devices.json").write_text('{"x": {"problem": 5}, "torn": ')
    assert "SIGABRT" in dev_module.build_problem(victim)
    assert "SIGABRT" in json.dumps(json.loads((cache / "devices.json").read_text()))
    assert not list(cache.glob(".*.tmp"))


def test_a_program_without_its_kernels_is_built_again_past_the_cache(runtime, monkeypatch, caplog):
    """What a compiler killed mid-build left in PoCL's cache came back as a program with no
    kernels, and every later run failed with "cfar.cl has no kernel 'cfar'"."""
    from radarcl.stages import build

    real = rt_module.Runtime._build
    seen = []

    class Empty:
        def all_kernels(self):
            return []

    def damaged_once(self, path, source, options):
        seen.append(options)
        if len(seen) == 1:
            return Empty(), ""
        return real(self, path, source, options)

    fresh = rt_module.Runtime(runtime.device)
    monkeypatch.setattr(rt_module.Runtime, "_build", damaged_once)
    from radarcl.stages.cfar import Cfar

    stage = Cfar(fresh, (4,), 256)
    assert len(seen) == 2 and "-DRADARCL_CACHE_BYPASS=1" in seen[1] and "-DRADARCL_CACHE_BYPASS=1" not in seen[0]
    assert "without kernel(s) cfar" in caplog.text
    assert stage is not None and build is not None


def test_a_verdict_is_kept_only_while_the_python_it_rests_on_is_unchanged(runtime, monkeypatch):
    """The self-test's verdict rests on every module of radarcl, not only the stages and the check
    itself: a change anywhere (here one byte more in the default model's module, whose bug once
    made the check fail) is a new key, so a verdict a bug gave does not outlive its fix."""
    import radarcl.models.detstats as detstats

    assert "radarcl.self_test:self_test" in dev_module.DEVICE_CHECKS           # the suite's conftest registered it
    before = dev_module._identity(runtime.device)
    assert dev_module._identity(runtime.device) == before                       # a key, not a draw
    target = Path(detstats.__file__).resolve()
    real = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda self: real(self) + (b"#" if self.resolve() == target else b""))
    assert dev_module._identity(runtime.device) != before
