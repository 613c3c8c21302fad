"""The habits' own files agree with each other (docs/development.md).

* constraints.txt pins every dependency of pyproject.toml (its dependencies and every extra)
  at a version that the range admits, and each pin once: a dependency added, or a range
  moved, without ``make lock`` fails here, naming the package;
* the environment the tests run in holds the pinned versions (a venv older than the lock
  fails, naming the package and both versions: ``make`` rebuilds it);
* the classes ruff is told are immutable call defaults (B008's extend-immutable-calls) are
  frozen dataclasses, so a shared default instance cannot be changed through anyone's copy.
"""

from __future__ import annotations

import dataclasses
import importlib
import tomllib
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
LOCK = ROOT / "constraints.txt"


def read_lock(text: str) -> tuple[dict[str, Version], list[str]]:
    """name -> pinned version, and the problems (a line that is not NAME==VERSION, a repeat)."""
    pins: dict[str, Version] = {}
    problems = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        if not sep or not name.strip() or not version.strip():
            problems.append(f"constraints.txt:{number}: not NAME==VERSION: {line!r}")
            continue
        key = canonicalize_name(name.strip())
        if key in pins:
            problems.append(f"constraints.txt:{number}: {name.strip()} pinned twice")
        pins[key] = Version(version.strip())
    return pins, problems


def requirements(project: dict) -> list[Requirement]:
    """Every requirement of the project: its dependencies and those of every extra."""
    reqs = [Requirement(r) for r in project.get("dependencies", [])]
    for extra in project.get("optional-dependencies", {}).values():
        reqs += [Requirement(r) for r in extra]
    # an extra naming the project's own extras (test = [..., "pzc-rover[mcap,view]"]) adds
    # their requirements, already listed; the project itself is never pinned
    me = canonicalize_name(project.get("name", ""))
    return [r for r in reqs if canonicalize_name(r.name) != me]


def disagreements(reqs: list[Requirement], pins: dict[str, Version]) -> list[str]:
    out = []
    for req in reqs:
        pinned = pins.get(canonicalize_name(req.name))
        if pinned is None:
            out.append(f"{req.name}: in pyproject.toml ({req}) but not in constraints.txt")
        elif not req.specifier.contains(pinned, prereleases=True):
            out.append(f"{req.name}: constraints.txt pins {pinned}, outside pyproject.toml's "
                       f"'{req.specifier}'")
    return out


def test_the_lock_pins_every_dependency_inside_its_range():
    pins, problems = read_lock(LOCK.read_text(encoding="utf-8"))
    problems += disagreements(requirements(PYPROJECT["project"]), pins)
    assert not problems, "run `make lock` (docs/development.md):\n" + "\n".join(problems)


def test_the_checker_catches_each_kind_of_disagreement():
    pins, problems = read_lock("# a comment\nnumpy==1.25.0\npytest==8.1\npytest==8.2\nbroken\n")
    assert problems == ["constraints.txt:4: pytest pinned twice",
                        "constraints.txt:5: not NAME==VERSION: 'broken'"]
    project = {"name": "pzc-rover", "dependencies": ["numpy>=1.26"],
               "optional-dependencies": {"x": ["Zenoh_Thing>=1"], "y": ["pzc-rover[x]"]}}
    assert disagreements(requirements(project), pins) == [
        "numpy: constraints.txt pins 1.25.0, outside pyproject.toml's '>=1.26'",
        "Zenoh_Thing: in pyproject.toml (Zenoh_Thing>=1) but not in constraints.txt"]


def test_the_environment_holds_the_locked_versions():
    pins, _ = read_lock(LOCK.read_text(encoding="utf-8"))
    stale = []
    for name, pinned in sorted(pins.items()):
        try:
            installed = Version(metadata.version(name))
        except metadata.PackageNotFoundError:
            stale.append(f"{name}: pinned {pinned}, not installed")
            continue
        if installed != pinned:
            stale.append(f"{name}: pinned {pinned}, installed {installed}")
    assert not stale, "this venv is not the locked one (`make` rebuilds it):\n" + "\n".join(stale)


def test_the_call_defaults_ruff_accepts_are_frozen_dataclasses():
    names = PYPROJECT["tool"]["ruff"]["lint"]["flake8-bugbear"]["extend-immutable-calls"]
    assert names
    for dotted in names:
        module, _, name = dotted.rpartition(".")
        cls = getattr(importlib.import_module(module), name)
        assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen, dotted
