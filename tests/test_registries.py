"""A new evidence model and a new export format need nothing but their registries: a toy model of
constant evidence (``radarcl.models.register``) fuses a frame through the whole pipeline as the
float64 oracle says, and a toy format (``radarcl.maps.exports.register``) exports that map from
the command line. No code outside the registry asks which model is in force."""

import re
from pathlib import Path

import numpy as np
import pytest
from tolerances import FUSION_AMBIGUOUS_MAX, FUSION_DECISION_MARGIN, FUSION_UNITS_PER_UPDATE

from radarcl import logodds, models, oracle
from radarcl.config import mapconfig
from radarcl.errors import ConfigError
from radarcl.maps import exports
from radarcl.maps.disk import save_grid
from radarcl.pipeline import Mapping
from radarcl.scene.observe import observe
from radarcl.scene.outdoor import paper_scene

ROOT = Path(__file__).resolve().parents[1]
CONSTANT_NATS = -0.25


class Constant(models.EvidenceModel):
    """Every bin of every beam says the same: ``CONSTANT_NATS``, whatever it measured."""

    name = "constant"
    summary = "the same evidence on every bin (a test's toy)"
    per_bin = "constant"

    def after_kernel(self, interpreter, event, profiles):
        evidence = interpreter.arrays["evidence"]
        evidence.fill(np.int32(logodds.to_fixed(CONSTANT_NATS)), wait_for=[event])
        return evidence.events[-1]

    def oracle(self, profiles, noise, mask, config, bin_spacing_m, bin_model=None, flags=None):
        return np.full(np.shape(profiles), logodds.to_fixed(CONSTANT_NATS), np.int32)


def count_free(m, path):
    """The toy format: one line, the number of voxels whose log-odds is below 0."""
    n = int((m.dense() < 0).sum())
    Path(path).write_text(f"{n}\n")
    return dict(files=[Path(path)], free=n)


@pytest.fixture
def toy_model(monkeypatch):
    monkeypatch.setattr(models, "MODELS", dict(models.MODELS))       # the registry as it was, after the test
    return models.register(Constant())


@pytest.fixture
def toy_format(monkeypatch):
    monkeypatch.setattr(exports, "FORMATS", dict(exports.FORMATS))
    return exports.register(exports.Export("count", (".txt",), "the number of voxels below 0 nat, as text",
                                           count_free))


def test_a_toy_model_and_a_toy_format_through_the_registries_alone(runtime, toy_model, toy_format, tmp_path, capsys):
    config = mapconfig.resolve("paper", program={"grid.voxel_m": 0.8, "interpret.model": "constant"})
    assert config.evidence_model() is toy_model and config.reading() is None
    obs = observe(paper_scene(), (-9.2,), seed=1)
    mapping = Mapping.from_config(runtime, config=config)
    assert not mapping.grid.has_knowledge
    mapping.fuse(obs.samples[0], obs.poses[0])
    got = mapping.snapshot()

    it, f = mapping.detection.interpreter, mapping.fusion
    per_bin = it.arrays["evidence"].get()
    assert (per_bin == logodds.to_fixed(CONSTANT_NATS)).all()       # the model's evidence, not eq. 12's
    ev = toy_model.oracle(per_bin, None, None, it.config, it.bin_spacing_m).reshape(f.lattice.n_beams, -1)
    sums, updates, ambiguous = oracle.fusion(mapping.grid.spec, ev, f.lattice, f.model, obs.poses[0],
                                              f.bin_spacing_m, f.first_bin, f.last_bin, margin=FUSION_DECISION_MARGIN)
    reached = updates > 0
    assert reached.sum() > 1000 and ambiguous.sum() <= FUSION_AMBIGUOUS_MAX * reached.sum()
    clear = ~ambiguous
    assert (np.abs(got.astype(np.int64) - sums)[clear] <= FUSION_UNITS_PER_UPDATE * updates[clear]).all()
    assert (got[reached & clear] < 0).all() and (got[~reached & clear] == 0).all()

    path = tmp_path / "constant.npz"
    save_grid(mapping.grid, path, reading=config.reading())
    from radarcl.cli import main

    assert main(["export", str(path), "--to", "count", "--out", str(tmp_path / "n.txt")]) == 0
    assert int((tmp_path / "n.txt").read_text()) == int((got < 0).sum()) > 1000
    assert f"(count: {int((got < 0).sum()):,} free; every voxel's log-odds)" in capsys.readouterr().out


def test_a_name_taken_or_no_model_is_refused(toy_model):
    with pytest.raises(ConfigError, match="registered already"):
        models.register(Constant())
    with pytest.raises(ConfigError, match="unknown evidence model 'nothing'; models: paper, occlusion, detstats"):
        models.get("nothing")
    with pytest.raises(ConfigError, match="interpret.model must be one of"):
        mapconfig.resolve("paper", program={"interpret.model": "nothing"})


def test_no_code_outside_the_registry_asks_which_model_is_in_force():
    """A test of the model's name (a line about a model comparing with "detstats", "occlusion" or
    "paper", or comparing what interpret.model holds) anywhere in the package but radarcl/models
    is a decision that belongs to the model."""
    names = "|".join(models.names())
    test = re.compile(rf"""model.*((==|!=)\s*["']({names})["']|["']({names})["']\s*(==|!=))|"""
                      r"""\[["']interpret\.model["']\]\s*(==|!=|in\b)|\.model\s*(==|!=)""")
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in sorted((ROOT / "radarcl").rglob("*.py"))
             if "models" not in p.relative_to(ROOT).parts
             for n, line in enumerate(p.read_text().splitlines(), 1) if test.search(line)]
    assert found == []
