"""radarcl/bench/suite.py (`radarcl bench all`): every bench of the suite runs at its --quick size
and lands in one valid JSON with the run's context and finite headline figures; a bench that
fails is recorded with its sentence, the others run, and the exit status says so; the table
prints."""

import dataclasses
import datetime
import json
import math
import subprocess
import sys

import pytest

import radarcl
from radarcl.bench import cfar, suite
from radarcl.cl.limits import DeviceLimits
from radarcl.cli import main

ROW_KEYS = {"figure", "value", "unit", "baseline", "baseline_value", "ratio", "ratio_is"}


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """The whole suite at its --quick size, once for the tests below (the file's slow part), as a
    user runs it: a command of its own (its memory leaves with it; the drive test that follows
    measures this process's resident memory)."""
    out = tmp_path_factory.mktemp("bench_all") / "sub" / "bench.json"    # its directory is made
    done = subprocess.run([sys.executable, "-m", "radarcl", "bench", "all", "--quick", "--json", str(out)],
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=900)
    return done.returncode, json.loads(out.read_text()), done.stdout.splitlines(), done.stderr.splitlines()


def test_every_bench_runs_at_the_quick_size_into_one_json(quick_run):
    status, report, _, stderr = quick_run
    assert status == 0, report["failed"]
    assert report["benchmark"] == "all" and report["complete"] and report["quick"] and report["failed"] == []
    assert list(report["benches"]) == list(suite.SUITE)
    assert report["radarcl_version"] == radarcl.__version__
    datetime.datetime.fromisoformat(report["date"])
    assert set(report["limits"]) == {f.name for f in dataclasses.fields(DeviceLimits)}
    assert report["device"] == report["limits"]["name"] and report["limits"]["global_mem_size"] > 0
    assert report["cpu"]["model"] and report["cpu"]["cores"] >= 1
    for key in ("load_before", "load_after"):
        assert len(report[key]) == 3 and all(v >= 0 for v in report[key])
    assert report["wall_s"] > 0
    for name, b in report["benches"].items():
        assert b["status"] == "ok" and {k: v for k, v in b["size"].items() if k != "data"} == suite.SUITE[name].quick
        assert b["wall_s"] > 0 and b["lines"] and b["result"]
        assert b["rows"], name
        for r in b["rows"]:
            assert set(r) == ROW_KEYS, (name, r)
            assert isinstance(r["value"], (int, float)) and math.isfinite(r["value"]), (name, r)
            if r["ratio"] is not None:
                assert math.isfinite(r["ratio"]) and r["ratio"] > 0, (name, r)
                assert r["ratio_is"] in (suite.FIGURE_OF_BASELINE, suite.BASELINE_OF_FIGURE) and r["baseline"]
    assert any(line.startswith("[6/6] viewer done in") for line in stderr), "progress names the bench and its time"


def test_the_table_has_a_line_per_headline_row(quick_run):
    _, report, stdout, _ = quick_run
    table = stdout
    assert table[0].split() == ["benchmark", "figure", "value", "unit", "baseline", "ratio"]
    rows = sum(len(b["rows"]) for b in report["benches"].values())
    assert len(table) == 2 + rows + 2
    assert any(line.startswith("fusion") and "detection statistics, gather" in line and "eq. 12's gather" in line
               for line in table)
    assert table[-1] == f"all {len(suite.SUITE)} benchmarks ran" and report["device"] in table[-2]


def test_a_failing_bench_is_recorded_and_the_others_run(tmp_path, monkeypatch, capsys):
    def on_fire(*args, **kwargs):
        raise RuntimeError("the device caught fire")

    monkeypatch.setattr(cfar, "run", on_fire)
    out = tmp_path / "bench.json"
    out.write_text("an older report")                                # replaced, as `make bench-device` reruns
    assert main(["bench", "all", "--quick", "--only", "cfar,range-fft", "--json", str(out)]) == 1
    report = json.loads(out.read_text())
    assert report["complete"] and report["failed"] == ["cfar"] and list(report["benches"]) == ["range-fft", "cfar"]
    failed = report["benches"]["cfar"]
    assert failed["status"] == "failed" and failed["error"] == "RuntimeError: the device caught fire"
    assert "on_fire" in failed["traceback"] and "rows" not in failed
    assert report["benches"]["range-fft"]["status"] == "ok"
    captured = capsys.readouterr()
    assert "cfar  FAILED: RuntimeError: the device caught fire" in captured.out.splitlines()
    assert captured.out.splitlines()[-1] == "1 of 2 benchmarks FAILED: cfar"
    assert "1 of 2 benchmarks failed (cfar)" in captured.err


def test_a_report_path_that_cannot_be_written_is_refused_before_measuring(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(suite, "measure", lambda *a, **k: pytest.fail("measured before checking the output"))
    assert main(["bench", "all", "--json", str(tmp_path)]) == 2
    assert "is a directory" in capsys.readouterr().err


def test_unknown_names_are_refused(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "all", "--only", "range-fft,warp-drive"])
    assert exit_.value.code == 2 and "expected names from range-fft, cfar" in capsys.readouterr().err


def test_a_drive_process_that_dies_without_answering_is_an_error_not_a_hang():
    """The suite runs unattended on a lent machine: the drive's child process killed (for memory,
    by a driver's crash) must end the bench with a sentence, not wait for ever."""
    import multiprocessing
    import os

    from radarcl.bench import drive

    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    process = ctx.Process(target=os._exit, args=(9,))
    process.start()
    status, why = drive._answer(queue, process, poll_s=0.2)
    process.join()
    assert status == "error" and why == "its process ended (exit code 9) without a result"


def test_two_failures_in_a_row_each_keep_their_line(tmp_path, monkeypatch, capsys):
    from radarcl.bench import range_fft

    def on_fire(*args, **kwargs):
        raise RuntimeError("the device caught fire")

    monkeypatch.setattr(cfar, "run", on_fire)
    monkeypatch.setattr(range_fft, "run", on_fire)
    assert main(["bench", "all", "--quick", "--only", "range-fft,cfar", "--json", str(tmp_path / "b.json")]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert "range-fft  FAILED: RuntimeError: the device caught fire" in lines
    assert "cfar  FAILED: RuntimeError: the device caught fire" in lines
    assert lines[-1] == "2 of 2 benchmarks FAILED: range-fft, cfar"
