"""`radarcl info`: the OpenCL platforms and devices, and what the kernels need."""

SUMMARY = "list OpenCL platforms and devices and what the kernels need"
DESCRIPTION = "List OpenCL platforms and devices and what the kernels need."


def add_arguments(parser):
    """No options."""


def run(args):
    from radarcl.cl import choose_device, device_report

    print("\n".join(device_report()))
    choose_device()  # after the listing: no usable device, or a RADARCL_DEVICE that fits none, is an error
    return 0
