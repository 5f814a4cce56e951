"""Rendering without a display: ``radarcl render`` (a map file to a PNG through EGL) and the
frame timing the viewer bench uses."""

import time
from pathlib import Path

import numpy as np
from radarcl.viewer.camera import Camera
from radarcl.viewer.modes import Settings
from radarcl.viewer.renderer import Renderer, create_context, read_rgb
from radarcl.viewer.volume import load_map


def compose(renderer, camera, mode_name, settings, size, colorbar=True, guides=True):
    """Render offscreen, with the guides (ground grid, axes, the sensor's poses; the grid's
    spacing in a label) and the colour bar at the right edge unless turned off; returns RGB
    uint8 (height, width, 3) and the clamp (lo, hi) [nat]."""
    from radarcl.viewer.guides import Guides
    from radarcl.viewer.overlay import Overlay, text_panel

    fbo = renderer.framebuffer(size)
    fbo.use()
    lo, hi = renderer.render(camera, mode_name, settings, size)
    overlay = Overlay(renderer.ctx)
    if guides:
        volume = renderer.volume
        box_lo, box_hi = volume.view_box(lo)
        step = Guides(renderer.ctx).draw(camera, size, box_lo, box_hi, volume.poses,
                                         z=renderer.height_range(settings.threshold)[0])
        label = text_panel([scale_label(step, volume.poses)])
        overlay.draw(label, 10, size[1] - label.shape[0] - 10, size)
    if colorbar:
        bar = legend(renderer, mode_name, settings, lo, hi, height=min(220, size[1] - 60))
        overlay.draw(bar, size[0] - bar.shape[1] - 10, 10, size)
    return read_rgb(fbo), (lo, hi)


def scale_label(step, poses=None):
    """The text beside the guides: the grid's spacing, the axes' colours, the sensor's path."""
    path = "; yellow: sensor path" if poses is not None and len(poses) > 1 else \
        "; yellow: sensor" if poses is not None and len(poses) else ""
    return f"grid {step:g} m; axes x red (forward), y green (left), z blue (up){path}"


def legend(renderer, mode_name, settings, lo, hi, height):
    """The colour bar of a mode: log-odds, or for the isosurface the heights its colours span."""
    from radarcl.viewer.overlay import colour_bar

    if mode_name == "iso" and renderer.colours_by_height(settings.threshold):
        z_lo, z_hi = renderer.height_range(settings.threshold)
        return colour_bar(settings.colormap, z_lo, z_hi, 1.0, label="height [m]", height=height)
    label = "log-odds [nat]" if mode_name != "free" else f"log-odds [nat]; blue: free (below {settings.free_threshold:g})"
    return colour_bar(settings.colormap, 0.0 if mode_name == "spheres" else lo, hi, settings.gamma, label=label,
                      height=height)


def render_map(path, out, mode_name="occupancy", camera="iso", size=(1024, 768), settings=Settings(),
               colorbar=True, report=print, guides=True):
    """Render the map file ``path`` to the PNG ``out``; ``camera`` is a ``Camera`` or its
    command-line text (``Camera.parse``). Returns a dict of what was drawn."""
    from PIL import Image

    start = time.perf_counter()
    ctx = create_context()
    volume = load_map(path, max_size=int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]))
    if volume.note:
        report(volume.note)
    renderer = Renderer(ctx, volume)
    region = volume.view_box(settings.clamp_range(volume)[0])
    cam = camera if isinstance(camera, Camera) else Camera.parse(camera, volume.spec, region, size[0] / size[1])
    image, (lo, hi) = compose(renderer, cam, mode_name, settings, size, colorbar, guides)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(out, format="PNG")
    info = dict(out=str(out), mode=mode_name, size=list(size), lo=lo, hi=hi, grid=list(volume.spec.shape),
                voxel_m=volume.spec.voxel_m, renderer=ctx.info["GL_RENDERER"], note=volume.note,
                seconds=time.perf_counter() - start)
    if mode_name == "spheres":
        info["spheres"] = renderer.sphere_count
    report(f"wrote {out}: {mode_name}, {size[0]} x {size[1]}, clamp {lo:.2f}..{hi:.2f} nat, "
           f"{info['seconds']:.1f} s on {info['renderer']}")
    return info


def time_frames(renderer, camera, mode_name, settings, size, repeat=5):
    """Median and minimum milliseconds per frame (render, then wait for the GL to finish) and
    the last frame's RGB image."""
    fbo = renderer.framebuffer(size)
    fbo.use()
    renderer.render(camera, mode_name, settings, size)     # warm-up: shader build, first use
    renderer.ctx.finish()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        renderer.render(camera, mode_name, settings, size)
        renderer.ctx.finish()
        times.append((time.perf_counter() - start) * 1e3)
    return float(np.median(times)), float(np.min(times)), read_rgb(fbo)
