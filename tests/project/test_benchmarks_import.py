"""Every benchmark and test-bed module imports: a benchmark is run by hand, rarely, so a name it
imports that went away (a module moved, a helper renamed) would otherwise be found only by the
next person who runs it."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(f"{folder}.{p.stem}" for folder in ("benchmarks", "testbed")
                 for p in (ROOT / folder).glob("*.py") if p.stem != "__init__")


@pytest.mark.parametrize("name", MODULES)
def test_the_module_imports(name):
    module = importlib.import_module(name)
    assert module.__doc__, f"{name} says nothing of what it is"
