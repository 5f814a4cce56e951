"""Overlays drawn over the picture: the colour bar, the help text and the status line. Pillow
draws them into RGBA images; ``Overlay`` puts an image on screen as a textured rectangle
(``shaders/overlay.glsl``) with alpha blending."""

import math
from functools import lru_cache

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from radarcl.viewer.renderer import build_program, colormap_lut

TEXT = (235, 235, 235, 255)
PANEL = (0, 0, 0, 170)


FONT_PX = 14


@lru_cache(maxsize=None)
def _font(size=FONT_PX):
    """DejaVu Sans, the TrueType font matplotlib ships (readable at 100 %, a real minus sign),
    or Pillow's own scalable default when matplotlib's file is missing."""
    try:
        from matplotlib import font_manager

        return ImageFont.truetype(font_manager.findfont("DejaVu Sans", fallback_to_default=False), size)
    except Exception:                   # noqa: BLE001 - any font trouble falls back to Pillow's
        return ImageFont.load_default(size)


def number(value, digits=3):
    """A tick label: ``digits`` significant digits, a true minus sign."""
    text = f"{value:.{digits}g}"
    return text.replace("-", "\u2212")


def tick_labels(values):
    """Labels for ``values``: three significant digits, more where they would look alike."""
    digits = next((d for d in range(3, 12) if len({number(v, d) for v in values}) == len(values)), 12)
    return [number(v, digits) for v in values]


def nice_step(extent, lines=8):
    """A grid spacing of 1, 2 or 5 x 10^k metres giving about ``lines`` lines over ``extent``."""
    raw = max(float(extent), 1e-6) / lines
    base = 10 ** math.floor(math.log10(raw))
    return next(b * base for b in (1, 2, 5, 10) if b * base >= raw)


def ticks(lo, hi, count=5):
    """Round values (multiples of 1, 2 or 5 x 10^k) from ``lo`` to ``hi``, about ``count`` of them."""
    if not hi > lo:
        return [lo]
    raw = (hi - lo) / (count - 1)
    base = 10 ** math.floor(math.log10(raw))
    step = max(b * base for b in (1, 2, 5) if b * base <= raw * (1 + 1e-9))     # at least ``count`` - 1 gaps
    first = math.ceil(lo / step - 1e-9)
    values = [k * step for k in range(first, int(math.floor(hi / step + 1e-9)) + 1)]
    return [0.0 if abs(v) < 1e-9 * step else v for v in values]


def text_panel(lines):
    """RGBA uint8 image of ``lines`` of text on a translucent panel."""
    font = _font()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    width = max((probe.textlength(line, font=font) for line in lines), default=0)
    line_h = FONT_PX + 5
    img = Image.new("RGBA", (int(width) + 16, line_h * len(lines) + 12), PANEL)
    draw = ImageDraw.Draw(img)
    for i, line in enumerate(lines):
        draw.text((8, 6 + i * line_h), line, fill=TEXT, font=font)
    return np.asarray(img)


def colour_bar(colormap, lo, hi, gamma=1.0, label="log-odds [nat]", height=220):
    """RGBA uint8 image: the colormap from ``lo`` (bottom) to ``hi`` (top) [nat] with ticks.
    With ``gamma`` != 1 the ticks sit where the transfer function puts those values."""
    lut = colormap_lut(colormap)
    font = _font()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    values = ticks(lo, hi)
    labels = tick_labels(values)
    text_w = max(probe.textlength(text, font=font) for text in labels)
    bar_w, pad = 18, 10
    width = int(max(pad + bar_w + 10 + text_w, probe.textlength(label, font=font)) + 2 * pad)
    img = Image.new("RGBA", (width, height + 2 * pad + FONT_PX + 10), PANEL)
    draw = ImageDraw.Draw(img)
    for row in range(height):
        x = 1.0 - row / (height - 1)                       # transfer-function output at this row
        draw.line([(pad, pad + row), (pad + bar_w, pad + row)], fill=tuple(lut[int(round(x * 255))]) + (255,))
    for value, text in zip(values, labels):
        frac = min(max((value - lo) / (hi - lo), 0.0), 1.0) if hi > lo else 1.0
        y = pad + (1.0 - frac ** gamma) * (height - 1)
        draw.line([(pad + bar_w, y), (pad + bar_w + 4, y)], fill=TEXT)
        draw.text((pad + bar_w + 10, y), text, fill=TEXT, font=font, anchor="lm")
    draw.text((pad, height + pad + 6), label, fill=TEXT, font=font)
    return np.asarray(img)


class Overlay:
    """Textured rectangles on ``ctx``: ``draw(image, x, y, viewport)`` places an RGBA image
    (row 0 at the top) with its top-left corner at pixel (x, y)."""

    def __init__(self, ctx):
        import moderngl

        self.ctx, self.moderngl = ctx, moderngl
        self.program = build_program(ctx, "overlay")
        square = np.array([0, 0, 1, 0, 0, 1, 1, 1], np.float32)
        self.vao = ctx.vertex_array(self.program, [(ctx.buffer(square.tobytes()), "2f", "in_pos")])
        self._textures = {}

    def draw(self, image, x, y, viewport, key=None):
        """Draw ``image`` at (x, y) over a viewport of (width, height) pixels. With a ``key``
        its texture is kept for the next draw with that key (``forget`` it when it changes)."""
        tex = self._textures.get(key) if key else None
        if tex is None:
            h, w = image.shape[:2]
            tex = self.ctx.texture((w, h), 4, np.ascontiguousarray(image).tobytes())
            tex.repeat_x = tex.repeat_y = False
            if key:
                self._textures[key] = tex
        w, h = tex.size
        self.program["viewport"].value = tuple(float(v) for v in viewport)
        self.program["rect"].value = (float(x), float(y), float(w), float(h))
        tex.use(0)
        self.ctx.enable(self.moderngl.BLEND)
        self.ctx.blend_func = self.moderngl.SRC_ALPHA, self.moderngl.ONE_MINUS_SRC_ALPHA
        self.vao.render(self.moderngl.TRIANGLE_STRIP)
        self.ctx.disable(self.moderngl.BLEND)
        if not key:
            tex.release()

    def forget(self, key):
        """Drop a cached texture (its image changed)."""
        tex = self._textures.pop(key, None)
        if tex is not None:
            tex.release()
