"""`radarcl fit-sensor` (``evaluation.sensor_fit``, ``jobs.fit_sensor``): the fit recovers the
background law and the sensitivity of recordings simulated from the model itself within its
intervals, with and without a lidar; a recording too short or too empty is refused in a sentence;
on the shared RADIATE scans the command writes a configuration every command reads."""

import math

import numpy as np
import pytest

from radarcl import sensor_model as sm
from radarcl.cli import main
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.evaluation import sensor_fit as F
from radarcl.jobs.fit_sensor import scan_selection

DATA = "../shared/data/radiate_fog"
TRUE = dict(clutter_share=0.15, clutter_db=12.0, clutter_spread_db=6.0, snr_1m2_at_10m_db=55.0, noise_scale=1.2)
RANGES_M = np.stack([np.geomspace(2.0, 60.0, F.N_BANDS + 1)[:-1], np.geomspace(2.0, 60.0, F.N_BANDS + 1)[1:]], 1)
COVER = 3.0          # a value within this many jackknife standard errors of the truth is recovered


def geometry():
    return F.Geometry(sm.ModelParams(target_spread_db=6.0), math.radians(0.9), math.radians(20.0))


def simulated(rng, n_scans, per_band, target_share, clutter_share, truth=TRUE):
    """``PowerCounts`` of powers drawn as the model says: per bin, clutter with the chance
    ``clutter_share`` (exponential of mean v + G, G log-normal), else a typical target with the
    chance ``target_share`` (exponential of mean v + s, s the radar equation's at one of the band's
    ranges and beam offsets, log-normal over the target's spread), else noise of mean v."""
    spans = np.stack([RANGES_M[:, 0], np.sqrt(RANGES_M[:, 0] * RANGES_M[:, 1]), RANGES_M[:, 1]], axis=1)
    ln_s = geometry().ln_snr(spans, truth["snr_1m2_at_10m_db"])                       # (bands, 15)
    v = truth["noise_scale"]
    counts = np.zeros((n_scans, F.N_BANDS, len(F.U_EDGES) + 1), np.int64)
    for k in range(n_scans):
        for b in range(F.N_BANDS):
            kind = rng.random(per_band)
            clutter = kind < clutter_share
            target = ~clutter & (kind < clutter_share + (1 - clutter_share) * target_share)
            mean = np.full(per_band, v)
            g = np.exp((truth["clutter_db"] + truth["clutter_spread_db"] * rng.standard_normal(per_band)) * F.DB)
            s = np.exp(rng.choice(ln_s[b], per_band) + 6.0 * F.DB * rng.standard_normal(per_band))
            mean = np.where(clutter, v + g, np.where(target, v + s, mean))
            x = rng.exponential(mean)
            counts[k, b] = np.bincount(np.searchsorted(F.U_EDGES, np.log(x), side="right"),
                                       minlength=len(F.U_EDGES) + 1)
    return F.PowerCounts(counts, spans)


def assert_recovered(result, keys):
    for key in keys:
        i = F.FITTED.index(key)
        value, se = result.values[i], result.errors[i]
        assert key not in result.at_edge
        assert abs(value - TRUE[key]) <= COVER * se + 1e-9, (key, value, se, TRUE[key])


def test_the_fit_recovers_a_simulated_background_and_sensitivity():
    """Without a lidar the mixture per band tells the clutter (the same at every range) from the
    targets (falling as r^-4): every parameter within 3 jackknife SEs of the truth."""
    counts = simulated(np.random.default_rng(1), 4, 25000, 0.08, TRUE["clutter_share"])
    result = F.fit(counts, geometry())
    assert_recovered(result, F.FITTED)
    assert result.log_likelihood > result.noise_only and result.n_scans == 4
    assert all(0.02 < s < 0.2 for s in result.shares[2:])           # the bands' target shares near 0.08


def test_the_fit_with_a_lidar_fits_the_background_and_the_targets_apart():
    rng = np.random.default_rng(2)
    background = simulated(rng, 3, 20000, 0.0, TRUE["clutter_share"])
    targets = simulated(rng, 3, 3000, 1.0, TRUE["clutter_share"])
    everything = F.PowerCounts(background.counts + targets.counts, background.ranges_m)
    result = F.fit(everything, geometry(), background=background, targets=targets)
    assert result.lidar
    assert_recovered(result, F.FITTED)


def test_a_recording_too_short_or_too_empty_is_refused_in_a_sentence():
    rng = np.random.default_rng(3)
    with pytest.raises(ConfigError, match="needs at least 3 scans .* got 2"):
        F.fit(simulated(rng, 2, 20000, 0.05, 0.1), geometry())
    with pytest.raises(ConfigError, match=f"needs at least {F.MIN_BINS} powers in the range window; the scans give"):
        F.fit(simulated(rng, 3, 100, 0.05, 0.1), geometry())
    quiet = simulated(rng, 3, 20000, 0.0, 0.0, dict(TRUE, noise_scale=1.0))
    with pytest.raises(ConfigError, match="bins 10 dB or more over their noise floor; the fit needs at least 100"):
        F.fit(quiet, geometry())
    some = simulated(rng, 3, 20000, 0.05, 0.1)
    with pytest.raises(ConfigError, match="the lidar's occupied cells hold 0 of the radar's bins.*overlap"):
        F.fit(some, geometry(), background=some, targets=F.PowerCounts(0 * some.counts, some.ranges_m))


def test_power_counts_takes_each_beam_over_its_own_floor():
    """A beam of constant power p is x = ln 2 everywhere (its median / ln 2 is the floor), whatever
    p; a mask keeps only its bins; the bands run log-spaced over the window."""
    beams = np.full((2, 200), 5.0)
    beams[1] *= 1e6
    c = F.power_counts([beams], 0.5, 1.0, 90.0)
    k = np.searchsorted(F.U_EDGES, math.log(math.log(2.0)), side="right")
    assert c.counts.sum() == c.counts[0, :, k].sum() == 2 * 179
    mask = np.zeros(beams.shape, bool)
    mask[0, 50:60] = True
    assert F.power_counts([beams], 0.5, 1.0, 90.0, mask=[mask]).counts.sum() == 10
    assert c.ranges_m[0, 0] == pytest.approx(1.0) and c.ranges_m[-1, -1] == pytest.approx(90.5)   # the last bin inside
    with pytest.raises(ConfigError, match="holds 3 bins; the fit needs at least 12"):
        F.power_counts([beams], 0.5, 1.0, 2.0)


def test_scan_selection():
    assert scan_selection("all", 5) == [0, 1, 2, 3, 4]
    assert scan_selection("0::2", 5) == [0, 2, 4] and scan_selection("1:3", 5) == [1, 2]
    assert scan_selection("-2:", 5) == [3, 4]
    for text, why in (("3:1", "selects no scan"), ("0:9", "has 5 scans"), ("a:b", "expected A:B"),
                      ("0:2:0", "step must be positive"), ("2", "expected A:B")):
        with pytest.raises(ConfigError, match=why):
            scan_selection(text, 5)


def test_fit_sensor_writes_a_configuration_every_command_reads(tmp_path, capsys):
    """On RADIATE's first six scans with their lidar: the table, a configuration whose fitted and
    chosen values name their source, read back by --config; an existing file is kept."""
    out = tmp_path / "radiate.toml"
    assert main(["fit-sensor", DATA, "--sensor", "radiate-cts350x", "--scans", "0:6", "--lidar",
                 "--save", str(out), "--json", str(tmp_path / "fit.json")]) == 0
    text = capsys.readouterr().out
    assert "with at most 0.1 of the free ones and some of the occupied ones called occupied in every band" in text
    assert "<- chosen" in text
    config = mapconfig.resolve("radiate-cts350x", str(out))
    lines = {line.split(" = ")[0]: line for line in out.read_text().splitlines() if " = " in line}
    for key in ("snr_1m2_at_10m_db", "look_limit", "clutter_share", "clutter_spread_db"):
        assert "# radarcl fit-sensor --lidar on scans 0-5" in lines[key]
        assert config[f"sensor_model.{key}"] == pytest.approx(float(lines[key].split()[2]))
    assert config["sensor_model.clutter_share"] == 0.0 and "the fitted law unused" in lines["clutter_spread_db"]
    assert "not fitted" in lines["block_gamma_db"]
    assert main(["fit-sensor", DATA, "--sensor", "radiate-cts350x", "--save", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    alone = tmp_path / "alone.toml"                   # without the lidar: only what the scans bound is written
    assert main(["fit-sensor", DATA, "--sensor", "radiate-cts350x", "--scans", "0:6", "--save", str(alone)]) == 0
    text = capsys.readouterr().out
    assert "without a lidar nothing here tells a map that finds obstacles" in text and "kept)" in text
    lines = {line.split(" = ")[0]: line for line in alone.read_text().splitlines() if " = " in line}
    # RADIATE's background runs to its search's edges: all four of its values stay the configuration's
    for key in ("clutter_share", "clutter_db", "clutter_spread_db", "noise_scale"):
        assert "(kept: the fit's was" in lines[key]
    assert lines["clutter_share"].startswith("clutter_share = 0.0 ")
    assert "radarcl fit-sensor" not in lines["look_limit"]
    assert "(kept: the fit's was not the map's: chosen with a lidar only (--lidar))" in lines["snr_1m2_at_10m_db"]
    assert main(["fit-sensor", DATA, "--scans", "0:6"]) == 2                 # the default sensor reads Oxford's layout
    assert "read with --sensor radiate-cts350x" in capsys.readouterr().err
    assert main(["fit-sensor", DATA, "--sensor", "radiate-cts350x", "--scans", "0::2", "--lidar"]) == 2
    assert "--lidar takes a run of consecutive scans" in capsys.readouterr().err


def test_the_lidar_choice_never_takes_a_blind_map():
    """A map that calls nothing occupied in a band keeps its phantoms at 0 and can rank best; it is
    not taken, and with no other map within the phantom limit the choice is refused."""
    from radarcl.jobs.fit_sensor import best_candidate
    row = lambda name, auc, phantom, blind: dict(candidate=name, auc=auc, phantom=phantom, blind=blind,
                                                 log_likelihood=-0.4)
    blind, seeing, noisy = row("110 dB", 0.95, 0.0, True), row("90 dB", 0.90, 0.08, False), row("70 dB", 0.97, 0.3, False)
    assert best_candidate([blind, seeing, noisy], "here")["candidate"] == "90 dB"
    with pytest.raises(ConfigError, match="calling some of the lidar's occupied cells occupied"):
        best_candidate([blind, noisy], "here")
