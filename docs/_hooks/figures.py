"""MkDocs hook: measured figures from the benchmarks' own JSON, never typed by hand.

A page's marker ``<!-- figures: NAME -->`` becomes the figures of ``docs/figures/NAME.json``, the
output of ``radarcl bench NAME --json``: a table of the bench's headline figures, each beside
the baseline measured in the same run and the bench's ratio to it (``radarcl.bench.suite.HEADLINES``,
the rows `radarcl bench all` prints), then the command, the CPU, the device, the date and the
load average the JSON recorded, a link to the JSON, and all the bench printed, folded. A marker
naming a JSON that is missing or unreadable stops the build with a sentence saying how to write it.

Written by hand because the figures are the benches' own result dicts, which no MkDocs plugin
knows; a table-from-data plugin (e.g. mkdocs-table-reader) would show raw keys, not the ratios.
"""

import argparse
import html
import json
import posixpath
import re
from pathlib import Path

from mkdocs.exceptions import PluginError

MARKER = re.compile(r"<!--\s*figures:\s*([\w-]+)\s*-->")
FOLDER = "figures"                  # under docs_dir: the JSON files, published beside the pages


def on_page_markdown(markdown, page, config, files):
    """Replace every figures marker of the page by its figures."""
    def figures(match):
        name = match.group(1)
        path = Path(config["docs_dir"]) / FOLDER / f"{name}.json"
        link = posixpath.relpath(f"{FOLDER}/{name}.json", posixpath.dirname(page.file.src_uri) or ".")
        return "\n".join(render(name, read(path, name, page.file.src_uri), link)) + "\n"

    return MARKER.sub(figures, markdown)


def read(path, name, page):
    """The bench's result dict at ``path``; a PluginError that says what is wrong otherwise."""
    how = f"write it with `radarcl bench {name} --json > docs/{FOLDER}/{name}.json`"
    if not path.is_file():
        raise PluginError(f"{page}: the marker <!-- figures: {name} --> needs docs/{FOLDER}/{name}.json, which "
                          f"does not exist; {how}")
    try:
        result = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise PluginError(f"{page}: docs/{FOLDER}/{name}.json is not readable JSON ({exc}); {how}") from None
    if not isinstance(result, dict):
        raise PluginError(f"{page}: docs/{FOLDER}/{name}.json holds a {type(result).__name__}, expected the "
                          f"JSON object of `radarcl bench {name} --json`; {how}")
    return result


def render(name, result, link):
    """Markdown lines: the headline table, the run's context, the bench's own printed table."""
    from radarcl.bench import BENCHES
    from radarcl.bench.suite import BASELINE_OF_FIGURE, HEADLINES

    if name not in BENCHES:
        raise PluginError(f"figures marker names {name!r}, which is no benchmark; expected one of "
                          f"{', '.join(BENCHES)}")
    lines = []
    try:
        rows = HEADLINES[name](result) if name in HEADLINES else []
        printed = BENCHES[name][0].format_table(result)
    except (KeyError, TypeError, IndexError) as exc:
        raise PluginError(f"docs/{FOLDER}/{name}.json lacks the figure {exc} that `radarcl bench {name}` "
                          f"reports; rerun the bench to rewrite it") from None
    if rows:
        lines += ["| figure | measured | baseline, same run | ratio |", "| --- | ---: | --- | ---: |"]
        for r in rows:
            base = "" if r["baseline"] is None else r["baseline"] + (
                "" if r["baseline_value"] is None else f": {number(r['baseline_value'])} {r['unit']}")
            ratio = "" if r["ratio"] is None else (
                f"{number(r['ratio'])} ({'baseline / measured' if r['ratio_is'] == BASELINE_OF_FIGURE else 'measured / baseline'})")
            lines.append(f"| {r['figure']} | {number(r['value'])} {r['unit']} | {base} | {ratio} |")
        lines.append("")
    lines += [context_line(name, result, link), "",
              f"<details><summary>All that <code>radarcl bench {name}</code> printed</summary>",
              "<pre>" + html.escape("\n".join(printed)) + "</pre>", "</details>", ""]
    return lines


def context_line(name, result, link):
    """One sentence: the command, the machine, the date, the load average and the wall time, as
    far as the JSON recorded them."""
    c = result.get("context") or {}
    parts = [f"`{command(name, c.get('options') or {})}`"]
    cpu = c.get("cpu") or {}
    if cpu.get("model"):
        family = f"family {cpu['family']}, " if cpu.get("family") else ""
        parts.append(f"on {cpu['model']} ({family}{cpu.get('cores')} cores)")
    if result.get("device"):
        parts.append(f"device {result['device']}")
    if c.get("date"):
        parts.append(c["date"].replace("T", " "))
    before, after = c.get("load_before") or result.get("load_before"), c.get("load_after") or result.get("load_after")
    if before:
        parts.append("load average " + f"{before[0]:.2f} before" + (f", {after[0]:.2f} after" if after else ""))
    if c.get("wall_s") is not None:
        parts.append(f"{c['wall_s']:.0f} s")
    return "Measured by " + ", ".join(parts) + f" ([the JSON]({link}))."


def command(name, options):
    """``radarcl bench NAME`` with the options that differ from the bench's defaults."""
    from radarcl.bench import add_arguments

    parser = argparse.ArgumentParser(prog="radarcl bench")
    add_arguments(parser)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    words = ["radarcl", "bench", name]
    for action in sub._actions:                 # argparse keeps the options only here
        if action.dest in options and action.option_strings and options[action.dest] != action.default:
            value = options[action.dest]
            words += [action.option_strings[-1], *map(str, value if isinstance(value, list) else [value])]
    return " ".join(words)


def number(value):
    """A figure as a person reads it: integers as they are, other numbers to three significant
    digits (trailing zeros kept: 1.00, 27.0), whole from 100 up."""
    if value is None:
        return "-"
    if isinstance(value, int):
        return str(value)
    if abs(value) >= 100:
        return f"{value:.0f}"
    return f"{value:#.3g}"
