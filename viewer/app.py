"""`radarcl view`: the interactive viewer in a moderngl-window window.

Mouse: left drag orbits, right drag (or shift + left) pans, the wheel zooms. Keys are the
``ACTIONS`` table (press h in the window for it). With ``live`` the app watches the map file
and, when a fusion rewrites it (``radarcl fuse --every``, which replaces it atomically), reads
it with numpy and uploads only the bricks that changed. A file caught half-written or broken is
reported on the status line and read again at the next change: the view keeps running.
"""

import logging
import os
import time
from dataclasses import replace
from pathlib import Path

from radarcl.viewer.camera import Camera
from radarcl.viewer.modes import COLORMAPS, MODES, Settings
from radarcl.viewer.renderer import Renderer, ViewerError, import_moderngl, read_rgb
from radarcl.viewer.volume import changed_bricks, from_bricks, load_map, update, write_bricks

from radarcl.errors import RadarclError
from radarcl.maps.disk import read, read_poses

log = logging.getLogger(__name__)
POLL_S = 0.25                       # how often --live looks at the file
SLICE_STEP = 0.02                   # fraction of the axis per [ or ]
AXES = "xyz"


class ViewerApp:
    """The app's state and behaviour, independent of the event loop: ``press(char)`` runs a
    key's action, ``drag``/``scroll`` move the camera, ``frame()`` draws one frame into the
    window's framebuffer (polling the file first when live)."""

    def __init__(self, window, path, volume, mode_name="occupancy", camera=None, settings=Settings(), live=False,
                 follow=None):
        from radarcl.viewer.overlay import Overlay

        self.wnd, self.ctx = window, window.ctx
        self.path, self.live, self.follow = Path(path), live, follow    # follow: a BrickSubscriber
        from radarcl.viewer.guides import Guides

        self.renderer = Renderer(self.ctx, volume)
        self.overlay = Overlay(self.ctx)
        self.guides, self.show_guides = Guides(self.ctx), True
        self.mode, self.settings = mode_name, settings
        self.camera = camera or Camera.fit(volume.spec)
        self.home = self.camera
        self.show_help, self.slice_axis, self.slice_width = False, None, 0.05
        self.frame_ms, self.updates, self.message = 0.0, 0, volume.note
        self.screenshots = 0
        self._mtime = self._stat()
        self._last_poll = time.monotonic()

    # -- input ----------------------------------------------------------------------------
    def press(self, char):
        """Run the action bound to ``char`` (see ``ACTIONS``); unknown keys do nothing."""
        action = ACTIONS.get(char)
        if action is not None:
            action[1](self)

    def drag(self, dx, dy, pan=False):
        """Mouse drag by (dx, dy) pixels: orbit, or pan with ``pan``."""
        h = max(self.wnd.buffer_size[1], 1)
        if pan:
            self.camera = self.camera.pan(dx / h, dy / h)
        else:
            self.camera = self.camera.orbit(-0.3 * dx, 0.3 * dy)

    def scroll(self, dy):
        """Mouse wheel: zoom in for positive ``dy``."""
        self.camera = self.camera.zoom(0.9 ** dy)

    def set(self, **changes):
        """Change the transfer-function settings; a bad value goes to the status line."""
        try:
            self.settings = replace(self.settings, **changes)
        except RadarclError as exc:
            self.message = str(exc)

    def _slice(self, axis):
        self.slice_axis = None if self.slice_axis == axis else axis
        self._apply_slice(0.5 - self.slice_width / 2 if self.slice_axis is not None else None)

    def _move_slice(self, delta):
        if self.slice_axis is not None:
            start = self.settings.clip[AXES.index(self.slice_axis)][0] + delta
            self._apply_slice(min(max(start, 0.0), 1.0 - self.slice_width))

    def _apply_slice(self, start):
        clip = [(0.0, 1.0)] * 3
        if start is not None:
            clip[AXES.index(self.slice_axis)] = (start, start + self.slice_width)
        self.set(clip=tuple(clip))

    def screenshot(self, path=None):
        """Save what the window shows to ``path`` (default radarcl_view_<n>.png here); returns it."""
        from PIL import Image

        self.screenshots += 1
        path = Path(path or f"radarcl_view_{self.screenshots}.png")
        Image.fromarray(read_rgb(self.wnd.fbo)).save(path)
        self.message = f"saved {path}"
        return path

    # -- live -----------------------------------------------------------------------------
    def _stat(self):
        try:
            return os.stat(self.path).st_mtime_ns
        except OSError:
            return None

    def poll(self, force=False):
        """When live (or ``force``), read the file if it changed and upload the changed bricks;
        when following an engine, write the bricks it sent. Returns the number of bricks
        written (None when nothing was read)."""
        if self.follow is not None:
            return self._follow()
        now = time.monotonic()
        if not force and (not self.live or now - self._last_poll < POLL_S):
            return None
        self._last_poll = now
        mtime = self._stat()
        if mtime is None or (mtime == self._mtime and not force):
            return None
        self._mtime = mtime
        volume = self.renderer.volume
        try:
            spec, keys, bricks = read(self.path)
            poses = read_poses(self.path)                   # the sensor's path grows with the map
            fresh = from_bricks(spec, keys, bricks, self.renderer.max_texture) \
                if spec != volume.spec or volume.keys is None else None
        except (RadarclError, MemoryError) as exc:
            self.message = f"live: {exc or 'out of memory'} (waiting for the next write)"
            return None
        if fresh is not None:
            fresh.poses = poses
            self.renderer.upload(fresh)
            changed = len(keys)
        else:
            diff = changed_bricks(volume.keys, volume.bricks, keys, bricks)
            boxes, coarse_box = update(volume, keys, bricks, diff)
            self.renderer.update(boxes, coarse_box)
            volume.poses = poses
            changed = len(diff)
        self.updates += 1
        self.message = f"live: update {self.updates}, {changed} bricks changed"
        return changed

    def _follow(self):
        volume, written = self.renderer.volume, None
        for item in self.follow.take():
            if item[0] == "bricks" and len(item[1]):
                boxes, coarse_box = write_bricks(volume, item[1], item[2])
                self.renderer.update(boxes, coarse_box)
                written = (written or 0) + len(item[1])
            elif item[0] == "poses":
                volume.poses = item[1]
        if written:
            self.updates += 1
            self.message = f"follow: update {self.updates}, {written} bricks"
        if self.follow.error:
            # short: the status line is one line of a window that may be 1024 px wide
            self.message = f"follow ended: {self.follow.error}; showing the last map"
        return written

    # -- drawing --------------------------------------------------------------------------
    def frame(self):
        """Poll (live), render, draw the overlays."""
        from radarcl.viewer.headless import legend, scale_label
        from radarcl.viewer.overlay import text_panel

        self.poll()
        size = self.wnd.buffer_size
        self.wnd.fbo.use()
        start = time.perf_counter()
        lo, hi = self.renderer.render(self.camera, self.mode, self.settings, size)
        if self.show_guides:
            volume = self.renderer.volume
            box_lo, box_hi = volume.view_box(lo)
            step = self.guides.draw(self.camera, size, box_lo, box_hi, volume.poses,
                                    z=self.renderer.height_range(self.settings.threshold)[0])
            guide = text_panel([scale_label(step, volume.poses)])
            self.overlay.draw(guide, 10, size[1] - guide.shape[0] - 40, size)
        bar = legend(self.renderer, self.mode, self.settings, lo, hi, height=max(60, min(220, size[1] - 80)))
        self.overlay.draw(bar, size[0] - bar.shape[1] - 10, 10, size)
        status = (f"{self.mode} | threshold {self.settings.threshold:.2f} nat | clamp {lo:.2f}..{hi:.2f} | "
                  f"{self.frame_ms:.0f} ms | skip {'on' if self.settings.skip else 'off'}"
                  + (f" | slice {self.slice_axis}" if self.slice_axis else "")
                  + (f" | {self.message}" if self.message else "") + " | h: help")
        panel = text_panel([status])
        self.overlay.draw(panel, 10, size[1] - panel.shape[0] - 10, size)
        if self.show_help:
            lines = ["mouse: drag orbit, right/shift drag pan, wheel zoom"]
            lines += [f"{k}  {d}" for k, (d, _) in ACTIONS.items()]
            self.overlay.draw(text_panel(lines), 10, 10, size)
        self.ctx.finish()
        self.frame_ms = (time.perf_counter() - start) * 1e3


def _mode_action(name):
    return (f"mode: {MODES[name].description}", lambda app: setattr(app, "mode", name))


def _cycle_colormap(app):
    app.set(colormap=COLORMAPS[(COLORMAPS.index(app.settings.colormap) + 1) % len(COLORMAPS)])


# every key of the app, in one table: the help overlay is printed from it
ACTIONS = {
    **{m.key: _mode_action(m.name) for m in MODES.values()},
    "t": ("threshold -0.25 nat", lambda app: app.set(threshold=app.settings.threshold - 0.25)),
    "T": ("threshold +0.25 nat", lambda app: app.set(threshold=app.settings.threshold + 0.25)),
    "g": ("gamma / 1.25", lambda app: app.set(gamma=app.settings.gamma / 1.25)),
    "G": ("gamma * 1.25", lambda app: app.set(gamma=app.settings.gamma * 1.25)),
    "c": ("next colormap", _cycle_colormap),
    "x": ("slice across x (again: off)", lambda app: app._slice("x")),
    "y": ("slice across y (again: off)", lambda app: app._slice("y")),
    "z": ("slice across z (again: off)", lambda app: app._slice("z")),
    "[": ("move the slice down the axis", lambda app: app._move_slice(-SLICE_STEP)),
    "]": ("move the slice up the axis", lambda app: app._move_slice(SLICE_STEP)),
    "k": ("empty-space skipping on/off", lambda app: app.set(skip=not app.settings.skip)),
    "a": ("guides (ground grid, axes, sensor path) on/off", lambda app: setattr(app, "show_guides", not app.show_guides)),
    "r": ("reset the camera", lambda app: setattr(app, "camera", app.home)),
    "+": ("zoom in", lambda app: app.scroll(1)),
    "-": ("zoom out", lambda app: app.scroll(-1)),
    "s": ("screenshot to radarcl_view_<n>.png", lambda app: app.screenshot()),
    "h": ("help on/off", lambda app: setattr(app, "show_help", not app.show_help)),
    "q": ("quit", lambda app: app.wnd.close()),
}


def open_window(backend, size, title):
    """A moderngl-window window of ``backend`` (pyglet, glfw, headless ...), or a ``ViewerError``
    saying what is missing."""
    import_moderngl()
    try:
        import moderngl_window
    except ImportError as exc:
        raise ViewerError(f"the window needs moderngl-window: pip install 'radarcl[viewer]' ({exc})") from exc
    if backend != "headless" and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        hint = ("there is no display: set DISPLAY, run under xvfb-run (apt-get install xvfb), "
                "use --window headless, or render to a file with radarcl render")
    else:
        hint = "check the OpenGL driver (Debian/Ubuntu: apt-get install libgl1-mesa-dri libegl-mesa0)"
    try:
        cls = moderngl_window.get_local_window_cls(backend)
        window = cls(title=title, size=size, gl_version=(3, 3), vsync=False,
                     **(dict(backend="egl") if backend == "headless" else {}))
    except Exception as exc:    # pyglet, glfw and EGL raise their own types, with useful text
        raise ViewerError(f"could not open a {backend!r} window ({exc}); {hint}") from exc
    moderngl_window.activate_context(window=window)
    return window


def run(path, mode_name="occupancy", camera="iso", size=(1024, 768), settings=Settings(), live=False, frames=None,
        screenshot=None, keys="", window="pyglet", follow=None):
    """Open the window on the map file ``path`` (or, with ``follow`` "HOST:PORT", on the map a
    running ``radarcl live --serve`` sends) and run until it closes (or ``frames`` frames have
    been drawn); ``keys`` are pressed one per frame first; the last frame is saved to
    ``screenshot``. Returns the exit status."""
    subscriber = None
    if follow is not None:
        subscriber, volume = follow_engine(follow)
        path = f"follow-{follow.replace(':', '-')}"
    else:
        volume = load_map(path)                         # a bad file fails before a window opens
    wnd = open_window(window, size, f"radarcl view {Path(path).name}")
    if volume.note:
        log.warning("%s", volume.note)
    region = volume.view_box(settings.clamp_range(volume)[0])
    cam = Camera.parse(camera, volume.spec, region, size[0] / size[1])
    app = ViewerApp(wnd, path, volume, mode_name, cam, settings, live, subscriber)
    wnd.unicode_char_entered_func = app.press
    wnd.key_event_func = lambda key, action, modifiers: (
        wnd.close() if key == wnd.keys.ESCAPE and action == wnd.keys.ACTION_PRESS else None)
    wnd.mouse_drag_event_func = lambda x, y, dx, dy: app.drag(
        dx, dy, pan=wnd.mouse_states.right or wnd.modifiers.shift)
    wnd.mouse_scroll_event_func = lambda dx, dy: app.scroll(dy)
    pending, drawn = list(keys), 0
    while True:
        if pending:
            app.press(pending.pop(0))
        app.frame()
        drawn += 1
        if wnd.is_closing or (frames is not None and drawn >= frames):
            if screenshot:                              # the frame just drawn, before any swap
                app.screenshot(screenshot)
            break
        wnd.swap_buffers()
    wnd.destroy()
    return 0


def follow_engine(address, timeout_s=10.0):
    """(subscriber, Volume) of a running engine's map: waits for its grid and first bricks."""
    from radarcl.io.brick_stream import BrickSubscriber

    sub = BrickSubscriber(address, timeout_s)
    deadline = time.monotonic() + timeout_s
    spec = keys = data = None
    poses = None
    while data is None:
        if not sub.arrived.wait(max(0.0, deadline - time.monotonic())) or sub.error:
            sub.close()
            raise ViewerError(f"the engine at {address} sent no map within {timeout_s:g} s"
                              + (f" ({sub.error})" if sub.error else ""))
        sub.arrived.clear()
        for item in sub.take():
            if item[0] == "spec":
                spec = item[1]
            elif item[0] == "bricks" and spec is not None and data is None:
                keys, data = item[1], item[2]
            elif item[0] == "poses":
                poses = item[1]
    volume = from_bricks(spec, keys, data)
    if volume.note:
        sub.close()
        raise ViewerError(f"the engine's grid {spec.shape} is too large to follow brick by brick here ({volume.note}); "
                          "open its saved map with radarcl view instead")
    volume.poses = poses
    return sub, volume
