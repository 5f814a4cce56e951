"""MkDocs hook: the CLI reference page (``reference/cli.md``), generated at build time from the
argparse parsers of ``radarcl.cli.build_parser``, so it cannot drift from the command's --help.

Written by hand because mkdocs-click and similar plugins read Click, not argparse, and the
argparse plugins for MkDocs render options in their own layout; the text users see in a
terminal is what this page should show.
"""

import argparse
import os

from mkdocs.structure.files import File

PAGE = "reference/cli.md"
WIDTH = "100"                   # argparse wraps at $COLUMNS: a fixed width keeps the page reproducible


def subcommands(parser):
    """(name, parser) of each subcommand of ``parser``, in the order --help lists them."""
    for action in parser._actions:              # argparse keeps subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            seen = set()
            for name, sub in action.choices.items():
                if id(sub) not in seen:
                    seen.add(id(sub))
                    yield name, sub


def section(path, parser, depth):
    """Markdown for one command: its heading, its --help text, then its subcommands'."""
    title = "#" * depth + f" `{' '.join(path)}`"
    lines = [title, "", "```text", parser.format_help().rstrip(), "```", ""]
    for name, sub in subcommands(parser):
        lines += section([*path, name], sub, min(depth + 1, 4))
    return lines


def markdown():
    """The whole page: one section per command and subcommand."""
    from radarcl.cli import build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        parser = build_parser()
        lines = ["# Command-line reference", "",
                 "Every command and option of `radarcl`, as `radarcl COMMAND --help` prints it "
                 "(this page is generated from the command's own parsers when the site is built).", "",
                 "```text", parser.format_help().rstrip(), "```", ""]
        for name, sub in subcommands(parser):
            lines += section(["radarcl", name], sub, 2)
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    return "\n".join(lines) + "\n"


def on_files(files, config):
    """Add the generated page to the site's files (no file is written into docs/)."""
    files.append(File.generated(config, PAGE, content=markdown()))
    return files
