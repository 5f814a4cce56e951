"""The child program that checks a device before radarcl uses it (``devices.build_problem``):
``python -m radarcl.cl.probe P D [MODULE:FUNCTION ...]`` builds a small kernel on device P:D,
then runs each named check (``devices.DEVICE_CHECKS``, registered by the application:
``radarcl.self_test``, every kernel against the float64 oracle) and prints one line,
``radarcl-probe: {"problem": null or why, "notes": [what it cannot run]}``.
A compiler that aborts kills this process, not radarcl; the parent reads the signal."""

import importlib
import json
import sys

from radarcl.cl import devices, runtime


def main(argv=None):
    """Check device P:D (argv[0], argv[1]) with the checks named in argv[2:]; returns 0."""
    argv = sys.argv[1:] if argv is None else argv
    p, d, checks = int(argv[0]), int(argv[1]), argv[2:]
    device = next(dev for pi, di, _, dev in devices._all_devices() if (pi, di) == (p, d))
    problem, notes = devices.probe(device), []
    for name in checks if problem is None else ():
        module, _, function = name.partition(":")
        try:
            said = getattr(importlib.import_module(module), function)(runtime.Runtime(device))
        except Exception as exc:                     # noqa: BLE001 - the verdict is the point
            said = f"{type(exc).__name__} in {name}: {str(exc).splitlines()[0] if str(exc) else ''}"
        if isinstance(said, dict):
            problem, notes = said.get("problem"), notes + list(said.get("notes", []))
        else:
            problem = said
        if problem is not None:
            break
    print(devices.PROBE_MARK + json.dumps(dict(problem=problem, notes=notes)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
