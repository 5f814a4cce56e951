"""Outputs are never destructive by surprise and never half-written (radarcl.io.files)."""

import os
import shutil
import subprocess
import sys

import pytest
from conftest import interactive_signals

from radarcl.errors import ConfigError
from radarcl.io import files as outputs


def test_refusals(tmp_path):
    existing = tmp_path / "map.npz"
    existing.write_bytes(b"the user's file")
    with pytest.raises(ConfigError, match="exists; pass --force to replace it"):
        outputs.check(existing)
    assert outputs.check(existing, force=True) == existing
    with pytest.raises(ConfigError, match="is one of this command's inputs"):
        outputs.check(existing, force=True, inputs=[existing])
    with pytest.raises(ConfigError, match="is a directory"):
        outputs.check(tmp_path, force=True)
    link = tmp_path / "link.npz"
    link.symlink_to(existing)
    with pytest.raises(ConfigError, match="is a symbolic link"):
        outputs.check(link, force=True)
    with pytest.raises(ConfigError, match="is not a regular file"):
        outputs.check("/dev/null", force=True)
    assert existing.read_bytes() == b"the user's file"
    deep = outputs.check(tmp_path / "a" / "b" / "m.npz")
    assert deep.parent.is_dir()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="cannot create the directory"):
        outputs.check(tmp_path / "file" / "m.npz")


CHECK = """
import sys
from radarcl.errors import ConfigError
from radarcl.io import files
try:
    files.check(sys.argv[1])
except ConfigError as exc:
    print(exc)
    sys.exit(3)
print("accepted")
"""


def test_an_unwritable_directory_is_refused(tmp_path):
    """A directory the user may not write is refused before any work. Root writes through mode
    bits (CI runs as root): there the check runs in a child that is root without the capability
    to override them (setpriv drops CAP_DAC_OVERRIDE from its bounding set), which is refused
    just as an ordinary user is in this process."""
    (tmp_path / "ro").mkdir(mode=0o555)
    (tmp_path / "rw").mkdir()
    if os.geteuid() != 0:
        with pytest.raises(ConfigError, match="is not a writable directory"):
            outputs.check(tmp_path / "ro" / "m.npz")
        assert outputs.check(tmp_path / "rw" / "m.npz") == tmp_path / "rw" / "m.npz"
        return
    setpriv = shutil.which("setpriv")
    assert setpriv, "running as root, this test needs util-linux's setpriv to take away root's write-anywhere"
    runs = {name: subprocess.run([setpriv, "--bounding-set=-dac_override,-dac_read_search", sys.executable, "-c",
                                  CHECK, str(tmp_path / name / "m.npz")], capture_output=True, text=True, timeout=120)
            for name in ("ro", "rw")}
    ro, rw = runs["ro"], runs["rw"]
    assert ro.returncode == 3 and "is not a writable directory" in ro.stdout, (ro.stdout, ro.stderr)
    assert rw.returncode == 0 and "accepted" in rw.stdout, (rw.stdout, rw.stderr)   # the child can write where allowed


def test_atomic_writes_all_or_nothing_and_cleans_stale_files(tmp_path):
    out = tmp_path / "m.bin"
    with outputs.atomic(out) as tmp:
        tmp.write_bytes(b"one")
    assert out.read_bytes() == b"one"
    with pytest.raises(RuntimeError):
        with outputs.atomic(out) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("writer failed")
    assert out.read_bytes() == b"one" and not list(tmp_path.glob(".*.tmp"))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = tmp_path / f".m.bin.{int(dead.stdout)}.tmp"           # left by a killed writer
    stale.write_bytes(b"junk")
    mine = tmp_path / f".m.bin.{os.getpid()}.tmp"
    outputs.check(out, force=True)
    assert not stale.exists()
    with outputs.atomic(out) as tmp:
        assert tmp == mine
        tmp.write_bytes(b"two")
    assert out.read_bytes() == b"two"


def test_sigterm_and_ctrl_c_leave_no_temporary_file(tmp_path):
    """A writer stopped by SIGTERM or Ctrl-C inside ``atomic`` under the CLI's handlers exits
    with 143 or 130 and removes its temporary file."""
    script = ("import os, signal, sys, time\n"
              "from radarcl import cli\nfrom radarcl.commands import info\nfrom radarcl.io import files as outputs\n"
              "def job(args):\n"
              "    with outputs.atomic(sys.argv[1]) as tmp:\n"
              "        tmp.write_bytes(b'partial')\n"
              "        os.kill(os.getpid(), getattr(signal, sys.argv[2]))\n"
              "        time.sleep(5)\n"
              "info.run = job\n"
              "sys.exit(cli.main(['info']))\n")
    for sig, status in (("SIGTERM", 143), ("SIGINT", 130)):
        out = tmp_path / f"{sig}.npz"
        run = subprocess.run([sys.executable, "-c", script, str(out), sig], capture_output=True, text=True, timeout=60,
                             preexec_fn=interactive_signals)
        assert run.returncode == status, run.stderr
        assert "Traceback" not in run.stderr and not out.exists() and not list(tmp_path.glob(".*.tmp"))
    assert "radarcl: interrupted" in run.stderr
