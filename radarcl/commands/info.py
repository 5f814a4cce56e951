"""`radarcl info`: the OpenCL platforms and devices, and what the kernels need."""

SUMMARY = "list OpenCL platforms and devices, what the kernels need, and which devices pass radarcl's check"
DESCRIPTION = ("List OpenCL platforms and devices and what the kernels need. Each device is checked once (per driver "
               "version and radarcl version, the verdict cached in ~/.cache/radarcl/devices.json) in a child process: "
               "every kernel of every built-in pipeline built and run against the float64 oracle; a device that fails "
               "or crashes is marked UNUSABLE with the reason and never chosen.")


def add_arguments(parser):
    """No options."""


def run(args):
    from radarcl.cl import choose_device, device_report

    print("\n".join(device_report()))
    choose_device()  # after the listing: no usable device, or a RADARCL_DEVICE that fits none, is an error
    return 0
