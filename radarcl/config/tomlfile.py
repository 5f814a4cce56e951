"""radarcl's TOML files (sensor profiles, map configurations): read with file and line in every
error, checked against a schema of named fields, written back in the same shape.

Reading uses ``tomllib``. Writing is by hand: the files hold flat
tables of numbers, strings, booleans and short lists of numbers, which a dozen lines write
exactly (``repr`` of a float round-trips), so no TOML writer is needed as a dependency.
"""

import math
import numbers
import re
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path

from radarcl.errors import ConfigError


@dataclass(frozen=True)
class Source:
    """Where a TOML text came from (a path, or a built-in name) and the text itself, so an
    error can name the line of a key."""

    name: str
    text: str

    def line(self, section, key):
        """1-based line of ``key`` in ``[section]`` (dotted for sub-tables; "" for the top), or None."""
        current = ""
        for number, raw in enumerate(self.text.splitlines(), 1):
            line = raw.split("#", 1)[0].strip()
            header = re.fullmatch(r"\[\s*([^\]]+?)\s*\]", line)
            if header:
                current = header.group(1).replace(" ", "")
                if not section and current == key or current.startswith(f"{key}."):
                    return number                    # a table named like the key asked for
            elif current == section and re.match(rf"{re.escape(key)}\s*=", line):
                return number
        return None

    def where(self, section, key=None):
        """'file:line: [section] key' for messages."""
        line = self.line(section, key) if key is not None else None
        at = f"{self.name}:{line}" if line else self.name
        what = f"[{section}]" if section else "top level"
        return f"{at}: {what}" + (f" {key}" if key is not None else "")


MAX_BYTES = 1 << 20           # a profile or configuration is a few kB; anything far larger is not one


def load(path):
    """(dict, Source) of a TOML file; ConfigError names the file and what is wrong. A pipe or
    socket is refused before it is opened (reading one with no writer would wait for ever), and
    at most ``MAX_BYTES`` are read (``/dev/zero`` never ends)."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode) or stat.S_ISDIR(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "a pipe or socket"
            raise ConfigError(f"cannot read {path}: it is {kind}, not a TOML file")
        with open(path, "rb") as f:
            raw = f.read(MAX_BYTES + 1)
        if len(raw) > MAX_BYTES:
            raise ConfigError(f"cannot read {path}: more than {MAX_BYTES >> 20} MiB, not a profile or configuration")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from exc
    return loads(text, str(path)), Source(str(path), text)


def loads(text, name="<text>"):
    """The tables of a TOML text; ConfigError with the name and tomllib's line and column."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{name}: not valid TOML: {exc}") from exc
    except RecursionError:
        raise ConfigError(f"{name}: arrays or tables nested too deeply to be a profile or configuration") from None


# -- value checks: each returns the value in its Python type or raises ConfigError(reason) ------
def number(value, lo=None, hi=None, lo_open=False, unit=""):
    """A finite real number within [lo, hi] ((lo, hi] when lo_open)."""
    if isinstance(value, bool) or type(value).__name__ == "bool_" or not isinstance(value, numbers.Real) \
            or not math.isfinite(value):
        raise ConfigError(f"must be a finite number{_unit(unit)}, got {value!r}")
    below = (value <= lo) if lo_open else (value < lo) if lo is not None else False
    if below or (hi is not None and value > hi):
        raise ConfigError(f"must lie in {'(' if lo_open else '['}{'-inf' if lo is None else lo}, "
                          f"{'inf' if hi is None else hi}]{_unit(unit)}, got {value!r}")
    return float(value)


def integer(value, lo=None, hi=None):
    """An integer (not a bool, not 64.7) within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ConfigError(f"must be an integer, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigError(f"must lie in [{lo}, {'inf' if hi is None else hi}], got {value!r}")
    return int(value)


def choice(value, options):
    """One of ``options`` (strings)."""
    if value not in options:
        raise ConfigError(f"must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def boolean(value):
    """true or false."""
    if not isinstance(value, bool):
        raise ConfigError(f"must be true or false, got {value!r}")
    return value


def text(value):
    """A string."""
    if not isinstance(value, str):
        raise ConfigError(f"must be a string, got {value!r}")
    return value


def vector(value, n=3, lo=None, lo_open=False, unit=""):
    """A list of ``n`` finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ConfigError(f"must be a list of {n} numbers{_unit(unit)}, got {value!r}")
    return tuple(number(v, lo=lo, lo_open=lo_open, unit=unit) for v in value)


def _unit(unit):
    return f" [{unit}]" if unit else ""


def check_keys(table, allowed, source, section):
    """ConfigError naming the first key of ``table`` that is not in ``allowed``."""
    if not isinstance(table, dict):
        raise ConfigError(f"{source.where(section)} must be a table, got {table!r}")
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{source.where(section, key)}: unknown key; allowed: {', '.join(sorted(allowed))}")


# -- writing ------------------------------------------------------------------------------------------
def format_value(value):
    """A TOML literal of a bool, int, float, string or list of numbers."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ConfigError(f"cannot write the non-finite number {value!r}")
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {value!r} as TOML")


def dumps(tables, header=(), top=None, comments=None):
    """TOML text: ``header`` lines as comments, ``top`` keys, then ``{section: {key: value}}``
    in order; ``comments[(section, key)]`` goes after a value. None values are left out."""
    comments = comments or {}
    lines = [f"# {h}" if h else "#" for h in header]
    for key, value in (top or {}).items():
        if value is not None:
            lines.append(f"{key} = {format_value(value)}")
    for section, table in tables.items():
        entries = [(k, v) for k, v in table.items() if v is not None]
        if not entries:
            continue
        lines += ["", f"[{section}]"]
        for key, value in entries:
            note = comments.get((section, key))
            lines.append(f"{key} = {format_value(value)}" + (f"    # {note}" if note else ""))
    return "\n".join(lines) + "\n"
