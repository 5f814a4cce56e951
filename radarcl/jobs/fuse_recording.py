"""`radarcl fuse`: a recording of raw frames (``radarcl.io.recording``, e.g. the demo's
reference_scene.npz) fused into a map file with the tuned or the paper's constants. With
``every`` the map file is rewritten every that many frames (atomically), so ``radarcl view
--live`` shows the map growing."""

import time
from dataclasses import replace

from radarcl.config import PAPER_RADAR
from radarcl.evaluation.evaluate import MapConfig, make_mapping
from radarcl.io import recording
from radarcl.evaluation.tuning import TUNED


def run(runtime, recording_path, out, voxel_m=0.1, paper=False, every=None, progress=None, report=print):
    """Fuse every frame of ``recording_path`` into the paper grid at ``voxel_m`` and write
    ``out``; returns a dict with the frame count and milliseconds per frame (saving included)."""
    obs = recording.load(recording_path, PAPER_RADAR.n_azimuth, PAPER_RADAR.n_elevation, PAPER_RADAR.n_samples)
    config = replace(MapConfig() if paper else TUNED, voxel_m=voxel_m)
    report(f"fusing {len(obs.samples)} frames of {recording_path} with {config.label()} at {voxel_m} m into {out}")
    mapping = make_mapping(runtime, config)
    start = time.perf_counter()
    n = len(obs.samples)
    for j in range(n):
        mapping.fuse(obs.samples[j], obs.poses[j])
        if every and (j + 1) % every == 0 and j + 1 < n:
            mapping.grid.save(out)                     # waits for the device: a snapshot
        if progress is not None:
            progress(j + 1, n, "frames fused")
    mapping.grid.save(out)
    ms = (time.perf_counter() - start) * 1e3 / n
    mem = mapping.grid.memory()
    report(f"wrote {out}: {mem['bricks']} bricks ({mem['sparse_bytes'] / 2 ** 20:.0f} MiB), {ms:.0f} ms per frame"
           + (f" with a save every {every} frames" if every else ""))
    return dict(frames=n, ms_per_frame=ms, bricks=mem["bricks"])
