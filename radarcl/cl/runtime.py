"""Program builds memoised per context, kernels fetched once (the device is chosen by
``radarcl.cl.devices``).

A ``Runtime`` owns one context and one in-order queue. Kernel programs come from the
``kernels/`` directory (``radarcl/kernels`` once installed), built with ``-I`` on that
directory so ``#include "radarcl_common.h"`` works and PoCL's cache follows header edits,
and with ``-D`` switches that specialise a kernel (disabled features cost nothing).
"""

import logging
import weakref

from radarcl.cl.devices import _cl, _quiet_build, choose_device, kernels_dir
from radarcl.cl.limits import DeviceLimits, size_text
from radarcl.cl.signature import KernelFunction, parse_kernels
from radarcl.errors import DeviceCapabilityError, KernelBuildError

log = logging.getLogger(__name__)


class KernelSet:
    """The kernels of one built program, fetched once (``program.name`` would make a new
    ``cl.Kernel`` on every access), each called by argument name as its ``.cl`` signature
    declares them (``radarcl.cl.signature``)."""

    def __init__(self, program, source_path, options, source):
        self.program = program
        self.source_path = source_path
        self.options = options
        signatures = parse_kernels(source, source_path)
        self._kernels = {}
        for kernel in program.all_kernels():
            name = kernel.function_name
            if name not in signatures:
                raise KernelBuildError(f"{source_path}: kernel {name} was built but its signature was not "
                                       "found in the source")
            self._kernels[name] = KernelFunction(kernel, signatures[name], source_path)

    def __getitem__(self, name):
        """The ``KernelFunction`` called ``name``."""
        try:
            return self._kernels[name]
        except KeyError:
            raise KeyError(f"{self.source_path.name} has no kernel {name!r}; it has "
                           f"{sorted(self._kernels)}") from None


def _define(name, value):
    if isinstance(value, bool):
        value = int(value)
    if isinstance(value, float):
        value = repr(float(value)) + "f"
    return f"-D{name}={value}"


class Runtime:
    """One OpenCL context and in-order queue on one device, with memoised program builds.

    ``limits`` (default: the device's own, ``DeviceLimits.of``) are what every stage honours;
    ``held_bytes`` counts the device memory the stages of this runtime hold (``hold``), which the
    grid's growth leaves room for."""

    def __init__(self, device=None, profiling=False, limits=None):
        cl = _cl()
        self.device = device if device is not None else choose_device()
        self.limits = DeviceLimits.of(self.device) if limits is None else limits
        self.context = cl.Context([self.device])
        props = cl.command_queue_properties.PROFILING_ENABLE if profiling else 0
        self.queue = cl.CommandQueue(self.context, properties=props)
        self._programs = {}
        self.held_bytes = 0

    @property
    def name(self):
        """'platform / device' of this runtime (with the narrowed limits, if any)."""
        return self.limits.name

    @property
    def is_cpu(self):
        """True for a CPU device (PoCL's pthread device, for instance) not narrowed to a GPU's limits."""
        return self.limits.is_cpu

    def hold(self, owner, nbytes, what):
        """Count ``nbytes`` of device memory held by ``owner`` until it is collected; raises
        DeviceCapabilityError, before anything is allocated, when everything held would pass
        the device's global memory."""
        nbytes = int(nbytes)
        total = self.held_bytes + nbytes
        if total > self.limits.global_mem_size:
            raise DeviceCapabilityError(
                f"{what} need {size_text(nbytes)} of device memory beside the {size_text(self.held_bytes)} "
                f"radarcl already holds; {self.name} has {size_text(self.limits.global_mem_size)} (radarcl info)")
        self.held_bytes = total
        weakref.finalize(owner, self._release, nbytes)

    def _release(self, nbytes):
        self.held_bytes -= nbytes

    def kernels(self, stem, defines=None):
        """Build ``kernels/<stem>.cl`` with ``-D`` ``defines`` (memoised) and return its KernelSet."""
        directory = kernels_dir()
        path = directory / f"{stem}.cl"
        options = [f"-I{directory}"] + [_define(k, v) for k, v in sorted((defines or {}).items())]
        key = (stem, tuple(options))
        cached = self._programs.get(key)
        if cached is not None:
            return cached
        try:
            source = path.read_text()
        except OSError as exc:
            raise KernelBuildError(f"cannot read kernel source {path}: {exc}") from exc
        program, said = self._build(path, source, options)
        declared = set(parse_kernels(source, path))
        missing = declared - {k.function_name for k in program.all_kernels()}
        if missing:
            # A program that lacks kernels its source declares comes from a damaged driver cache (a
            # compiler killed mid-build by an earlier process): never used; built again under
            # options the damaged entry does not match.
            log.warning("%s built on %s without kernel(s) %s (a damaged driver cache, e.g. PoCL's); building it "
                        "again past the cache", path.name, self.name, ", ".join(sorted(missing)))
            program, said = self._build(path, source, options + ["-DRADARCL_CACHE_BYPASS=1"])
            missing = declared - {k.function_name for k in program.all_kernels()}
            if missing:
                raise KernelBuildError(f"building {path} on {self.name} gave no kernel {', '.join(sorted(missing))} "
                                       "even past the driver's cache; this device cannot run radarcl")
        log.debug("built %s with %s%s", path.name, options, f"; the compiler said:\n{said}" if said else "")
        kernel_set = KernelSet(program, path, options, source)
        self._programs[key] = kernel_set
        return kernel_set

    def _build(self, path, source, options):
        """(the built program, what the compiler said) of ``source``, or KernelBuildError with the log."""
        cl = _cl()
        program = cl.Program(self.context, source)
        try:
            with _quiet_build() as said:
                program.build(options=options)
        except cl.Error as exc:
            try:
                build_log = program.get_build_info(self.device, cl.program_build_info.LOG)
            except cl.Error:
                build_log = "(no build log)"
            raise KernelBuildError(f"building {path} failed on {self.name}\n"
                                   f"options: {' '.join(options)}\nlog:\n{build_log or exc}") from exc
        return program, said[0]

    def max_local_size(self, kernel):
        """Largest work-group size this device allows for ``kernel`` (a ``KernelFunction`` or
        a ``pyopencl.Kernel``)."""
        cl = _cl()
        kernel = getattr(kernel, "kernel", kernel)
        return int(min(self.limits.max_work_group_size,
                       kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, self.device)))

    def empty(self, nbytes):
        """A new read-write device buffer of ``nbytes`` bytes (at least 1)."""
        cl = _cl()
        return cl.Buffer(self.context, cl.mem_flags.READ_WRITE, size=max(1, int(nbytes)))
