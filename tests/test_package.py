"""The package as a user installs it: a wheel and an sdist built with the standard tool
(``python -m build``, offline: no build isolation), the wheel (built from the sdist, so the sdist
is complete) installed into a fresh virtual environment, and ``radarcl info`` and
``radarcl demo --quick`` run from there, outside the source tree."""

import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LEFT_OUT = shutil.ignore_patterns(".git", ".venv", "out", "build", "dist", "*.egg-info", "__pycache__",
                                  ".pytest_cache")


def test_wheel_and_sdist_install_into_a_fresh_venv_and_run_the_demo(tmp_path):
    pytest.importorskip("build", reason="python -m build (the test extra) is not installed")
    # no PYTHONPATH anywhere: a source tree on it (with a .egg-info an in-place install left) would
    # pass for the installed package, and pip would skip the install as already done
    clean = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=LEFT_OUT)          # a clean copy: the build writes beside the sources
    subprocess.run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(tmp_path / "dist"), str(src)],
                   check=True, capture_output=True, cwd=tmp_path, env=clean)
    sdists, wheels = list((tmp_path / "dist").glob("radarcl-*.tar.gz")), list((tmp_path / "dist").glob("radarcl-*.whl"))
    assert len(sdists) == 1 and len(wheels) == 1
    shipped = set(zipfile.ZipFile(wheels[0]).namelist())
    # paths inside the wheel (the kernels and shaders ship inside the package, not where the sources keep them)
    for parts in (("kernels", "range_fft.cl"), ("profiles", "navtech-cts350x.toml"), ("viewer", "shaders", "volume.glsl"),
                  ("jobs", "api.py")):
        assert "/".join(("radarcl",) + parts) in shipped, parts

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, env=clean)
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True, env=clean).stdout.strip())
    # offline: the dependencies come from this environment (a .pth), the package from the wheel alone
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", str(wheels[0])],
                   check=True, capture_output=True, cwd=tmp_path, env=clean)
    radarcl = venv / "bin" / "radarcl"
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(tmp_path)}
    where = subprocess.run([str(py), "-c", "import radarcl; print(radarcl.__file__)"], cwd=tmp_path,
                           capture_output=True, text=True, env=env)
    assert where.returncode == 0 and where.stdout.startswith(str(site)), (where.stdout, where.stderr)
    info = subprocess.run([str(radarcl), "info"], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert info.returncode == 0, info.stderr
    demo = subprocess.run([str(radarcl), "demo", "--quick", "--out", "demo", "--no-progress"], cwd=tmp_path,
                          capture_output=True, text=True, env=env)
    assert demo.returncode == 0, demo.stderr[-2000:]
    for name in ("map.npz", "report.html", "summary.json", "topdown.png"):
        assert (tmp_path / "demo" / name).is_file(), name
