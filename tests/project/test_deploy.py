"""The service files in deploy/: the systemd unit, its system user and the example config.

* the unit passes ``systemd-analyze verify`` with no complaint about it (skipped where systemd's
  tools are not installed), and the sysusers file parses and creates the unit's user;
* the unit's restart policy agrees with ``companion run``'s exit codes as its --help documents
  them: every documented code (done, user error, fault such as a pilot takeover or a vehicle
  restart) ends the service for good, while a crash (an unhandled exception, a fatal signal) is
  restarted, a bounded number of times;
* every key of deploy/rover.toml and every flag of ExecStart is a ``companion run`` flag, with a
  value of the flag's kind.
"""

from __future__ import annotations

import argparse
import configparser
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import pytest

from companion import cli
from companion.commands import run as run_command
from companion.errors import NO_RESTART, ExitCode

ROOT = Path(__file__).resolve().parents[2]
UNIT = ROOT / "deploy" / "pzc-rover.service"
SYSUSERS = ROOT / "deploy" / "pzc-rover.sysusers"
CONFIG = ROOT / "deploy" / "rover.toml"


def unit_service() -> configparser.SectionProxy:
    parser = configparser.ConfigParser(interpolation=None, strict=True)
    parser.optionxform = str    # systemd keys are case-sensitive
    parser.read(UNIT)
    return parser["Service"]


def run_parser() -> argparse.ArgumentParser:
    sub = next(a for a in cli.build_parser()._actions
               if isinstance(a, argparse._SubParsersAction))
    return sub.choices["run"]


def documented_exit_codes() -> dict[int, str]:
    """``companion run --help``'s "exit codes:" paragraph as {code: what it means}."""
    text = " ".join(run_command.EPILOG.split("exit codes:", 1)[1].split())
    found = re.findall(r"(?:^|;)\s*(\d+)\s+([^;]+)", text)
    return {int(code): meaning.strip() for code, meaning in found}


def restarts(service: configparser.SectionProxy, exit_code: int | None = None,
             sig: signal.Signals | None = None) -> bool:
    """Would systemd restart the service after this end? systemd.service(5): ``Restart=``'s
    table (clean = exit 0, SuccessExitStatus=, or SIGHUP / SIGINT / SIGTERM / SIGPIPE), then
    ``RestartPreventExitStatus=`` vetoes the listed codes and signals."""
    policy = service.get("Restart", "no")
    prevent = service.get("RestartPreventExitStatus", "").split()
    success = service.get("SuccessExitStatus", "").split()
    if exit_code is not None and str(exit_code) in prevent:
        return False
    if sig is not None and (sig.name in prevent or sig.name[3:] in prevent):
        return False
    clean = (exit_code == 0 or str(exit_code) in success if sig is None else
             sig in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM, signal.SIGPIPE)
             or sig.name in success)
    table = {
        "no": False, "always": True, "on-success": clean, "on-failure": not clean,
        "on-abnormal": sig is not None and not clean,
        "on-abort": sig is not None and not clean, "on-watchdog": False,
    }
    return table[policy]


def test_documented_exit_codes_end_the_service_and_crashes_restart_it():
    service = unit_service()
    codes = documented_exit_codes()
    assert {0, 2, 3, 4, 5, 6, 7} <= set(codes), codes
    assert "pilot" in codes[4] and "vehicle restarted" in codes[7], codes
    assert "autopilot's own failsafe" in codes[5] and "estimate" in codes[6], codes
    for code, meaning in codes.items():
        assert not restarts(service, exit_code=code), \
            f"exit {code} ({meaning[:60]}...) would be restarted by {UNIT.name}"
    # A crash of the companion itself: a traceback exits 1; signals from a bug or the OOM killer.
    for code in (1,):
        assert code not in codes
        assert restarts(service, exit_code=code), f"a crash (exit {code}) is not restarted"
    for sig in (signal.SIGKILL, signal.SIGSEGV, signal.SIGABRT):
        assert restarts(service, sig=sig), f"a crash ({sig.name}) is not restarted"
    # `systemctl stop` sends SIGTERM: the companion stops the rover and exits 0; not restarted.
    assert service["KillSignal"] == "SIGTERM" and not restarts(service, exit_code=0)
    # Crash restarts are bounded, with a pause between them.
    unit = configparser.ConfigParser(interpolation=None)
    unit.optionxform = str
    unit.read(UNIT)
    assert float(service["RestartSec"]) >= 1
    assert int(unit["Unit"]["StartLimitBurst"]) >= 1
    assert float(unit["Unit"]["StartLimitIntervalSec"]) > (
        int(unit["Unit"]["StartLimitBurst"]) * float(service["RestartSec"]))


def test_restart_policy_is_the_exit_code_enum():
    """The unit never restarts a run that ended on a user's mistake or a fault (restarting
    would repeat it, or drive a rover that a fault or a pilot stopped), and nothing else
    ``run`` means to return is in the list: the enum is the one statement of what they mean."""
    service = unit_service()
    prevent = {int(code) for code in service["RestartPreventExitStatus"].split()}
    assert prevent == {int(c) for c in NO_RESTART}
    assert {ExitCode.USER_ERROR, ExitCode.FAULT, ExitCode.PILOT_OVERRIDE,
            ExitCode.AUTOPILOT_FAILSAFE, ExitCode.ESTIMATE_UNHEALTHY,
            ExitCode.VEHICLE_RESTARTED} == set(NO_RESTART)
    # each named stop has a code of its own
    named = [ExitCode.FAULT, ExitCode.PILOT_OVERRIDE, ExitCode.AUTOPILOT_FAILSAFE,
             ExitCode.ESTIMATE_UNHEALTHY, ExitCode.VEHICLE_RESTARTED]
    assert len({int(c) for c in named}) == len(named)
    assert ExitCode.OK not in prevent and not restarts(service, exit_code=ExitCode.OK)
    # what run --help documents is what the enum says, code for code
    documented = documented_exit_codes()
    assert set(documented) == {ExitCode.OK, *NO_RESTART}
    # A crash is a Python traceback's exit 1 (run never returns CHECK_FAILED): restarted.
    assert restarts(service, exit_code=1)


def test_unit_runs_as_its_own_user_with_only_the_capability_realtime_needs():
    service = unit_service()
    assert service["User"] == "pzc-rover"
    assert service["AmbientCapabilities"].split() == ["CAP_SYS_NICE"]
    assert service["CapabilityBoundingSet"].split() == ["CAP_SYS_NICE"]
    assert "dialout" in service["SupplementaryGroups"].split()
    argv = shlex.split(service["ExecStart"])
    assert argv[argv.index("--log-dir") + 1] == "/var/log/" + service["LogsDirectory"]
    assert argv[argv.index("--config") + 1] == (
        "/etc/" + service["ConfigurationDirectory"] + "/rover.toml")


def test_exec_start_uses_only_run_flags():
    argv = shlex.split(unit_service()["ExecStart"])
    assert Path(argv[0]).name == "companion" and argv[1] == "run"
    known = set(run_parser()._option_string_actions)
    flags = [a for a in argv[2:] if a.startswith("-")]
    assert flags and not [f for f in flags if f not in known]


def test_example_config_keys_are_run_flags_with_values_of_their_kind():
    config = tomllib.loads(CONFIG.read_text())
    actions = {a.dest: a for a in run_parser()._actions}
    assert {"connect", "mission"} <= set(config)
    for key, value in config.items():
        action = actions.get(key)
        assert action is not None, f"{CONFIG.name}: {key} is not a companion run flag"
        if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
            assert isinstance(value, bool), (key, value)
        elif isinstance(action, argparse._AppendAction):
            assert isinstance(value, list) and all(isinstance(v, str) for v in value), key
        elif action.type is not None:
            assert not isinstance(value, bool)
            action.type(str(value))     # raises on a value the flag would refuse
        else:
            assert isinstance(value, str), (key, value)
        if action.choices:
            assert value in action.choices, (key, value)


def test_example_config_prints_as_effective_settings(tmp_path):
    """The example loads through ``companion run --config`` (its mission path swapped for a
    file that exists here)."""
    text = CONFIG.read_text().replace("/etc/pzc-rover/mission.toml",
                                      str(ROOT / "missions" / "circle.toml"))
    path = tmp_path / "rover.toml"
    path.write_text(text)
    proc = subprocess.run([sys.executable, "-m", "companion", "run", "--config", str(path),
                           "--print-config"], capture_output=True, text=True, timeout=60,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "921600" in proc.stdout and "/dev/serial0" in proc.stdout


def test_unit_passes_systemd_analyze_verify(tmp_path):
    tool = shutil.which("systemd-analyze")
    if tool is None:
        pytest.skip("systemd-analyze is not installed (Debian: apt-get install systemd)")
    # verify checks that ExecStart's program exists: point it at this checkout's companion.
    companion = Path(sys.executable).parent / "companion"
    assert companion.exists(), companion
    unit = tmp_path / UNIT.name
    unit.write_text(UNIT.read_text().replace("/opt/pzc-rover/bin/companion", str(companion)))
    proc = subprocess.run([tool, "verify", str(unit)], capture_output=True, text=True,
                          timeout=60)
    # verify exits 0 even for unknown keys or bad values: its complaints name the file.
    complaints = [line for line in (proc.stdout + proc.stderr).splitlines()
                  if unit.name in line]
    assert proc.returncode == 0 and not complaints, proc.stdout + proc.stderr


def test_unit_with_a_mistake_is_caught_by_systemd_analyze_verify(tmp_path):
    """The check above can fail: a misspelt key and a bad restart value are reported."""
    tool = shutil.which("systemd-analyze")
    if tool is None:
        pytest.skip("systemd-analyze is not installed (Debian: apt-get install systemd)")
    companion = Path(sys.executable).parent / "companion"
    unit = tmp_path / UNIT.name
    unit.write_text(UNIT.read_text().replace("/opt/pzc-rover/bin/companion", str(companion))
                    .replace("Restart=on-failure", "Restart=sometimes\nRestartSeconds=5"))
    proc = subprocess.run([tool, "verify", str(unit)], capture_output=True, text=True,
                          timeout=60)
    out = proc.stdout + proc.stderr
    assert "RestartSeconds" in out and "sometimes" in out, out


def test_sysusers_file_creates_the_units_user(tmp_path):
    tool = shutil.which("systemd-sysusers")
    if tool is None:
        pytest.skip("systemd-sysusers is not installed (Debian: apt-get install systemd)")
    (tmp_path / "etc" / "sysusers.d").mkdir(parents=True)
    conf = tmp_path / "etc" / "sysusers.d" / "pzc-rover.conf"
    shutil.copy(SYSUSERS, conf)
    proc = subprocess.run([tool, f"--root={tmp_path}", "--dry-run"], capture_output=True,
                          text=True, timeout=60)
    out = proc.stdout + proc.stderr
    user = unit_service()["User"]
    assert proc.returncode == 0 and conf.name not in out, out
    assert f"Creating user '{user}'" in out, out
    assert re.search(rf"^m\s+{user}\s+dialout\s*$", SYSUSERS.read_text(), re.M)


def _closed_to_others(*paths: Path) -> Path | None:
    """The first folder on the way to these paths that another user may not enter, or None."""
    for path in paths:
        for folder in reversed(path.parents):
            if not folder.stat().st_mode & 0o001:
                return folder
    return None


def _fly_as_nobody(caps: list[str], tmp_dir: Path) -> str:
    """``companion run --realtime`` as user nobody with these ambient capabilities, against
    sitl-plant for a second; its stderr."""
    from sitl_plant.testing import PlantProcess
    from testbed.missions import ellipse_mission
    mission = ellipse_mission(tmp_dir / "m.toml", 1.0)
    mission.chmod(0o644)
    setpriv = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
    if caps:
        names = ",".join("+" + c.lower().removeprefix("cap_") for c in caps)
        setpriv += [f"--inh-caps={names}", f"--ambient-caps={names}"]
    with PlantProcess("--loop-rate", "100") as plant:
        proc = subprocess.run(
            [*setpriv, sys.executable, "-m", "companion", "run", "--connect",
             f"udpin:127.0.0.1:{plant.port}", "--mission", str(mission), "--arm", "--realtime",
             "--no-log", "--no-zenoh"],
            capture_output=True, text=True, timeout=120, cwd=tmp_dir,
            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr
    return proc.stderr


def test_the_units_capability_is_what_realtime_needs():
    """As an unprivileged user, --realtime gets SCHED_FIFO with the unit's ambient
    capabilities and not without them."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv (util-linux) to run the companion as another user")
    shut = _closed_to_others(ROOT)
    if shut is not None:
        pytest.skip(f"user nobody cannot reach {shut} (no o+x): clone the checkout where others "
                    "may read it")
    caps = unit_service()["AmbientCapabilities"].split()
    tmp_dir = Path(tempfile.mkdtemp(prefix="pzc-deploy-"))
    try:
        tmp_dir.chmod(0o755)     # nobody reads the mission here
        granted = _fly_as_nobody(caps, tmp_dir)
        refused = _fly_as_nobody([], tmp_dir)
    finally:
        shutil.rmtree(tmp_dir)
    assert "control loop under SCHED_FIFO" in granted, granted
    assert "SCHED_FIFO not granted" in refused, refused
