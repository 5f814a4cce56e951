"""One self-contained HTML page per run (``report.html``): the run's configuration, its tables,
its figures and renders embedded as base64 PNGs, readable in any browser without a server and
without the files beside it.

A page is a list of sections, each a heading and blocks: ``Text(str)``, ``Table(headers,
rows)``, ``Figure(png path or bytes, caption)``, ``Pairs(dict)`` (a configuration as key/value
rows). A small script marks the body with ``data-images="loaded/total"`` and ``data-errors`` once
the page has loaded, so a test in a headless browser can check that every image decoded.
"""

import base64
import html
import time
from dataclasses import dataclass
from pathlib import Path

from radarcl import __version__
from radarcl.io.files import atomic

STYLE = """
body { font-family: "DejaVu Sans", Arial, sans-serif; margin: 2em auto; max-width: 1150px; color: #222;
       line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { font-size: 1.25em; margin-top: 1.6em;
     border-bottom: 1px solid #ccc; }
.meta { color: #555; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; display: block; max-width: 100%;
        overflow-x: auto; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.4em; text-align: left; }
td { max-width: 26em; overflow-wrap: break-word; }
td.n { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; overflow-wrap: normal; }
th { background: #f0f0f0; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #444; font-size: 0.95em; }
"""

SCRIPT = """
(function () {
  var errors = 0;
  window.addEventListener('error', function () { errors += 1; }, true);
  window.addEventListener('load', function () {
    var images = Array.prototype.slice.call(document.images);
    var loaded = images.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
    document.body.setAttribute('data-images', loaded + '/' + images.length);
    document.body.setAttribute('data-errors', String(errors));
    // what does not fit: the page wider than the window, and each table that must scroll
    var tables = Array.prototype.slice.call(document.querySelectorAll('table'));
    var wide = tables.filter(function (t) { return t.scrollWidth > t.clientWidth + 1; }).length;
    document.body.setAttribute('data-overflow', String(wide + (document.documentElement.scrollWidth > window.innerWidth ? 1 : 0)));
  });
})();
"""


@dataclass
class Text:
    text: str


@dataclass
class Table:
    headers: list
    rows: list


@dataclass
class Figure:
    png: object                  # a path or the PNG's bytes
    caption: str = ""


@dataclass
class Pairs:
    values: dict


def configuration(resolved):
    """A ``mapconfig.Resolved`` as key/value rows: each value (floats to 6 significant digits)
    with where it came from."""
    def text(v):
        if isinstance(v, float):
            return f"{v:.6g}"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(text(x) for x in v) + "]"
        return str(v)

    return Pairs({k: f"{text(v)}  ({resolved.origins[k]})" for k, v in resolved.values.items()})


def _cell(v):
    """A table cell: numbers right-aligned to 4 significant digits, the rest as text."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"<td>{html.escape(str(v))}</td>"
    return f'<td class="n">{v:.4g}</td>' if isinstance(v, float) else f'<td class="n">{v}</td>'


def _block(block):
    if isinstance(block, Text):
        return f"<p>{html.escape(block.text)}</p>"
    if isinstance(block, Table):
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in block.headers)
        body = "".join("<tr>" + "".join(_cell(v) for v in row) + "</tr>" for row in block.rows)
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    if isinstance(block, Pairs):
        rows = "".join(f"<tr><td>{html.escape(str(k))}</td>{_cell(v)}</tr>" for k, v in block.values.items())
        return f"<table><tbody>{rows}</tbody></table>"
    if isinstance(block, Figure):
        data = block.png if isinstance(block.png, (bytes, bytearray)) else Path(block.png).read_bytes()
        src = "data:image/png;base64," + base64.b64encode(data).decode()
        alt = html.escape(block.caption or "figure")
        return f'<figure><img src="{src}" alt="{alt}"><figcaption>{html.escape(block.caption)}</figcaption></figure>'
    raise TypeError(f"unknown report block {block!r}")


def render(title, sections, subtitle=""):
    """The page's HTML text."""
    parts = [f"<h2>{html.escape(h)}</h2>" + "".join(_block(b) for b in blocks) for h, blocks in sections]
    stamp = time.strftime("%Y-%m-%d %H:%M")
    return (f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
            f"<style>{STYLE}</style></head><body><h1>{html.escape(title)}</h1>"
            f'<p class="meta">{html.escape(subtitle)} Written by radarcl {__version__} on {stamp}.</p>'
            + "".join(parts) + f"<script>{SCRIPT}</script></body></html>\n")


def write(path, title, sections, subtitle=""):
    """Write the page to ``path`` (through a temporary file); returns the path."""
    with atomic(path) as tmp:
        Path(tmp).write_text(render(title, sections, subtitle), encoding="utf-8")
    return Path(path)
