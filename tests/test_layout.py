"""House rules: one name, three files; the installed package carries kernels/ and viewer/ (GLSL too);
library below applications (``LAYERS``, docs/design/layers.md)."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_kernel_has_its_wrapper_and_test():
    stems = [p.stem for p in (ROOT / "kernels").glob("*.cl")]
    assert stems, "no kernels found"
    for stem in stems:
        assert (ROOT / "radarcl" / "stages" / f"{stem}.py").is_file(), f"kernels/{stem}.cl has no wrapper"
        assert (ROOT / "tests" / f"test_{stem}.py").is_file(), f"kernels/{stem}.cl has no test"


def test_installed_copy_runs_a_kernel(tmp_path):
    """`pip install .` (not editable) into a fresh target, then run a kernel from there,
    from a directory where the source tree cannot be imported."""
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                    "--target", str(target), str(ROOT)], check=True, cwd=tmp_path)
    assert (target / "radarcl" / "kernels" / "range_fft.cl").is_file()
    profiles = {p.name for p in (target / "radarcl" / "profiles").glob("*.toml")}
    assert profiles == {p.name for p in (ROOT / "radarcl" / "profiles").glob("*.toml")} and "paper.toml" in profiles
    shipped = {p.name for p in (target / "radarcl" / "viewer" / "shaders").glob("*.glsl")}
    assert shipped == {p.name for p in (ROOT / "viewer" / "shaders").glob("*.glsl")} and "volume.glsl" in shipped
    script = ("import numpy as np, radarcl, radarcl.cl as c\n"
              "from radarcl.stages.range_fft import RangeFFT\n"
              "assert str(c.kernels_dir()).startswith(%r), c.kernels_dir()\n"
              "p = RangeFFT(c.Runtime(), (2, 1), 8, 16, dtype=np.float32)(np.ones((2, 1, 8), np.float32)).profiles\n"
              "import radarcl.viewer.renderer as r\n"
              "from radarcl.config import sensors\n"
              "assert str(sensors.PROFILE_DIR).startswith(%r) and sensors.load('navtech-cts350x').n_bins() == 3768\n"
              "assert r.__file__.startswith(%r) and 'FRAGMENT_SHADER' in r.shader_source('volume')\n"
              "print(radarcl.__file__, float(p[0, 0, 0]))\n") % (str(target), str(target), str(target))
    env = {**os.environ, "PYTHONPATH": str(target)}
    out = subprocess.run([sys.executable, "-c", script], check=True, cwd=tmp_path, env=env,
                         capture_output=True, text=True).stdout
    assert out.startswith(str(target)) and out.split()[-1] == "1.0"


# -- layers: library below applications ------------------------------------------------------------------
# The rule, stated once (docs/design/layers.md says it for people): the package is a few named
# layers, top to bottom; inside a layer its rooms (top-level modules and folders) stand in tiers,
# top to bottom. A module may import a module of a lower tier (of its layer or of any layer below),
# or a sibling in its own room (no circle); never a room of its own tier or above. Imports inside
# functions count: one that only dodges a circle is a circle.
LAYERS = (
    ("applications", (("__main__",), ("cli",), ("bench",), ("commands",), ("jobs",), ("report",))),
    ("evaluation", (("evaluation",),)),
    ("engine", (("livemap", "self_test"), ("pipeline",), ("stages", "scene", "viewer"))),
    ("configuration and the map", (("config", "maps"),)),
    ("models and inputs", (("io", "models"),)),
    ("core numerics and device", (("oracle",), ("geometry", "grid", "sensor_model"), ("node_pairs",),
                                  ("physics", "cfar_theory", "cl", "logodds", "gridspec", "snr_evidence"),
                                  ("errors", "__init__"))),
)
TIERS = tuple(rooms for _, tiers in LAYERS for rooms in tiers)


def layer_of(module):
    """(tier index, room) of a dotted module name of the package (radarcl.x.y -> room x)."""
    parts = module.split(".")
    room = parts[1] if len(parts) > 1 else "__init__"
    for depth, rooms in enumerate(TIERS):
        if room in rooms:
            return depth, room
    raise AssertionError(f"{module}: room {room!r} is in no layer of LAYERS")


def layer_name(room):
    """The named layer holding ``room``."""
    return next(name for name, tiers in LAYERS if any(room in rooms for rooms in tiers))


def _is_module(name):
    """True when the dotted ``name`` is a module or package of radarcl (viewer/ ships as radarcl.viewer)."""
    parts = name.split(".")
    if parts[0] != "radarcl" or len(parts) < 2:
        return False
    base = ROOT / "viewer" if parts[1] == "viewer" else ROOT / "radarcl" / parts[1]
    path = base.joinpath(*parts[2:])
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def package_imports():
    """[(importer, imported, line)] of every internal import of radarcl and viewer (shipped as
    radarcl.viewer), at module level and inside functions; relative imports resolved."""
    import ast

    out = []
    for base, package in ((ROOT / "radarcl", "radarcl"), (ROOT / "viewer", "radarcl.viewer")):
        for path in sorted(base.rglob("*.py")):
            rel = path.relative_to(base).with_suffix("").parts
            name = ".".join((package,) + tuple(p for p in rel if p != "__init__"))
            pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    targets = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    mod = node.module or ""
                    if node.level:
                        mod = ".".join(pkg.split(".")[:len(pkg.split(".")) - node.level + 1] + ([mod] if mod else []))
                    # `from radarcl.x import y`, y a module: y is what is imported
                    targets = [f"{mod}.{a.name}" if _is_module(f"{mod}.{a.name}") else mod for a in node.names]
                else:
                    continue
                out += [(name, t, node.lineno) for t in targets if t == "radarcl" or t.startswith("radarcl.")]
    return out


def layer_violations(imports):
    """Lines naming each import that runs upward or sideways across rooms, and each circle."""
    bad = []
    graph = {}
    for importer, imported, line in imports:
        (a, room_a), (b, room_b) = layer_of(importer), layer_of(imported)
        if room_a == room_b:
            graph.setdefault(importer, set()).add(imported)
        elif b <= a:
            bad.append(f"{importer}:{line} imports {imported} ({room_b!r}, tier {b} in {layer_name(room_b)!r}, is "
                       f"not below {room_a!r}, tier {a} in {layer_name(room_a)!r})")
    # circles inside a room (a folder's modules importing each other)
    state = {}

    def visit(node, path):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                bad.append("circle: " + " -> ".join(path[path.index(nxt):] + [nxt]) if nxt in path else nxt)
            elif nxt not in state:
                visit(nxt, path + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    return bad


def test_imports_run_downward():
    assert layer_violations(package_imports()) == []


def test_the_layer_check_catches_an_upward_import():
    """A planted import of the CLI from the grid, one of a job from a model, one sideways between
    two rooms of a tier, and a planted circle, are all reported."""
    planted = package_imports() + [("radarcl.grid", "radarcl.cli", 1), ("radarcl.maps.npz", "radarcl.maps.store", 1),
                                   ("radarcl.maps.store", "radarcl.maps.npz", 1),
                                   ("radarcl.models.eq12", "radarcl.jobs.fuse", 2), ("radarcl.io.inputs", "radarcl.models", 3)]
    found = layer_violations(planted)
    assert any(v.startswith("radarcl.grid:1 imports radarcl.cli") and "'applications'" in v for v in found), found
    assert any(v.startswith("radarcl.models.eq12:2 imports radarcl.jobs.fuse") for v in found), found
    assert any(v.startswith("radarcl.io.inputs:3 imports radarcl.models") for v in found), found
    assert any(v.startswith("circle:") and "radarcl.maps.store" in v for v in found), found
    assert layer_violations(package_imports()) == []


def test_the_layers_page_states_the_layer_table():
    """docs/design/layers.md lists every named layer with its tiers of rooms, in this order."""
    text = (ROOT / "docs" / "design" / "layers.md").read_text()
    table = text.split("\n## The layers\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in table.splitlines() if line.startswith("| ") and not line.startswith("| layer")]
    listed = [(r.split("|")[1].strip(), r.split("|")[2].strip()) for r in rows]
    want = [(name, " > ".join(", ".join(f"`{room}`" for room in rooms if room not in ("__main__", "__init__"))
                              for rooms in tiers if [r for r in rooms if r not in ("__main__", "__init__")]))
            for name, tiers in LAYERS]
    assert listed == want, (listed, want)


def resolves(dotted):
    """True when ``dotted`` (radarcl.module[.attribute...]) names something that exists."""
    import importlib

    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def test_every_name_the_code_and_the_docs_cite_exists():
    """Kernel headers say which oracle they equal, docstrings, the README and the docs pages
    point to modules: every ``radarcl.x.y`` they name must import (a renamed module leaves no
    stale pointer)."""
    import re

    pattern = re.compile(r"\bradarcl(?:\.[A-Za-z_]\w*)+")
    sources = [*(ROOT / "kernels").glob("*.cl"), *(ROOT / "radarcl").rglob("*.py"), *(ROOT / "viewer").rglob("*.py"),
               ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]
    stale = sorted({f"{path.relative_to(ROOT)}: {name}" for path in sources
                    for name in pattern.findall(path.read_text()) if not resolves(name.rstrip("."))})
    assert stale == []


def test_every_file_the_code_and_the_docs_cite_exists():
    import re

    pattern = re.compile(r"\b(?:radarcl|viewer|kernels|tests|docs)/[\w/.-]*\w\.(?:py|cl|h|toml|glsl|png|md)\b")
    sources = [*(ROOT / "kernels").glob("*.cl"), *(ROOT / "radarcl").rglob("*.py"), *(ROOT / "viewer").rglob("*.py"),
               *(ROOT / "tests").glob("*.py"), ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), ROOT / "Makefile",
               ROOT / "pyproject.toml"]
    missing = sorted({f"{path.relative_to(ROOT)}: {name}" for path in sources for name in pattern.findall(path.read_text())
                      if "*" not in name and not (ROOT / name).exists()})
    assert missing == []


def test_the_readme_lists_every_command_and_every_built_in_profile():
    """The README's Commands section lists every subcommand, one line each, and its table of
    profiles (under "Map your own recording") every built-in sensor profile."""
    from radarcl.cli import COMMANDS
    from radarcl.config import sensors

    text = (ROOT / "README.md").read_text()
    block = text.split("\n## Commands\n", 1)[1].split("```sh\n", 1)[1].split("```", 1)[0]
    listed = {line.split()[1] for line in block.splitlines() if line.startswith("radarcl ")}
    assert listed == set(COMMANDS), set(COMMANDS) ^ listed
    assert text.index("\n## Commands\n") < text.index("\n## Map your own recording\n")
    table = text.split("\n## Map your own recording\n", 1)[1].split("\n\n| profile |", 1)[1].split("\n\n", 1)[0]
    rows = {line.split("`")[1] for line in table.splitlines() if line.startswith("| `")}
    assert rows == set(sensors.builtin_names()), set(sensors.builtin_names()) ^ rows
