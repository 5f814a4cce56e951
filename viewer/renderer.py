"""The volume renderer: a ``Volume`` as 3D textures on a moderngl context, drawn in the modes of
``viewer.modes`` by the programs in ``viewer/shaders``.

Textures: the log-odds as R16F (``Volume.values``), linear, clamp-to-edge on all three axes
(moderngl repeats by default, which would wrap the far face's evidence onto the near one); the
coarse max-mip as R16F, nearest; the colormap as a 256 x 1 RGB strip. Partial updates write
only the changed bricks into both (``update``).

``create_context`` makes the headless EGL context; the app passes its window's context.
"""

import logging
from functools import lru_cache
from importlib import resources

import numpy as np
from radarcl.viewer.camera import box
from radarcl.viewer.modes import Settings, mode
from radarcl.viewer.volume import above, active_box, coarser_max

from radarcl.errors import ConfigError, RadarclError

log = logging.getLogger(__name__)
MAX_SPHERES = 2_000_000          # Fig. 11 instances drawn at most; the largest values are kept


class ViewerError(RadarclError, RuntimeError):
    """OpenGL is missing or cannot do what the viewer needs; the message says what to install."""


def import_moderngl():
    """moderngl, or a ``ViewerError`` saying how to install it."""
    try:
        import moderngl
    except ImportError as exc:
        raise ViewerError("the viewer needs moderngl: pip install 'radarcl[viewer]' "
                          f"(moderngl, moderngl-window, pyglet) ({exc})") from exc
    return moderngl


def create_context():
    """A headless OpenGL 3.3+ context through EGL (no display needed), or a ``ViewerError``
    naming the packages that provide EGL."""
    moderngl = import_moderngl()
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as exc:   # glcontext raises bare Exception subclasses with the loader's text
        raise ViewerError("no EGL OpenGL context could be created. Install Mesa's EGL "
                          "(Debian/Ubuntu: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri) or a GPU "
                          f"driver with EGL; the loader said: {exc}") from exc
    return ctx


@lru_cache(maxsize=None)
def shader_source(stem):
    """The text of ``shaders/<stem>.glsl`` from the installed package."""
    return resources.files("radarcl.viewer").joinpath("shaders", f"{stem}.glsl").read_text()


def build_program(ctx, stem, defines=()):
    """Compile ``shaders/<stem>.glsl`` with ``defines``; a compile error names the file."""
    head = "#version 330\n" + "".join(f"#define {d}\n" for d in defines)
    src = shader_source(stem)
    try:
        return ctx.program(vertex_shader=head + "#define VERTEX_SHADER\n" + src,
                           fragment_shader=head + "#define FRAGMENT_SHADER\n" + src)
    except Exception as exc:
        raise ViewerError(f"shaders/{stem}.glsl with {list(defines)} failed to build: {exc}") from exc


def colormap_lut(name):
    """256 x 3 uint8 RGB of a matplotlib colormap (``gray`` is matplotlib's too)."""
    import matplotlib

    return (matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255 + 0.5).astype(np.uint8)


def _unit_cube(ctx, program):
    """The unit cube's 12 triangles, counter-clockwise seen from outside."""
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], np.float32)
    tris = []
    for axis in range(3):
        for side in (0, 1):
            quad = [i for i in range(8) if corners[i, axis] == side]     # 4 corners of one face
            a, b, c, d = quad                                           # (0,0), (1,0), (0,1), (1,1)
            for tri in ((a, b, d), (a, d, c)):
                n = np.cross(corners[tri[1]] - corners[tri[0]], corners[tri[2]] - corners[tri[0]])
                outward = (n[axis] > 0) == (side == 1)
                tris.extend(tri if outward else tri[::-1])
    return ctx.vertex_array(program, [(ctx.buffer(corners.tobytes()), "3f", "in_pos")],
                            index_buffer=ctx.buffer(np.array(tris, np.int32).tobytes()))


def icosphere(subdivisions=1):
    """Unit-sphere triangles (n, 3, 3) float32: an icosahedron subdivided ``subdivisions`` times."""
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    tris = np.array([[v[i] for i in face] for face in f], float)
    for _ in range(subdivisions):
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        tris = np.concatenate([np.stack(s, 1) for s in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    tris /= np.linalg.norm(tris, axis=2, keepdims=True)
    return tris.astype(np.float32)


class Renderer:
    """Draws one ``Volume`` on ``ctx`` (``create_context()`` or a window's). ``max_texture``
    is the context's GL_MAX_3D_TEXTURE_SIZE; ``render`` draws into the bound framebuffer,
    ``image`` returns an RGB array."""

    def __init__(self, ctx, volume):
        moderngl = import_moderngl()
        self.ctx, self.moderngl = ctx, moderngl
        self.max_texture = int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"])
        if max(volume.spec.shape) > self.max_texture:
            raise ConfigError(f"grid {volume.spec.shape} exceeds this GL's 3D texture limit {self.max_texture}; "
                              f"build the volume with max_size={self.max_texture} to downsample it")
        self._programs, self._vaos, self._luts = {}, {}, {}
        self._spheres_stale, self._sphere_vao, self._sphere_count = True, None, 0
        self.volume = None
        self.upload(volume)

    # -- textures -------------------------------------------------------------------------
    def upload(self, volume):
        """Upload a whole volume (replaces the textures)."""
        spec = volume.spec
        for name in ("texture", "coarse", "coarser"):
            old = getattr(self, name, None)
            if old is not None:
                old.release()
        # (nz, ny, nx) x-fastest bytes are a (nx, ny, nz) GL texture: see viewer.volume
        self.texture = self.ctx.texture3d(spec.shape, 1, volume.values.tobytes(), dtype="f2")
        self.texture.filter = (self.moderngl.LINEAR, self.moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = self.texture.repeat_z = False
        nbz, nby, nbx = volume.coarse.shape
        self.coarse = self.ctx.texture3d((nbx, nby, nbz), 1, volume.coarse.tobytes(), dtype="f2")
        self.coarse.filter = (self.moderngl.NEAREST, self.moderngl.NEAREST)
        self.coarse.repeat_x = self.coarse.repeat_y = self.coarse.repeat_z = False
        self.coarser = self._coarser_texture(volume.coarse)
        self.volume = volume
        self._spheres_stale = True
        self._heights = {}

    def update(self, boxes, coarse_box):
        """Write the changed voxel boxes ((z0, z1), (y0, y1), (x0, x1)) and coarse cells
        ((bx0, by0, bz0), (bx1, by1, bz1)) of ``self.volume`` (``viewer.volume.update``'s
        result) into the textures."""
        values = self.volume.values
        for (z0, z1), (y0, y1), (x0, x1) in boxes:
            block = np.ascontiguousarray(values[z0:z1, y0:y1, x0:x1])
            self.texture.write(block.tobytes(), viewport=(x0, y0, z0, x1 - x0, y1 - y0, z1 - z0))
        if coarse_box is not None:
            (bx0, by0, bz0), (bx1, by1, bz1) = coarse_box
            block = np.ascontiguousarray(self.volume.coarse[bz0:bz1, by0:by1, bx0:bx1])
            self.coarse.write(block.tobytes(), viewport=(bx0, by0, bz0, bx1 - bx0, by1 - by0, bz1 - bz0))
            self.coarser.release()
            self.coarser = self._coarser_texture(self.volume.coarse)   # 1/64 of the coarse level: whole
        self._spheres_stale = True
        self._heights = {}

    def _coarser_texture(self, coarse):
        level = coarser_max(coarse)
        nz, ny, nx = level.shape
        tex = self.ctx.texture3d((nx, ny, nz), 1, level.tobytes(), dtype="f2")
        tex.filter = (self.moderngl.NEAREST, self.moderngl.NEAREST)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        return tex

    def _lut(self, name):
        if name not in self._luts:
            lut = self.ctx.texture((256, 1), 3, colormap_lut(name).tobytes())
            lut.repeat_x = lut.repeat_y = False
            self._luts[name] = lut
        return self._luts[name]

    def _program(self, stem, defines):
        key = (stem, defines)
        if key not in self._programs:
            self._programs[key] = build_program(self.ctx, stem, defines)
        return self._programs[key]

    # -- drawing --------------------------------------------------------------------------
    def render(self, camera, mode_name="occupancy", settings=Settings(), size=None):
        """Draw the volume into the bound framebuffer of ``size`` (width, height) pixels
        (default: the framebuffer's); returns the clamp (lo, hi) [nat] used."""
        m = mode(mode_name)
        ctx = self.ctx
        width, height = size or ctx.fbo.size
        spec = self.volume.spec
        lo, hi = settings.clamp_range(self.volume)
        free_lo, free_hi = settings.free_clamp(self.volume) if m.name == "free" else (1.0, 2.0)
        ctx.clear(*settings.background, 1.0, depth=1.0)
        mvp = camera.mvp(width, height).astype("f4").T.tobytes()     # column-major for GL
        dims = np.asarray(spec.shape, float)
        clip = np.asarray(settings.clip, float)
        lut = self._lut(settings.colormap)
        if m.program == "spheres":
            self._draw_spheres(camera, mvp, lo, hi, settings, lut, clip)
            return lo, hi
        skip = settings.skip and m.skips
        defines = (m.define,) + (("SKIP",) if skip else ())
        prog = self._program("volume", defines)
        clip_lo, clip_hi = clip[:, 0] * dims, clip[:, 1] * dims
        active_lo, active_hi = clip_lo, clip_hi
        if skip:                                    # only where this mode can see anything
            visible = (lambda c: c >= settings.threshold) if m.name == "iso" else (lambda c: c > lo)
            found = active_box(self.volume.coarse, visible)
            if found is None:
                return lo, hi                       # nothing to see: background only
            active_lo, active_hi = np.maximum(clip_lo, found[0]), np.minimum(clip_hi, found[1])
        values = dict(mvp=mvp, origin=spec.origin_m, voxel=spec.voxel_m, dims=tuple(dims),
                      camera_u=tuple((camera.eye - np.asarray(spec.origin_m)) / spec.voxel_m),
                      clip_lo=tuple(clip_lo), clip_hi=tuple(clip_hi), active_lo=tuple(active_lo),
                      active_hi=tuple(active_hi), lo=lo, hi=hi, free_lo=free_lo, free_hi=free_hi,
                      by_height=int(self.colours_by_height(settings.threshold)), gamma=settings.gamma,
                      density=settings.density,
                      threshold=settings.threshold, step_u=settings.step, background=settings.background,
                      height_range=tuple((np.asarray(self.height_range(settings.threshold)) - spec.origin_m[2])
                                         / spec.voxel_m),
                      volume=0, coarse=1, coarser=3, colormap=2)
        _set_uniforms(prog, values)
        self.texture.use(0)
        self.coarse.use(1)
        self.coarser.use(3)
        lut.use(2)
        if prog not in self._vaos:
            self._vaos[prog] = _unit_cube(ctx, prog)
        ctx.disable(self.moderngl.DEPTH_TEST | self.moderngl.BLEND)
        ctx.enable(self.moderngl.CULL_FACE)
        ctx.front_face = "ccw"
        ctx.cull_face = "front"                       # back faces only: one fragment per ray
        self._vaos[prog].render()
        ctx.cull_face = "back"
        ctx.disable(self.moderngl.CULL_FACE)
        return lo, hi

    def colours_by_height(self, threshold):
        """Whether the isosurface is coloured by height: not where its surface spans less than
        two voxels of height (a planar map), where height says nothing and log-odds does."""
        z_lo, z_hi = self.height_range(threshold)
        return z_hi - z_lo >= 2 * self.volume.spec.voxel_m

    def height_range(self, threshold):
        """(z_lo, z_hi) [m] the isosurface's colours span: the heights of the surface seen from
        above, the top-most cell at or above ``threshold`` of every column (2nd to 98th
        percentile: evidence under a surface is not what a view shows), or the grid's heights."""
        key = float(threshold)
        if key not in self._heights:
            spec = self.volume.spec
            z0, v = spec.origin_m[2], spec.voxel_m
            mask = above(self.volume.values, key, inclusive=True)
            seen = mask.any(axis=0)
            if seen.any():
                top = (mask.shape[0] - 1 - np.argmax(mask[::-1], axis=0))[seen]
                a, b = np.percentile(top, [2, 98])
                self._heights[key] = (z0 + a * v, z0 + (b + 1) * v)
            else:
                self._heights[key] = (z0, z0 + spec.shape[2] * v)
        return self._heights[key]

    def sphere_instances(self, max_spheres=MAX_SPHERES):
        """(centres (n, 3) float32 world [m], values (n,) float32 [nat]) of the cells with
        positive log-odds, the ``max_spheres`` largest if there are more (and says so)."""
        values = self.volume.values
        idx = np.flatnonzero(values > 0)
        if len(idx) > max_spheres:
            keep = np.argpartition(values.ravel()[idx], len(idx) - max_spheres)[len(idx) - max_spheres:]
            log.warning("spheres: %d positive cells, drawing the %d largest", len(idx), max_spheres)
            idx = np.sort(idx[keep])
        spec = self.volume.spec
        z, y, x = np.unravel_index(idx, values.shape)
        centres = (np.asarray(spec.origin_m) + (np.stack([x, y, z], 1) + 0.5) * spec.voxel_m).astype(np.float32)
        return centres, values.ravel()[idx].astype(np.float32)

    def _draw_spheres(self, camera, mvp, lo, hi, settings, lut, clip):
        prog = self._program("spheres", ("MODE_SPHERES",))
        if self._spheres_stale:
            centres, vals = self.sphere_instances()
            mesh = icosphere(1 if len(vals) < 200_000 else 0).reshape(-1, 3)
            inst = np.concatenate([centres, vals[:, None]], axis=1).astype(np.float32)
            if self._sphere_vao is not None:
                self._sphere_vao.release()
            self._sphere_vao = self.ctx.vertex_array(prog, [
                (self.ctx.buffer(mesh.tobytes()), "3f", "in_pos"),
                (self.ctx.buffer(inst.tobytes() if len(inst) else np.zeros(4, np.float32).tobytes()),
                 "3f 1f/i", "in_centre", "in_value")])
            self._sphere_count, self._sphere_vertices, self._spheres_stale = len(vals), len(mesh), False
        spec = self.volume.spec
        lo_w, hi_w = box(spec)
        _set_uniforms(prog, dict(mvp=mvp, voxel=spec.voxel_m, hi=hi, gamma=settings.gamma,
                                 clip_lo=tuple(lo_w + clip[:, 0] * (hi_w - lo_w)),
                                 clip_hi=tuple(lo_w + clip[:, 1] * (hi_w - lo_w)),
                                 light=tuple(camera.view()[2, :3]), colormap=2))
        lut.use(2)
        if self._sphere_count:
            self.ctx.enable(self.moderngl.DEPTH_TEST | self.moderngl.CULL_FACE)
            self._sphere_vao.render(instances=self._sphere_count)
            self.ctx.disable(self.moderngl.DEPTH_TEST | self.moderngl.CULL_FACE)

    @property
    def sphere_count(self):
        """Instances the last sphere draw used."""
        return self._sphere_count

    @property
    def sphere_triangles(self):
        """Triangles per sphere instance."""
        return self._sphere_vertices // 3

    def image(self, camera, mode_name="occupancy", settings=Settings(), size=(512, 512)):
        """Render offscreen at ``size`` (width, height); RGB uint8 (height, width, 3), row 0 at the top."""
        fbo = self.framebuffer(size)
        fbo.use()
        self.render(camera, mode_name, settings, size)
        return read_rgb(fbo)

    def framebuffer(self, size):
        """An offscreen RGBA8 + depth framebuffer of ``size``, kept for reuse."""
        cached = getattr(self, "_fbo", None)
        if cached is None or cached.size != tuple(size):
            if cached is not None:
                cached.release()
            self._fbo = self.ctx.framebuffer(color_attachments=[self.ctx.renderbuffer(tuple(size), 4)],
                                             depth_attachment=self.ctx.depth_renderbuffer(tuple(size)))
        return self._fbo


def _set_uniforms(prog, values):
    """Set the uniforms ``prog`` uses (the compiler drops unused ones); bytes are raw matrices."""
    for name, value in values.items():
        uniform = prog.get(name, None)
        if uniform is None:
            continue
        if isinstance(value, bytes):
            uniform.write(value)
        else:
            uniform.value = value


def read_rgb(fbo):
    """RGB uint8 (height, width, 3) of a framebuffer, row 0 at the top."""
    w, h = fbo.size
    return np.frombuffer(fbo.read(components=3, alignment=1), np.uint8).reshape(h, w, 3)[::-1].copy()
