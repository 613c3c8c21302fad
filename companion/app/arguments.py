"""The flags several commands share, one function per group, and the value types they parse.

Each group's defaults are the live loop's own (:mod:`companion.live.config`), read when the
parser is built, so a default is stated once; :mod:`companion.app.options` reads a group's
values back into the typed options of a flight. Only light modules are imported here: building
the parser (``companion --help``) must stay instant.
"""

from __future__ import annotations

import argparse
import math
import re
from typing import Any

from ..errors import UserError
from ..live.config import BAD_ESTIMATE_ACTIONS, LINK, ORIGIN, RUNNER

CONNECT_HELP = ("pymavlink connection string or serial device, e.g. /dev/ttyAMA0 or "
                "/dev/ttyACM0,921600")
BAUD_HELP = ("serial devices only: bits per second (default: DEVICE,BAUD's, else 115200 as "
             "pymavlink; ArduPilot companion ports usually 921600)")
DEFAULT_START_DISTANCE = 25.0   # m: --max-start-distance


# --- value types ------------------------------------------------------------------------------

def _finite(text: str, ok, want: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f"must be a finite number {want}, not {text}")
    return value


def positive(text: str) -> float:
    return _finite(text, lambda v: v > 0, "> 0")


def non_negative(text: str) -> float:
    return _finite(text, lambda v: v >= 0, ">= 0")


def _integer(text: str, lowest: int, highest: int | None, what: str) -> int:
    """An integer flag within [lowest, highest]; ``what`` names the range in the error."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < lowest or (highest is not None and value > highest):
        raise argparse.ArgumentTypeError(f"{what}, not {value}")
    return value


def at_least_one(text: str) -> int:
    return _integer(text, 1, None, "must be >= 1")


def mavlink_id(text: str) -> int:
    return _integer(text, 1, 255, "a MAVLink id is 1..255")


def port_number(text: str) -> int:
    return _integer(text, 1, 65535, "a port is 1..65535")


def baud_rate(text: str) -> int:
    from ..mav.connection import parse_baud
    try:
        return parse_baud(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def allow_negative_pairs(parser: argparse.ArgumentParser) -> None:
    """Let ``--origin -35.36,149.16`` (southern / western) be a value, as argparse already lets
    ``-35.36`` be: its test for a negative number knows no comma-separated list."""
    parser._negative_number_matcher = re.compile(r"^-\d*\.?\d+(,-?\d*\.?\d+)*$")


# --- groups -----------------------------------------------------------------------------------

def add_link_arguments(p: argparse.ArgumentParser, title: str | None = None, *,
                       default_connect: bool = False, required: bool = False) -> None:
    """--connect, --baud, --sysid, --source-system, --arm: the vehicle and how to reach it."""
    g = p.add_argument_group(title) if title else p
    g.add_argument("--connect", metavar="URL", required=required,
                   default=LINK.url if default_connect else None,
                   help=CONNECT_HELP + (f" (default {LINK.url})" if default_connect else ""))
    g.add_argument("--baud", type=baud_rate, metavar="BPS", help=BAUD_HELP)
    g.add_argument("--sysid", type=int, metavar="N",
                   help="system id of the vehicle to follow (default: the first heartbeat's)")
    g.add_argument("--source-system", type=mavlink_id, metavar="N",
                   help="the companion's own MAVLink system id (default: the vehicle's, as an "
                        "onboard computer's; component 191). 255 is a ground station's: see "
                        "docs/ground-station.md before choosing it")
    g.add_argument("--arm", action="store_true",
                   help="arm the vehicle (retrying once a second); default: wait for it")


def add_gcs_arguments(p: argparse.ArgumentParser) -> None:
    """What the ground station sees of the run and may ask of it (docs/ground-station.md)."""
    g = p.add_argument_group("ground station (docs/ground-station.md)")
    g.add_argument("--no-gcs-report", dest="gcs_report", action="store_false",
                   help="send no STATUSTEXT / NAMED_VALUE_FLOAT to the ground station and "
                        "ignore its MAV_CMD_DO_PAUSE_CONTINUE")
    g.add_argument("--start-on-guided", action="store_true",
                   help="engage nothing: wait (without a timeout) until the pilot or a "
                        "ground station switches the vehicle to GUIDED (PX4: OFFBOARD) and "
                        "arms it, then track; leaving that mode ends the run as a pilot's "
                        "switch does")
    g.add_argument("--handover", action="store_true",
                   help="ArduPilot: wait while the vehicle flies its own AUTO mission and track "
                        "each segment between a NAV_GUIDED_ENABLE 1 and 0 item when AUTO "
                        "reaches it, then hand back; with --mission vehicle (pulled from it)")


def add_origin_arguments(p: argparse.ArgumentParser) -> None:
    """Where a mission placed by latitude / longitude goes, and how far its start may be."""
    g = p.add_argument_group(
        "where the mission is",
        "A mission placed by latitude / longitude (.plan, .waypoints, TOML frame\n"
        "\"geodetic\") is placed around the vehicle's own EKF origin, read from it\n"
        "(GPS_GLOBAL_ORIGIN / HOME_POSITION) after connecting.")
    g.add_argument("--origin", metavar="LAT,LON",
                   help="the EKF origin you expect: refused when more than 5 m from the "
                        "vehicle's; used as given only if the vehicle tells none")
    g.add_argument("--origin-timeout", type=positive, default=ORIGIN.timeout, metavar="S",
                   help="wall s to wait for the vehicle's EKF origin (its GPS fix; default "
                        f"{ORIGIN.timeout:g})")
    g.add_argument("--max-start-distance", type=non_negative, default=DEFAULT_START_DISTANCE,
                   metavar="M", help="refuse a mission whose first point is more than M m from "
                   f"the rover (default {DEFAULT_START_DISTANCE:g}; 0: no limit)")
    allow_negative_pairs(p)


def controller_gains(controller: str, text: str | None) -> Any:
    """``--controller-gains NAME=VALUE[,NAME=VALUE...]`` for ``--controller controller``: an
    instance of that controller's own gains dataclass, the fields named set and the rest at
    their defaults (``None``: the flag not given, the defaults fly).

    Parsed after argparse, once the controller is known (the fields are its gains'), so every
    mistake is one line naming the flag and the field (UserError, exit 2): a missing ``=``, a
    field named twice, a word for a number; unknown fields and values out of range are the
    gains' own checks (:meth:`companion.core.controllers.Controller.with_gains`).
    """
    if text is None:
        return None
    from ..core import controllers
    entry = controllers.get(controller)
    if entry.uses_pzc_gains:
        raise UserError(f"--controller-gains sets the own gains of a baseline (pid, kanayama); "
                        f"--controller {controller} flies the filter + PZC gains (--gains, "
                        "--k-df, --lambda-f, --k-dc, --lambda-c)")
    defaults = entry.gain_defaults()
    values: dict[str, float | str] = {}
    for item in text.split(","):
        name, eq, raw = (part.strip() for part in item.partition("="))
        if not eq or not name or not raw:
            raise UserError(f"--controller-gains: {item.strip()!r} is not NAME=VALUE (e.g. "
                            f"{next(iter(defaults))}=1.5; {controller}'s gains: "
                            f"{', '.join(defaults)})")
        if name in values:
            raise UserError(f"--controller-gains: {name} given twice")
        if name in defaults and isinstance(defaults[name], str):
            values[name] = raw                    # a word (pid's speed_law)
            continue
        try:
            values[name] = float(raw)
        except ValueError:
            if name not in defaults:              # the unknown name is the mistake to report
                values[name] = raw
                continue
            raise UserError(f"--controller-gains: {name} must be a number, not {raw!r}") from None
    try:
        return entry.with_gains(values)
    except ValueError as exc:
        raise UserError(f"--controller-gains: {exc}") from None


def add_controller_arguments(g) -> None:
    """--controller and --controller-gains (run, demo, simulate): which law flies, and a
    baseline's own gains (read back by :func:`controller_gains`)."""
    from ..core.controllers import DEFAULT, NAMES  # names only: no numpy to build the CLI
    g.add_argument("--controller", choices=NAMES, default=DEFAULT,
                   help=f"the tracker to fly (default {DEFAULT}); pid and kanayama fly their "
                        "own gains (default, or --controller-gains) within the same limits")
    g.add_argument("--controller-gains", dest="controller_gains", metavar="NAME=VALUE[,...]",
                   help="pid and kanayama only: set fields of the controller's own gains, the "
                        "rest at their defaults, e.g. kx=1,ky=0.5,kth=1.2 (kanayama: kx, ky, "
                        "kth; pid: kp, ki, kd, speed_law)")


def add_gain_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("gains and limits")
    add_controller_arguments(g)
    g.add_argument("--rate", type=positive, metavar="HZ",
                   help="telemetry / control rate to ask for (default: the mission's, else 40)")
    g.add_argument("--gains", metavar="FILE", help="tuned-gains TOML file (companion tune)")
    g.add_argument("--k-df", type=positive, dest="k_df", metavar="K", help="filter k_{d,f}")
    g.add_argument("--lambda-f", type=positive, dest="lambda_f", metavar="L", help="filter lambda_f")
    g.add_argument("--k-dc", type=positive, dest="k_dc", metavar="K", help="PZC k_{d,c}")
    g.add_argument("--lambda-c", type=positive, dest="lambda_c", metavar="L", help="PZC lambda_c")
    add_limit_arguments(g)


def add_limit_arguments(g) -> None:
    g.add_argument("--max-speed", type=positive, dest="max_speed", metavar="M_S",
                   help="speed limit of every setpoint (m/s)")
    g.add_argument("--max-yaw-rate", type=positive, dest="max_yaw_rate", metavar="RAD_S",
                   help="turn-rate limit of every setpoint (rad/s)")


def add_vehicle_arguments(p: argparse.ArgumentParser) -> None:
    v = p.add_argument_group("vehicle (to pick tuned gains)")
    v.add_argument("--vehicle", metavar="FILE",
                   help="the rover's vehicle file (companion identify / calibrate): its gains "
                        "(found beside it, else tuned now and stored there) and its limits; "
                        "default: the mission's [vehicle] file")
    v.add_argument("--w-c", type=positive, dest="w_c", metavar="RAD_S",
                   help="speed-loop bandwidth (default: the mission's [vehicle], else 20)")
    v.add_argument("--d-cen", type=non_negative, dest="d_cen", metavar="M",
                   help="axle to tracked point (default: the mission's [vehicle], else 0)")


def add_timeout_arguments(p: argparse.ArgumentParser) -> None:
    """The live loop's failsafe timeouts (companion run, identify, calibrate)."""
    t = p.add_argument_group("timeouts (wall seconds)")
    t.add_argument("--stale-timeout", type=positive, default=RUNNER.stale_timeout, metavar="S",
                   help=f"stop the rover when no valid sample arrives for S (default {RUNNER.stale_timeout:g})")
    t.add_argument("--heartbeat-timeout", type=positive, default=LINK.heartbeat_timeout,
                   metavar="S", help="wait this long for the vehicle's heartbeat "
                                     f"(default {LINK.heartbeat_timeout:g})")
    t.add_argument("--telemetry-timeout", type=positive, default=RUNNER.telemetry_timeout,
                   metavar="S", help="wait this long for the first valid sample "
                                     f"(default {RUNNER.telemetry_timeout:g})")
    t.add_argument("--arm-timeout", type=positive, default=RUNNER.arm_timeout, metavar="S",
                   help=f"wait this long to see the vehicle armed (default {RUNNER.arm_timeout:g})")
    t.add_argument("--lost-timeout", type=positive, default=RUNNER.lost_timeout, metavar="S",
                   help=f"give up when telemetry stays lost for S (default {RUNNER.lost_timeout:g})")
    h = p.add_argument_group("the vehicle's health (docs/field-faults.md)")
    h.add_argument("--on-bad-estimate", choices=BAD_ESTIMATE_ACTIONS,
                   default=RUNNER.on_bad_estimate,
                   help="when the position estimate is flagged (GPS glitch or loss, variance) or "
                        "steps: pause (zero setpoint, HOLD, reference held) and resume once "
                        "healthy, or end the run (exit 6) (default "
                        f"{RUNNER.on_bad_estimate})")
    h.add_argument("--estimate-healthy-for", type=positive, metavar="S",
                   default=RUNNER.estimate_healthy_for,
                   help="resume after the estimate has been healthy this long (default "
                        f"{RUNNER.estimate_healthy_for:g})")
    h.add_argument("--estimate-step", type=positive, metavar="M", default=RUNNER.estimate_step,
                   help="a LOCAL_POSITION_NED step its velocity does not explain by more than "
                        f"M pauses the run (default {RUNNER.estimate_step:g})")
    h.add_argument("--estimate-variance", type=positive, metavar="RATIO",
                   default=RUNNER.estimate_variance,
                   help="pause when an estimator test ratio passes RATIO (1 = its own gate; "
                        f"default {RUNNER.estimate_variance:g})")
    h.add_argument("--estimate-wait", type=positive, metavar="S", default=RUNNER.estimate_wait,
                   help="at start, wait this long for a healthy position estimate (GPS fix, "
                        "EKF) before engaging; then end, exit 6 (default "
                        f"{RUNNER.estimate_wait:g})")
    h.add_argument("--retake-after-failsafe", action="store_true",
                   help="once the autopilot's own failsafe has cleared, take the vehicle back "
                        "into GUIDED / OFFBOARD and go on (default: end the run, exit 5)")


def add_safety_arguments(p: argparse.ArgumentParser) -> None:
    """Flight logs and MAVLink signing (companion run, demo, identify, calibrate)."""
    g = p.add_argument_group("flight log and signing")
    g.add_argument("--log-dir", metavar="DIR",
                   help="where the .tlog (all MAVLink traffic) and .csv (control loop) go "
                        "(default ./logs); written as they go, a crash loses at most 100 ms")
    g.add_argument("--no-log", dest="log", action="store_false", help="write no flight log")
    g.add_argument("--log-format", choices=("csv", "mcap"), default="csv",
                   help="the control loop beside the .tlog: csv (default), or mcap in "
                        "Foxglove's schemas (companion log export writes the same)")
    add_signing_argument(g)


def add_signing_argument(g, help: str | None = None) -> None:
    g.add_argument("--signing-key", metavar="FILE",
                   help=help or "MAVLink 2 signing: 32-byte secret (raw or 64 hex digits, mode "
                                "600); sign what is sent, refuse unsigned or wrongly signed input")


def add_output_arguments(p: argparse.ArgumentParser, progress: bool = False,
                         json_help: str = "print one JSON result object at the end") -> None:
    o = p.add_argument_group("output")
    o.add_argument("--json", action="store_true", help=json_help)
    if progress:
        o.add_argument("--progress", action="store_true", help="progress bar on stderr")
    o.add_argument("-q", "--quiet", action="store_true", help="no log lines on stderr")


def add_zenoh_arguments(p: argparse.ArgumentParser, vehicle: bool = True,
                        modes: tuple[str, ...] = ("peer", "client"),
                        roles: tuple[str, ...] | None = None) -> None:
    """The ``--zenoh-*`` flags (run, demo, identify, calibrate, monitor, control, router).
    ``vehicle``: the command is a rover's (it publishes: --no-zenoh, --vehicle-id, ...);
    ``roles``: the certificate roles it accepts with --zenoh-tls (a vehicle's command: rover)."""
    p.set_defaults(zenoh_roles=roles if roles is not None else (("rover",) if vehicle else ()),
                   zenoh_vehicle=vehicle)
    g = p.add_argument_group(
        "zenoh (live telemetry and remote control)",
        "By default an embedded Zenoh peer (no router needed) with Zenoh's default discovery. "
        "Flags override --zenoh-config FILE (else $ZENOH_CONFIG).")
    if vehicle:
        g.add_argument("--no-zenoh", dest="zenoh", action="store_false",
                       help="publish nothing and open no Zenoh session")
    g.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT",
                   help="connect to this Zenoh endpoint, e.g. tcp/10.0.0.2:7447 (repeatable)")
    g.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT",
                   help="listen on this Zenoh endpoint, e.g. tcp/0.0.0.0:7448 (repeatable)")
    g.add_argument("--zenoh-config", metavar="FILE", help="a Zenoh JSON5 config file")
    p.set_defaults(zenoh_mode=None)
    if len(modes) > 1:
        g.add_argument("--zenoh-mode", choices=modes, default=None,
                       help="peer (default) or client (all traffic through the router "
                            "given with --zenoh-connect); with --zenoh-tls, a --zenoh-connect "
                            "and no --zenoh-listen the default is client")
    g.add_argument("--zenoh-scouting", action=argparse.BooleanOptionalAction, default=None,
                   help="multicast scouting (finding peers on the LAN); default: Zenoh's (on)")
    g.add_argument("--zenoh-tls", metavar="DIR/NAME",
                   help="mutual TLS with DIR/NAME.pem and DIR/NAME.key, issued by the CA "
                        "DIR/ca.pem (companion pki); every endpoint must then be "
                        "tls/HOST:PORT, and access control enforces the certificate's role")
    if vehicle:
        g.add_argument("--vehicle-id", metavar="ID",
                       help="the <vehicle_id> in rover/<vehicle_id>/... (default rover<sysid>)")
        g.add_argument("--state-every", type=at_least_one, default=1, metavar="N",
                       help="publish state every N-th control cycle (default 1: every cycle)")
        g.add_argument("--control-secret", metavar="FILE",
                       help="enable the rover/<vehicle_id>/control queryable; requests must "
                            "carry this file's secret (the file must be chmod 600)")


def parse_origin(text: str | None) -> tuple[float, float] | None:
    """``"LAT,LON"`` -> (lat, lon); a one-line UserError otherwise."""
    if text is None:
        return None
    from ..mission import geo
    try:
        lat, lon = (float(part) for part in text.split(","))
    except ValueError:
        raise UserError(f"--origin must be LAT,LON in degrees, not {text!r}") from None
    problem = geo.check_latlon(lat, lon)
    if problem:
        raise UserError(f"--origin {problem}")
    return lat, lon
