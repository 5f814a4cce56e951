"""The viewer's commands and app: `radarcl render` headless, `radarcl view` in a real window
under Xvfb (CI installs it: `make test` runs `apt-get install xvfb` where it is missing) and in
moderngl-window's headless window, keys, live updates, bad input, and no pyopencl."""

import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image
from radarcl.viewer.modes import Settings

from radarcl import cli
from radarcl.gridspec import BRICK, GridSpec

SPEC = GridSpec((-4.0, -3.0, -1.0), 0.25, (40, 32, 24))
CUBE = (16, 24, 8, 16, 8, 16)   # brick-aligned: the view frames it in the middle
BACKGROUND = np.round(np.asarray(Settings().background) * 255).astype(np.uint8)


def write_map(path, cube=CUBE, value=4.0, poses=None):
    """A map file as radarcl writes it, with one cube (x0, x1, y0, y1, z0, z1) of
    ``value`` nat in free space (-1 nat) and the sensor's ``poses`` when given; numpy only."""
    nats = np.full(SPEC.array_shape, -1.0)
    x0, x1, y0, y1, z0, z1 = cube
    nats[z0:z1, y0:y1, x0:x1] = value
    units = np.rint(nats * 1024).astype(np.int32)
    nbx, nby, nbz = SPEC.brick_shape
    keys = np.argwhere(np.ones((nbx, nby, nbz), bool)).astype(np.int32)
    blocks = units.reshape(nbz, BRICK, nby, BRICK, nbx, BRICK).transpose(0, 2, 4, 1, 3, 5)
    data = np.ascontiguousarray(blocks[keys[:, 2], keys[:, 1], keys[:, 0]])
    tmp = f"{path}.tmp"
    with open(tmp, "wb") as f:
        np.savez_compressed(f, version=1, origin_m=np.asarray(SPEC.origin_m), voxel_m=SPEC.voxel_m,
                            shape=np.asarray(SPEC.shape), keys=keys, data=data,
                            **({} if poses is None else dict(poses=poses)))
    shutil.move(tmp, path)
    return path


def _lit(path):
    img = np.asarray(Image.open(path).convert("RGB"))
    return img, (img != BACKGROUND).any(axis=-1)


def test_render_writes_the_picture_with_its_colour_bar(tmp_path, capsys):
    m = write_map(tmp_path / "map.npz")
    for mode in ("occupancy", "mip", "iso", "spheres"):
        out = tmp_path / f"{mode}.png"
        assert cli.main(["render", str(m), "--out", str(out), "--mode", mode, "--size", "240", "180"]) == 0
        img, lit = _lit(out)
        assert img.shape == (180, 240, 3)
        assert lit[90, 120], mode                         # the cube is what the camera frames
        assert lit[10:40, 200:].any()                     # the colour bar, top right
    out = tmp_path / "bare.png"
    assert cli.main(["render", str(m), "--out", str(out), "--no-colorbar", "--no-guides", "--size", "240", "180",
                     "--camera", "top"]) == 0
    _, lit = _lit(out)
    rows, cols = np.flatnonzero(lit.any(axis=1)), np.flatnonzero(lit.any(axis=0))
    assert lit[90, 120] and 0 < cols.min() and cols.max() < 239 and 0 < rows.min() and rows.max() < 179
    guided = tmp_path / "guided.png"
    assert cli.main(["render", str(m), "--out", str(guided), "--no-colorbar", "--size", "240", "180",
                     "--camera", "top"]) == 0
    _, lit_g = _lit(guided)
    assert lit_g[:, :50].any() and lit_g[160:].any()           # the ground grid and the scale label
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("camera", ["iso", "top", "front", "-160,30"])
def test_the_default_view_frames_the_content_tightly(tmp_path, camera):
    """The map's content, not its grid, fills the picture: the cube's pixels span at least 80 %
    of the height or width and touch no edge, and a lone false alarm far off (0.2 % of the
    occupied voxels) does not change the frame."""
    m = write_map(tmp_path / "map.npz")
    with np.load(m) as f:
        arrays = dict(f)
    outlier = arrays["data"].copy()
    outlier[0, 0, 0, 0] = 4 * 1024                  # the grid's corner voxel, 7 m from the cube
    tmp = tmp_path / "outlier.npz"
    with open(tmp, "wb") as f:
        np.savez_compressed(f, **{**arrays, "data": outlier})
    spans = []
    for path in (m, tmp):
        out = tmp_path / f"{path.stem}.png"
        assert cli.main(["render", str(path), "--out", str(out), "--no-colorbar", "--no-guides", "--size", "240",
                         "180", f"--camera={camera}"]) == 0
        _, lit = _lit(out)
        rows, cols = np.flatnonzero(lit.any(axis=1)), np.flatnonzero(lit.any(axis=0))
        assert 0 < rows.min() and rows.max() < 179 and 0 < cols.min() and cols.max() < 239, camera
        assert max((rows.max() - rows.min()) / 180, (cols.max() - cols.min()) / 240) >= 0.8, camera
        spans.append((rows.min(), rows.max(), cols.min(), cols.max()))
    assert spans[0] == spans[1], (camera, spans)


def test_bad_input_gets_a_sentence_not_a_traceback(tmp_path, capsys):
    text = tmp_path / "not_a_map.npz"
    text.write_text("not a zip")
    assert cli.main(["render", str(text), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "radarcl: error:" in err and "is not a radarcl grid file" in err and "Traceback" not in err
    m = write_map(tmp_path / "map.npz")
    assert cli.main(["render", str(m), "--camera", "1,2,3,4", "--out", str(tmp_path / "x.png")]) == 2
    assert "AZ,EL" in capsys.readouterr().err
    assert cli.main(["view", str(text), "--window", "headless", "--frames", "1"]) == 2
    assert "is not a radarcl grid file" in capsys.readouterr().err


def test_the_window_under_xvfb_saves_a_screenshot(tmp_path):
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        pytest.fail("xvfb-run not found: `make test` installs it (apt-get install xvfb)")
    m = write_map(tmp_path / "map.npz")
    shot = tmp_path / "shot.png"
    cmd = [xvfb, "-a", "-s", "-screen 0 800x600x24", sys.executable, "-m", "radarcl", "view", str(m),
           "--size", "320", "240", "--frames", "4", "--keys", "2h", "--screenshot", str(shot)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    img, lit = _lit(shot)
    assert img.shape == (240, 320, 3)
    assert lit[120, 160]                                 # the cube, framed in the middle
    assert lit[10:60, 10:100].any()                      # the help overlay ('h')
    assert lit[-30:, :100].any()                         # the status line


@pytest.fixture
def app_for(tmp_path):
    from radarcl.viewer.app import ViewerApp, open_window
    from radarcl.viewer.camera import Camera
    from radarcl.viewer.volume import load_map

    made = []

    def make(path, **kw):
        wnd = open_window("headless", (160, 120), "test")
        vol = load_map(path)
        app = ViewerApp(wnd, path, vol, camera=Camera.fit(vol.spec, region=vol.content_box(1.0)), **kw)
        made.append(wnd)
        return app

    yield make
    for wnd in made:
        wnd.destroy()


def _frame(app):
    from radarcl.viewer.renderer import read_rgb

    app.frame()
    return read_rgb(app.wnd.fbo)


def test_keys_change_what_the_app_draws(tmp_path, app_for, monkeypatch):
    from radarcl.viewer.app import ACTIONS

    monkeypatch.chdir(tmp_path)                          # 's' saves here
    app = app_for(write_map(tmp_path / "map.npz"))
    first = _frame(app)
    for key, expect in (("2", "mip"), ("3", "iso"), ("4", "spheres"), ("1", "occupancy")):
        app.press(key)
        assert app.mode == expect
    app.press("3")
    assert not np.array_equal(_frame(app), first)
    app.press("T")
    assert app.settings.threshold == 1.25
    app.press("x")
    assert app.slice_axis == "x" and app.settings.clip[0] == (0.475, 0.525)
    app.press("]")
    assert app.settings.clip[0][0] == pytest.approx(0.495)
    app.press("x")
    assert app.slice_axis is None and app.settings.clip[0] == (0.0, 1.0)
    before = app.camera
    app.drag(30, 0)
    app.drag(10, 10, pan=True)
    app.scroll(2)
    assert app.camera != before
    app.press("r")
    assert app.camera == before
    app.press("c")
    assert app.settings.colormap == "viridis"
    for _ in range(40):
        app.press("g")                                   # a gamma out of range goes to the status line
    assert "gamma" in app.message
    app.press("s")
    assert (tmp_path / "radarcl_view_1.png").exists() and app.message == "saved radarcl_view_1.png"
    assert set(ACTIONS) >= {"1", "2", "3", "4", "t", "T", "x", "y", "z", "[", "]", "s", "h", "q"}


def test_live_uploads_the_changed_bricks_and_survives_a_broken_file(tmp_path, app_for):
    path = write_map(tmp_path / "map.npz")
    app = app_for(path, live=True)
    before = _frame(app)
    path_so_far = np.stack([np.eye(4)] * 2)
    path_so_far[1, 0, 3] = 1.5
    write_map(path, value=9.0, poses=path_so_far)                   # the cube gains evidence, the sensor moves
    assert app.poll(force=True) == 1                                # the cube is one brick
    assert np.array_equal(app.renderer.volume.poses, path_so_far)   # the path drawn grows with the map
    after = _frame(app)
    assert not np.array_equal(before, after)
    fresh = app_for(path)
    fresh.settings = app.settings
    assert np.array_equal(after, _frame(fresh))                     # as if loaded anew
    path.write_bytes(b"half a file")
    assert app.poll(force=True) is None and "waiting for the next write" in app.message
    assert np.array_equal(_frame(app)[:-40], after[:-40])           # the map is kept (status line aside)


def test_the_viewer_never_imports_pyopencl(tmp_path):
    m = write_map(tmp_path / "map.npz")
    script = ("import sys\n"
              "from radarcl.viewer.headless import render_map\n"
              "from radarcl.viewer import app, volume, renderer, overlay, camera, modes\n"
              f"render_map({str(m)!r}, {str(tmp_path / 'v.png')!r}, 'iso', size=(64, 48), report=lambda s: None)\n"
              "print('pyopencl' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_bench_viewer_on_a_small_map(tmp_path):
    from radarcl.bench import viewer

    result = viewer.run(str(write_map(tmp_path / "map.npz")), repeat=2)
    assert {"ms_per_frame", "naive_ms_per_frame", "renderer"} <= set(result)
    for name in ("occupancy", "mip", "iso"):
        assert result["modes"][name]["max_pixel_diff"] == 0 and result["modes"][name]["lit_pixels"] > 0
    assert result["modes"]["spheres"]["instances"] == 8 ** 3
    assert result["update"]["partial_ms"] > 0


def test_no_display_says_what_to_do(tmp_path):
    m = write_map(tmp_path / "map.npz")
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    res = subprocess.run([sys.executable, "-m", "radarcl", "view", str(m), "--frames", "1"], capture_output=True,
                         text=True, timeout=60, env=env)
    assert res.returncode == 2 and "there is no display" in res.stderr and "xvfb-run" in res.stderr
    assert "Traceback" not in res.stderr
