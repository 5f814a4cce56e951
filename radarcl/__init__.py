"""radarcl: FMCW radar data to 3D evidence grids (Foessel-Bunting, "Radar Sensor Model for
Three-Dimensional Map Building"), with OpenCL kernels that run on GPUs and on PoCL's CPU device.

Layout, top to bottom (docs/development.md, "Layout"; ``tests/test_layout.py`` holds the table): the
``cli`` and its ``commands`` and ``bench``marks run ``jobs``, which use ``report``,
``evaluation``, ``livemap`` and ``pipeline``; the pipeline chains ``stages`` (one per kernel);
below them ``scene`` (simulation), ``viewer``, ``config``, ``maps`` (the map on disk), ``io``,
``oracle`` (float64 reference of every stage), ``geometry``, ``grid``, the paper's equations
(``physics``, ``cfar_theory``, ``logodds``), ``cl`` (OpenCL runtime) and ``errors``.
"""

__version__ = "0.1.0"
