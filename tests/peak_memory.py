"""Peak memory of a piece of work, measured where a limit can fail: in a fresh child process,
from a peak reset after its imports.

``ru_maxrss`` cannot serve: it is the peak of the whole process, and Linux carries it across
``exec`` from the forked copy of the parent, so even a fresh child starts at the test process's
size, which after the heavy tests of a full run hides any growth. The child reads its own
memory map's high-water mark instead (``VmHWM`` in /proc/self/status, per address space: it
starts anew at ``exec``), reset to the current size after the imports by writing 5 to
/proc/self/clear_refs (Linux >= 4.0), so the growth is the work's alone.
"""

import json
import os
import subprocess
import sys

_TEMPLATE = """
import json
{imports}


def _status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key + ":"))


with open("/proc/self/clear_refs", "w") as f:
    f.write("5")                                  # VmHWM := VmRSS
_base = _status("VmHWM")
result = None
{body}
print("PEAK_MEMORY " + json.dumps(dict(growth_kib=_status("VmHWM") - _base, result=result)))
"""


def peak_growth(imports, body, env=None, timeout=300):
    """Run ``imports`` then ``body`` (Python source; ``body`` may set ``result`` to something
    JSON-able) in a fresh interpreter; returns (peak resident memory growth of ``body`` [MiB],
    result). ``env``: variables added to this process's environment."""
    source = _TEMPLATE.format(imports=imports, body=body)
    run = subprocess.run([sys.executable, "-c", source], capture_output=True, text=True, timeout=timeout,
                         env=dict(os.environ, **(env or {})))
    lines = [line for line in run.stdout.splitlines() if line.startswith("PEAK_MEMORY ")]
    assert run.returncode == 0 and lines, f"the child failed (exit {run.returncode}):\n{run.stdout}\n{run.stderr}"
    out = json.loads(lines[-1][len("PEAK_MEMORY "):])
    return out["growth_kib"] / 1024, out["result"]
