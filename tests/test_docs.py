"""The documentation site (mkdocs.yml, docs/): it builds with warnings as errors, so a broken
link, a missing anchor or an API reference to a name that does not exist fails the suite; a
page added under docs/ joins the site with no nav to edit; the CLI reference is the parsers'
own help, and the API reference the docstrings."""

import html
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def build(config, site):
    """``mkdocs build --strict`` of ``config`` into ``site``; the finished process."""
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], capture_output=True, text=True, timeout=300,
                          env={**_env(), "NO_MKDOCS_2_WARNING": "1"})


def _env():
    import os

    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}


def page_text(site, page):
    """The visible text of a built page (tags dropped, entities decoded)."""
    return html.unescape(re.sub(r"<[^>]+>", "", (site / page / "index.html").read_text()))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site as the repository holds it, built once for the tests of this file."""
    out = tmp_path_factory.mktemp("site")
    done = build(ROOT / "mkdocs.yml", out)
    assert done.returncode == 0, done.stdout + done.stderr
    return out


@pytest.fixture
def copy(tmp_path):
    """A copy of mkdocs.yml and docs/ to plant faults in; the package itself is linked, not copied."""
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    (tmp_path / "radarcl").symlink_to(ROOT / "radarcl")
    return tmp_path


def test_the_site_builds_strict_with_every_guide_page_and_figure(site):
    for page in ("guide/pipeline", "guide/sensors", "guide/maps", "guide/live", "reference/cli", "reference/api"):
        assert (site / page / "index.html").is_file(), page
    for figure in re.findall(r"\]\(\.\./([\w.-]+\.png)\)", (ROOT / "docs" / "guide" / "maps.md").read_text()
                             + (ROOT / "docs" / "guide" / "datasets.md").read_text()):
        assert (site / figure).is_file(), figure


def test_getting_started_is_the_readme(site):
    """The README is included, not copied: its every command is on the site's first page."""
    text = page_text(site, "getting-started")
    readme = (ROOT / "README.md").read_text()
    commands = re.findall(r"^radarcl [^#\n]*?(?=\s*(?:#|$))", readme, re.M)
    assert len(commands) > 20 and [c for c in commands if c not in text] == []


def test_the_cli_reference_is_every_parser_s_help(site):
    """Each subcommand's usage line, as argparse writes it, is on the page (nothing hand-kept)."""
    from radarcl.cli import COMMANDS

    text = page_text(site, "reference/cli")
    for name in COMMANDS:
        assert f"usage: radarcl {name} " in text, name
    assert "usage: radarcl bench range-fft" in text                 # subcommands of subcommands too
    assert "--occupied-threshold" in text and "--window [R]" in text


def test_the_api_reference_holds_the_docstrings(site):
    from radarcl.maps.map import Map

    text = " ".join(page_text(site, "reference/api").split())
    first_line = " ".join(Map.probability_at.__doc__.split())
    assert first_line in text
    assert "Mapping" in text and "open_input" in text


@pytest.mark.parametrize("planted, says", [
    ("See [the missing page](nowhere.md).", "nowhere.md"),
    ("See [the maps page's missing part](guide/maps.md#no-such-heading).", "no-such-heading"),
    ("::: radarcl.maps.map.NoSuchThing", "NoSuchThing"),
])
def test_a_broken_link_or_reference_fails_the_build(copy, planted, says):
    """The check can fail: each planted fault alone stops the strict build and is named."""
    page = copy / "docs" / "index.md"
    page.write_text(page.read_text() + "\n" + planted + "\n")
    done = build(copy / "mkdocs.yml", copy / "site")
    assert done.returncode != 0
    assert says in done.stdout + done.stderr


def test_a_new_page_joins_the_site_without_a_nav(copy):
    """Pages other work adds (docs/design/*.md and the like) are picked up with no nav to edit,
    and their links are checked like every other page's."""
    (copy / "docs" / "design").mkdir(exist_ok=True)
    (copy / "docs" / "design" / "a-choice.md").write_text("# A choice\n\nSee [the maps](../guide/maps.md).\n")
    done = build(copy / "mkdocs.yml", copy / "site")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "A choice" in (copy / "site" / "design" / "a-choice" / "index.html").read_text()
    assert "design/a-choice/" in (copy / "site" / "index.html").read_text()      # in the navigation


# The benches whose figures docs/measured-figures.md shows, each from its docs/figures/NAME.json
FIGURES = ("drive", "fusion", "live", "range-fft", "cfar", "polar-read", "fuse-bag", "store")


def figures(name):
    """The JSON `radarcl bench NAME --json` wrote for the measured-figures page."""
    import json

    return json.loads((ROOT / "docs" / "figures" / f"{name}.json").read_text())


def three(x):
    """A figure as the page writes it: three significant digits, whole from 100 up."""
    return f"{x:.0f}" if abs(x) >= 100 else f"{x:#.3g}"


def test_the_measured_figures_are_the_benches_json(site):
    """Every bench's table is built from its JSON: the page shows the ratios the JSON holds (to
    three digits), each bench's command, and the load average it recorded."""
    source = (ROOT / "docs" / "measured-figures.md").read_text()
    text = " ".join(page_text(site, "measured-figures").split())
    for name in FIGURES:
        assert f"<!-- figures: {name} -->" in source, name
        r = figures(name)
        assert f"radarcl bench {name}" in text and f"load average {r['context']['load_before'][0]:.2f} before" in text
        assert (site / "figures" / f"{name}.json").is_file()                            # linked under the table
    fusion, drive, live = figures("fusion"), figures("drive"), figures("live")
    pipeline = fusion["detstats_pipeline_ms_per_frame"] / fusion["pipeline_ms_per_frame"]
    assert (f"detection statistics, whole pipeline {three(fusion['detstats_pipeline_ms_per_frame'])} ms/frame "
            f"eq. 12's pipeline: {three(fusion['pipeline_ms_per_frame'])} ms/frame {three(pipeline)} "
            "(measured / baseline)") in text
    moving = fusion["moving_ms_per_frame"] / fusion["floor_ms_per_frame"]
    assert (f"moving radar, planning included {three(fusion['moving_ms_per_frame'])} ms/frame memory floor: "
            f"{three(fusion['floor_ms_per_frame'])} ms/frame {three(moving)} (measured / baseline)") in text
    overlap = drive["overlap"]
    assert (f"decoding on a reader thread, end to end {three(overlap['end_to_end_per_s'])} scans/s fusion alone: "
            f"{three(overlap['fuse_alone_per_s'])} scans/s {three(overlap['end_to_end_over_fuse_alone'])}") in text
    assert f"rolling map, real time {three(drive['rolling']['realtime_factor'])} x real time" in text
    assert f"beam latency p99 at 921600 baud {three(live['latency_p99_ms'])} ms" in text
    assert "radarcl bench drive --scans 100 --baseline-scans 100" in text


def test_the_configuration_page_s_front_is_the_quality_bench_s_json(site):
    """docs/choosing-a-configuration.md shows `radarcl bench quality`'s front from its JSON: the
    command, the load it recorded, each run on a front with its run time, and the count."""
    source = (ROOT / "docs" / "choosing-a-configuration.md").read_text()
    assert "<!-- figures: quality -->" in source
    r = figures("quality")
    text = " ".join(page_text(site, "choosing-a-configuration").split())
    assert "radarcl bench quality" in text and f"load average {r['context']['load_before'][0]:.2f} before" in text
    front = [x for x in r["runs"] if x["pareto"] or x["pareto_ece"]]
    assert front and all(f"{x['label']} ({x['voxel_m']:g} m; front:" in text for x in front)
    assert f"the default model's configurations on a Pareto front: {r['default_model_on_front']}" in text


@pytest.mark.parametrize("fault, says", [
    (lambda folder: (folder / "store.json").unlink(), "docs/figures/store.json, which does not exist"),
    (lambda folder: (folder / "cfar.json").write_text('{"ms_per_frame": '), "cfar.json is not readable JSON"),
    (lambda folder: (folder / "live.json").write_text('{"latency_p50_ms": 1.0}'), "live.json lacks the figure"),
])
def test_a_figure_without_its_json_fails_the_build(copy, fault, says):
    """A marker whose JSON is missing, broken or not the bench's stops the strict build, named."""
    fault(copy / "docs" / "figures")
    done = build(copy / "mkdocs.yml", copy / "site")
    assert done.returncode != 0
    assert says in done.stdout + done.stderr
