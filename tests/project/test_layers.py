"""The tree is the architecture: imports run one way, down the layers each package's docstring names.

Every ``import`` in ``companion/`` and ``sitl_plant/`` is read with ``ast`` (lazy imports inside
functions included) and held against the table below; a new import that runs back up a layer, or
an I/O module pulled into the mathematics, fails here with the file and line. Above them both,
``testbed/`` (what the tests and benchmarks share) and ``benchmarks/``: the product never imports
them, and they reach the product through its library layers, never through a command's module.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "companion"

# layer -> the companion layers it may import (itself always allowed).
ALLOWED: dict[str, set[str]] = {
    "core": set(),
    "sim": {"core", "errors"},
    "mission": {"core", "sim", "errors"},
    "mav": {"errors", "secretfile"},
    "profiles": {"core", "sim", "errors"},
    "vehicle": {"core", "sim", "profiles", "errors"},
    "live": {"core", "sim", "mission", "mav", "profiles", "vehicle", "errors"},
    "bus": {"live", "security", "errors", "secretfile"},
    "security": {"errors", "secretfile"},
    "logs": {"core", "live", "mission", "errors"},
    "ident": {"core", "sim", "live", "logs", "profiles", "errors"},
    "preflight": {"live", "profiles", "errors"},
    "view": {"bus", "errors"},
    "errors": set(),
    "secretfile": {"errors"},
    "progress": {"live"},
    "cli": {"__init__", "errors", "commands", "app"},
    "__main__": {"cli"},
    "__init__": set(),
    "app": {"core", "sim", "mission", "mav", "live", "bus", "security", "logs", "ident",
            "errors", "progress", "secretfile", "__init__", "preflight", "profiles", "view",
            "vehicle"},
    "commands": {"core", "sim", "mission", "mav", "live", "bus", "security", "logs", "ident",
                 "errors", "progress", "secretfile", "__init__", "preflight", "profiles", "view",
                 "vehicle", "app"},
}
SITL_PLANT_ALLOWED = {"core", "sim", "mission", "mav", "profiles", "errors"}   # mission: geo only
PURE = {"core", "profiles"}   # no I/O: the mathematics, and the facts of autopilots and steering
# The mathematics touches no file, socket, clock, process or thread.
IO_MODULES = {"os", "sys", "time", "socket", "threading", "subprocess", "pathlib", "io", "signal",
              "pymavlink", "zenoh", "tomllib", "json", "csv", "matplotlib", "tqdm", "random"}


def layer_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def imports(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in the file, relative ones resolved."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
                if node.module is None:   # from . import a, b: each name may be a module
                    out += [(node.lineno, f"{mod}.{alias.name}" if is_module(f"{mod}.{alias.name}")
                             else mod) for alias in node.names]
                    continue
                out.append((node.lineno, mod))
            else:
                out.append((node.lineno, node.module or ""))
    return out


def is_module(dotted: str) -> bool:
    path = ROOT.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def companion_layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "companion":
        return None
    if len(parts) == 1:
        return "__init__"
    return parts[1]


def module_files(root: Path):
    return sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)


def package_of(path: Path) -> str:
    """The package a file's relative imports start from (an ``__init__`` is its own package)."""
    return ".".join(path.relative_to(ROOT).with_suffix("").parts[:-1])


@pytest.mark.parametrize("path", module_files(PACKAGE), ids=lambda p: str(p.relative_to(ROOT)))
def test_companion_imports_run_down_the_layers(path):
    layer = layer_of(path)
    assert layer in ALLOWED, f"{path.relative_to(ROOT)}: layer {layer!r} is not in the table"
    bad = []
    for line, module in imports(path, package_of(path)):
        target = companion_layer(module)
        if target is not None and target != layer and target not in ALLOWED[layer]:
            bad.append(f"{path.relative_to(ROOT)}:{line}: {layer} imports {module}")
        if layer in PURE and module.split(".")[0] in IO_MODULES:
            bad.append(f"{path.relative_to(ROOT)}:{line}: pure {layer} imports {module}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", module_files(ROOT / "sitl_plant"), ids=lambda p: p.name)
def test_sitl_plant_imports_only_the_mathematics_and_the_plant(path):
    bad = [f"sitl_plant/{path.name}:{line}: imports {module}"
           for line, module in imports(path, "sitl_plant")
           if companion_layer(module) not in (None, *SITL_PLANT_ALLOWED)]
    assert not bad, "\n".join(bad)


def subpackage_inits() -> list[Path]:
    """Every package's ``__init__.py`` in ``companion/`` (nested ones too, the root's aside) and
    ``sitl_plant/``."""
    inits = [*PACKAGE.rglob("*/__init__.py"), *(ROOT / "sitl_plant").rglob("__init__.py")]
    return sorted(p for p in inits if "__pycache__" not in p.parts)


def docstring_problem(init: Path, text: str | None = None) -> str | None:
    """Why a package's docstring does not say what lives there and what it may import, or None.
    A layer of ``companion/`` says it in two lines (what lives here; ``May import: ...``) and is
    in the layer table; any other package has a summary line and a ``May import`` line."""
    doc = ast.get_docstring(ast.parse(init.read_text() if text is None else text)) or ""
    lines = [line for line in doc.splitlines() if line.strip()]
    where = init.relative_to(ROOT)
    if not lines:
        return f"{where}: no docstring (what lives here, and 'May import: ...')"
    if init.parent.parent == PACKAGE:
        if not (len(lines) == 2 and lines[1].startswith("May import")):
            return f"{where}: two lines, what lives here and 'May import: ...'"
        if init.parent.name not in ALLOWED:
            return f"{where}: {init.parent.name} missing from the layer table"
        return None
    if not any(line.startswith("May import") for line in lines[1:]):
        return f"{where}: no 'May import: ...' line after what lives here"
    return None


def test_every_subpackage_says_what_lives_there_and_what_it_may_import():
    inits = subpackage_inits()
    assert PACKAGE / "commands" / "__init__.py" in inits and ROOT / "sitl_plant" / "__init__.py" in inits
    problems = [problem for init in inits if (problem := docstring_problem(init))]
    assert not problems, "\n".join(problems)


def test_a_subpackage_without_a_docstring_is_named():
    layer, nested = PACKAGE / "x" / "__init__.py", PACKAGE / "live" / "x" / "__init__.py"
    assert docstring_problem(layer, "from .a import b\n") == (
        "companion/x/__init__.py: no docstring (what lives here, and 'May import: ...')")
    assert "missing from the layer table" in docstring_problem(layer, '"""X.\nMay import: core."""')
    assert docstring_problem(nested, '"""What lives here."""') == (
        "companion/live/x/__init__.py: no 'May import: ...' line after what lives here")
    assert docstring_problem(nested, '"""What lives here.\n\nMay import: core."""') is None


# Above the product: the test bed, the benchmarks and the tests. What they may not import.
ABOVE = {"testbed", "benchmarks"}
COMMAND_MODULES = ("companion.commands", "companion.cli", "companion.__main__")


def _top_modules(folder: str) -> set[str]:
    """The bare module names of ``folder``'s files (what ``import NAME`` would find there only
    with the folder on ``sys.path``)."""
    return {p.stem for p in (ROOT / folder).glob("*.py")} - {"__init__", "conftest"}


@pytest.mark.parametrize("path", module_files(PACKAGE) + module_files(ROOT / "sitl_plant"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_the_product_never_imports_the_test_bed_or_the_benchmarks(path):
    bad = [f"{path.relative_to(ROOT)}:{line}: imports {module}"
           for line, module in imports(path, package_of(path))
           if module.split(".")[0] in ABOVE]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", module_files(ROOT / "testbed") + module_files(ROOT / "benchmarks"),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_the_test_bed_and_benchmarks_are_packages_that_use_no_command_internals(path):
    """No ``sys.path`` edit, no module of ``tests/`` or a sibling script imported by its bare
    name (a benchmark imports another only as ``benchmarks.NAME``), no ``companion.commands``
    module (what a benchmark needs of a command lives in a library layer)."""
    bare = _top_modules("tests") | _top_modules("benchmarks") | _top_modules("testbed")
    bad = [f"{path.relative_to(ROOT)}:{line}: imports {module}"
           for line, module in imports(path, package_of(path))
           if module.startswith(COMMAND_MODULES) or module.split(".")[0] in bare]
    bad += [f"{path.relative_to(ROOT)}:{node.lineno}: reaches sys.path"
            for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.Attribute)
            and node.attr == "path" and isinstance(node.value, ast.Name) and node.value.id == "sys"]
    assert not bad, "\n".join(bad)


def test_documented_python_names_still_work():
    mission = importlib.import_module("companion.mission")
    bus = importlib.import_module("companion.bus.control_client")
    for name in ("load", "loads", "paper_ellipse", "Mission"):
        assert callable(getattr(mission, name))
    assert callable(bus.control_request)
    m = mission.paper_ellipse(0.04, 10.0)
    assert m.duration == 10.0
