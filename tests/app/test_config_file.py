"""``--config FILE`` / ``--print-config`` (companion.app.config_file): every flag of ``run``
is a key, values pass the flags' own checks, flags win over the file, paths are relative to the
file, the printed settings read back, and ``companion run --config rover.toml`` flies."""

from __future__ import annotations

import argparse
import json
import os
import tomllib
from functools import partial
from pathlib import Path

import pytest

from companion import cli
from companion.app.config_file import keyed_actions
from sitl_plant.testing import PlantProcess
from testbed.missions import ellipse_mission
from testbed.process import ROOT, companion_cli

MISSION = str(ROOT / "missions" / "circle.toml")


def subparser(name: str) -> argparse.ArgumentParser:
    parser = cli.build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]


def main(capsys, *argv: str) -> tuple[int, str, str]:
    """``companion ARGV`` in this process: (exit code, stdout, stderr)."""
    try:
        code = cli.main(list(argv))
    except SystemExit as exc:       # argparse's own usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def printed(capsys, *argv: str) -> dict:
    code, out, err = main(capsys, *argv, "--print-config")
    assert code == 0, err
    return tomllib.loads(out)


def test_every_run_flag_is_a_key_and_printed(capsys):
    """Read off the parser: a flag added to run later is covered without touching this test."""
    code, out, err = main(capsys, "run", "--mission", MISSION, "--print-config")
    assert code == 0, err
    flags = [a for a in subparser("run")._actions if a.option_strings
             and a.dest not in ("help", "config", "print_config")]
    assert len(flags) > 30
    for action in flags:
        assert (f"\n{action.dest} = " in out or f"\n# {action.dest}: unset" in out), action.dest
    assert set(keyed_actions(subparser("run"))) == {a.dest for a in flags}


def bad_texts() -> list[str]:
    return ["-1", "0", "nan", "inf", "abc", "1.5", "7", "peer", ""]


@pytest.mark.parametrize("command", ["run", "demo", "identify"])
def test_file_values_pass_the_flags_own_checks(capsys, tmp_path, command):
    """For every flag that takes a value (type= or choices=), each of a handful of texts is
    refused by the file with the command line's words, or accepted by both alike."""
    sub = subparser(command)
    base = {"run": ["--mission", MISSION], "demo": [], "identify": ["--out", "x.toml"]}[command]
    checked = 0
    for dest, action in keyed_actions(sub).items():
        if not action.option_strings or (action.type is None and action.choices is None):
            continue
        if isinstance(action, argparse._AppendAction) or action.nargs not in (None, "?"):
            continue
        flag = action.option_strings[-1]
        for text in bad_texts():
            cli_code, cli_out, cli_err = main(capsys, command, *base, f"{flag}={text}",
                                              "--print-config")
            conf = tmp_path / "c.toml"
            conf.write_text(f"{dest} = {tomllib_string(text)}\n")
            code, out, err = main(capsys, command, *base, "--config", str(conf), "--print-config")
            assert code == cli_code, (flag, text, cli_err, err)
            if code == 0:
                assert out == cli_out, (flag, text)
                continue
            why = cli_err.strip().splitlines()[-1].split(f"argument {flag}: ", 1)[1]
            assert err.strip() == f"companion {command}: error: {conf}: {dest}: {why}", err
            checked += 1
    assert checked >= 10


def tomllib_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def test_flags_win_and_the_printed_settings_read_back(capsys, tmp_path):
    conf = tmp_path / "rover.toml"
    conf.write_text('mission = "circle.toml"\nconnect = "/dev/ttyAMA0"\nbaud = 921600\n'
                    'max-speed = 2\nmax_yaw_rate = 1.5\narm = true\nno_log = true\n'
                    'zenoh_connect = ["tcp/10.0.0.2:7447", "tcp/10.0.0.3:7447"]\n'
                    'zenoh_scouting = false\nstale_timeout = 0.25\n')
    s = printed(capsys, "run", "--config", str(conf), "--max-speed", "1.2",
                "--zenoh-connect", "tcp/10.0.0.9:7447", "--sysid", "3")
    assert s["max_speed"] == 1.2                                  # flag over file
    assert s["max_yaw_rate"] == 1.5 and s["baud"] == 921600 and s["arm"] is True
    assert s["connect"] == "/dev/ttyAMA0" and s["stale_timeout"] == 0.25
    assert s["log"] is False and s["zenoh_scouting"] is False and s["sysid"] == 3
    assert s["zenoh_connect"] == ["tcp/10.0.0.9:7447"]            # the flag's list replaces
    assert s["heartbeat_timeout"] == 10.0                         # defaults fill the rest
    assert s["mission"] == str(tmp_path / "circle.toml")          # beside the file
    assert "rate" not in s                                        # unset: a comment
    # Round trip: the printed settings, as a config file, print the same settings.
    code, first, _ = main(capsys, "run", "--config", str(conf), "--max-speed", "1.2",
                          "--zenoh-connect", "tcp/10.0.0.9:7447", "--sysid", "3",
                          "--print-config")
    again = tmp_path / "elsewhere" / "again.toml"
    again.parent.mkdir()
    again.write_text(first)
    code, second, err = main(capsys, "run", "--config", str(again), "--print-config")
    assert code == 0 and second == first, err


def test_paths_are_relative_to_the_config_file(capsys, tmp_path, monkeypatch):
    folder = tmp_path / "rover"
    folder.mkdir()
    conf = folder / "rover.toml"
    conf.write_text('mission = "missions/m.toml"\nlog_dir = "logs"\ngains = "../g.toml"\n'
                    'signing_key = "~/keys/rover.key"\nzenoh_tls = "pki/rover1"\n'
                    'vehicle_id = "logs"\n')
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(ROOT)
    s = printed(capsys, "run", "--config", "../" + os.path.relpath(conf, ROOT.parent))
    assert s["mission"] == str(folder / "missions" / "m.toml")
    assert s["log_dir"] == str(folder / "logs")
    assert os.path.normpath(s["gains"]) == str(tmp_path / "g.toml")
    assert s["signing_key"] == str(tmp_path / "home" / "keys" / "rover.key")
    assert s["zenoh_tls"] == str(folder / "pki" / "rover1")
    assert s["vehicle_id"] == "logs"                               # not a path: as written
    # A path flag on the command line is the shell's: relative to the working directory.
    s = printed(capsys, "run", "--config", str(conf), "--mission", "missions/circle.toml")
    assert s["mission"] == MISSION


def test_required_flag_may_come_from_the_file_and_not_from_nowhere(capsys, tmp_path):
    conf = tmp_path / "c.toml"
    conf.write_text("max_speed = 1.0\n")
    code, _, err = main(capsys, "run", "--config", str(conf), "--print-config")
    assert code == 2 and "required: --mission" in err
    conf.write_text(f'mission = "{MISSION}"\n')
    assert printed(capsys, "run", "--config", str(conf))["mission"] == MISSION


companion = partial(companion_cli, timeout=30.0)


@pytest.mark.parametrize("text, needle", [
    ("max_speed = -1\n", "c.toml: max_speed: must be a finite number > 0, not -1"),
    ("max_sped = 1\n", "c.toml: unknown key 'max_sped' (did you mean max_speed?)"),
    ("stale-timeout = nan\n", "c.toml: stale-timeout: must be a finite number > 0, not nan"),
    ("arm = 1\n", "c.toml: arm: must be true or false, not 1"),
    ('zenoh_mode = "router"\n', "c.toml: zenoh_mode: invalid choice: 'router'"),
    ("sysid = 1.5\n", "c.toml: sysid: invalid int value: '1.5'"),
    ("baud = 0\n", "c.toml: baud: must be > 0, not 0"),
    ("max_speed = [1]\n", "c.toml: max_speed: must be a number or a string, not [1]"),
    ("zenoh = {on = true}\n", "c.toml: zenoh: must be true or false, not a table"),
    ("log = false\nno-log = true\n", "c.toml: no-log: the same flag as log, give one"),
    ('config = "other.toml"\n', "c.toml: unknown key 'config' (not allowed in a config file)"),
    ("max_speed = \n", "c.toml: not valid TOML: "),
])
def test_bad_config_is_one_line_naming_the_key(tmp_path, text, needle):
    (tmp_path / "c.toml").write_text(text)
    p = companion("run", "--config", "c.toml", "--mission", MISSION, cwd=tmp_path)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("companion run: error: "), p.stderr
    assert needle in lines[0], lines[0]


def test_missing_or_unreadable_config_is_one_line(tmp_path):
    for path, needle in ((tmp_path / "none.toml", "none.toml: no such file"),
                         (tmp_path, "Is a directory")):
        p = companion("run", "--config", str(path), "--mission", MISSION)
        assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert needle in p.stderr, p.stderr


def test_print_config_connects_to_nothing(tmp_path):
    """--print-config exits 0 at once, even pointed at a vehicle that is not there."""
    p = companion("run", "--connect", "/dev/ttyNOPE", "--mission", MISSION, "--print-config")
    assert p.returncode == 0 and p.stderr == "", p.stderr
    assert 'connect = "/dev/ttyNOPE"' in p.stdout


def test_demo_and_identify_read_configs_the_same_way(capsys, tmp_path):
    conf = tmp_path / "d.toml"
    conf.write_text('preset = "stock"\nlockstep = true\nout = "plots"\nno_plot = true\n')
    s = printed(capsys, "demo", "--config", str(conf))
    assert s["preset"] == "stock" and s["lockstep"] is True and s["plot"] is False
    assert s["out"] == str(tmp_path / "plots")
    conf.write_text('out = "vehicle.toml"\nconnect = "/dev/ttyACM0,921600"\nspace = 5\n')
    s = printed(capsys, "identify", "--config", str(conf))
    assert s["out"] == str(tmp_path / "vehicle.toml") and s["space"] == 5.0
    assert s["connect"] == "/dev/ttyACM0,921600"


def test_run_flies_from_a_config_file(tmp_path):
    """The service's short command line: everything but --config in rover.toml, paths in it
    relative to its folder (run from elsewhere)."""
    folder = tmp_path / "rover"
    folder.mkdir()
    ellipse_mission(folder / "ellipse.toml", 12.0)
    with PlantProcess("--lockstep", "--d-cen", "0.3") as plant:
        (folder / "rover.toml").write_text(
            f'connect = "udpin:127.0.0.1:{plant.port}"\nmission = "ellipse.toml"\n'
            'arm = true\njson = true\nquiet = true\nlog_dir = "flightlogs"\nw_c = 20\n'
            'd_cen = 0.3\n')
        proc = companion("run", "--config", "rover/rover.toml", timeout=60.0, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["reason"] == "mission_done" and r["duration_s"] == pytest.approx(12.0)
    assert r["steady_rms"] is not None and r["steady_rms"] <= 0.3
    assert r["tlog"].startswith(str(folder / "flightlogs")) and Path(r["csv"]).is_file()
