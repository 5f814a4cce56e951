"""Files radarcl writes: never destructive by surprise, never half-written.

``check(path, force, inputs)`` runs before any work: it refuses an existing output unless
``force``, anything that is not a regular file (a directory, a device node, a symbolic link:
``os.replace`` would replace the link or the node itself, not write through it), and the
command's own inputs; it creates the parent directories and says when they cannot be written.
``atomic(path)`` gives a temporary file in the same directory and renames it over ``path`` only
when the writer finished; the temporary file is removed on every other way out (an exception,
Ctrl-C, SIGTERM, which the CLI turns into an exception). Temporary files left by a process that
was killed (``kill -9``) are removed by the next ``check`` or ``atomic`` of the same output.
"""

import contextlib
import os
import re
from pathlib import Path

from radarcl.errors import ConfigError

_TMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.tmp$")


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale(path):
    """Remove temporary files of ``path`` whose writer process no longer exists; returns them."""
    path = Path(path)
    removed = []
    if not path.parent.is_dir():
        return removed
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        m = _TMP.match(tmp.name)
        if m and m.group("name") == path.name and int(m.group("pid")) != os.getpid() and not _alive(int(m.group("pid"))):
            with contextlib.suppress(OSError):
                if tmp.is_dir():
                    import shutil

                    shutil.rmtree(tmp)
                else:
                    tmp.unlink()
                removed.append(tmp)
    return removed


def check(path, force=False, inputs=(), what="output", store=False, bag=False):
    """``path`` as a Path that may be written (see the module docstring), or ConfigError.
    ``store`` / ``bag``: the output is a directory (a map store, ``radarcl.store``; a ROS 2
    bag), which may replace an existing one of its kind (or an empty directory) with ``force``,
    never another directory."""
    from radarcl.store import is_store

    path = Path(path)
    if str(path) in ("", "."):
        raise ConfigError(f"the {what} needs a file name")
    if path.is_symlink():
        raise ConfigError(f"{what} {path} is a symbolic link; give the path of a regular file")
    if path.exists():
        kind = "map store" if store else "ROS 2 bag" if bag else None
        ours = (store and is_store(path)) or (bag and (path / "metadata.yaml").is_file())
        if kind and path.is_dir() and (ours or not any(path.iterdir())):
            pass
        elif kind and path.is_dir():
            raise ConfigError(f"{what} {path} is a directory that is not a {kind}; choose another name")
        elif not path.is_file():
            kind = "a directory" if path.is_dir() else "not a regular file"
            raise ConfigError(f"{what} {path} is {kind}; give the path of a regular file")
        for source in inputs:
            with contextlib.suppress(OSError):
                if source is not None and Path(source).exists() and os.path.samefile(path, source):
                    raise ConfigError(f"{what} {path} is one of this command's inputs; choose another name")
        if not force:
            raise ConfigError(f"{what} {path} exists; pass --force to replace it")
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot create the directory of {what} {path}: {exc.strerror or exc}") from None
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"cannot write {what} {path}: {parent} is not a writable directory")
    clean_stale(path)
    return path


@contextlib.contextmanager
def atomic(path):
    """Yield a temporary path beside ``path``; rename it over ``path`` when the block ends
    normally, remove it otherwise."""
    import shutil

    path = Path(path)
    clean_stale(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        yield tmp
        if tmp.is_dir() and path.is_dir():               # a directory output (a bag) replaces one
            shutil.rmtree(path)
        elif tmp.is_dir() and path.exists():             # ... or the file --force named
            path.unlink()
        os.replace(tmp, path)
    finally:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        with contextlib.suppress(OSError):
            tmp.unlink()
