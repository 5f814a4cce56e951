"""OpenCL runtime only: device choice, program build and memoisation, kernel sets."""

from radarcl.cl.runtime import DEVICE_ENV, Runtime, choose_device, device_report, kernels_dir

__all__ = ["DEVICE_ENV", "Runtime", "choose_device", "device_report", "kernels_dir"]
