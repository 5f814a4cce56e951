"""Calibration as a fit (radarcl/evaluation/calibration.py, radarcl/jobs/calibrate.py): the fit
recovers known coefficients from synthetic logistic data, holds the signs eq. 12 requires, the
per-bin features with the fitted constants are the occlusion-aware interpreter's evidence, and
`calibrate --save` then `fuse --config` round-trips."""

import numpy as np
import pytest

from radarcl import logodds, oracle
from radarcl.config.stage_config import CfarConfig, InterpretConfig
from radarcl.evaluation import calibration as cal


def synthetic(beta, n=200_000, seed=3):
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.exponential(2.0, n), rng.random(n) * 3, rng.random(n) * 3, rng.random(n) * 2])
    X[rng.random(n) < 0.5, 0] = 0                                   # half the voxels saw no pulse
    p = 1 / (1 + np.exp(-(X @ beta)))
    return X, rng.random(n) < p


def test_the_fit_recovers_known_coefficients():
    beta = np.array([0.8, -0.6, -1.4, -0.3])
    X, y = synthetic(beta)
    f = cal.fit(X, y, "occlusion")
    got = np.array(list(f.values.values()))
    se = np.array(list(f.stderr.values()))
    assert np.all(np.abs(got - beta) < 4 * se) and np.all(se < 0.05), (got, se)
    assert f.held == [] and f.n == len(y)
    assert f.log_likelihood == pytest.approx(cal.log_likelihood(X, y, got))


def test_a_coefficient_on_the_wrong_side_is_held_at_zero():
    beta = np.array([0.8, -0.6, -1.4, +0.5])                        # the data want E_l > 0
    X, y = synthetic(beta, seed=4)
    f = cal.fit(X, y, "occlusion")
    assert f.held == ["interpret.e_low"] and f.values["interpret.e_low"] == 0.0
    assert f.values["interpret.k_occ"] > 0 and f.values["interpret.e_high"] < 0
    held = cal.fit(X, y, "occlusion", zero=("interpret.e_low",))
    assert held.values == f.values and held.held == []
    with pytest.raises(Exception, match="both occupied and free"):
        cal.fit(X[:10], np.zeros(10, bool), "occlusion")


def test_features_times_constants_are_the_occlusion_interpreters_evidence():
    rng = np.random.default_rng(1)
    x = rng.exponential(size=(24, 256))
    x[0, 50:53] = 1e3                 # a strong narrow pulse: a surface at 20 dB
    x[1, 100:118] = 1e3               # a wide pulse
    x[2, 40] = 30.0                   # a weak narrow echo: not a surface at 20 dB
    config = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, model="occlusion",
                             surface_db=20.0, k_occ=0.7, e_high=-0.8, e_high_far=-0.3, e_low=-0.05)
    noise, _, mask = oracle.cfar(x, CfarConfig(guard=16, train=8))
    feats = cal.bin_features(x, noise, mask, config, 0.125)
    linear = feats @ np.array([0.7, -0.8, -0.3, -0.05])
    evidence = oracle.interpret(x, noise, mask, config, 0.125)[0] / logodds.SCALE
    # within one unit: rounding, and the ramp's integer truncation
    assert np.abs(linear - evidence).max() <= 1.0 / logodds.SCALE + 1e-12
    paper = InterpretConfig(range_min_m=1.0, range_max_m=30.0, wide_pulse_m=2.0, k_occ=0.7, e_high=-0.8, e_low=-0.05)
    pf = cal.bin_features(x, noise, mask, paper, 0.125)
    merged = np.stack([pf[..., 0], pf[..., 1] + pf[..., 2], pf[..., 3]], -1) @ np.array([0.7, -0.8, -0.05])
    assert np.abs(merged - oracle.interpret(x, noise, mask, paper, 0.125)[0] / logodds.SCALE).max() <= 1.0 / logodds.SCALE


def test_calibrate_saves_a_configuration_that_fuse_reads(runtime, tmp_path, capsys):
    """`calibrate --save` writes the fitted constants; `fuse --config` makes its map with them:
    the same integers as a pipeline built from the file's values, not those of the defaults."""
    from radarcl.cli import main
    from radarcl.config import mapconfig
    from radarcl.gridspec import assemble
    from radarcl.io import recording
    from radarcl.maps.disk import read
    from radarcl.pipeline import Mapping
    from radarcl.scene.observe import observe
    from radarcl.scene.outdoor import paper_scene

    saved, fig = tmp_path / "cal.toml", tmp_path / "cal.png"
    assert main(["calibrate", "--voxel", "0.8", "--seeds", "101", "102", "103", "--save", str(saved),
                 "--figure", str(fig), "--unknown-behind"]) == 0
    out = capsys.readouterr().out
    assert "fitted constants" in out and "interpret.e_low" in out and fig.stat().st_size > 0
    text = saved.read_text()
    assert 'model = "occlusion"' in text and "e_low = 0.0" in text
    rec = tmp_path / "rec.npz"
    obs = observe(paper_scene(), (-9.2,), seed=1)
    recording.save(rec, obs)
    assert main(["fuse", str(rec), "--config", str(saved), "--out", str(tmp_path / "m.npz"), "--no-progress",
                 "--no-report"]) == 0
    assert main(["config", "show", "--config", str(saved)]) == 0
    assert "occlusion" in capsys.readouterr().out
    fitted = mapconfig.resolve(None, saved)
    assert fitted["interpret.model"] == "occlusion" and fitted.origins["interpret.k_occ"].startswith(f"file {saved}")
    spec, keys, data = read(tmp_path / "m.npz")
    fused = assemble(spec, keys, data)
    maps = {}
    defaults = mapconfig.resolve("paper", flags={"grid.voxel_m": spec.voxel_m})
    for name, config in (("fitted", fitted), ("defaults", defaults)):
        m = Mapping.from_config(runtime, "paper", config)
        m.fuse(obs.samples[0], obs.poses[0])
        maps[name] = m.snapshot()
    assert maps["fitted"].shape == fused.shape and np.array_equal(fused, maps["fitted"]) and (fused > 0).any()
    assert not np.array_equal(fused, maps["defaults"])
