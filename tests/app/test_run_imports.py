"""What ``companion run`` loads on a board: a real run against ``sitl-plant`` (flight logs and
Zenoh on) records the modules it imported, start to exit. Nothing heavy is on that path (no
plotting, no progress bar without --progress, no scipy / pandas / cryptography without
--zenoh-tls), pymavlink loads only the dialect the link uses, not its default "all", and no
other command's module is imported.
Import time and memory themselves are figures: benchmarks/budget.py prints them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from sitl_plant.testing import PlantProcess
from testbed.missions import ellipse_mission

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("matplotlib", "scipy", "pandas", "PIL", "tqdm", "cryptography", "IPython")

# companion's own entry point, with the module list written at exit (after sys.exit(main())).
WRAPPER = """
import atexit, json, runpy, sys
out = sys.argv.pop(1)
atexit.register(lambda: open(out, "w").write(json.dumps(sorted(sys.modules))))
sys.argv[0] = "companion"
runpy.run_module("companion", run_name="__main__", alter_sys=True)
"""


def test_run_imports_nothing_heavy(tmp_path):
    mission = ellipse_mission(tmp_path / "m.toml", 2.0)
    modules_file = tmp_path / "modules.json"
    # As on a board: pymavlink, imported by this test process, exports MAVLINK_DIALECT=all.
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK_DIALECT"}
    with PlantProcess("--loop-rate", "100") as plant:
        proc = subprocess.run(
            [sys.executable, "-c", WRAPPER, str(modules_file), "run", "--connect",
             f"udpin:127.0.0.1:{plant.port}", "--mission", str(mission), "--arm", "--rate",
             "40", "--log-dir", str(tmp_path / "logs"), "--json", "-q"],
            capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["reason"] == "mission_done" and result["setpoints_sent"] > 0
    assert Path(result["tlog"]).exists()
    modules = set(json.loads(modules_file.read_text()))
    # The path did run: the live loop, the flight log, Zenoh, pymavlink's ardupilotmega.
    assert {"companion.live.session", "companion.live.flightlog", "companion.bus", "zenoh",
            "pymavlink.dialects.v20.ardupilotmega"} <= modules
    heavy = sorted(m for m in modules if m.split(".")[0] in HEAVY)
    assert not heavy, heavy
    assert "pymavlink.dialects.v20.all" not in modules
    # Only the command it names: not the other seventeen commands' modules and their imports.
    commands = sorted(m for m in modules if m.startswith("companion.commands."))
    assert commands == ["companion.commands.run"], commands


def test_the_parser_holds_the_named_command_or_every_one():
    from companion import cli
    assert cli.named_command(["paper-table", "--rate", "40"]) == "paper_table"
    assert cli.named_command(["run", "--help"]) == "run"
    # help, version, nothing or a typo: every command, so argparse can list them
    assert [cli.named_command(a) for a in (["--help"], ["--version"], [], ["runn"],
                                           ["mission_pull"])] == [None] * 5
    every = cli.build_parser()._subparsers._group_actions[0].choices     # type: ignore[union-attr]
    one = cli.build_parser("run")._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    assert len(every) == len(cli.COMMANDS) and list(one) == ["run"]
