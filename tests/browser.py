"""Pages opened in a real browser: Debian's headless Chromium (``make test`` installs it)."""

import shutil
import subprocess


def chromium():
    """Debian's chromium (``make`` installs it): a missing browser fails, it does not skip."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    assert path, "chromium is not installed: run make (it installs Debian's chromium) or apt-get install chromium"
    return path


BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1280,900"]                 # a laptop's window: the pages' tables must fit it


def open_in_browser(page, tmp_path):
    """(the DOM after load, the browser's console lines) of ``page`` in headless Chromium."""
    run = subprocess.run([chromium(), *BROWSER_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                          "--enable-logging=stderr", "--v=0", "--dump-dom", page.resolve().as_uri()],
                         capture_output=True, text=True, timeout=120)
    return run.stdout, [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
