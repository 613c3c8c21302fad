"""Mission files the tests and benchmarks fly: short ellipses and circles written on the spot,
the paper's ellipses shipped in ``missions/``, and the stand-still mission that waits for a
fresh SITL to boot.
"""

from __future__ import annotations

import time
from pathlib import Path

from testbed.process import ROOT, companion_json

# The paper's ellipse at each f_r (Hz): 60 s, anchored at the rover's start pose
PAPER_ELLIPSES = {0.04: ROOT / "missions" / "paper_ellipse_004.toml",
                  0.08: ROOT / "missions" / "paper_ellipse_008.toml",
                  0.12: ROOT / "missions" / "paper_ellipse_012.toml"}


def ellipse_mission(path: Path, duration: float, f_r: float = 0.12) -> Path:
    path.write_text(f'name = "ellipse {duration:g} s"\nframe = "start"\nduration = {duration}\n'
                    f'[trajectory]\nkind = "ellipse"\nf_r = {f_r}\n')
    return path


def mission_file(path: Path, duration: float, name: str = "ellipse") -> Path:
    """The 0.12 Hz ellipse for ``duration`` s, called ``name``."""
    path.write_text(f'name = "{name}"\nframe = "start"\nduration = {duration}\n'
                    '[trajectory]\nkind = "ellipse"\nf_r = 0.12\n')
    return path


def circle_mission(path: Path, duration: float, radius: float = 3.0, speed: float = 1.0) -> Path:
    """A clockwise circle from the rover's start pose, within a stock skid-steer rover's limits
    (the shipped 40 Hz gains for its 1.2 rad/s speed loop)."""
    path.write_text(
        f'name = "sitl circle"\nframe = "start"\nduration = {duration:g}\n'
        f'[trajectory]\nkind = "circle"\ncenter = [0.0, {radius:g}]\nradius = {radius:g}\n'
        f'speed = {speed:g}\ndirection = "cw"\nstart_bearing_deg = 270.0\n'
        f'[limits]\nmax_speed = 2.0\nmax_yaw_rate = 1.5\n[vehicle]\nw_c = 1.2\n')
    return path


# --------------------------------------------------------------------------- standing still

def stand_still_mission(folder: Path) -> Path:
    """A one-second mission whose reference never moves (an ellipse of size 0), in ``folder``."""
    mission = folder / "ready.toml"
    folder.mkdir(parents=True, exist_ok=True)
    mission.write_text('name = "ready"\nframe = "start"\nduration = 1\n[trajectory]\n'
                       'kind = "ellipse"\nf_r = 0.01\nax = 0\nbx = 0\nay = 0\nby = 0\n')
    return mission


def ready_argv(url: str, folder: Path) -> list[str]:
    """``companion`` arguments of the stand-still mission (written into ``folder``), flown
    first so that a timed command's clock starts on a booted vehicle (GPS fix, EKF position,
    arming checks: about 45 s on a fresh SITL, not the command's time; the run waits for the
    estimate itself, up to its --estimate-wait). The benchmarks that boot SITL share it."""
    return ["run", "--connect", url, "--mission", str(stand_still_mission(folder)), "--arm",
            "--json", "--no-zenoh", "--no-log", "-q", "--telemetry-timeout", "90",
            "--arm-timeout", "120", "--lost-timeout", "120"]


def wait_ready(url: str, folder: Path, timeout: float = 300) -> float:
    """The stand-still mission of :func:`ready_argv`, flown; the wall seconds it took."""
    t0 = time.monotonic()
    companion_json(ready_argv(url, folder), timeout)
    return time.monotonic() - t0


# missions/field.toml's field placed in the local frame where a rover boots (its route starts at
# the origin heading north): the field benchmark's and the field SITL test's
FIELD_BOUNDARY = [(-2.5, -3.5), (17.5, -3.5), (17.5, 8.5), (-2.5, 8.5)]   # north, east
FIELD_SPACING, FIELD_HEADLAND, FIELD_SPEED = 1.0, 3.0, 1.0


def field_mission(path: Path, turn_rate: float) -> Path:
    path.write_text(f'name = "field"\nframe = "local"\n[trajectory]\nkind = "field"\n'
                    f"boundary = {[list(p) for p in FIELD_BOUNDARY]}\nspacing = {FIELD_SPACING}\n"
                    f"headland = {FIELD_HEADLAND}\nangle_deg = 0\nspeed = {FIELD_SPEED}\n"
                    f"turn_rate = {turn_rate}\n")
    return path
