"""Which OpenCL device radarcl runs on: the devices listed, each checked in a child process
before it is used (``build_problem``: a small kernel, then the application's ``DEVICE_CHECKS``),
the verdicts cached per device, driver and the sources checked (kernels and Python), the choice
among the usable ones (``choose_device``) and ``radarcl info``'s report (``device_report``).
``radarcl.cl.runtime`` builds and runs the kernels on the chosen device.
"""

import contextlib
import hashlib
import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from radarcl.cl.limits import DeviceLimits
from radarcl.errors import KernelBuildError, NoOpenCLError

log = logging.getLogger(__name__)

DEVICE_ENV = "RADARCL_DEVICE"
"""Environment variable that picks the device: ``P:D`` indices (``0:0``) or a
case-insensitive substring of "platform / device" (``pocl``, ``nvidia``)."""

_INSTALL_HINT = ("No OpenCL platform was found. radarcl runs on any OpenCL 1.2 device; on a "
                 "machine without one, install PoCL for the CPU with "
                 "'pip install pocl-binary-distribution' (a dependency of radarcl, so "
                 "reinstalling radarcl with pip also brings it).")


AFFINITY_ENV = "POCL_AFFINITY"
"""PoCL's switch that pins its CPU driver's worker thread i to CPU i. radarcl sets it to 1
before PoCL starts, unless it is set already (``POCL_AFFINITY=0`` keeps the scheduler free)
or this process may not run on every CPU (PoCL stops the process when a pin is refused).
Unpinned, the workers follow the host thread between the planning and the kernels and lose
their caches (docs/measured-figures.md, "Why the code is shaped so")."""


def pin_pocl_workers(environ=None):
    """Set ``POCL_AFFINITY=1`` in ``environ`` (default ``os.environ``) where that is safe:
    not set by the user, PoCL's worker count not limited (``POCL_MAX_PTHREAD_COUNT``), and
    every CPU allowed to this process. Returns the value in force
    ("1", the user's, or None: left unset). Called before PoCL starts; later it changes
    nothing."""
    environ = os.environ if environ is None else environ
    if AFFINITY_ENV in environ:
        return environ[AFFINITY_ENV]
    if "POCL_MAX_PTHREAD_COUNT" in environ:     # fewer workers than CPUs, e.g. one per process
        return None                             # (fuse-many): pinned, they would share CPU 0
    try:
        allowed = os.sched_getaffinity(0)
    except (AttributeError, OSError):          # not Linux: PoCL ignores the switch there
        return None
    if allowed != set(range(os.cpu_count() or 0)):
        return None
    environ[AFFINITY_ENV] = "1"
    return "1"


def _cl():
    """Import pyopencl lazily so that io/, config and the viewer never need it; PoCL's CPU
    workers are pinned first (``pin_pocl_workers``, once per process)."""
    global _pin_checked
    if not _pin_checked:
        pin_pocl_workers()
        _pin_checked = True
    import pyopencl

    return pyopencl


_pin_checked = False


def kernels_dir():
    """Directory holding the ``.cl`` sources: ``radarcl/kernels`` when installed, ``kernels/``
    beside the package in a source checkout."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "kernels", here.parent / "kernels"):
        if (candidate / "radarcl_common.h").is_file():
            return candidate
    raise KernelBuildError(f"kernel sources not found beside {here} (looked for radarcl_common.h "
                           "in radarcl/kernels and ../kernels); reinstall radarcl")


def _all_devices():
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # PoCL-less pyopencl raises PLATFORM_NOT_FOUND_KHR here
        raise NoOpenCLError(f"{_INSTALL_HINT} (pyopencl said: {exc})") from exc
    found = []
    for p_index, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for d_index, device in enumerate(devices):
            found.append((p_index, d_index, platform, device))
    if not found:
        raise NoOpenCLError(_INSTALL_HINT)
    return found


_PROBE_SOURCE = "__kernel void probe(__global float *x) { x[get_global_id(0)] = sqrt(x[get_global_id(0)]); }"
_probed = {}                                  # device -> its verdict: {"problem": None or why, "notes": [...]}

_UNKNOWN_CPU_HINT = ("this PoCL's LLVM does not know this CPU (PyPI's PoCL 3.0 has LLVM 14, which "
                     "predates AMD Zen 4/5); install a newer PoCL, e.g. Debian's pocl-opencl-icd "
                     "(make test and make demo do it where they can)")

DEVICE_CHECKS = []
"""What the child process runs on a device before radarcl uses it, after the small kernel:
"module:function" names of checks taking a ``Runtime`` and returning None or the reason the
device cannot be used, or a dict ``{"problem": None or why, "notes": [sentences]}`` where the
device is usable but not for everything (a sensor it cannot fit: ``device_notes``). The runtime
sits below what it checks, so the application registers the checks (``register_device_check``:
``radarcl.self_test.register``, whose ``self_test`` builds every kernel of every built-in
pipeline and compares a frame with the float64 oracle)."""
_COVERS = {}                                  # check name -> modules whose sources its verdict rests on


def register_device_check(function, covers=()):
    """Have the child check devices with ``function`` (a module-level function taking a
    ``Runtime``, returning None or a reason) before any is used; registering twice is once.
    ``covers``: further modules or packages (dotted names; a package: every module in it) whose
    sources the verdict rests on besides the function's own (the pipeline it builds): a verdict
    is kept until one of them changes."""
    name = f"{function.__module__}:{function.__qualname__}"
    if name not in DEVICE_CHECKS:
        DEVICE_CHECKS.append(name)
        _COVERS[name] = tuple(covers)
        _probed.clear()                         # verdicts without this check do not answer for it
PROBE_TIMEOUT_S = 600
VERDICTS = "devices.json"


def cache_dir():
    """radarcl's cache: $XDG_CACHE_HOME/radarcl (default ~/.cache/radarcl)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(root) / "radarcl"


def build_problem(device):
    """None when ``device`` can run radarcl, else the reason it cannot (memoised per process, and
    across processes in ``cache_dir()/devices.json`` per device, driver version, radarcl version and
    kernel sources).

    A device can be listed and still fail: PyPI's PoCL 3.0 (LLVM 14) gets 'generic' for CPUs newer
    than LLVM 14 (AMD family 26) and every build fails with "unknown target CPU 'generic'"; on
    other CPUs its LLVM aborts the whole process while compiling a kernel ("Cannot emit physreg
    copy instruction", exit 134). So the check runs in a child process (``radarcl.cl.probe``):
    a small kernel, then the ``DEVICE_CHECKS``. A child that dies, fails a build, computes wrong results
    or runs past ``PROBE_TIMEOUT_S`` makes the device unusable, with the reason."""
    return _verdict(device)["problem"]


def device_notes(device):
    """What the check said of a usable ``device`` beside its verdict: sentences naming what it
    cannot run (a built-in sensor whose buffers do not fit it), [] when nothing."""
    return _verdict(device)["notes"]


def _verdict(device):
    key = device.int_ptr
    if key not in _probed:
        identity = _identity(device)
        verdicts = _read_verdicts()
        cached = verdicts.get(identity)
        if cached is not None:
            _probed[key] = dict(problem=cached["problem"], notes=cached.get("notes", []))
        else:
            verdict = _probe_in_child(device)
            _probed[key] = verdict
            verdicts[identity] = dict(verdict, device=f"{device.platform.name} / {device.name}",
                                      driver=device.driver_version, checked=time.strftime("%Y-%m-%dT%H:%M:%S"))
            _write_verdicts(verdicts)
    return _probed[key]


def _identity(device):
    """The key of a device's verdict: what it is, its driver, and what was checked on it: the
    kernel sources, and the Python that sizes and runs them (the stages, ``cl``, the checks'
    modules and the modules and packages they cover)."""
    from radarcl import __version__

    h = hashlib.sha256()
    for part in (device.platform.name, device.platform.version, device.name, device.version, device.driver_version,
                 __version__, _PROBE_SOURCE, *DEVICE_CHECKS):
        h.update(str(part).encode() + b"\0")
    package = Path(__file__).resolve().parent.parent
    try:
        sources = [*sorted(kernels_dir().iterdir()), *sorted((package / "stages").glob("*.py")),
                   *sorted((package / "cl").glob("*.py"))]
        modules = [m for name in DEVICE_CHECKS for m in (name.partition(":")[0], *_COVERS.get(name, ()))]
        for m in modules:
            path = package.parent / m.replace(".", "/")
            sources += sorted(path.rglob("*.py")) if path.is_dir() else [path.with_suffix(".py")]
        for p in sources:
            if p.is_file():
                h.update(str(p.relative_to(package.parent) if p.is_relative_to(package.parent) else p.name).encode()
                         + b"\0" + p.read_bytes())
    except (KernelBuildError, OSError):
        pass
    return h.hexdigest()


def _read_verdicts():
    """The cached verdicts, each checked; a file that is damaged or not ours counts as empty."""
    try:
        data = json.loads((cache_dir() / VERDICTS).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {k: v for k, v in data.items() if isinstance(k, str) and isinstance(v, dict)
            and (v.get("problem") is None or isinstance(v.get("problem"), str))
            and isinstance(v.get("notes", []), list) and all(isinstance(n, str) for n in v.get("notes", []))}


def _write_verdicts(verdicts):
    """Write the verdicts through a temporary file renamed over the cache (atomic for readers);
    a cache that cannot be written is only a cache."""
    directory = cache_dir()
    tmp = directory / f".{VERDICTS}.{os.getpid()}.tmp"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(verdicts, indent=1))
        os.replace(tmp, directory / VERDICTS)
    except OSError as exc:
        log.debug("cannot write the device verdicts in %s: %s", directory, exc)
        with contextlib.suppress(OSError):
            tmp.unlink()


def _probe_in_child(device):
    """Run ``radarcl.cl.probe`` on ``device`` in a child process: its verdict, a dict of
    "problem" (None or the reason it is unusable) and "notes" (what it cannot run)."""
    place = next(((p, d) for p, d, _, dev in _all_devices() if dev.int_ptr == device.int_ptr), None)
    if place is None:
        return dict(problem="is not among the listed devices", notes=[])
    cmd = [sys.executable, "-m", "radarcl.cl.probe", str(place[0]), str(place[1]), *DEVICE_CHECKS]
    env = dict(os.environ, RADARCL_PROBE_SOURCE=_PROBE_SOURCE)
    log.debug("checking %s / %s in a child process", device.platform.name, device.name)
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=PROBE_TIMEOUT_S, env=env,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return dict(problem=f"did not finish radarcl's self-test in {PROBE_TIMEOUT_S} s", notes=[])
    except OSError as exc:
        return dict(problem=f"could not be checked ({exc})", notes=[])
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith(PROBE_MARK)]
    if done.returncode == 0 and lines:
        try:
            said = json.loads(lines[-1][len(PROBE_MARK):])
            problem, notes = said["problem"], said.get("notes", [])
            if (problem is None or isinstance(problem, str)) and isinstance(notes, list) \
                    and all(isinstance(n, str) for n in notes):
                return dict(problem=problem, notes=list(notes))
        except (ValueError, KeyError, TypeError):
            pass
    said = [ln for ln in done.stderr.strip().splitlines() if ln.strip()]
    last = said[-1].strip() if said else ""
    if done.returncode < 0:
        how = f"signal {-done.returncode}" + (f" ({signal.Signals(-done.returncode).name})" if
                                              -done.returncode in signal.valid_signals() else "")
        return dict(problem=f"crashes while building or running radarcl's kernels ({how}: {last or 'no message'})",
                    notes=[])
    return dict(problem=f"failed radarcl's self-test (exit {done.returncode}: {last or 'no message'})", notes=[])


PROBE_MARK = "radarcl-probe: "


def probe(device):
    """In the child (``radarcl.cl.probe``): None when ``device`` builds and runs the small probe
    kernel, else why not."""
    cl = _cl()
    source = os.environ.get("RADARCL_PROBE_SOURCE", _PROBE_SOURCE)
    try:
        program = cl.Program(cl.Context([device]), source)
        with _quiet_build():
            program.build()
    except cl.Error as exc:
        try:
            said = program.get_build_info(device, cl.program_build_info.LOG).strip()
        except (cl.Error, UnboundLocalError):
            said = ""
        said = said.splitlines()[0] if said else str(exc).splitlines()[0]
        hint = f"; {_UNKNOWN_CPU_HINT}" if "unknown target CPU" in said else ""
        return f"cannot build kernels ({said}){hint}"
    return None


def choose_device(spec=None):
    """Pick the OpenCL device radarcl runs on.

    ``spec`` (or the ``RADARCL_DEVICE`` environment variable when ``spec`` is None) selects by
    ``"P:D"`` indices or by a substring of "platform / device". Without either, a GPU is
    preferred and PoCL's CPU device is the fallback, among the devices that pass radarcl's check
    (``build_problem``; checked in that order, so only as many as needed). Raises
    ``NoOpenCLError`` when nothing fits.
    """
    cl = _cl()
    spec = os.environ.get(DEVICE_ENV) if spec is None else spec
    found = _all_devices()
    if spec:
        spec = spec.strip()
        parts = spec.split(":")
        if len(parts) == 2 and all(p.isdigit() for p in parts):
            matches = [dev for p, d, _, dev in found if (p, d) == (int(parts[0]), int(parts[1]))]
        else:
            matches = [dev for _, _, pl, dev in found if spec.lower() in f"{pl.name} / {dev.name}".lower()]
        if matches:
            usable = next((dev for dev in matches if build_problem(dev) is None), None)
            if usable is not None:
                return usable
            raise NoOpenCLError(f"{DEVICE_ENV}={spec!r} picks {matches[0].platform.name} / {matches[0].name}, "
                                f"which {build_problem(matches[0])}")
        listing = "; ".join(f"{p}:{d} {pl.name} / {dev.name}" for p, d, pl, dev in found)
        raise NoOpenCLError(f"{DEVICE_ENV}={spec!r} matches no device; available: {listing}")
    order = sorted(found, key=lambda f: (not f[3].type & cl.device_type.GPU,
                                         "portable computing language" not in f[2].name.lower()))
    chosen = next((dev for _, _, _, dev in order if build_problem(dev) is None), None)
    if chosen is None:
        problems = "; ".join(f"{pl.name} / {dev.name}: {build_problem(dev)}" for _, _, pl, dev in found)
        raise NoOpenCLError(f"no OpenCL device can run radarcl's kernels: {problems}")
    return chosen


def device_report():
    """Lines describing every platform and device, with what radarcl's kernels need."""
    cl = _cl()
    try:
        chosen = choose_device()
    except NoOpenCLError:  # still list what is there; the caller says why none was chosen
        chosen = None
    lines = []
    for p_index, d_index, platform, device in _all_devices():
        ext = device.extensions.split()
        mark = "*" if chosen is not None and device.int_ptr == chosen.int_ptr else " "
        lines += [
            f"{mark} {p_index}:{d_index}  {platform.name} ({platform.version})",
            f"      device         {device.name} [{cl.device_type.to_string(device.type)}]",
            f"      OpenCL C       {device.opencl_c_version}",
            f"      compute units  {device.max_compute_units}, max work-group {device.max_work_group_size}",
            f"      memory         global {device.global_mem_size / 2**30:.1f} GiB, "
            f"largest buffer {device.max_mem_alloc_size / 2**30:.2f} GiB, "
            f"local {device.local_mem_size // 1024} KiB",
            f"      int32 atomics  {'yes' if 'cl_khr_global_int32_base_atomics' in ext else 'no'}, "
            f"int64 atomics {'yes' if 'cl_khr_int64_base_atomics' in ext else 'no'}, "
            f"64-bit integers {'yes' if DeviceLimits.of(device).int64 else 'no (kernels built without)'}, "
            f"fp64 {'yes' if 'cl_khr_fp64' in ext else 'no (not needed)'}",
        ]
        if build_problem(device):
            lines.append(f"      UNUSABLE       {build_problem(device)}")
        else:
            lines.append("      checked        builds and runs every kernel, agrees with the float64 oracle")
            lines += [f"      cannot run     {note}" for note in device_notes(device)]
    lines.append(f"(* = chosen; set {DEVICE_ENV}=P:D or a name substring to override)")
    pinned = os.environ.get(AFFINITY_ENV)
    lines.append(f"PoCL CPU workers pinned to cores: {'yes' if pinned == '1' else 'no'} ({AFFINITY_ENV}="
                 f"{pinned if pinned is not None else 'unset'}; radarcl sets 1 unless it is set or unsafe)")
    return lines


@contextlib.contextmanager
def _quiet_build():
    """Keep the compiler's notes off the user's terminal: PoCL's clang writes "N warnings
    generated." to file descriptor 2 and pyopencl repeats the log as a CompilerWarning (here
    notes on the ABI of 16-lane vectors on CPUs without AVX-512, nothing to act on). Both go to
    the debug log (``radarcl -v``); a failed build still reports its log in the error."""
    import tempfile
    import warnings

    said = [""]
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as sink, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said[0] = (sink.read().decode(errors="replace") + "".join(str(w.message) for w in caught)).strip()
