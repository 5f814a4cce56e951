"""Every figure reads at a glance: colour bars with units on image panels, labelled axes, text of
10 pt or more inside the canvas (``jobs.plots.problems``), for every figure radarcl draws; and
the report page opens in a real browser with every image loaded and no console message."""

import numpy as np
import pytest
from browser import open_in_browser

from radarcl.gridspec import GridSpec
from radarcl.report import figures as plots
from radarcl.report import html


def test_the_checker_catches_what_it_should():
    plt = plots._pyplot()
    fig, ax = plt.subplots()
    ax.imshow(np.zeros((4, 4)))
    ax.text(2e3, 0, "far away", fontsize=6)
    found = " ".join(plots.problems(fig))
    assert "no colour bar" in found and "no x label" in found and "6.0 pt" in found and "outside the canvas" in found
    plt.close(fig)
    fig = plt.figure()
    ax = fig.add_axes((0.0, 0.1, 0.9, 0.8))          # y tick labels left of the canvas
    ax.set(xlabel="x", ylabel="y", ylim=(0, 1e6))
    assert any("reaches outside the canvas" in p for p in plots.problems(fig))
    plt.close(fig)


QUALITY = {}                   # the bench quality result the figures use


def figures():
    rng = np.random.default_rng(0)
    r = np.linspace(0, 64, 512)
    spec = GridSpec((-8.0, -35.0, -10.0), 0.8, (100, 88, 25))
    occ = np.zeros(spec.array_shape, bool)
    occ[13, 40:48, 20:22] = True
    log_odds = rng.normal(0, 1, spec.array_shape)
    poses = np.stack([np.eye(4)] * 3)
    poses[:, 0, 3] = [0, 2, 4]
    plane = GridSpec((-20.0, -20.0, -0.15), 0.5, (80, 80, 1))
    scores = dict(auc_detectable=0.6, iou_detectable=0.1, auc_obstacles=0.7, iou_obstacles=0.05, auc_weak=0.5,
                  false_free=0.3, shadow_unknown=0.9, ece=0.4, brier=0.25, ece_occupied=0.3, objects_found=9,
                  objects_total=10,
                  reliability=[(k / 10, (k + 1) / 10, 10 * k, k / 10 + 0.05, k / 12) for k in range(10)])
    run = dict(scores, dimension="cfar", label="kind=ca", voxel_m=0.4, ms_per_frame=12.0, pareto=True, pareto_ece=False,
               model="paper")
    base = {"prior_only": dict(scores, auc_detectable=0.88, ms_per_frame=0.0),
            "raw_intensity": dict(scores, auc_detectable=0.67, ms_per_frame=9.0),
            "octomap": dict(scores, auc_detectable=0.48, ms_per_frame=45.0)}
    voxel_set = "fixed voxel set: the 498,343 voxels the reference configuration's beams reach at 0.4 m"
    quality = dict(device="Portable / pthread-cpu", observations=3840, seed=0, frames=15, reference_voxel_m=0.4,
                   voxel_set=voxel_set, runs=[
                       dict(run, dimension="reference", label="reference: kind=so, pfa=0.01, k_occ=0.25, e_high=-0.025"),
                       run, dict(run, label="n_fft=256", dimension="zero padding", ms_per_frame=9.0, pareto=False),
                       dict(run, label="default model: model=detstats", dimension="default model", model="detstats",
                            ms_per_frame=40.0, auc_detectable=0.55, ece_occupied=0.1, pareto=False, pareto_ece=True),
                       dict(run, label="look_limit=4", dimension="default model: look limit", model="detstats",
                            ms_per_frame=41.0, auc_detectable=0.5, ece_occupied=None, pareto=False)],
                   baselines=base)
    QUALITY.update(quality)
    return {  # built one at a time: a test draws only its own
        "fig9": lambda: plots.fig9_figure([r, r], [np.abs(np.sin(r)), np.abs(np.cos(r))], (7.2, 8.2), ["a", "b"]),
        "frame": lambda: plots.frame_figure(rng.normal(0, 10, (64, 4, 512)), np.arange(-31.5, 32.5), 64.0, 1024),
        "fig10": lambda: plots.interpretation_figure(r, rng.exponential(1, 512), np.ones(512), [(10, 20, 15, 1)],
                                             rng.integers(-1024, 2048, 512), "a title"),
        "beams": lambda: plots.beams_figure([(r, rng.exponential(1, 512), np.ones(512), rng.random(512) > 0.9,
                                      rng.integers(-100, 100, 512), "beam")] * 2, "two beams"),
        "topdown": lambda: plots.topdown_figure(log_odds, occ, spec),
        "plane map": lambda: plots.plane_map_figure(rng.normal(0, 2, (80, 80)), plane, poses, "a map\nsecond line"),
        "quality": lambda: plots.quality_figure(quality),
        "reliability": lambda: plots.reliability_figure({"map": scores["reliability"],
                                                         "prior_only": scores["reliability"][::-1]}, voxel_set),
    }


@pytest.mark.parametrize("name", list(figures()))
def test_every_figure_follows_the_house_rules(name):
    fig = figures()[name]()
    assert plots.problems(fig) == []
    plots._pyplot().close(fig)


def test_the_quality_chart_labels_coinciding_runs_once_and_lists_only_present_settings():
    fig = figures()["quality"]()
    auc, ece, table = fig.axes
    assert [t.get_text() for t in auc.texts] == ["1, 2", "3", "4", "5"]      # runs 1 and 2 sit on the same point
    assert [t.get_text() for t in ece.texts] == ["1, 2", "3", "4"]           # run 5 has no occupied calls to score
    legend = [t.get_text() for t in table.get_legend().get_texts()]
    assert "voxel" not in legend and "zero padding" in legend and "cfar" in legend and "look limit" in legend
    assert "eq. 12" in legend and "default model" in legend
    plots._pyplot().close(fig)


def test_a_report_opens_in_a_real_browser(tmp_path):
    fig = figures()["topdown"]()
    png = tmp_path / "topdown.png"
    plots.save(fig, png)
    page = html.write(tmp_path / "report.html", "a run <with> characters & more", [
        ("Numbers", [html.Table(["map", "AUC"], [["tuned", 0.634], ["baseline", 0.5]]),
                     html.Pairs({"voxel_m": 0.1, "sensor": "paper"})]),
        ("Figures", [html.Figure(png, "from above"), html.Figure(png.read_bytes(), "again, from bytes")]),
        ("Notes", [html.Text("x < y & y > z")])])
    dom, console = open_in_browser(page, tmp_path)
    assert 'data-images="2/2"' in dom and 'data-errors="0"' in dom, dom[-400:]
    assert console == []
    assert "a run &lt;with&gt; characters &amp; more" in dom and "x &lt; y &amp; y &gt; z" in dom
    broken = html.write(tmp_path / "broken.html", "a broken image", [("F", [html.Figure(b"not a png")])])
    dom, _ = open_in_browser(broken, tmp_path)
    assert 'data-images="0/1"' in dom                   # the check can fail


def test_a_wide_table_fits_the_window_and_the_check_can_fail(tmp_path):
    """A run-time table of sixteen columns with long configurations fits a laptop's window (its
    text wraps, its numbers do not); a table no window can hold is counted as not fitting."""
    headers = ["run", "configuration"] + [f"metric {k}" for k in range(14)]
    rows = [[k, "reference: kind=so, pfa=0.01, k_occ=0.25, e_high=-0.025, wide_pulse_m=1, model=paper, voxel_m=0.4"]
            + [0.123456 * (k + j) for j in range(14)] for k in range(12)]
    page = html.write(tmp_path / "wide.html", "a wide table", [("Runs", [html.Table(headers, rows)])])
    dom, console = open_in_browser(page, tmp_path)
    assert 'data-overflow="0"' in dom and 'data-errors="0"' in dom and console == [], dom[-300:]
    huge = html.write(tmp_path / "huge.html", "a table too wide", [
        ("Runs", [html.Table([f"c{k}" for k in range(60)], [[123456.789] * 60])])])
    dom, _ = open_in_browser(huge, tmp_path)
    assert 'data-overflow="1"' in dom, dom[-300:]


def test_the_bench_quality_page_opens_with_its_table_and_chart(tmp_path):
    from radarcl.report import quality

    plots.save(figures()["quality"](), tmp_path / "quality.png")
    page = tmp_path / "quality.html"
    quality.write_report(QUALITY, tmp_path / "quality.png", page)
    dom, console = open_in_browser(page, tmp_path)
    assert 'data-images="1/1"' in dom and 'data-errors="0"' in dom and console == []
    assert dom.count("<tr>") == 1 + len(QUALITY["runs"]) + 3 + 4       # header, runs, baselines; 4 run rows
