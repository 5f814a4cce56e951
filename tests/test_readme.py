"""Every command the README shows is run here, as written, on small data.

The README's ``sh`` blocks are read, not copied: ``RUNS`` says how each line is run, and a line
added to the README without an entry here (or an entry whose line left the README) fails. Most
lines run verbatim in a working directory beside a link to ../shared/data, in the README's
order, so the map one command writes is the one the next command reads. The exceptions, each
with its reason in ``RUNS``:

- placeholders for data sets that are not in ../shared/data (Boreas, MulRan): a recording in
  the data set's documented layout is written under the README's name first, then the line runs
  verbatim;
- a serial port: the README's ``radarcl live /dev/ttyUSB0 ...`` runs on a pseudo-terminal fed
  TI demo frames made from the shared TI capture, everything else verbatim;
- what takes minutes (``make demo``, ``make test``): their recipe (test_cli runs ``radarcl demo
  --quick``); the viewer's window runs on Xvfb, closed after four frames with a screenshot;
- the Commands table is a synopsis: each of its lines runs ``radarcl NAME --help``.
"""

import contextlib
import io
import math
import os
import re
import shlex
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA
from PIL import Image

from radarcl.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def sh_lines(text):
    """[(section, line)] of every command in the ``sh`` blocks, comments dropped."""
    found, section = [], None
    for block in re.finditer(r"^(## [^\n]*)$|^```sh\n(.*?)^```", text, re.S | re.M):
        if block.group(1):
            section = block.group(1)[3:]
            continue
        for line in block.group(2).splitlines():
            command = re.split(r"\s+#\s", line, maxsplit=1)[0].strip()
            if command:
                found.append((section, command))
    return found


SYNOPSIS = [line for section, line in sh_lines(README) if section == "Commands"]
EXAMPLES = [line for section, line in sh_lines(README) if section != "Commands"]


# -- data the README names but ../shared/data does not hold, written in each data set's layout --------

def boreas_recording(where):
    """Two scans in Boreas' layout (Oxford's 11 metadata columns, per-azimuth microseconds and
    encoder) and ``applanix/radar_poses.csv`` beside them, a car driving east at 2 m/s."""
    radar = where / "radar"
    radar.mkdir(parents=True)
    rng = np.random.default_rng(0)
    t0_us, turn_us = 1630597346000000, 250000
    for k in range(2):
        bins = rng.integers(0, 60, (400, 600), dtype=np.uint8)
        bins[:, 150] = 200                                            # a ring of targets at about 8.6 m
        raw = np.zeros((400, 611), np.uint8)
        start = t0_us + k * turn_us
        raw[:, 0:8] = (start + np.arange(400) * turn_us // 400).astype("<i8").view(np.uint8).reshape(400, 8)
        raw[:, 8:10] = (np.arange(400) * 14).astype("<u2").view(np.uint8).reshape(400, 2)
        raw[:, 11:] = bins
        Image.fromarray(raw).save(radar / f"{start + turn_us // 2}.png")
    rows = ["GPSTime,easting,northing,altitude,vel_east,vel_north,vel_up,roll,pitch,heading,angvel_z,angvel_y,angvel_x"]
    for j in range(-4, 16):
        t = t0_us + j * 50000
        rows.append(f"{t},{623452.6 + 2.0 * j * 0.05:.3f},4848823.37,154.6,2.0,0.0,0.0,{math.pi:.6f},0.0,0.0,0,0,0")
    (where / "applanix").mkdir()
    (where / "applanix" / "radar_poses.csv").write_text("\n".join(rows) + "\n")


def mulran_recording(where):
    """Three scans in MulRan's layout (3360 range rows x 400 azimuth columns, nanosecond file
    names) under ``sensor_data/radar/polar`` and a TUM trajectory, ``poses.tum``, covering them."""
    polar = where / "sensor_data" / "radar" / "polar"
    polar.mkdir(parents=True)
    rng = np.random.default_rng(1)
    t0 = 1566279920_000_000_000
    for k in range(3):
        img = rng.integers(0, 50, (3360, 400), dtype=np.uint8)
        img[300, :] = 220                                              # a ring of targets at about 18 m
        Image.fromarray(img).save(polar / f"{t0 + k * 250_000_000}.png")
    lines = [f"{(t0 + j * 100_000_000) / 1e9:.3f} {0.5 * j:.3f} 0 0 0 0 0 1" for j in range(-3, 12)]
    (where / "poses.tum").write_text("\n".join(lines) + "\n")


# -- how each README line runs ---------------------------------------------------------------------------

def verbatim(line, work):
    """The line as the README writes it, through ``radarcl.cli.main`` in ``work``; a ``> FILE``
    redirect writes the command's standard output there."""
    argv, target = shlex.split(line), None
    if ">" in argv:
        at = argv.index(">")
        argv, target = argv[:at], argv[at + 1]
    assert argv[0] == "radarcl", line
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main(argv[1:] + ["--no-progress"] if argv[1] == "fuse" else argv[1:])
    assert status == 0, f"{line}: exit {status}"
    if target:
        (work / target).write_text(out.getvalue())
    return out.getvalue()


def with_data(make, name):
    def run(line, work):
        make(work / name)
        return verbatim(line, work)
    return run


def windowed(line, work):
    """The viewer as written, in a window on Xvfb, closed after four frames with a screenshot of
    what it drew (the options a user would not type, appended)."""
    import shutil

    xvfb = shutil.which("xvfb-run")
    assert xvfb, "xvfb-run not found: `make test` installs it (apt-get install xvfb)"
    shot = work / "view-shot.png"
    argv = shlex.split(line) + ["--size", "320", "240", "--frames", "4", "--screenshot", str(shot)]
    done = subprocess.run([xvfb, "-a", "-s", "-screen 0 800x600x24", sys.executable, "-m", *argv], cwd=work,
                          capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr[-2000:]
    pixels = np.asarray(Image.open(shot).convert("RGB"))
    assert pixels.shape == (240, 320, 3) and (pixels.max(axis=2) > 40).mean() > 0.01     # something drawn


def make_recipe(target, says):
    """``make -n TARGET``: the recipe the README's make line runs (not run here: see each entry)."""
    def run(line, work):
        assert line == f"make {target}"
        recipe = subprocess.run(["make", "-n", target], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert recipe.returncode == 0 and says in recipe.stdout, recipe.stdout + recipe.stderr
    return run


def pip_extras(line, work):
    """The extras the README installs, and those its comment lists, are the project's own
    (pyproject.toml); test_layout.test_installed_copy_runs_a_kernel installs the package itself."""
    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])
    asked = set(re.search(r"\.\[([\w,]+)\]", line).group(1).split(","))
    comment = next(l for l in README.splitlines() if l.startswith(line))
    listed = set(re.findall(r"\w+", re.sub(r"\(.*?\)", "", comment.split("# extras:", 1)[1])))
    assert asked <= extras and listed <= extras and {"docs", "ros"} <= listed, (asked, listed, extras)


def ti_live(line, work):
    """`radarcl live` as written, its port a pseudo-terminal instead of /dev/ttyUSB0: 24 frames of
    the TI demo's range-profile TLV made from the shared TI capture, then the far end closes (the
    end of a stream: the map is saved and the command exits 0)."""
    from radarcl import livemap
    from radarcl.config import mapconfig
    from radarcl.io import emulator
    from radarcl.io.inputs import open_input

    capture = open_input(mapconfig.resolve("ti-xwr-openradar").sensor,
                         SHARED_DATA / "ti_adc_openradar" / "simple_frame_1.npy")
    chirps = np.stack([capture.frames[j] for j in range(24)]).reshape(24, -1)
    power = np.abs(np.fft.fft(chirps * np.hanning(chirps.shape[1]), axis=1)) ** 2
    antennas, q_bits = livemap.ti_scaling(mapconfig.resolve("ti-xwr18xx-uart").sensor)
    packets = emulator.ti_packets(emulator.q9_of_power(power, antennas, q_bits))
    master, name, slave = emulator.open_pty()
    argv = [name if a == "/dev/ttyUSB0" else a for a in shlex.split(line)]
    assert argv != shlex.split(line), "the README's port is /dev/ttyUSB0"
    proc = subprocess.Popen([sys.executable, "-m", *argv], cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    err = []
    while not err or "radarcl live: reading" not in err[-1]:
        err.append(proc.stderr.readline())
        assert err[-1], "".join(err) + proc.stderr.read()
    def close():                                  # the radar goes away once the reader had time to read
        time.sleep(0.5)
        os.close(master)
        os.close(slave)

    emu = emulator.Emulator(packets, lambda b: os.write(master, b), None, close=close,
                            due_s=[j / 20 for j in range(len(packets))]).start()     # the demo's 20 frames/s
    try:
        stdout, rest = proc.communicate(timeout=300)
    finally:
        emu.stop()
        proc.kill()
    assert proc.returncode == 0, "".join(err) + rest
    assert (work / "ti-live.rcmap").is_dir() and (work / "ti-live.rcs").is_file()
    from radarcl.maps.disk import read_meta

    assert read_meta(work / "ti-live.rcmap", "stream")["saved_beams"] == len(packets), stdout   # every frame fused
    return stdout


def python_block(work):
    """The README's Python block, run as a script in ``work``."""
    (code,) = re.findall(r"^```python\n(.*?)^```", README, re.S | re.M)
    done = subprocess.run([sys.executable, "-c", code], cwd=work, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    return done.stdout


def drive_bag(where):
    """The shared Oxford scans and their odometry as an MCAP rosbag2 (polar sensor_msgs/Image and
    nav_msgs/Odometry), built with rosbags' writer as test_rosbag does."""
    from test_rosbag import ODOMETRY, write_bag

    from radarcl.io.poses import read_trajectory

    write_bag(where, "mcap", "image", poses=read_trajectory(ODOMETRY))


RUNS = {
    "make demo": make_recipe("demo", "radarcl demo --out out/demo"),   # minutes: test_cli runs `demo --quick`
    "make test": make_recipe("test", "-m pytest"),                     # the suite cannot run itself
    "pip install -e '.[viewer,export]'": pip_extras,
    "radarcl info": verbatim,
    "radarcl fuse ../shared/data/navtech_oxford --sensor navtech-cts350x --out oxford.rcmap": verbatim,
    "radarcl fuse ../shared/data/radiate_fog --sensor radiate-cts350x --out radiate.rcmap": verbatim,
    "radarcl fuse boreas-2021-09-02-11-42 --sensor boreas-cir204 --out boreas.rcmap":
        with_data(boreas_recording, "boreas-2021-09-02-11-42"),
    "radarcl fuse KAIST01 --sensor mulran --poses KAIST01/poses.tum --out mulran.rcmap":
        with_data(mulran_recording, "KAIST01"),
    "radarcl fuse ../shared/data/ti_adc_openradar/simple_frame_1.npy --sensor ti-xwr-openradar --still --out ti.rcmap":
        verbatim,
    "radarcl sensors polar-png > my-radar.toml": verbatim,
    "radarcl fuse ../shared/data/navtech_oxford/radar --sensor my-radar.toml --poses "
    "../shared/data/navtech_oxford/gt/radar_odometry.csv --out my-radar.rcmap": verbatim,
    "radarcl fit-sensor ../shared/data/radiate_fog --sensor radiate-cts350x --scans 0:6 --lidar --save radiate-fit.toml":
        verbatim,
    "radarcl fuse ../shared/data/radiate_fog --config radiate-fit.toml --out radiate-fit.rcmap": verbatim,
    "radarcl render oxford.rcmap --out oxford.png": verbatim,
    "radarcl view oxford.rcmap": windowed,
    "radarcl export oxford.rcmap --to ply --out oxford.ply": verbatim,
    "radarcl export oxford.rcmap --to costmap --band -0.5 2 --out oxford.pgm": verbatim,
    "radarcl export oxford.rcmap --to rosbag --out oxford_bag": verbatim,
    "radarcl export oxford.rcmap --to octomap --out oxford.bt": verbatim,
    "radarcl live /dev/ttyUSB0 --sensor ti-xwr18xx-uart --mount 0,0,1.5,0,-10,0 --out ti-live.rcmap "
    "--record ti-live.rcs": ti_live,
    "radarcl replay ti-live.rcs --out ti-again.rcmap": verbatim,
    "radarcl info drive_bag": with_data(drive_bag, "drive_bag"),
    "radarcl fuse drive_bag --sensor navtech-cts350x --out bag.rcmap --mcap bag.mcap": verbatim,
    "radarcl export bag.rcmap --to rosbag --out bag_ros2": verbatim,
}

# What each line must leave in the working directory (beyond exit 0).
WRITES = {
    "oxford.rcmap": "manifest.json", "radiate.rcmap": "manifest.json", "boreas.rcmap": "manifest.json",
    "mulran.rcmap": "manifest.json", "ti.rcmap": "manifest.json", "my-radar.rcmap": "manifest.json",
    "radiate-fit.rcmap": "manifest.json", "ti-again.rcmap": "manifest.json", "oxford_bag": "metadata.yaml",
    "bag.rcmap": "manifest.json", "bag_ros2": "metadata.yaml",
}


def test_every_readme_command_has_its_run_and_every_run_its_readme_line():
    assert sorted(EXAMPLES) == sorted(RUNS), set(EXAMPLES) ^ set(RUNS)
    assert len(set(EXAMPLES)) == len(EXAMPLES)
    assert sorted({line.split()[1] for line in SYNOPSIS}) == sorted(COMMANDS)


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A working directory with ../shared beside it, as the checkout has; commands run there."""
    base = tmp_path_factory.mktemp("readme")
    (base / "shared").symlink_to(SHARED_DATA.parent)
    (base / "work").mkdir()
    return base / "work"


@pytest.mark.parametrize("line", EXAMPLES)
def test_the_readme_command_runs(line, work, monkeypatch):
    """Run in the README's order (each parameter after the ones before it), so exports read the
    map fuse wrote; a map written is read back as a map with occupied voxels."""
    from radarcl.maps.map import Map

    monkeypatch.chdir(work)
    RUNS[line](line, work)
    outputs = re.findall(r"--(?:out|save|mcap) (\S+)|> (\S+)", line)
    for name in (a or b for a, b in outputs):
        assert (work / name).exists(), f"{line} wrote no {name}"
        if name in WRITES:
            assert (work / name / WRITES[name]).is_file()
        if name.endswith(".rcmap"):
            assert Map.open(work / name).counts()["occupied"] > 0, name


def test_the_readme_python_runs_and_makes_a_map(work):
    from radarcl.maps.map import Map

    printed = python_block(work)
    counts = Map.open(work / "oxford.npz").counts()
    assert counts["occupied"] > 0 and str(counts["occupied"]) in printed


@pytest.mark.parametrize("line", SYNOPSIS)
def test_the_commands_table_lines_have_their_help(line):
    """The Commands table is a synopsis (INPUT, MAP are placeholders): each line's command answers
    --help; the examples above run the real ones."""
    name = line.split()[1]
    assert name in COMMANDS
    with pytest.raises(SystemExit) as done, contextlib.redirect_stdout(io.StringIO()) as out:
        main([name, "--help"])
    assert done.value.code == 0 and f"usage: radarcl {name}" in out.getvalue()
