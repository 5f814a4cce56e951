"""OpenCL runtime only: device choice, program build and memoisation, kernel sets."""

from radarcl.cl.devices import DEVICE_ENV, choose_device, device_report, kernels_dir
from radarcl.cl.runtime import Runtime

__all__ = ["DEVICE_ENV", "Runtime", "choose_device", "device_report", "kernels_dir"]
