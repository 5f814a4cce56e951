"""Guides over the rendered map: a ground grid with a stated spacing (the scale), the world
axes (x red, y green, z blue: REP-103, x forward, y left, z up), and the sensor's poses (its
path in yellow, each pose's forward axis as a tick, the last one larger). Drawn as blended
lines after the volume, so they never change what the volume shows underneath."""

import math

import numpy as np

from radarcl.viewer.overlay import nice_step
from radarcl.viewer.renderer import build_program

GRID_RGBA = (0.75, 0.75, 0.8, 0.35)
PATH_RGBA = (1.0, 0.85, 0.2, 0.95)
AXES_RGBA = ((0.95, 0.25, 0.25, 0.95), (0.3, 0.9, 0.3, 0.95), (0.35, 0.55, 1.0, 0.95))


def grid_lines(lo, hi, z):
    """(segments (n, 2, 3), step): a square grid over the box's (x, y) extent at height ``z``."""
    step = nice_step(max(hi[0] - lo[0], hi[1] - lo[1]))
    xs = np.arange(math.floor(lo[0] / step), math.ceil(hi[0] / step) + 1) * step
    ys = np.arange(math.floor(lo[1] / step), math.ceil(hi[1] / step) + 1) * step
    segs = [((x, ys[0], z), (x, ys[-1], z)) for x in xs] + [((xs[0], y, z), (xs[-1], y, z)) for y in ys]
    return np.array(segs, float), step


class Guides:
    """Draws the guides of a map on ``ctx``; ``draw`` returns the grid spacing [m] (for the scale
    label)."""

    def __init__(self, ctx):
        import moderngl

        self.ctx, self.moderngl = ctx, moderngl
        self.program = build_program(ctx, "lines")

    def segments(self, lo, hi, poses=None, z=None):
        """(points (2n, 3) float32, colours (2n, 4) float32, step [m]) of every line; the grid
        lies at height ``z`` (default: the box's floor)."""
        z = float(lo[2]) if z is None else float(z)
        grid, step = grid_lines(lo, hi, z)
        segs, cols = [grid], [np.tile(GRID_RGBA, (len(grid), 1))]
        if poses is not None and len(poses):
            centres = poses[:, :3, 3]
            if len(centres) > 1:
                segs.append(np.stack([centres[:-1], centres[1:]], axis=1))
                cols.append(np.tile(PATH_RGBA, (len(centres) - 1, 1)))
            ticks = np.stack([centres, centres + 0.2 * step * poses[:, :3, 0]], axis=1)
            ticks[-1, 1] = centres[-1] + 0.5 * step * poses[-1, :3, 0]            # the last pose: longer
            segs.append(ticks)
            cols.append(np.tile(PATH_RGBA, (len(ticks), 1)))
        # The axes last, over the path (a vehicle's path often runs along x). One grid step long;
        # z no taller than twice the box's height (a flat map's up axis would tower over it).
        at = np.array([0.0, 0.0, z])                                     # the world origin, on the grid
        lengths = (step, step, min(step, max(2.0 * (hi[2] - lo[2]), 0.25 * step)))
        for axis, rgba in enumerate(AXES_RGBA):
            end = at.copy()
            end[axis] += lengths[axis]
            segs.append(np.array([[at, end]]))
            cols.append(np.array([rgba]))
        segs, cols = np.concatenate(segs), np.concatenate(cols)
        return (segs.reshape(-1, 3).astype(np.float32), np.repeat(cols, 2, axis=0).astype(np.float32), step)

    def draw(self, camera, size, lo, hi, poses=None, z=None):
        """Draw over the bound framebuffer of ``size``; ``lo``/``hi`` the box the grid covers,
        at height ``z`` (the ground: where the surfaces seen from above begin)."""
        points, colours, step = self.segments(np.asarray(lo, float), np.asarray(hi, float), poses, z)
        vbo = self.ctx.buffer(points.tobytes())
        cbo = self.ctx.buffer(colours.tobytes())
        vao = self.ctx.vertex_array(self.program, [(vbo, "3f", "in_pos"), (cbo, "4f", "in_color")])
        self.program["mvp"].write(camera.mvp(*size).astype("f4").T.tobytes())
        self.ctx.enable(self.moderngl.BLEND)
        self.ctx.blend_func = self.moderngl.SRC_ALPHA, self.moderngl.ONE_MINUS_SRC_ALPHA
        vao.render(self.moderngl.LINES)
        self.ctx.disable(self.moderngl.BLEND)
        for obj in (vao, vbo, cbo):
            obj.release()
        return step
