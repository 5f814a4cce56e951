"""Overlays drawn over the picture: the colour bar, the help text and the status line. Pillow
draws them into RGBA images; ``Overlay`` puts an image on screen as a textured rectangle
(``shaders/overlay.glsl``) with alpha blending."""

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from radarcl.viewer.renderer import build_program, colormap_lut

TEXT = (235, 235, 235, 255)
PANEL = (0, 0, 0, 170)


def _font():
    return ImageFont.load_default()


def text_panel(lines):
    """RGBA uint8 image of ``lines`` of text on a translucent panel."""
    font = _font()
    probe = ImageDraw.Draw(Image.new("RGBA", (1, 1)))
    width = max((probe.textlength(line, font=font) for line in lines), default=0)
    line_h = 14
    img = Image.new("RGBA", (int(width) + 16, line_h * len(lines) + 12), PANEL)
    draw = ImageDraw.Draw(img)
    for i, line in enumerate(lines):
        draw.text((8, 6 + i * line_h), line, fill=TEXT, font=font)
    return np.asarray(img)


def colour_bar(colormap, lo, hi, gamma=1.0, label="log-odds [nat]", height=220):
    """RGBA uint8 image: the colormap from ``lo`` (bottom) to ``hi`` (top) [nat] with ticks.
    With ``gamma`` != 1 the ticks sit where the transfer function puts those values."""
    lut = colormap_lut(colormap)
    bar_w, pad = 18, 8
    img = Image.new("RGBA", (bar_w + 70, height + 2 * pad + 16), PANEL)
    draw = ImageDraw.Draw(img)
    for row in range(height):
        x = 1.0 - row / (height - 1)                       # transfer-function output at this row
        draw.line([(pad, pad + row), (pad + bar_w, pad + row)], fill=tuple(lut[int(round(x * 255))]) + (255,))
    font = _font()
    for frac in np.linspace(0.0, 1.0, 5):
        value = lo + frac * (hi - lo)
        y = pad + (1.0 - frac ** gamma) * (height - 1)
        draw.line([(pad + bar_w, y), (pad + bar_w + 4, y)], fill=TEXT)
        draw.text((pad + bar_w + 7, y - 6), f"{value:.2f}", fill=TEXT, font=font)
    draw.text((pad, height + pad + 3), label, fill=TEXT, font=font)
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
