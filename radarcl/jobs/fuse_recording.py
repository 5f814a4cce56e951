"""`radarcl fuse`: any sensor's frames fused into a map file.

The input is whatever the sensor's reader opens (``radarcl.io.open_input``): a radarcl recording
(the demo's ``reference_scene.npz``, or frames of any sensor), a directory of polar PNG scans
with their odometry, a TI raw ADC capture. The map configuration comes from
``mapconfig.resolve`` (sensor defaults, ``--config`` file, ``--set`` flags). With ``every`` the
map file is rewritten every that many frames (atomically), so ``radarcl view --live`` shows the
map growing; a store output makes each rewrite cost the changed bricks only.
"""

import time

import numpy as np

from radarcl import io
from radarcl.pipeline import Mapping


def run(runtime, source, config, out, every=None, progress=None, report=print, inputs=()):
    """Fuse every frame of ``source`` (an ``io.FrameSource``) with ``config`` (a
    ``mapconfig.Resolved``) and write the map to ``out``: an ``.npz`` file, or a map store
    (``radarcl.store``, any other name: only changed bricks are written after the first save).
    ``inputs`` go into the store's provenance. Returns a dict with the frame count and
    milliseconds per frame (saving included)."""
    from radarcl.store import MapSaver

    saver = MapSaver(out, config.sensor.toml(), config.as_dict(), inputs)

    trajectory = []                                     # the sensor's pose per frame (its middle beam's)

    def save(grid, path):
        saver(grid, np.array(trajectory) if trajectory else None)

    mapping = Mapping.from_config(runtime, config=config)
    spec = mapping.grid.spec
    report(f"fusing {source.summary} with sensor {config.sensor.name} ({config.label()}) into a "
           f"{' x '.join(map(str, spec.shape))} grid of {spec.voxel_m:g} m -> {out}")
    start = time.perf_counter()
    n = len(source)
    outside = 0
    for j in range(n):
        poses = np.asarray(source.poses[j])
        plan = mapping.fuse(source.frames[j], poses, flags=None if config.sensor.raw else source.flags[j])
        trajectory.append(poses if poses.ndim == 2 else poses[len(poses) // 2])
        outside += plan.beams_outside
        if every and (j + 1) % every == 0 and j + 1 < n:
            save(mapping.grid, out)                     # waits for the device: a snapshot
        if progress is not None:
            progress(j + 1, n, "frames fused")
    save(mapping.grid, out)
    ms = (time.perf_counter() - start) * 1e3 / n
    mem = mapping.grid.memory()
    report(f"wrote {out}: {mem['bricks']} bricks ({mem['sparse_bytes'] / 2 ** 20:.0f} MiB), {ms:.0f} ms per frame"
           + (f" with a save every {every} frames" if every else "")
           + (f"; {outside} beam(s) reached no voxel of the grid" if outside else ""))
    return dict(frames=n, ms_per_frame=ms, bricks=mem["bricks"], beams_outside=outside)


def open_source(sensor, path, odometry=None):
    """``io.open_input`` (kept here so the CLI imports one job module)."""
    return io.open_input(sensor, path, odometry)
