"""`radarcl fuse`: any sensor's frames fused into a map file.

The input is whatever the sensor's reader opens (``radarcl.io.inputs.open_input``): a radarcl recording
(the demo's ``reference_scene.npz``, or frames of any sensor), a directory of polar PNG scans
with their odometry, a TI raw ADC capture. The map configuration comes from
``mapconfig.resolve`` (sensor defaults, ``--config`` file, ``--set`` flags). With ``every`` the
map file is rewritten every that many frames (atomically), so ``radarcl view --live`` shows the
map growing; a store output makes each rewrite cost the changed bricks only.
"""

import tempfile
import time
from pathlib import Path

import numpy as np

from radarcl.maps.disk import MapSaver, reading_of
from radarcl.maps.map import Map
from radarcl.pipeline import Mapping
from radarcl.report import figures, html


def run(runtime, source, config, out, every=None, progress=None, report=print, inputs=(), page=None):
    """Fuse every frame of ``source`` (an ``io.inputs.FrameSource``) with ``config`` (a
    ``mapconfig.Resolved``) and write the map to ``out``: an ``.npz`` file, or a map store
    (``maps.store``, any other name: only changed bricks are written after the first save).
    ``inputs`` go into the store's provenance; ``page`` names the HTML report to write
    (``write_report``). Returns a dict with the frame count and milliseconds per frame (saving
    included)."""
    saver = MapSaver(out, config.sensor.toml(), config.as_dict(), inputs)
    mapping = Mapping.from_config(runtime, config=config)
    spec = mapping.grid.spec
    report(f"fusing {source.summary} with sensor {config.sensor.name} ({config.label()}) into a "
           f"{' x '.join(map(str, spec.shape))} grid of {spec.voxel_m:g} m -> {out}")
    start = time.perf_counter()
    n = len(source)

    def after_frame(j, trajectory):
        if every and (j + 1) % every == 0 and j + 1 < n:
            saver(mapping.grid, np.array(trajectory))   # waits for the device: a snapshot
        if progress is not None:
            progress(j + 1, n, "frames fused")

    trajectory, outside = mapping.fuse_source(source, after_frame)
    saver(mapping.grid, trajectory if len(trajectory) else None)
    ms = (time.perf_counter() - start) * 1e3 / n
    mem = mapping.grid.memory()
    report(f"wrote {out}: {mem['bricks']} bricks ({mem['sparse_bytes'] / 2 ** 20:.0f} MiB), {ms:.0f} ms per frame"
           + (f" with a save every {every} frames" if every else "")
           + (f"; {outside} beam(s) reached no voxel of the grid" if outside else ""))
    result = dict(frames=n, ms_per_frame=ms, bricks=mem["bricks"], beams_outside=outside,
                  memory_mib=mem["sparse_bytes"] / 2 ** 20, every=every, device=runtime.name)
    if page is not None:
        reading = reading_of(config) if mapping.grid.has_knowledge else None
        write_report(page, out, source, config, result, Map.of_grid(mapping.grid, reading), trajectory)
        report(f"wrote {page}")
    return result


def write_report(page, out, source, config, result, map_, trajectory):
    """The run as one HTML page: what was fused and how fast, the map from above (each column's
    most telling voxel, ``Map.column_extremes``) with the sensor's path, the viewer's render
    (when EGL is there), and the configuration with where each value came from."""
    run = {"input": source.summary, "sensor": config.sensor.name, "map": str(out), "frames": result["frames"],
           "device": result["device"], "ms per frame (saving included)": round(result["ms_per_frame"], 1),
           "bricks": result["bricks"], "memory [MiB]": round(result["memory_mib"], 1),
           "beams that reached no voxel": result["beams_outside"]}
    if result["every"]:
        run["saved every"] = f"{result['every']} frames"
    spec = map_.spec
    title = f"{config.sensor.name}: {result['frames']} frames fused at {spec.voxel_m:g} m, seen from above"
    with tempfile.TemporaryDirectory() as tmp:
        top = Path(tmp) / "top.png"
        unknown = ~map_.known_columns() if map_.has_knowledge else None
        figures.save(figures.plane_map_figure(map_.column_extremes(), spec, trajectory, title, "sensor path",
                                          "most telling log-odds of the column [nat]", unknown=unknown), top)
        shown = [html.Figure(top.read_bytes(), "Each column's largest log-odds where positive, else its "
                                                 "smallest: red occupied, blue free, white unseen"
                                                 + ("; grey: never observed (unknown)" if unknown is not None else ""))]
        shown.append(_render(out, Path(tmp) / "view.png"))
    html.write(page, f"radarcl fuse: {Path(str(out)).name}", [
        ("Run", [html.Pairs(run)]), ("Map", shown),
        ("Configuration", [html.configuration(config)])],
        f"{source.summary}, sensor {config.sensor.name}.")


def _render(map_path, png):
    """The viewer's isosurface of the map as a report figure, or a sentence when it cannot render."""
    try:
        from radarcl.viewer.headless import render_map
        from radarcl.viewer.renderer import ViewerError

        render_map(map_path, png, "iso", size=(800, 500), report=lambda _: None)
    except (ImportError, ViewerError) as exc:
        return html.Text(f"No render: {exc}")
    return html.Figure(png.read_bytes(), "The viewer's isosurface at 1 nat, coloured by height (radarcl render)")

