"""radarcl/jobs/calibrate_scans.py on the shared Oxford scans: the constants fitted on the first
part of the sequence make a map whose predictions of held-out detections in the last part are
better calibrated than the profile's constants and than the detection rate as a constant; the
saved configuration round-trips through the CLI."""

import math

import numpy as np
import pytest

from radarcl.jobs import calibrate_scans as cs


@pytest.fixture(scope="module")
def calibrated(runtime, shared_data):
    from radarcl.config import mapconfig

    saved = cs.CFAR_CANDIDATES, cs.SURFACE_CANDIDATES_DB
    cs.CFAR_CANDIDATES, cs.SURFACE_CANDIDATES_DB = (("ca", 1e-3), ("ca", 1e-2)), (15.0,)   # a quicker search
    try:
        return cs.run(runtime, mapconfig.resolve("navtech-cts350x"), shared_data / "navtech_oxford")
    finally:
        cs.CFAR_CANDIDATES, cs.SURFACE_CANDIDATES_DB = saved


def test_the_fit_and_the_report_use_disjoint_scans(calibrated):
    _, r = calibrated
    assert set(r["fit_scans"]).isdisjoint(r["report_scans"]) and len(r["report_scans"]) >= 4
    assert len(r["candidates"]) == 2 and r["chosen"] in [c["candidate"] for c in r["candidates"]]
    bins = {s["bins"] for s in r["results"].values()}
    assert len(bins) == 1 and bins.pop() > 10 ** 6                      # every row on the same held-out bins


def test_calibrated_constants_predict_held_out_detections_better(calibrated):
    config, r = calibrated
    res = r["results"]
    k = r["constants"]
    assert k["interpret.k_occ"]["value"] > 0 and all(k[n]["value"] <= 0 for n in k if n != "interpret.k_occ")
    for c in k.values():
        assert c["jackknife_se"] > 0 and c["ci95"][0] <= c["value"] <= c["ci95"][1]
    assert config["interpret.k_occ"] == pytest.approx(k["interpret.k_occ"]["value"], abs=1e-4)
    cal, prof, rate = res["calibrated"], res["profile constants"], res["baseline: detection rate"]
    assert cal["log_likelihood"] > prof["log_likelihood"] + 0.05
    assert cal["log_likelihood"] > rate["log_likelihood"]              # the map adds to one number
    assert cal["ece"] < prof["ece"] / 2
    assert cal["auc"] > 0.6 and abs(cal["auc"] - prof["auc"]) < 0.02    # a rescaling ranks about alike
    assert res["baseline: no map"]["log_likelihood"] == pytest.approx(math.log(0.5))
    assert np.isfinite([s["log_likelihood"] for s in res.values()]).all()
    assert any("calibrated" in line for line in cs.format_lines(r))


def test_the_command_saves_a_configuration_that_heldout_scans_reads(tmp_path, shared_data, monkeypatch, capsys):
    from radarcl.cli import main

    monkeypatch.setattr(cs, "CFAR_CANDIDATES", (("ca", 1e-3),))
    monkeypatch.setattr(cs, "SURFACE_CANDIDATES_DB", (15.0,))
    out = tmp_path / "navtech-cal.toml"
    data = str(shared_data / "navtech_oxford")
    assert main(["calibrate-scans", data, "--save", str(out), "--figure", str(tmp_path / "rel.png")]) == 0
    assert out.exists() and (tmp_path / "rel.png").stat().st_size > 10_000
    assert main(["calibrate-scans", data, "--save", str(out)]) != 0           # no silent overwrite
    assert "exists" in capsys.readouterr().err
    assert main(["bench", "heldout-scans", data, "--config", str(out)]) == 0
    text = capsys.readouterr().out
    assert "k_occ=1," not in text.split("map:")[1].split("outcomes")[0]       # the map used the fitted constants
