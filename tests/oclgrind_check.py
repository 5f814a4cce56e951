"""Every kernel file's tests on Oclgrind, a simulated OpenCL device that reports out-of-bounds
accesses, data races and failed API calls (``make check-kernels``; ``tests/test_oclgrind.py`` runs a
small slice of it in the normal suite).

How Oclgrind is hooked in: the tests of each ``kernels/<stem>.cl``, ``tests/test_<stem>.py``, run
in their own ``oclgrind --check-api --data-races --build-options -cl-opt-disable --local-mem-size
... --global-mem-size ... python -m pytest ...`` (``LOCAL_MEM``, ``GLOBAL_MEM``). The ``oclgrind``
command preloads Oclgrind's OpenCL runtime, which answers before pyopencl's ICD loader, so
pyopencl sees one platform, Oclgrind (Debian ships Oclgrind's ICD library but registers it
nowhere: /etc/OpenCL/vendors lists PoCL only), and ``RADARCL_DEVICE=oclgrind`` makes radarcl
refuse any other. ``-cl-opt-disable``: with its optimiser on, Oclgrind 21.10 computes chained vector
ternaries wrongly. ``--uninitialized`` is never used: it aborts on LLVM's ``freeze`` and calls
fill-buffer and host-pointer memory uninitialised (ARCHITECTURE.md). ``PYOPENCL_NO_CACHE`` has
pyopencl build from source, so each report quotes its source line.

A report is whatever Oclgrind writes to stderr in its formats (``reports``). Loaded into that
pytest as a plugin (``-p oclgrind_check``), this module

- fails each test during which Oclgrind reported anything, with the reports as its failure, and
  hands the counts to ``run_pytest``;
- keeps radarcl's device check to its small probe kernel: ``devices.DEVICE_CHECKS`` is emptied
  and ``radarcl.self_test.register`` made a no-op before the suite's conftest registers the
  check and chooses the device, as ``test_device_check`` does. The full check
  runs every built-in sensor's pipeline against the float64 oracle; under the simulator that
  takes minutes, again after every kernel edit (the verdict is keyed by the kernel sources), and
  it would add nothing here: every test compares its kernel with the float64 oracle, so a
  simulator that computed wrongly would fail the tests. A verdict's key names the checks run, so
  this narrower one never answers for a full one; it goes to a private cache all the same;
- answers pyopencl's "is this an NVIDIA GPU?" for Oclgrind without asking the device: pyopencl
  asks for ``CL_DEVICE_COMPUTE_CAPABILITY_MAJOR_NV`` on each new kernel, a device without NVIDIA's
  extension must refuse it, and ``--check-api`` reports the refusal. The answer is the same, None;
- makes the grid's pool chunks small (``CHUNK_BYTES``; tests/test_drive.py does the same): the
  race detector keeps a load and a store record, 48 bytes, for every byte of global memory, so a
  default 32 MiB chunk costs 1.5 GiB and tests holding a few grids exhaust the machine. Grids
  larger than a chunk take the grid's many-chunk path, which is checked with them.

The kernel files run at small sizes (``SMALL``); ``--full`` runs every test. ``--passes`` names
the passes: ``cpu`` (the device's own limits, so the CPU code paths) and GPU classes of
``tests/device_classes.py`` (``RADARCL_TEST_LIMITS``: the GPU code paths).
"""

import argparse
import codecs
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from device_classes import DEVICE_CLASSES, LIMITS_ENV

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
KERNELS = ROOT / "kernels"

OCLGRIND_FLAGS = ("--check-api", "--data-races", "--build-options", "-cl-opt-disable")
PASSES = ("cpu", "gpu-32k")
# The simulated device's memory. Oclgrind's own, 32 KiB local and 128 MiB global, is less than the
# GPU classes that tests narrow it to (a class is never granted more than the device has) and
# than the local memory the CPU paths size their work-groups by (PoCL's CPU device: 512 KiB to
# 4 MiB). So it gets a CPU device's, as PoCL's in the suite, and RADARCL_TEST_LIMITS narrows it.
LOCAL_MEM = max(1 << 20, *(c["local_mem_size"] for c in DEVICE_CLASSES.values()))
GLOBAL_MEM = max(1 << 30, *(c.get("global_mem_size", 0) for c in DEVICE_CLASSES.values()))
# Past this address space a test run fails on its own (std::bad_alloc) instead of leaving the
# machine's OOM killer to pick a process: the race detector's records grow with global memory.
MEMORY_LIMIT = 6 << 30
CHUNK_BYTES = 1 << 20                          # radarcl.grid.CHUNK_BYTES under the check
RESULTS_ENV = "RADARCL_OCLGRIND_RESULTS"       # where the plugin writes its counts (JSON)

# Small sizes: per kernel file, a pytest -k expression (a file not named runs whole). Left out
# are tests that exist for their scale or for host-side bookkeeping and whose kernel builds and
# launches other tests of the file make too.
SMALL = {
    "fusion": "not (test_one_update_per_beam_per_voxel"                     # a 4 M-voxel grid
              " or test_detstats_sums_do_not_depend_on_the_order_of_frames)",
    "fusion_cached": "not test_the_table_is_recorded_when_a_pose_comes_back",  # the plan cache
    "fusion_plan": "not test_the_plans_lose_no_voxel_at_the_papers_scale",  # 112 M voxels
    "node_reach": "not test_the_bound_holds_every_node_pair_the_voxels_read",  # a table at every voxel height
}

# The first line of each report Oclgrind 21.10 writes (src/plugins/MemCheck.cpp, RaceDetector.cpp,
# src/core/WorkGroup.cpp, WorkItem.cpp, WorkItemBuiltins.cpp, Context.cpp, src/runtime/runtime.cpp);
# the lines after it are indented ("\tKernel: ...", "\tFunction: ...") or blank.
REPORT_HEAD = re.compile(
    r"^(Invalid (read|write) of size \d+ at"            # out of bounds
    r"|Invalid (read from|write to) (write-only|read-only|buffer|mapped)"   # buffer flags, maps
    r"|Invalid memory (load|store)"                      # a pointer into no buffer
    r"|Invalid wait event"
    r"|Index \(\d+\) exceeds static array size"
    r"|Unaligned address on"
    r"|(Read-write|Write-write) data race at"            # --data-races
    r"|Work-group divergence detected"                   # a barrier or async copy not reached by all
    r"|Uninitialized value"
    r"|OCLGRIND FATAL ERROR"
    r"|Oclgrind - "                                      # --check-api: "Oclgrind - OpenCL runtime error detected"
    r"|Oclgrind: "                                       # "Oclgrind: 1000 errors generated - suppressing ..."
    r"|\[Oclgrind\] )")
# A report whose first line this version does not know still counts, by its indented body.
REPORT_BODY = re.compile(r"^\t(Kernel|Function):")


def reports(text):
    """The reports Oclgrind wrote in ``text`` (what a process or a test wrote to stderr), each as
    one string: from a known first line (``REPORT_HEAD``), or from a "Kernel:" or "Function:" line
    outside any report, up to the next line that is neither indented nor blank."""
    found, current = [], None
    for line in text.splitlines():
        if REPORT_HEAD.match(line) or (current is None and REPORT_BODY.match(line)):
            current = [line]
            found.append(current)
        elif current is not None and (not line.strip() or line[0] in " \t"):
            current.append(line)
        else:
            current = None
    return ["\n".join(lines).rstrip() for lines in found]


def oclgrind():
    """The ``oclgrind`` command, Debian's (``make test`` and ``make check-kernels`` install it): a
    missing one fails, it does not skip."""
    path = shutil.which("oclgrind")
    assert path, ("oclgrind is not installed: run make test (it installs Debian's oclgrind) or "
                  "apt-get install oclgrind")
    return path


def oclgrind_version():
    """"Oclgrind 21.10", as the command says it."""
    said = subprocess.run([oclgrind(), "--version"], capture_output=True, text=True, timeout=60).stdout
    return next((ln.strip() for ln in said.splitlines() if ln.strip().startswith("Oclgrind ")), "Oclgrind")


def run_pytest(args, limits=None, cwd=ROOT, echo=True, timeout=None, memory=MEMORY_LIMIT):
    """Run ``python -m pytest args`` in ``cwd`` under Oclgrind, with this module as a plugin and
    radarcl on the Oclgrind device, as GPU class ``limits`` (tests/device_classes.py) or with the
    device's own limits. ``echo`` copies pytest's output here as it comes; past ``timeout``
    seconds pytest is stopped, past ``memory`` bytes of address space it fails. Returns a dict:
    "exit" (pytest's status), "tests" (that ran), "passed", "failed", "skipped", "reports" (test
    id -> Oclgrind's reports), "stray" (reports outside any test), "output" (pytest's stdout),
    "timed_out", "seconds"."""
    with tempfile.TemporaryDirectory(prefix="radarcl-oclgrind-") as scratch:
        results = Path(scratch) / "results.json"
        env = dict(os.environ, RADARCL_DEVICE="oclgrind", PYOPENCL_NO_CACHE="1",
                   XDG_CACHE_HOME=str(Path(scratch) / "cache"), **{RESULTS_ENV: str(results)},
                   PYTHONPATH=os.pathsep.join(p for p in (str(TESTS), os.environ.get("PYTHONPATH")) if p))
        env.pop(LIMITS_ENV, None)
        if limits:
            env[LIMITS_ENV] = limits
        cmd = [oclgrind(), *OCLGRIND_FLAGS, "--local-mem-size", str(LOCAL_MEM), "--global-mem-size", str(GLOBAL_MEM),
               sys.executable, "-m", "pytest", "-p", "oclgrind_check", "-p", "no:cacheprovider", *args]
        started, timed_out = time.monotonic(), []

        def limit_memory():
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

        def stop():
            timed_out.append(True)
            child.kill()

        with subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, preexec_fn=limit_memory if memory else None) as child:
            err = []              # stderr on a thread of its own: neither pipe fills while the other is read
            reader = threading.Thread(target=lambda: err.append(child.stderr.read()), daemon=True)
            reader.start()
            timer = threading.Timer(timeout, stop) if timeout else None
            if timer:
                timer.start()
            out, decoder = [], codecs.getincrementaldecoder("utf-8")(errors="replace")
            while chunk := os.read(child.stdout.fileno(), 1 << 16):
                out.append(decoder.decode(chunk))
                if echo:
                    sys.stdout.write(out[-1])
                    sys.stdout.flush()
            child.wait()
            if timer:
                timer.cancel()
            reader.join()
        stderr = b"".join(err).decode(errors="replace")
        if timed_out:
            stderr += f"\n(pytest stopped after {timeout} s)\n"
        if echo and stderr.strip():
            print(stderr, end="" if stderr.endswith("\n") else "\n", file=sys.stderr, flush=True)
        counts = json.loads(results.read_text()) if results.is_file() else {}
    outcomes = list(counts.get("outcomes", {}).values())
    return dict(exit=child.returncode, tests=outcomes.count("passed") + outcomes.count("failed"),
                passed=outcomes.count("passed"), failed=outcomes.count("failed"), skipped=outcomes.count("skipped"),
                reports=counts.get("reports", {}), stray=reports(stderr) + counts.get("stray", []),
                output="".join(out), timed_out=bool(timed_out), seconds=time.monotonic() - started)


# -- the plugin, in ``oclgrind ... python -m pytest -p oclgrind_check`` --------------------------------------
_counts = dict(outcomes={}, reports={}, stray=[])


def pytest_load_initial_conftests(early_config, parser, args):
    """Before the suite's conftest chooses the device (the module docstring says why each)."""
    import pyopencl.characterize

    import radarcl.grid
    import radarcl.self_test
    from radarcl.cl import devices

    radarcl.self_test.register = lambda: None        # the suite's conftest registers the full check: not here
    devices.DEVICE_CHECKS.clear()
    radarcl.grid.CHUNK_BYTES = CHUNK_BYTES
    asked = pyopencl.characterize.nv_compute_capability

    def nv_compute_capability(device):
        return None if device.platform.name == "Oclgrind" else asked(device)

    pyopencl.characterize.nv_compute_capability = nv_compute_capability


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    """A test phase during which Oclgrind reported anything fails, with the reports."""
    report = yield
    said = "".join(text for name, text in report.sections if name == f"Captured stderr {report.when}")
    found = reports(said)
    if found:
        _counts["reports"].setdefault(report.nodeid, []).extend(found)
        report.outcome = "failed"
        report.longrepr = (f"Oclgrind reported {len(found)} problem(s) during {report.when}:\n\n"
                           + "\n\n".join(found))
    return report


def pytest_collectreport(report):
    """Reports while collecting belong to no test, and count all the same."""
    for name, text in report.sections:
        if name.startswith("Captured stderr"):
            _counts["stray"].extend(reports(text))


def pytest_runtest_logreport(report):
    """A test's outcome: failed if any phase failed, skipped (or xfailed) if it did not run to
    the end, else passed."""
    outcomes = _counts["outcomes"]
    if report.failed:
        outcomes[report.nodeid] = "failed"
    elif report.skipped and report.when in ("setup", "call"):
        outcomes[report.nodeid] = "skipped"
    elif report.when == "call":
        outcomes[report.nodeid] = "passed"


def pytest_sessionfinish(session, exitstatus):
    """Hand the counts to ``run_pytest``."""
    path = os.environ.get(RESULTS_ENV)
    if path:
        Path(path).write_text(json.dumps(_counts))


# -- make check-kernels ------------------------------------------------------------------------------------
def kernel_files():
    """(stem, its test file) of every ``kernels/*.cl`` (test_layout asserts each has one)."""
    return [(p.stem, TESTS / f"test_{p.stem}.py") for p in sorted(KERNELS.glob("*.cl"))]


def main(argv=None):
    """Run every kernel file's tests under Oclgrind once per pass, print the counts per kernel
    file and pass, and the reports; exit 1 on any report, any failed test, or a file that ran
    no test."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    parser.add_argument("stems", nargs="*", help="kernel files to check, by stem (default: every kernels/*.cl)")
    parser.add_argument("--full", action="store_true", help="every test, not the small sizes (SMALL)")
    parser.add_argument("--passes", default=",".join(PASSES),
                        help=f"comma-separated: cpu and GPU classes of tests/device_classes.py (default {','.join(PASSES)})")
    parser.add_argument("--timeout", type=float, default=3600, help="seconds per test file and pass (default 3600)")
    args = parser.parse_args(argv)
    files = [(stem, path) for stem, path in kernel_files() if not args.stems or stem in args.stems]
    unknown = sorted(set(args.stems) - {stem for stem, _ in files})
    if unknown:
        parser.error(f"no kernels/{unknown[0]}.cl")
    passes = [p.strip() for p in args.passes.split(",") if p.strip()]
    wrong = [p for p in passes if p != "cpu" and p not in DEVICE_CLASSES]
    if wrong:
        parser.error(f"--passes: {wrong[0]!r} is neither cpu nor one of {sorted(DEVICE_CLASSES)}")
    version = oclgrind_version()
    how = f"{version}, {' '.join(OCLGRIND_FLAGS)}, {'every test' if args.full else 'small sizes'}"
    print(how, flush=True)
    rows, started = [], time.monotonic()
    for name in passes:
        for stem, test_file in files:
            print(f"\n== kernels/{stem}.cl, {name}: {test_file.relative_to(ROOT)}", flush=True)
            if not test_file.is_file():
                rows.append(dict(stem=stem, name=name, missing=True))
                continue
            select = [] if args.full or stem not in SMALL else ["-k", SMALL[stem]]
            result = run_pytest(["-q", str(test_file.relative_to(ROOT)), *select],
                                limits=None if name == "cpu" else name, timeout=args.timeout)
            rows.append(dict(result, stem=stem, name=name,
                             n_reports=sum(map(len, result["reports"].values())) + len(result["stray"])))
    print(f"\nOclgrind check ({how}):")
    print(f"{'kernel file':<17} {'pass':<9} {'tests':>5} {'passed':>6} {'failed':>6} {'skipped':>7} {'reports':>7}"
          f" {'time':>6}")
    bad = []
    for row in rows:
        if row.get("missing"):
            print(f"{row['stem'] + '.cl':<17} {row['name']:<9} no tests/test_{row['stem']}.py")
            bad.append(row)
            continue
        print(f"{row['stem'] + '.cl':<17} {row['name']:<9} {row['tests']:>5} {row['passed']:>6} {row['failed']:>6} "
              f"{row['skipped']:>7} {row['n_reports']:>7} {row['seconds']:>5.0f}s"
              + ("  (stopped: --timeout)" if row["timed_out"] else ""))
        if row["n_reports"] or row["failed"] or row["exit"] != 0 or row["tests"] == 0:
            bad.append(row)
    ran = [r for r in rows if not r.get("missing")]
    print(f"{'total':<27} {sum(r['tests'] for r in ran):>5} {sum(r['passed'] for r in ran):>6} "
          f"{sum(r['failed'] for r in ran):>6} {sum(r['skipped'] for r in ran):>7} {sum(r['n_reports'] for r in ran):>7}"
          f" {time.monotonic() - started:>5.0f}s")
    for row in ran:
        for test, found in row["reports"].items():
            for text in found:
                print(f"\n{test} ({row['name']}):\n{text}")
        for text in row["stray"]:
            print(f"\nkernels/{row['stem']}.cl ({row['name']}), outside any test:\n{text}")
    if bad:
        print(f"\nFAILED: {', '.join(sorted({r['stem'] + '.cl ' + r['name'] for r in bad}))} "
              "(reports above; failed tests in each run's output)")
        return 1
    print("\nno reports: every kernel file's tests ran clean under Oclgrind")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
