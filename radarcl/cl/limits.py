"""What a device allows (``DeviceLimits``), read in one place.

Every stage sizes its work by ``runtime.limits``, never by the device's own attributes, so one
class says what radarcl honours: local memory per work-group, the largest buffer, global memory,
work-group size, 64-bit integers. ``DeviceLimits.narrowed`` gives a CPU device a GPU's limits,
so the GPU code paths (one job per work-item, global-memory scratch where local memory is short)
run and are checked against the float64 oracle on machines without a GPU.
"""

import dataclasses


@dataclasses.dataclass(frozen=True)
class DeviceLimits:
    """What a device allows, read once: every stage sizes its work by these, never by the device
    directly, so that one place says what radarcl honours and a test can narrow them
    (``narrowed``) to run the GPU code paths on a CPU device under a GPU's limits."""

    name: str                      # "platform / device", for error messages
    is_cpu: bool                   # CPU code paths (SIMD across a work-item's vector lanes)
    local_mem_size: int            # bytes of local memory per work-group
    max_mem_alloc_size: int        # bytes of the largest single buffer
    global_mem_size: int           # bytes of global memory
    max_work_group_size: int       # work-items per work-group
    fp64: bool                     # doubles (no kernel needs them; reported)
    int64: bool                    # 64-bit integers in kernels (optional in the embedded profile)

    @classmethod
    def of(cls, device):
        """The limits ``device`` reports."""
        import pyopencl as cl

        ext = device.extensions.split()
        return cls(name=f"{device.platform.name} / {device.name}", is_cpu=bool(device.type & cl.device_type.CPU),
                   local_mem_size=int(device.local_mem_size), max_mem_alloc_size=int(device.max_mem_alloc_size),
                   global_mem_size=int(device.global_mem_size), max_work_group_size=int(device.max_work_group_size),
                   fp64="cl_khr_fp64" in ext,
                   int64="EMBEDDED" not in device.profile.upper() or "cles_khr_int64" in ext)

    def narrowed(self, label=None, **changes):
        """These limits with ``changes``, each no more than the device allows (a narrowed device
        still runs on the real one): sizes no larger, features only taken away, and ``is_cpu``
        only turned off (GPU code paths run anywhere; CPU ones assume a CPU's local memory).
        ``label`` names them in messages (default: the changes)."""
        for key, value in changes.items():
            real = getattr(self, key)
            if isinstance(real, bool):
                if value and not real:
                    raise ValueError(f"{key} cannot be granted to a device that lacks it")
            elif not 0 < value <= real:
                raise ValueError(f"{key} can be narrowed to at most the device's {real}, got {value!r}")
        name = f"{self.name} (as {label or ', '.join(f'{k}={v}' for k, v in changes.items())})"
        return dataclasses.replace(self, name=name, **changes)


def size_text(nbytes):
    """``nbytes`` for a sentence: "512 bytes", "32.0 KiB", "7.8 MiB", "1.25 GiB"."""
    nbytes = float(nbytes)
    for unit, scale in (("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} bytes"
