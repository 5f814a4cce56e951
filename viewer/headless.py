"""Rendering without a display: ``radarcl render`` (a map file to a PNG through EGL) and the
frame timing the viewer bench uses."""

import time
from pathlib import Path

import numpy as np

from radarcl.viewer.camera import Camera
from radarcl.viewer.modes import Settings
from radarcl.viewer.renderer import Renderer, create_context, read_rgb
from radarcl.viewer.volume import load_map


def compose(renderer, camera, mode_name, settings, size, colorbar=True):
    """Render offscreen, with the colour bar at the right edge unless ``colorbar`` is False;
    returns RGB uint8 (height, width, 3) and the clamp (lo, hi) [nat]."""
    from radarcl.viewer.overlay import Overlay

    fbo = renderer.framebuffer(size)
    fbo.use()
    lo, hi = renderer.render(camera, mode_name, settings, size)
    if colorbar:
        bar = legend(renderer.volume, mode_name, settings, lo, hi, height=min(220, size[1] - 60))
        Overlay(renderer.ctx).draw(bar, size[0] - bar.shape[1] - 10, 10, size)
    return read_rgb(fbo), (lo, hi)


def legend(volume, mode_name, settings, lo, hi, height):
    """The colour bar of a mode: log-odds, or height for the isosurface."""
    from radarcl.viewer.overlay import colour_bar

    if mode_name == "iso":
        z0 = volume.spec.origin_m[2]
        return colour_bar(settings.colormap, z0, z0 + volume.spec.shape[2] * volume.spec.voxel_m, 1.0,
                          label="height [m]", height=height)
    return colour_bar(settings.colormap, 0.0 if mode_name == "spheres" else lo, hi, settings.gamma, height=height)


def render_map(path, out, mode_name="occupancy", camera="iso", size=(1024, 768), settings=Settings(),
               colorbar=True, report=print):
    """Render the map file ``path`` to the PNG ``out``; ``camera`` is a ``Camera`` or its
    command-line text (``Camera.parse``). Returns a dict of what was drawn."""
    from PIL import Image

    start = time.perf_counter()
    ctx = create_context()
    volume = load_map(path, max_size=int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]))
    if volume.note:
        report(volume.note)
    renderer = Renderer(ctx, volume)
    region = volume.content_box(settings.clamp_range(volume)[0])
    cam = camera if isinstance(camera, Camera) else Camera.parse(camera, volume.spec, region)
    image, (lo, hi) = compose(renderer, cam, mode_name, settings, size, colorbar)
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
