"""radarcl: FMCW radar data to 3D evidence grids (Foessel-Bunting, "Radar Sensor Model for
Three-Dimensional Map Building"), with OpenCL kernels that run on GPUs and on PoCL's CPU device.

Layers, top to bottom (docs/design/layers.md states the rule; ``tests/test_layout.py`` holds the
table): applications (the ``cli`` and its ``commands`` and ``bench``marks run ``jobs``, which use
``report``); ``evaluation``; the engine (``livemap``, ``self_test``, the ``pipeline`` chaining
``stages``, one per kernel, ``scene`` simulation, ``viewer``); the configuration and the map
(``config``, ``maps``); the evidence ``models`` and the input readers (``io``); core numerics and
device (``oracle``, the float64 reference of every stage, ``geometry``, ``grid``, the
detection-statistics physics, the paper's equations, ``cl``, the OpenCL runtime, and ``errors``).
"""

__version__ = "0.1.0"
