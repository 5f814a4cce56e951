"""GPU device classes, faked on the device under test by narrowing its limits
(``radarcl.cl.limits.DeviceLimits.narrowed``): the kernels then take their GPU code paths (one job
per work-item, work-group sizes up to the class's maximum, global-memory scratch where local memory
is short) on PoCL's CPU device, and every result is still compared with the float64 oracle.

Local memory per work-group of real GPUs: Apple, Arm Mali and Qualcomm Adreno 32 KiB, NVIDIA 48 KiB
(without opting in to more), AMD and Intel 64 KiB; 16 KiB is the least OpenCL 1.2 allows a
full-profile device. ``RADARCL_TEST_LIMITS=<class>`` runs the whole suite's ``runtime`` fixture
as that class."""

MIB = 1 << 20
KIB = 1 << 10

_GPU = dict(is_cpu=False, max_work_group_size=256, max_mem_alloc_size=128 * MIB, fp64=False)

DEVICE_CLASSES = {
    "gpu-16k": dict(_GPU, local_mem_size=16 * KIB),
    "gpu-32k": dict(_GPU, local_mem_size=32 * KIB),
    "gpu-48k": dict(_GPU, local_mem_size=48 * KIB),
    "embedded-32k": dict(_GPU, local_mem_size=32 * KIB, int64=False, global_mem_size=512 * MIB),
}
LIMITS_ENV = "RADARCL_TEST_LIMITS"


def narrowed(device, name, **more):
    """``device``'s limits narrowed to class ``name``, and further by ``more`` (named in the label)."""
    from radarcl.cl.limits import DeviceLimits

    changes = {**DEVICE_CLASSES[name], **more}
    real = DeviceLimits.of(device)
    # a class cannot grant what the device lacks; fp64 and int64 are only ever taken away
    changes = {k: v for k, v in changes.items() if not (isinstance(v, bool) and v and not getattr(real, k))}
    label = ", ".join([name, *(f"{k}={v}" for k, v in more.items())])
    return real.narrowed(label=label, **changes)
