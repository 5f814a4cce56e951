"""The map out of the engine, on disk and in memory.

``map.Map`` queries a map with numpy (no device); ``disk`` reads, writes and converts it in its
formats, ``npz`` (one file) and ``store`` (a zarr directory saved incrementally); ``exports``
writes it for other tools (OctoMap, PLY, VTK, ROS). ``Map`` is handed on here:
``from radarcl.maps import Map``. The design, its invariants and how to add a format:
docs/design/maps.md.
"""

from radarcl.maps.map import UNKNOWN, Map

__all__ = ["Map", "UNKNOWN"]
