"""Files radarcl reads and writes: never destructive by surprise, never half-written, never
trusted beyond their declared sizes.

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
import logging
import os
import re
import shutil
import stat
import zipfile
import zlib
from pathlib import Path

import numpy as np

from radarcl.errors import ConfigError, FrameFormatError

log = logging.getLogger(__name__)
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
                    shutil.rmtree(tmp)
                else:
                    tmp.unlink()
                removed.append(tmp)
                log.warning("removed %s, left by a run that was killed while writing %s", tmp, path.name)
    return removed


def check(path, force=False, inputs=(), what="output", directory=None):
    """``path`` as a Path that may be written (see the module docstring), or ConfigError.
    ``directory`` (kind, is_ours): the output is a directory of that kind (a map store, a ROS 2
    bag) which, with ``force``, may replace an existing directory ``is_ours(path)`` recognises,
    or an empty one; never another directory."""
    path = Path(path)
    if str(path) in ("", "."):
        raise ConfigError(f"the {what} needs a file name")
    if path.is_symlink():
        raise ConfigError(f"{what} {path} is a symbolic link; give the path of a regular file")
    if path.exists():
        kind, is_ours = directory or (None, None)
        if kind and path.is_dir() and (not any(path.iterdir()) or is_ours(path)):
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


@contextlib.contextmanager
def scratch(beside):
    """A private directory beside the output ``beside`` for a command's intermediate files (a
    report's figures, dask's spill), removed on every way out; one a killed process left
    (``kill -9``) is removed by the next ``scratch`` of the same output."""
    owner = Path(beside).with_name(Path(beside).name + ".work")
    clean_stale(owner)
    directory = owner.with_name(f".{owner.name}.{os.getpid()}.tmp")
    directory.mkdir(parents=True, exist_ok=True)
    try:
        yield directory
    finally:
        shutil.rmtree(directory, ignore_errors=True)


# -- reading: .npz files without pickles, sizes checked before allocating ------------------------------
def check_readable(path, what="file"):
    """FrameFormatError unless ``path`` is a regular file: a pipe with no writer would hold the
    reader for ever, a device such as /dev/zero never ends, a directory is not a file."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FrameFormatError(f"{path} does not exist") from None
    except OSError as exc:
        raise FrameFormatError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "a pipe" if stat.S_ISFIFO(mode) else \
            "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "special"
        raise FrameFormatError(f"{path} is {kind}, not a {what}")



def memory_budget():
    """Bytes one loaded file may take: RADARCL_MEMORY_BUDGET (bytes), else half the RAM."""
    env = os.environ.get("RADARCL_MEMORY_BUDGET")
    if env:
        try:
            return int(float(env))
        except ValueError:
            raise ConfigError(f"RADARCL_MEMORY_BUDGET must be a number of bytes, got {env!r}") from None
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (ValueError, OSError, AttributeError):
        return 4 << 30


def read_npy_header(f):
    """(shape, dtype) from an open .npy stream positioned at its start."""
    version = np.lib.format.read_magic(f)
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _, dtype = read(f)
    return shape, dtype


def declared_bytes(shape, dtype):
    """Bytes an array of ``shape`` and ``dtype`` takes (float64 arithmetic: never overflows)."""
    return float(np.prod(shape, dtype=np.float64)) * np.dtype(dtype).itemsize


# What zipfile and numpy raise on a damaged archive member (a flipped compression method field
# gives NotImplementedError, a damaged deflate stream zlib.error).
_DAMAGED = (KeyError, OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError)


class SafeNpz:
    """An ``.npz`` read member by member: no pickles, and each array's header (shape, dtype) is
    read and checked against the budget before its data is. Use as a context manager."""

    def __init__(self, path, budget=None, what="readable .npz file"):
        self.path = Path(path)
        self.budget = memory_budget() if budget is None else budget
        check_readable(self.path, what)
        try:
            self._zip = zipfile.ZipFile(self.path)
        except (OSError, zipfile.BadZipFile, ValueError, NotImplementedError) as exc:
            raise FrameFormatError(f"{self.path} is not a {what} ({exc})") from exc
        names = self._zip.namelist()
        if len(set(names)) != len(names):
            raise FrameFormatError(f"{self.path}: an archive member appears twice")
        self.files = [n[:-4] for n in names if n.endswith(".npy")]
        self.used = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._zip.close()

    def header(self, key):
        """(shape, dtype) that member ``key`` declares."""
        try:
            with self._zip.open(f"{key}.npy") as f:
                shape, dtype = read_npy_header(f)
        except _DAMAGED as exc:
            raise FrameFormatError(f"{self.path}: member {key!r} is not a readable array ({exc})") from exc
        if dtype.hasobject:
            raise FrameFormatError(f"{self.path}: member {key!r} holds Python objects; radarcl never unpickles")
        return shape, dtype

    def __getitem__(self, key):
        shape, dtype = self.header(key)
        nbytes = declared_bytes(shape, dtype)
        if self.used + nbytes > self.budget:
            raise FrameFormatError(f"{self.path}: member {key!r} declares {shape} {dtype} = {nbytes / 2**20:.0f} MiB; "
                                   f"with the rest that exceeds the memory budget of {self.budget / 2**20:.0f} MiB "
                                   "(RADARCL_MEMORY_BUDGET)")
        try:
            with self._zip.open(f"{key}.npy") as f:
                array = np.lib.format.read_array(f, allow_pickle=False)
        except _DAMAGED as exc:
            raise FrameFormatError(f"{self.path}: member {key!r} is truncated or corrupt ({exc})") from exc
        self.used += nbytes
        return array


def safe_npz(path, budget=None, what="readable .npz file"):
    """A ``SafeNpz`` over ``path``; ``what`` names the expected kind of file in errors."""
    return SafeNpz(path, budget, what)
