"""House rules: one name, three files; the installed package carries kernels/ and viewer/ (GLSL too)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_kernel_has_its_wrapper_and_test():
    stems = [p.stem for p in (ROOT / "kernels").glob("*.cl")]
    assert stems, "no kernels found"
    for stem in stems:
        assert (ROOT / "radarcl" / "stages" / f"{stem}.py").is_file(), f"kernels/{stem}.cl has no wrapper"
        assert (ROOT / "tests" / f"test_{stem}.py").is_file(), f"kernels/{stem}.cl has no test"


def test_installed_copy_runs_a_kernel(tmp_path):
    """`pip install .` (not editable) into a fresh target, then run a kernel from there,
    from a directory where the source tree cannot be imported."""
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(ROOT)], check=True, cwd=tmp_path)
    assert (target / "radarcl" / "kernels" / "range_fft.cl").is_file()
    profiles = {p.name for p in (target / "radarcl" / "profiles").glob("*.toml")}
    assert profiles == {p.name for p in (ROOT / "radarcl" / "profiles").glob("*.toml")} and "paper.toml" in profiles
    shipped = {p.name for p in (target / "radarcl" / "viewer" / "shaders").glob("*.glsl")}
    assert shipped == {p.name for p in (ROOT / "viewer" / "shaders").glob("*.glsl")} and "volume.glsl" in shipped
    script = ("import numpy as np, radarcl, radarcl.cl as c\n"
              "from radarcl.stages.range_fft import RangeFFT\n"
              "assert str(c.kernels_dir()).startswith(%r), c.kernels_dir()\n"
              "p = RangeFFT(c.Runtime(), (2, 1), 8, 16, dtype=np.float32)(np.ones((2, 1, 8), np.float32)).profiles\n"
              "import radarcl.viewer.renderer as r\n"
              "from radarcl import sensors\n"
              "assert str(sensors.PROFILE_DIR).startswith(%r) and sensors.load('navtech-cts350x').n_bins() == 3768\n"
              "assert r.__file__.startswith(%r) and 'FRAGMENT_SHADER' in r.shader_source('volume')\n"
              "print(radarcl.__file__, float(p[0, 0, 0]))\n") % (str(target), str(target), str(target))
    env = {**os.environ, "PYTHONPATH": str(target)}
    out = subprocess.run([sys.executable, "-c", script], check=True, cwd=tmp_path, env=env,
                         capture_output=True, text=True).stdout
    assert out.startswith(str(target)) and out.split()[-1] == "1.0"
