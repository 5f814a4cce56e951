"""The volume renderer looked at pixel by pixel (EGL, Mesa llvmpipe in CI), and its numpy side.

Where a voxel must appear comes from ``Camera.project``, the matrices the shaders get. A
trilinear sample reads voxels up to one voxel away, so a lone occupied voxel may light pixels
within the projection of its box grown by one voxel on each side, and nowhere else."""

import numpy as np
import pytest
from radarcl.viewer import volume as V
from radarcl.viewer.camera import Camera, box
from radarcl.viewer.modes import MODES, Settings
from radarcl.viewer.renderer import Renderer, ViewerError, create_context

from radarcl.errors import ConfigError, FrameFormatError, ShapeError
from radarcl.gridspec import BRICK, GridSpec
from radarcl.maps.disk import read

SIZE = (160, 120)
RAY_MODES = [m for m in MODES if m != "spheres"]
# a non-cubic grid, off the origin, with an odd number of voxels along each axis
SPEC = GridSpec((-3.0, 2.0, -1.0), 0.25, (41, 23, 13))


@pytest.fixture(scope="module")
def ctx():
    return create_context()


def _nats(fill=-1.0):
    return np.full(SPEC.array_shape, fill, np.float64)


def _lit(img, background):
    return (img != np.asarray(np.asarray(background) * 255 + 0.5, np.uint8)).any(axis=-1)


def _background_u8(settings=Settings()):
    """The background as the framebuffer stores it (RGBA8 rounds to nearest)."""
    return np.round(np.asarray(settings.background) * 255).astype(np.uint8)


def _box_pixels(camera, lo, hi):
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    px = camera.project(corners, *SIZE)
    return px.min(axis=0), px.max(axis=0)


def _voxel_box(index, grow=1.0):
    lo = np.asarray(SPEC.origin_m) + (np.asarray(index) - grow) * SPEC.voxel_m
    return lo, lo + (1 + 2 * grow) * SPEC.voxel_m


@pytest.mark.parametrize("mode_name", list(MODES))
@pytest.mark.parametrize("preset", ["iso", "top", "front"])
def test_a_single_cube_appears_where_its_projection_says_and_nowhere_else(ctx, mode_name, preset):
    index = (30, 5, 9)                                   # asymmetric: an axis swap puts it elsewhere
    nats = _nats()
    nats[index[2], index[1], index[0]] = 5.0
    renderer = Renderer(ctx, V.from_nats(SPEC, nats))
    camera = Camera.fit(SPEC, preset)
    img = renderer.image(camera, mode_name, Settings(), SIZE)
    lit = np.argwhere((img != _background_u8()).any(axis=-1))[:, ::-1]      # (column, row)
    assert len(lit), "the cube did not appear"
    grow = 0.5 if mode_name == "spheres" else 1.0      # a sphere stays inside its voxel
    lo, hi = _box_pixels(camera, *_voxel_box(index, grow - 0.5))
    assert (lit >= np.floor(lo) - 1).all() and (lit <= np.ceil(hi) + 1).all(), (lit.min(0), lit.max(0), lo, hi)
    centre = camera.project(SPEC.index_to_world(np.array(index)), *SIZE)[0]
    assert _lit(img, Settings().background)[int(centre[1]), int(centre[0])]


@pytest.mark.parametrize("fill", [0.0, -2.0])
@pytest.mark.parametrize("mode_name", list(MODES))
def test_an_empty_grid_renders_background_only(ctx, mode_name, fill):
    """Nothing occupied: background everywhere, except in the free mode, where an all-free grid
    (-2 nat) is a blue haze over the whole box and an unknown one (0) shows nothing."""
    renderer = Renderer(ctx, V.from_nats(SPEC, _nats(fill)))
    for preset in ("iso", "top"):
        camera = Camera.fit(SPEC, preset)
        img = renderer.image(camera, mode_name, Settings(), SIZE)
        if mode_name == "free" and fill < -1.0:
            lit = (img != _background_u8()).any(axis=-1)
            lo, hi = _box_pixels(camera, *box(SPEC))
            assert lit.mean() > 0.2 and (img[lit][:, 2] > img[lit][:, 0]).all()        # blue, over the box
            assert not lit[:, :max(0, int(lo[0]) - 2)].any()
        else:
            assert (img == _background_u8()).all()


@pytest.mark.parametrize("mode_name", RAY_MODES)
def test_no_wrap_around_at_the_faces(ctx, mode_name):
    """A patch on the last layer of each axis must not show on the first layer, where GL's
    default REPEAT would blend it into samples within half a voxel of the face. Threshold 0
    and quarter-voxel steps put samples there; the oblique camera puts the two faces apart."""
    settings = Settings(threshold=0.0, step=0.25, skip=False)   # the plain march reads every sample
    for axis in range(3):
        nats = _nats(0.0) if mode_name == "free" else _nats()       # the free mode shows free space
        index = [3, 3, 3]
        index[axis] = SPEC.shape[axis] - 1
        patch = [slice(i - 1, i + 2) for i in index]
        patch[axis] = slice(index[axis], index[axis] + 1)
        nats[patch[2], patch[1], patch[0]] = 5.0
        renderer = Renderer(ctx, V.from_nats(SPEC, nats))
        camera = Camera.fit(SPEC, "iso")
        img = renderer.image(camera, mode_name, settings, SIZE)
        lit = np.argwhere((img != _background_u8(settings)).any(axis=-1))[:, ::-1]
        lo = np.asarray(SPEC.origin_m) + (np.array([p.start for p in patch]) - 1) * SPEC.voxel_m
        hi = np.asarray(SPEC.origin_m) + (np.array([p.stop for p in patch]) + 1) * SPEC.voxel_m
        p_lo, p_hi = _box_pixels(camera, lo, hi)
        assert len(lit) and (lit >= np.floor(p_lo) - 1).all() and (lit <= np.ceil(p_hi) + 1).all(), axis


def test_textures_clamp_to_edge(ctx):
    renderer = Renderer(ctx, V.from_nats(SPEC, _nats()))
    for tex in (renderer.texture, renderer.coarse, renderer.coarser):
        assert not (tex.repeat_x or tex.repeat_y or tex.repeat_z)


@pytest.mark.parametrize("mode_name", list(MODES))
def test_every_mode_renders_without_gl_errors(ctx, mode_name):
    rng = np.random.default_rng(3)
    nats = rng.normal(0.0, 2.0, SPEC.array_shape)
    renderer = Renderer(ctx, V.from_nats(SPEC, nats))
    assert ctx.error == "GL_NO_ERROR"
    for settings in (Settings(), Settings(skip=False), Settings(gamma=0.5, colormap="viridis", step=0.5),
                     Settings(clip=((0.2, 0.4), (0.0, 1.0), (0.0, 1.0)))):
        img = renderer.image(Camera.fit(SPEC, "iso"), mode_name, settings, SIZE)
        assert ctx.error == "GL_NO_ERROR"
        assert _lit(img, settings.background).any()


def test_spheres_draw_one_instance_per_positive_cell(ctx):
    rng = np.random.default_rng(4)
    nats = _nats()
    cells = rng.choice(SPEC.n_voxels, 57, replace=False)
    nats.ravel()[cells] = rng.uniform(0.01, 6.0, len(cells))
    nats.ravel()[cells[:5]] = 0.0                         # zero is not positive
    renderer = Renderer(ctx, V.from_nats(SPEC, nats))
    fbo = renderer.framebuffer(SIZE)
    fbo.use()
    with ctx.query(primitives=True) as q:
        renderer.render(Camera.fit(SPEC), "spheres", Settings(), SIZE)
    positive = int((renderer.volume.values > 0).sum())
    assert positive == 52 and renderer.sphere_count == positive
    assert q.primitives == positive * renderer.sphere_triangles
    centres, values = renderer.sphere_instances()
    np.testing.assert_allclose(np.sort(values), np.sort(renderer.volume.values[renderer.volume.values > 0]))
    # centres are voxel centres in world coordinates
    idx = SPEC.world_to_index(centres)
    np.testing.assert_allclose(SPEC.index_to_world(idx), centres, atol=1e-5)


def _blobs(seed=5):
    rng = np.random.default_rng(seed)
    nats = _nats(-0.5)
    z, y, x = np.indices(SPEC.array_shape)
    for _ in range(6):
        c = rng.uniform(0, 1, 3) * SPEC.shape
        nats += 6 * np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / 3.0)
    return nats


@pytest.mark.parametrize("mode_name", RAY_MODES)
def test_skipping_changes_time_not_pixels(ctx, mode_name):
    renderer = Renderer(ctx, V.from_nats(SPEC, _blobs()))
    for preset in ("iso", "top", "side"):
        camera = Camera.fit(SPEC, preset)
        a = renderer.image(camera, mode_name, Settings(skip=True), SIZE)
        b = renderer.image(camera, mode_name, Settings(skip=False), SIZE)
        assert _lit(a, Settings().background).sum() > 50
        assert np.array_equal(a, b), f"{preset}: {np.abs(a.astype(int) - b).max()}"
    inside = Camera(tuple(np.asarray(SPEC.origin_m) + np.asarray(SPEC.shape) * SPEC.voxel_m / 2), 0.5, 30, 10)
    a = renderer.image(inside, mode_name, Settings(skip=True), SIZE)         # the camera inside the box
    assert np.array_equal(a, renderer.image(inside, mode_name, Settings(skip=False), SIZE))


def test_partial_update_equals_a_fresh_upload(ctx, tmp_path):
    units = np.rint(_blobs() * 1024).astype(np.int32)
    spec = SPEC
    keys = np.argwhere(np.ones(spec.brick_shape, bool)).astype(np.int32)            # (bx, by, bz)
    nbx, nby, nbz = spec.brick_shape
    full = np.zeros((nbz * BRICK, nby * BRICK, nbx * BRICK), np.int32)
    full[:units.shape[0], :units.shape[1], :units.shape[2]] = units
    bricks = full.reshape(nbz, BRICK, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)[keys[:, 2], keys[:, 1], keys[:, 0]]
    old = V.from_units(spec, units)
    old.keys, old.bricks = keys, bricks.copy()
    renderer = Renderer(ctx, old)
    new_bricks = bricks.copy()
    new_bricks[3] += 4096                                # one brick gains evidence
    new_bricks[-1] = 0                                   # a corner brick is cleared
    new_keys = keys[:-2]                                 # and one brick disappears entirely
    new_bricks = new_bricks[:-2]
    new_bricks[-1] -= 2048
    changed = V.changed_bricks(old.keys, old.bricks, new_keys, new_bricks)
    assert {tuple(k) for k in changed.tolist()} == {tuple(keys[3]), tuple(keys[-1]), tuple(keys[-2]), tuple(keys[-3])}
    boxes, coarse_box = V.update(old, new_keys, new_bricks, changed)
    renderer.update(boxes, coarse_box)
    from radarcl.gridspec import assemble
    fresh = V.from_units(spec, assemble(spec, new_keys, new_bricks))
    assert np.array_equal(old.values, fresh.values) and np.array_equal(old.coarse, fresh.coarse)
    camera = Camera.fit(spec)
    for mode_name in MODES:
        a = renderer.image(camera, mode_name, Settings(hi=6.0), SIZE)
        b = Renderer(ctx, fresh).image(camera, mode_name, Settings(hi=6.0), SIZE)
        assert np.array_equal(a, b), mode_name


# -- the numpy side -------------------------------------------------------------------------

def test_coarse_max_holds_every_readable_value():
    rng = np.random.default_rng(6)
    values = rng.standard_normal((19, 27, 35)).astype(np.float32)
    coarse = V.coarse_max(values)
    nz, ny, nx = values.shape
    for bz, by, bx in np.ndindex(coarse.shape):
        idx = [np.clip(np.arange(b * 8 - 1, b * 8 + 9), 0, n - 1) for b, n in ((bz, nz), (by, ny), (bx, nx))]
        assert coarse[bz, by, bx] == values[np.ix_(*idx)].max()
    assert np.array_equal(V.coarse_max(values, (1, 1, 0), (3, 3, 2)), coarse[0:2, 1:3, 1:3])
    coarser = V.coarser_max(coarse)
    assert coarser.shape == (1, 1, 2) and coarser[0, 0, 0] == coarse[:, :, :4].max()


def test_texture_values_and_voxel_centres():
    units = np.array([0, 1024, -1024, 2 ** 30, -(2 ** 30), 1536], np.int32)
    assert V.to_texture(units).tolist() == [0.0, 1.0, -1.0, 1000.0, -1000.0, 1.5]
    spec = GridSpec((1.0, -2.0, 0.5), 0.5, (4, 3, 2))
    camera = Camera.fit(spec)
    # the box's corners are the grid's outer faces: voxel centres sit half a voxel inside
    lo, hi = np.asarray(spec.origin_m), np.asarray(spec.origin_m) + np.asarray(spec.shape) * spec.voxel_m
    np.testing.assert_allclose(spec.index_to_world(np.array([0, 0, 0])), lo + 0.25)
    np.testing.assert_allclose(spec.index_to_world(np.array([3, 2, 1])), hi - 0.25)
    np.testing.assert_allclose(camera.project(np.asarray(camera.target)[None], 64, 48)[0], (32, 24), atol=1e-9)


def test_a_grid_over_the_texture_limit_is_downsampled_and_says_so():
    units = np.zeros(SPEC.array_shape, np.int32)
    units[12, 22, 40] = 5000                             # the far corner voxel
    vol = V.from_units(SPEC, units, max_size=16)
    assert "texture limit of 16" in vol.note and "max-pooled by 3" in vol.note
    assert vol.spec.shape == (14, 8, 5) and vol.spec.voxel_m == pytest.approx(0.75)
    assert vol.values.max() == pytest.approx(5000 / 1024, abs=1e-3) and vol.values[4, 7, 13] == vol.values.max()


def test_renderer_refuses_a_volume_over_its_limit(ctx):
    big = GridSpec((0, 0, 0), 1.0, (int(ctx.info["GL_MAX_3D_TEXTURE_SIZE"]) + 1, 1, 1))
    vol = V.Volume(big, np.zeros(big.array_shape, np.float16), np.zeros((1, 1, 257), np.float16))
    with pytest.raises(ConfigError, match="3D texture limit"):
        Renderer(ctx, vol)


def _save(path, **arrays):
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def test_a_file_that_is_not_a_map_gets_a_sentence(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(FrameFormatError, match="is not a radarcl grid file"):
        V.load_map(text)
    with pytest.raises(FrameFormatError, match="missing.npz does not exist \\(yet\\)"):    # not "not a grid file"
        V.load_map(tmp_path / "missing.npz")
    dup = tmp_path / "dup.npz"                  # a crafted map: the same brick twice
    _save(dup, version=1, origin_m=np.zeros(3), voxel_m=1.0, shape=np.array([16, 16, 16]),
          keys=np.zeros((2, 3), np.int32), data=np.zeros((2, 8, 8, 8), np.int32))
    with pytest.raises(FrameFormatError, match="a brick key appears more than once"):
        V.load_map(dup)
    other = tmp_path / "recording.npz"
    _save(other, samples=np.zeros(3))
    with pytest.raises(FrameFormatError, match="lacks"):
        V.load_map(other)
    ok = dict(version=1, origin_m=np.zeros(3), voxel_m=0.5, shape=np.array([8, 8, 8]),
              keys=np.zeros((1, 3), np.int32), data=np.zeros((1, 8, 8, 8), np.int32))
    for change, message in ((dict(version=7), "version 7"), (dict(data=np.zeros((1, 8, 8, 8), np.float32)), "int32"),
                            (dict(keys=np.full((1, 3), 5, np.int32)), "outside the grid"),
                            (dict(voxel_m=-1.0), "voxel_m")):
        bad = tmp_path / "bad.npz"
        _save(bad, **{**ok, **change})
        with pytest.raises(FrameFormatError, match=message):
            read(bad)
    with pytest.raises(ShapeError):
        V.from_units(SPEC, np.zeros((2, 2, 2), np.int32))
    with pytest.raises(ConfigError, match="NaN"):
        V.from_nats(SPEC, np.full(SPEC.array_shape, np.nan))


def test_no_egl_or_no_moderngl_says_what_to_install(monkeypatch):
    import moderngl

    def fail(**kwargs):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(ViewerError, match="apt-get install libegl1 libegl-mesa0"):
        create_context()
    monkeypatch.setitem(__import__("sys").modules, "moderngl", None)
    with pytest.raises(ViewerError, match=r"pip install 'radarcl\[viewer\]'"):
        create_context()


def test_settings_and_camera_refuse_impossible_values():
    for bad in (dict(colormap="rainbow"), dict(step=0.0), dict(gamma=0), dict(lo=2.0, hi=1.0),
                dict(clip=((0.5, 0.4), (0, 1), (0, 1)))):
        with pytest.raises(ConfigError):
            Settings(**bad)
    with pytest.raises(ConfigError, match="preset"):
        Camera.parse("sideways", SPEC)
    with pytest.raises(ConfigError, match="distance"):
        Camera((0, 0, 0), -1.0)
    cam = Camera.parse("30,20,15,1,2,3", SPEC)
    assert (cam.azimuth_deg, cam.elevation_deg, cam.distance, cam.target) == (30.0, 20.0, 15.0, (1.0, 2.0, 3.0))


def test_pooled_loading_equals_the_dense_downsample_and_bounds_memory(tmp_path):
    """load_map pools from bricks a slab at a time: the same volume as downsampling the dense
    snapshot (factors 2, 3, 8), and a 3.6 KB file declaring 1000^3 voxels (4 GB dense) loads in
    a small budget, pooled, with a note, its peak memory measured in a fresh process (peak_memory.py)."""
    from peak_memory import peak_growth

    from radarcl.gridspec import assemble

    rng = np.random.default_rng(4)
    spec = GridSpec((0.0, 0.0, 0.0), 0.5, (45, 30, 21))
    keys = np.array([(bx, by, bz) for bx in range(6) for by in range(4) for bz in range(3)
                     if rng.random() < 0.6], np.int32)
    bricks = rng.integers(-5000, 5000, (len(keys), 8, 8, 8)).astype(np.int32)
    path = tmp_path / "m.npz"
    _save(path, version=1, origin_m=np.zeros(3), voxel_m=0.5, shape=np.array(spec.shape), keys=keys, data=bricks)
    dense = assemble(spec, keys, bricks)
    for max_size in (23, 15, 6):
        want = V.from_units(spec, dense, max_size=max_size)
        got = V.load_map(path, max_size=max_size)
        assert got.spec == want.spec and np.array_equal(got.values, want.values) and got.note
    big = tmp_path / "big.npz"
    _save(big, version=1, origin_m=np.zeros(3), voxel_m=0.1, shape=np.array([1000, 1000, 1000]),
          keys=np.array([[0, 0, 0], [124, 124, 124]], np.int32), data=np.full((2, 8, 8, 8), 2048, np.int32))
    assert big.stat().st_size < 10_000
    grew_mib, got = peak_growth("from radarcl.viewer import volume as V", f"""
vol = V.load_map({str(big)!r}, max_size=2048, budget=64 * 2 ** 20)
result = dict(note=vol.note, shape=list(vol.spec.shape), max=float(vol.values.max()))
""")
    assert "memory budget" in got["note"] and max(got["shape"]) <= 1000 // 4 and grew_mib < 256, (grew_mib, got)
    assert got["max"] == 2.0


@pytest.mark.parametrize("lo, hi", [(-0.1, 2.1), (1.0, 5.98), (-10.0, 10.0), (1.0, 86.87), (-0.15, 0.15),
                                    (0.0, 1e-7), (-1000.0, 1000.0), (2.5, 2.5001)])
def test_colour_bar_ticks_are_round_and_inside(lo, hi):
    from radarcl.viewer.overlay import tick_labels, ticks

    values = ticks(lo, hi)
    assert 3 <= len(values) <= 10, values
    span = hi - lo
    assert all(lo - 1e-9 * span <= v <= hi + 1e-9 * span for v in values)
    step = values[1] - values[0]
    mantissa = step / 10 ** np.floor(np.log10(step))
    assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-6, step
    assert len(set(tick_labels(values))) == len(values)          # labels tell the ticks apart


@pytest.mark.parametrize("lo", [0.0, 1.0, 1.0009, 3.3, 65504.0, -0.5, -1000.0])
def test_the_fast_float16_compare_equals_numpy(lo):
    rng = np.random.default_rng(7)
    values = np.concatenate([rng.normal(0, 5, 5000), [0.0, -0.0, 1.0, 1.0009, np.inf, -np.inf, 65504.0, 6e-8]])
    values = values.astype(np.float16)
    assert np.array_equal(V.above(values, lo), values > np.float16(lo))
    assert np.array_equal(V.above(values, lo, inclusive=True), values >= np.float16(lo))


def test_the_default_clamp_spans_what_the_map_holds():
    """The colours run from the threshold to the 90th percentile of the values above it, so
    most occupied voxels get distinct colours (at the 99.9th nearly all of them were dark)."""
    rng = np.random.default_rng(3)
    nats = _nats(0.0)
    values = rng.exponential(1.0, nats.size) + 1.0
    nats.reshape(-1)[:] = np.where(rng.random(nats.size) < 0.3, values, 0.0)
    volume = V.from_nats(SPEC, nats)
    lo, hi = Settings().clamp_range(volume)
    stored = volume.values[volume.values > 1.0].astype(np.float64)
    assert lo == 1.0 and hi == pytest.approx(np.percentile(stored, 90), rel=1e-6)
    assert np.mean(stored <= hi) == pytest.approx(0.9, abs=0.01)


def test_a_planar_map_is_coloured_by_log_odds_and_the_free_mode_shows_free_space(ctx):
    """One layer (a spinning radar's map): height says nothing, so the isosurface takes its colours
    from the log-odds and the legend says so; the free mode draws free voxels as a blue haze."""
    from radarcl.viewer.headless import legend

    flat = GridSpec((0.0, 0.0, -0.125), 0.25, (40, 40, 1))
    nats = np.zeros(flat.array_shape)
    nats[0, 10:30, 10:14] = 2.0                       # a weak wall ...
    nats[0, 10:30, 26:30] = 9.0                       # ... and a strong one
    nats[0, 5:35, 15:25] = -3.0                       # free between them
    renderer = Renderer(ctx, V.from_nats(flat, nats))
    assert not renderer.colours_by_height(1.0)
    camera = Camera.fit(flat, "top")
    img = renderer.image(camera, "iso", Settings(), (200, 200))
    walls = [img[camera.project(np.array([[x, 5.0, 0.0]]), 200, 200)[0, 1].astype(int),
                 camera.project(np.array([[x, 5.0, 0.0]]), 200, 200)[0, 0].astype(int)] for x in (3.0, 7.0)]
    assert np.abs(walls[0].astype(int) - walls[1].astype(int)).sum() > 60     # two values, two colours
    bar = legend(renderer, "iso", Settings(), 1.0, 9.0, height=120)
    assert bar.shape[0] > 0
    free = renderer.image(camera, "free", Settings(density=2.0), (200, 200))
    px = camera.project(np.array([[5.0, 5.0, 0.0]]), 200, 200)[0].astype(int)
    r, g, b = free[px[1], px[0]].astype(int)
    assert b > r + 15 and b > np.asarray(_background_u8())[2] + 15                  # blue over the background


def test_a_map_with_knowledge_is_drawn_as_it_reads_and_unknown_is_not_free(tmp_path):
    """load_map of a detection-statistics map: the reading (16 looks of -0.5 nat with a look
    limit of 4 read -2 nat, not the raw -8), and a voxel the radar never observed (a quarter look)
    is 0, which no mode draws, though its raw sum says -3 nat."""
    from radarcl.maps import npz

    keys = np.array([[0, 0, 0]], np.int32)
    data, knowledge, looks = (np.zeros((1, BRICK, BRICK, BRICK), np.int32) for _ in range(3))
    data[0, 1, 1, 1], knowledge[0, 1, 1, 1], looks[0, 1, 1, 1] = -8 * 1024, 16 * 4096, 16
    data[0, 2, 2, 2], knowledge[0, 2, 2, 2], looks[0, 2, 2, 2] = -3 * 1024, 1024, 1
    data[0, 3, 3, 3], knowledge[0, 3, 3, 3], looks[0, 3, 3, 3] = 5 * 1024, 4096, 1
    path = tmp_path / "k.npz"
    npz.write(path, SPEC, keys, data, channels=npz.Channels(knowledge, looks,
                                                            dict(look_limit=4.0, prior_nats=0.0, prior_looks=0.5)))
    values = V.load_map(path).values.astype(np.float64)
    assert [values[i, i, i] for i in (1, 2, 3)] == [-2.0, 0.0, 5.0]
