"""The `radarcl` command: help, info, the demo's outputs, the bench's JSON, clear errors."""

import json
import subprocess
import sys

from browser import open_in_browser

from radarcl.cli import main


def run_cli(*args, env=None):
    return subprocess.run([sys.executable, "-m", "radarcl", *args], capture_output=True, text=True, env=env)


def test_help_lists_commands():
    out = run_cli("--help")
    assert out.returncode == 0
    for command in ("info", "demo", "bench", "navtech", "navtech-map"):
        assert command in out.stdout


def test_info(capsys):
    assert main(["info"]) == 0
    assert "(* = chosen" in capsys.readouterr().out


def test_demo_sizes_are_one_choice(tmp_path, capsys):
    """The default demo runs at 0.2 m (a laptop's memory), --full at the paper's 0.1 m, --quick at
    0.4 m; asking for two sizes is a usage error before anything runs."""
    import pytest

    from radarcl.commands import demo as command
    from radarcl.jobs import demo

    assert (demo.DEFAULT_VOXEL_M, demo.FULL_VOXEL_M, demo.QUICK_VOXEL_M) == (0.2, 0.1, 0.4)
    assert "0.2 m" in command.SUMMARY and "--full" in command.SUMMARY
    with pytest.raises(SystemExit) as exc:
        main(["demo", "--quick", "--full", "--out", str(tmp_path / "d")])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_fuse_writes_a_map_the_viewer_reads(tmp_path, capsys):
    """radarcl fuse on a two-frame recording at 0.4 m, saving after each frame: the map holds
    positive evidence, no temporary file is left and the viewer renders it."""
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    rec = tmp_path / "rec.npz"
    recording.save(rec, observe(paper_scene(), (-9.2, -5.2), seed=1))
    out = tmp_path / "map.npz"
    assert main(["fuse", str(rec), "--out", str(out), "--voxel", "0.4", "--every", "1", "--no-progress"]) == 0
    assert "wrote" in capsys.readouterr().out
    from radarcl.viewer.volume import load_map
    assert load_map(out).positive > 0
    assert main(["render", str(out), "--out", str(tmp_path / "v.png"), "--size", "64", "48"]) == 0
    assert not list(tmp_path.glob("*.tmp"))
    dom, console = open_in_browser(tmp_path / "map.html", tmp_path)       # the run's page, beside the map
    assert 'data-images="2/2"' in dom and 'data-errors="0"' in dom and console == [], (dom[-300:], console)
    assert 'data-overflow="0"' in dom
    assert "2 frames" in dom or "<td class=\"n\">2</td>" in dom
    assert main(["fuse", str(rec), "--out", str(tmp_path / "again.npz"), "--voxel", "0.4", "--no-progress",
                 "--report", str(tmp_path / "map.html")]) == 2             # the page is kept like any output
    assert "exists; pass --force" in capsys.readouterr().err and not (tmp_path / "again.npz").exists()
    assert main(["fuse", str(rec), "--out", str(tmp_path / "x.html"), "--voxel", "0.4", "--no-progress"]) == 2
    assert "would both be" in capsys.readouterr().err


def test_demo_refuses_a_file_that_is_not_a_recording(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    assert main(["demo", "--quick", "--no-progress", "--out", str(tmp_path / "out"), "--replay", str(bad)]) == 2
    assert "bad.npz is not a readable .npz file" in capsys.readouterr().err
    assert not (tmp_path / "out").exists(), "nothing may be written before the input is read"


def test_bench_json_has_the_issue_keys(capsys):
    assert main(["bench", "range-fft", "--json", "--repeat", "10", "--n-fft", "512"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("ms_per_frame", "scipy_ms_per_frame", "ratio_vs_scipy", "max_rel_err", "runs"):
        assert key in result
    assert result["max_rel_err"] < 1e-6 and result["ratio_vs_scipy"] > 0
    context = result["context"]                       # where and when: the measured-figures page says it
    assert context["bench"] == "range-fft" and context["options"] == {"repeat": 10, "n_fft": [512]}
    assert len(context["load_before"]) == len(context["load_after"]) == 3 and context["wall_s"] > 0
    assert context["cpu"]["cores"] >= 1 and context["date"][:2] == "20"


def test_bench_cfar_json_has_the_issue_keys(capsys):
    """The numpy baseline computes the same thing: its mask and evidence match the oracle."""
    assert main(["bench", "cfar", "--json", "--repeat", "10"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("ms_per_frame", "numpy_ms_per_frame", "ratio_vs_numpy"):
        assert result[key] > 0
    assert result["mask_mismatches"] == 0 and result["evidence_max_abs_err_units"] <= 1
    assert result["numpy_evidence_max_abs_err_units"] <= 1 and result["detections"] > 0


def test_bad_device_is_a_sentence_not_a_traceback():
    import os

    out = run_cli("info", env={**os.environ, "RADARCL_DEVICE": "no-such-device"})
    assert out.returncode == 2
    assert out.stderr.startswith("radarcl: error: RADARCL_DEVICE='no-such-device' matches no device")
    assert "Traceback" not in out.stderr


def test_unknown_benchmark_is_refused():
    out = run_cli("bench", "warp-drive")
    assert out.returncode == 2 and "invalid choice" in out.stderr


def test_bench_fusion_has_the_issue_keys():
    """The fusion bench on a coarse grid (the paper's 0.1 m grid takes ~25 s): keys and sanity."""
    from radarcl.bench import fusion
    from radarcl.cl import Runtime
    from radarcl.gridspec import GridSpec

    r = fusion.run(Runtime(), repeat=2, spec=GridSpec((-8.0, -35.0, -10.0), 0.5, (160, 140, 40)),
                   spin_spec=GridSpec((-20.0, -20.0, -2.0), 0.5, (80, 80, 8)))
    for key in ("still_ms_per_frame", "moving_ms_per_frame", "spinning_ms_per_frame", "planning_ms",
                "planning_ms_numpy", "pipeline_ms_per_frame", "voxels_per_frame", "floor_ms_per_frame",
                "spinning_voxels_per_frame", "ratio_vs_floor", "ratio_vs_numpy", "detstats_gather_ms_per_frame",
                "detstats_still_ms_per_frame", "detstats_moving_ms_per_frame", "detstats_gather_ratio",
                "detstats_pipeline_ms_per_frame", "interpret_ms_per_frame", "detstats_interpret_ms_per_frame",
                "spinning_interpret_ms_per_frame", "detstats_spinning_interpret_ms_per_frame"):
        assert r[key] > 0, key
    assert set(r["load"]) == {"still", "gather", "moving", "planning", "planning_numpy", "spinning", "spinning_gather",
                              "pipeline", "detstats_still", "detstats_gather", "detstats_moving", "detstats_pipeline",
                              "spinning_pipeline", "detstats_spinning_pipeline", "interpret", "detstats_interpret",
                              "spinning_interpret", "detstats_spinning_interpret"}
    assert r["detstats_interpret_ms_per_frame"] < r["detstats_pipeline_ms_per_frame"]
    assert r["detstats_gather_ms_per_frame"] > 0 and r["detstats_gather_ratio"] > 0
    assert any("detection statistics" in line for line in fusion.format_table(r))
    assert r["max_error_units"] <= 1 and r["oracle_voxels_compared"] > 10000
    assert r["sparse_mib"] < r["dense_mib"]
    assert any("ratio_vs_floor" in line for line in fusion.format_table(r))


def test_debug_shows_the_traceback(tmp_path, monkeypatch):
    """An error is one sentence; with --debug or RADARCL_DEBUG=1 it is raised (a traceback for
    a bug report)."""
    import pytest

    from radarcl.errors import FrameFormatError

    missing = str(tmp_path / "missing.npz")
    assert main(["fuse", missing, "--out", str(tmp_path / "m.npz")]) == 2
    with pytest.raises(FrameFormatError, match="does not exist"):
        main(["--debug", "fuse", missing, "--out", str(tmp_path / "m.npz")])
    monkeypatch.setenv("RADARCL_DEBUG", "1")
    with pytest.raises(FrameFormatError):
        main(["fuse", missing, "--out", str(tmp_path / "m.npz")])


def test_fuse_report_of_the_detection_statistics_model_draws_unknown(tmp_path, capsys):
    """radarcl fuse --report with interpret.model = detstats: the map is read with its reading
    (Map.of_grid refuses a knowledge grid without one) and the top-down says grey is unknown."""
    from radarcl.io import recording
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    rec = tmp_path / "rec.npz"
    recording.save(rec, observe(paper_scene(), (-9.2,), seed=1))
    page = tmp_path / "map.html"
    assert main(["fuse", str(rec), "--out", str(tmp_path / "map.npz"), "--voxel", "0.4", "--no-progress",
                 "--set", "interpret.model=detstats", "--report", str(page)]) == 0
    assert f"wrote {page}" in capsys.readouterr().out
    assert "grey: never observed (unknown)" in page.read_text()
