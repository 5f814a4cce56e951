"""The package as a user installs it: a wheel and an sdist built with the standard tool
(``python -m build``, offline: no build isolation), the wheel (built from the sdist, so the sdist
is complete) installed into a fresh virtual environment, and ``radarcl info`` and
``radarcl demo --quick`` run from there, outside the source tree. The demo's outputs are checked
here too (its one run in the suite), and a ``--replay`` of its recording gives the same maps."""

import json
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

from browser import open_in_browser

from radarcl.cli import main

ROOT = Path(__file__).resolve().parents[1]
LEFT_OUT = shutil.ignore_patterns(".git", ".venv", "out", "build", "dist", "*.egg-info", "__pycache__",
                                  ".pytest_cache")


def test_wheel_and_sdist_install_into_a_fresh_venv_and_run_the_demo(tmp_path):
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
    check_demo(tmp_path / "demo", demo.stdout, tmp_path)


def check_demo(out, printed, tmp_path):
    """--quick: the whole main job at 0.4 m, its files, its page in a browser, its summary; then
    --replay of the recording it wrote gives the same maps (the pipeline is deterministic)."""
    for name in ("fig9.png", "frame.png", "fig10_scene.png", "topdown.png", "quality.png", "reliability.png",
                 "map.npz", "reference_scene.npz", "summary.json", "view.png", "report.html"):
        assert (out / name).stat().st_size > 0
    dom, console = open_in_browser(out / "report.html", tmp_path)
    assert 'data-images="7/7"' in dom and 'data-errors="0"' in dom and console == [], (dom[-300:], console)
    assert 'data-overflow="0"' in dom, dom[-300:]                      # every table fits a laptop's window
    summary = json.loads((out / "summary.json").read_text())
    assert summary["view"]["mode"] == "iso" and "error" not in summary["view"]
    assert summary["observations"] == 3840 and summary["voxel_m"] == 0.4
    assert len(summary["fig9"]["pair_peaks_m"]["256"]) == 1 and len(summary["fig9"]["pair_peaks_m"]["1024"]) == 2
    q = summary["quality"]
    keys = {"auc_detectable", "auc_obstacles", "auc_weak", "false_free", "shadow_unknown", "ece", "brier",
            "objects_found", "objects_total"}
    assert set(q["baselines"]) == {"prior_only", "raw_intensity", "octomap"} and any(r["pareto"] for r in q["runs"])
    for b in q["baselines"].values():
        assert keys <= set(b) and b["auc_detectable"] is not None
    for r in q["runs"]:
        assert keys | {"config", "ms_per_frame", "max_dev_nats"} <= set(r)
    assert "fixed voxel set" in q["voxel_set"] and summary["voxel_set"] == q["voxel_set"]
    assert "baseline: octomap" in printed and "baseline: prior_only" in printed and "§4.1 sweep" in printed
    assert main(["demo", "--quick", "--no-progress", "--out", str(tmp_path / "again"),
                 "--replay", str(out / "reference_scene.npz")]) == 0
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    for name in ("paper constants", "tuned"):
        assert again["maps"][name]["metrics"] == summary["maps"][name]["metrics"]
