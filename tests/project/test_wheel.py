"""The installable wheel: ``python -m build`` on a copy of this checkout makes an sdist and a
wheel (built from the sdist, so both are checked); the wheel, installed into a fresh venv
without the test extras, runs ``companion --version``, ``companion demo --json`` and
``sitl-plant --help`` from outside the source tree, and carries every data file the packages
have in git.

Needs the package registry (the build backend and the project's dependencies are installed
from it); skipped, with the reason, only when it cannot be reached. The venvs, the build and the
installs go through uv when ``make`` installed it beside this interpreter (the tests' venv):
uv's ``build`` is a PEP 517 frontend like ``python -m build`` (an sdist, then the wheel from
it); pip and ``build`` otherwise. With uv about 20 s of CPU, with pip about 60 (ensurepip in
each venv, then pip resolving and unpacking every dependency one at a time).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import companion

ROOT = Path(__file__).resolve().parents[2]
NETWORK_TROUBLE = ("Could not find a version", "No matching distribution", "ConnectionError",
                   "Temporary failure in name resolution", "Network is unreachable",
                   "Max retries exceeded", "NewConnectionError", "ReadTimeoutError",
                   "Failed to fetch", "error sending request", "dns error")
UV = Path(sys.executable).with_name("uv")      # make installs it (constraints.txt pins it)

pytestmark = pytest.mark.slow


def clean_env() -> dict[str, str]:
    """No PYTHONPATH or venv of this checkout leaking into the fresh venv's processes."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def make_venv(path: Path) -> Path:
    if UV.exists():     # (no pip in it: uv installs into it)
        subprocess.run([str(UV), "venv", "-q", "--python", sys.executable, str(path)],
                       check=True, timeout=120, env=clean_env())
    else:
        subprocess.run([sys.executable, "-m", "venv", str(path)], check=True, timeout=120)
    return path / "bin"


def pip_install(bin_dir: Path, *what: str) -> None:
    # No bytecode for every module of every dependency (numpy, numba, matplotlib, ...): most
    # of this test's CPU time with pip; what the checks below import compiles as it loads.
    # (uv writes none unless asked.)
    if UV.exists():
        argv = [str(UV), "pip", "install", "-q", "--python", str(bin_dir / "python"), *what]
    else:
        argv = [str(bin_dir / "python"), "-m", "pip", "install", "-q", "--no-compile", *what]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=600, env=clean_env())
    if proc.returncode != 0:
        out = proc.stdout + proc.stderr
        if any(s in out for s in NETWORK_TROUBLE):
            pytest.skip(f"the package registry is not reachable: pip install {' '.join(what)}: "
                        f"{out.strip().splitlines()[-1]}")
        pytest.fail(f"pip install {' '.join(what)} failed:\n{out}")


def source_copy(dest: Path) -> Path:
    """This checkout's files as they are now (committed or not), without venvs, build
    leftovers or logs: building in a copy leaves the checkout untouched."""
    ignore = shutil.ignore_patterns(".git", ".venv*", "build", "dist", "*.egg-info",
                                    "__pycache__", "logs", "out", ".pytest_cache",
                                    ".hypothesis")
    shutil.copytree(ROOT, dest, ignore=ignore)
    return dest


def package_data_in_git() -> set[str]:
    proc = subprocess.run(["git", "ls-files", "companion", "sitl_plant"], cwd=ROOT,
                          capture_output=True, text=True, check=True)
    return {f for f in proc.stdout.split() if not f.endswith(".py")}


def build_dists(src: Path, dist: Path, scratch: Path) -> subprocess.CompletedProcess:
    """An sdist of ``src``, then the wheel built from that sdist, into ``dist``."""
    if UV.exists():
        argv = [str(UV), "build", "-q", "--python", sys.executable, "--out-dir", str(dist),
                str(src)]
    else:
        build_bin = make_venv(scratch)
        pip_install(build_bin, "build")
        argv = [str(build_bin / "python"), "-m", "build", "--outdir", str(dist), str(src)]
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, env=clean_env())


def test_wheel_installs_and_runs_in_a_clean_venv(tmp_path):
    src = source_copy(tmp_path / "src")
    dist = tmp_path / "dist"
    proc = build_dists(src, dist, tmp_path / "build-venv")
    out = proc.stdout + proc.stderr
    if proc.returncode != 0 and any(s in out for s in NETWORK_TROUBLE):
        pytest.skip(f"the package registry is not reachable for the build backend: "
                    f"{out.strip().splitlines()[-1]}")
    assert proc.returncode == 0, out
    wheels = list(dist.glob("*.whl"))
    assert len(wheels) == 1 and list(dist.glob("*.tar.gz")), sorted(dist.iterdir())
    wheel = wheels[0]
    assert wheel.name == f"pzc_rover-{companion.__version__}-py3-none-any.whl", wheel.name

    # Every data file the packages keep in git is in the wheel (a new one outside
    # [tool.setuptools.package-data] would be missing from an installed rover).
    names = set(zipfile.ZipFile(wheel).namelist())
    data = package_data_in_git()
    assert data and not (data - names), sorted(data - names)
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/"))]

    bin_dir = make_venv(tmp_path / "venv")
    pip_install(bin_dir, str(wheel))
    run_dir = tmp_path / "elsewhere"     # not the source tree: only the installed package
    run_dir.mkdir()
    env = clean_env()

    def run(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run([str(bin_dir / argv[0]), *argv[1:]], capture_output=True,
                              text=True, timeout=timeout, cwd=run_dir, env=env)

    # Without the test extras, and the package imported is the installed one.
    proc = run("python", "-c", "import companion, importlib.util as u; "
               "print(companion.__file__); print(u.find_spec('pytest') is not None)")
    where, has_pytest = proc.stdout.split()
    assert proc.returncode == 0 and Path(where).is_relative_to(tmp_path / "venv"), proc
    assert has_pytest == "False"

    proc = run("companion", "--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"companion {companion.__version__}"

    proc = run("sitl-plant", "--help")
    assert proc.returncode == 0 and "--preset" in proc.stdout, proc.stderr

    # The demo: sitl-plant and the companion as two installed processes, the shipped tuned
    # gains (package data) picked for 40 Hz. $ZENOH_CONFIG (conftest) keeps Zenoh on loopback.
    # 30 s of the ellipse (steady RMS over its second half): the installed package flying,
    # not the default minute again (test_companion_demo.py flies that)
    proc = run("companion", "demo", "--json", "--duration", "30", timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert result["reason"] == "mission_done" and result["exit_code"] == 0
    assert result["gains_source"].startswith("shipped ")
    assert Path(result["gains_source"].split(" ", 1)[1]).is_relative_to(tmp_path / "venv")
    # (lockstep: no telemetry lost; a cycle answered later than its period, an overrun, is
    # the loaded machine's scheduling, not the installed package's: 2 of 2400 in a make test
    # with a second pytest beside it, 2026-12-04)
    assert result["steady_rms"] < 0.2 and result["missed_gaps"] == 0, result
