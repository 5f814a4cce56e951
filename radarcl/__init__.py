"""radarcl: FMCW radar data to 3D evidence grids (Foessel-Bunting, "Radar Sensor Model for
Three-Dimensional Map Building"), with OpenCL kernels that run on GPUs and on PoCL's CPU device.

Layout: ``config``/``physics`` (the radar and its equations), ``reference`` (float64 oracle of
every stage), ``cl`` (OpenCL runtime), ``stages`` (one plan per kernel), ``scene`` (simulation),
``io`` (file formats), ``cli``.
"""

__version__ = "0.1.0"
