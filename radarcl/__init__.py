"""radarcl: FMCW radar data to 3D evidence grids (Foessel-Bunting, "Radar Sensor Model for
Three-Dimensional Map Building"), with OpenCL kernels that run on GPUs and on PoCL's CPU device.

The Python API (docs/python-api.md), named here and imported only when first used, so that
``import radarcl`` stays light (no numpy, no OpenCL)::

    import radarcl
    m = radarcl.fuse("../shared/data/navtech_oxford", sensor="navtech-cts350x", out="oxford.npz")
    m = radarcl.Map.open("oxford.npz")
    m.state_at([[10.0, 0.0, 0.5]]) == radarcl.OCCUPIED
    costmap = m.costmap(band=(0.2, 1.5))

Layers, top to bottom (docs/design/layers.md states the rule; ``tests/test_layout.py`` holds the
table): applications (the ``cli`` and its ``commands`` and ``bench``marks run ``jobs``, which use
``report``); ``evaluation``; the engine (``livemap``, ``self_test``, the ``pipeline`` chaining
``stages``, one per kernel, ``scene`` simulation, ``viewer``); the configuration and the map
(``config``, ``maps``); the evidence ``models`` and the input readers (``io``); core numerics and
device (``oracle``, the float64 reference of every stage, ``geometry``, ``grid``, the
detection-statistics physics, the paper's equations, ``cl``, the OpenCL runtime, and ``errors``).
"""

__version__ = "0.1.0"

# name -> the module that defines it (the API's one table; test_api checks every entry)
API = {
    "fuse": "radarcl.jobs.api",
    "open_input": "radarcl.jobs.api",
    "Map": "radarcl.maps.map",
    "Costmap": "radarcl.maps.map",
    "OCCUPIED": "radarcl.maps.map",
    "FREE": "radarcl.maps.map",
    "UNDECIDED": "radarcl.maps.map",
    "UNOBSERVED": "radarcl.maps.map",
    "UNKNOWN": "radarcl.maps.map",
    "save_grid": "radarcl.maps.disk",
    "load_grid": "radarcl.maps.disk",
    "Mapping": "radarcl.pipeline",
    "Runtime": "radarcl.cl",
    "load_sensor": "radarcl.config.sensors",
    "resolve_config": "radarcl.config.mapconfig",
    "ConfigError": "radarcl.errors",
    "FrameFormatError": "radarcl.errors",
}
_ALIASES = {"load_sensor": "load", "resolve_config": "resolve"}      # names the API gives otherwise

__all__ = ["__version__", *API]


def __getattr__(name):
    """The API's names, imported on first use (PEP 562)."""
    if name not in API:
        raise AttributeError(f"module 'radarcl' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(API[name]), _ALIASES.get(name, name))
    globals()[name] = value
    return value


def __dir__():
    return __all__
