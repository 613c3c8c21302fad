"""``sitl-plant``: a MAVLink-speaking software rover (ArduPilot Rover or PX4 personality).

Parses the command line into a :class:`~sitl_plant.config.PlantConfig`, opens the link, runs the
plant until ``--duration`` or SIGTERM / SIGINT, and exits 0. A user's mistake is one line on
stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import socket
import sys

import companion.profiles as profiles
from companion.sim.vehicle_file import PRESETS, preset
from companion.sim.vehicle_file import load as load_vehicle

from .config import DEFAULT_URL, PlantConfig
from .earth import CMAC, OriginConfig
from .status import GpsFault
from .telemetry import TelemetryConfig
from .vehicle import VehicleConfig


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are a single line (and exit code 2)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # `--origin -35.36,149.16` is a value, as argparse already takes `-35.36` for one.
        self._negative_number_matcher = re.compile(r"^-\d*\.?\d+(,-?\d*\.?\d+)*$")

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _number(kind: str, ok, what: str, allow_inf: bool = False):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if math.isnan(value) or (math.isinf(value) and not allow_inf) or not ok(value):
            raise argparse.ArgumentTypeError(f"{text!r}: must be {what}")
        return value
    parse.__name__ = kind
    return parse


_positive = _number("positive", lambda v: v > 0, "a finite number > 0")
_positive_or_inf = _number("limit", lambda v: v > 0, "> 0 (inf for no limit)", allow_inf=True)
_non_negative = _number("non-negative", lambda v: v >= 0, "a finite number >= 0")
_probability = _number("probability", lambda v: 0 <= v <= 1, "between 0 and 1")
_finite = _number("finite", lambda v: True, "a finite number")
_step = _number("step", lambda v: 0 < v <= 0.05, "> 0 and <= 0.05 s")


def _sysid(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 1 <= value <= 255:
        raise argparse.ArgumentTypeError(f"{text!r}: must be 1..255")
    return value


def _param_override(text: str) -> tuple[str, float]:
    from .params import parse_override
    try:
        return parse_override(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _mav_type(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value <= 255:
        raise argparse.ArgumentTypeError(f"{text!r}: must be 0..255")
    return value


def _origin(text: str) -> tuple[float, float, float]:
    from companion.mission.geo import check_latlon
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: must be LAT,LON or LAT,LON,ALT in degrees "
                                         "(and metres)")
    problem = check_latlon(values[0], values[1])
    if problem:
        raise argparse.ArgumentTypeError(f"{text!r}: {problem}")
    return values[0], values[1], values[2] if len(values) == 3 else CMAC[2]


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="sitl-plant", description=(
        "A skid-steer or Ackermann rover (companion.sim.plant) behind a MAVLink 2 autopilot "
        "that behaves like ArduPilot Rover (or PX4): heartbeat, modes, arming, message rates, "
        "SET_POSITION_TARGET_LOCAL_NED, the guided timeout."))
    _link_arguments(p)
    _clock_arguments(p)
    _vehicle_arguments(p)
    _earth_arguments(p)
    _telemetry_arguments(p)
    _fault_arguments(p)
    return p


def _link_arguments(p: argparse.ArgumentParser) -> None:
    """The link: where, who, which autopilot, how its scheduler sends."""
    link = p.add_argument_group("link")
    link.add_argument("--connect", metavar="URL", default=DEFAULT_URL,
                      help=f"any pymavlink connection string (default {DEFAULT_URL})")
    link.add_argument("--sysid", type=_sysid, default=1, help="MAVLink system id (default 1)")
    link.add_argument("--gcs", metavar="URL",
                      help="a second link, a ground station's (as ArduPilot's SERIAL1): "
                           "heartbeats, texts, commands and mission transfers, and messages "
                           "routed to and from the companion's link; no pose streams")
    link.add_argument("--autopilot", choices=list(profiles.AUTOPILOTS),
                      default=profiles.DEFAULT_AUTOPILOT,
                      help=f"personality (default {profiles.DEFAULT_AUTOPILOT})")
    link.add_argument("--loop-rate", type=_positive, default=50.0, metavar="HZ",
                      help="scheduler rate; message rates above 0.8x are refused (default 50)")
    link.add_argument("--tick-aligned", action=argparse.BooleanOptionalAction, default=None,
                      help="send telemetry on the scheduler's ticks as ArduPilot does (40 Hz on "
                           "50 Hz: 20/20/20/40 ms); default on with --preset ardupilot-skid")
    link.add_argument("--arm-delay", type=_non_negative, default=0.0, metavar="S",
                      help="arming refused for the first S s of vehicle time (default 0)")


def _clock_arguments(p: argparse.ArgumentParser) -> None:
    """Vehicle time against wall time, and the integration step."""
    clock = p.add_argument_group("clock")
    clock.add_argument("--speedup", type=_positive, default=1.0, metavar="N",
                       help="vehicle time runs N x wall time (default 1)")
    clock.add_argument("--lockstep", action="store_true",
                       help="advance to the next telemetry tick only once a setpoint answered")
    clock.add_argument("--lockstep-timeout", type=_positive, default=0.25, metavar="S",
                       help="wall s to wait for that setpoint (default 0.25)")
    clock.add_argument("--physics-dt", type=_step, default=0.001, metavar="S",
                       help="integration step, vehicle s (default 0.001)")
    clock.add_argument("--duration", type=_positive, default=None, metavar="S",
                       help="exit after S s of vehicle time (default: run until a signal)")


def _vehicle_arguments(p: argparse.ArgumentParser) -> None:
    """The vehicle model: a preset or a vehicle file, and flags that override it."""
    veh = p.add_argument_group("vehicle")
    veh.add_argument("--preset", choices=PRESETS, default="paper",
                     help="paper: the paper's plant; stock: a stock ArduPilot skid-steer rover "
                          "as a linear lag; ardupilot-skid: SITL rover-skid as identified "
                          "(delays, rate limits, coupling; implies --tick-aligned)")
    veh.add_argument("--vehicle", metavar="FILE",
                     help="a vehicle file (companion identify); the flags below override it")
    veh.add_argument("--d-cen", type=_non_negative, metavar="M", help="axle to tracked point")
    veh.add_argument("--w-c", type=_positive, metavar="RAD_S", help="speed-loop bandwidth")
    veh.add_argument("--w-c-yaw", type=_positive, metavar="RAD_S", help="turn-rate bandwidth")
    veh.add_argument("--max-speed", type=_positive_or_inf, metavar="M_S")
    veh.add_argument("--max-yaw-rate", type=_positive_or_inf, metavar="RAD_S")
    veh.add_argument("--max-accel", type=_positive_or_inf, metavar="M_S2")
    veh.add_argument("--max-decel", type=_positive_or_inf, metavar="M_S2")
    veh.add_argument("--max-yaw-accel", type=_positive_or_inf, metavar="RAD_S2")
    veh.add_argument("--speed-delay", type=_non_negative, metavar="S")
    veh.add_argument("--yaw-delay", type=_non_negative, metavar="S")
    veh.add_argument("--turn-speed-coupling", type=_probability, metavar="C",
                     help="share of top speed lost at full turn rate (skid-steer mixing)")
    veh.add_argument("--speed-turn-coupling", type=_probability, metavar="C",
                     help="share of the turn rate lost at top speed (skid-steer mixing)")
    veh.add_argument("--start", type=_finite, nargs=3, metavar=("X", "Y", "YAW"),
                     default=(0.0, 0.0, 0.0), help="start pose: north m, east m, yaw rad")


def _earth_arguments(p: argparse.ArgumentParser) -> None:
    """Where the rover is on the earth, and when the autopilot says so."""
    earth = p.add_argument_group("position on the earth")
    earth.add_argument("--origin", type=_origin, default=CMAC, metavar="LAT,LON[,ALT]",
                       help="EKF origin, sent as GPS_GLOBAL_ORIGIN on MAV_CMD_REQUEST_MESSAGE; "
                            "home (HOME_POSITION) is the --start position; default ArduPilot "
                            f"SITL's home {CMAC[0]},{CMAC[1]},{CMAC[2]:g}")
    earth.add_argument("--origin-delay", type=_non_negative, default=0.0, metavar="S",
                       help="the origin is set (a GPS fix) S s of vehicle time after boot; "
                            "not reported before (default 0)")
    earth.add_argument("--global-position-rate", type=_non_negative, default=0.0, metavar="HZ",
                       help="stream GLOBAL_POSITION_INT at HZ from boot (default 0: only when "
                            "asked with MAV_CMD_SET_MESSAGE_INTERVAL)")


def _telemetry_arguments(p: argparse.ArgumentParser) -> None:
    """What the link does to the telemetry: noise, latency, loss, duplicates, reordering, bursts."""
    tel = p.add_argument_group("telemetry")
    tel.add_argument("--noise-pos", type=_non_negative, default=0.0, metavar="M")
    tel.add_argument("--noise-yaw", type=_non_negative, default=0.0, metavar="RAD")
    tel.add_argument("--seed", type=int, default=None, help="noise/dropout seed (default sysid)")
    tel.add_argument("--latency", type=_non_negative, default=0.0, metavar="S",
                     help="telemetry sent S s of vehicle time after sampling")
    tel.add_argument("--dropout", type=_probability, default=0.0, metavar="P",
                     help="each pose message lost with probability P")
    tel.add_argument("--duplicate", type=_probability, default=0.0, metavar="P",
                     help="each pose message sent twice with probability P")
    tel.add_argument("--reorder", type=_probability, default=0.0, metavar="P",
                     help="each pose message held back 60 ms (overtaken) with probability P")
    tel.add_argument("--burst", type=_probability, default=0.0, metavar="P",
                     help="with probability P per pose message the link stalls 100 ms, "
                          "then delivers everything at once")


def _fault_arguments(p: argparse.ArgumentParser) -> None:
    """Faults to inject, and MAVLink signing."""
    flt = p.add_argument_group("faults and security")
    flt.add_argument("--takeover-at", type=_positive, metavar="S", dest="takeover_at",
                     help="a pilot switches to HOLD at S s of vehicle time (SIGUSR1: now)")
    flt.add_argument("--battery-low-at", type=_positive, metavar="S", dest="battery_low_at",
                     help="the autopilot's battery failsafe at S s of vehicle time, as ArduPilot "
                          "Rover's with BATT_FS_LOW_ACT 2: HOLD (its heartbeat first), then "
                          "\"Battery 1 is low ...\" and SYS_STATUS's battery bit unhealthy")
    flt.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                     type=_param_override,
                     help="serve this parameter value (repeatable): overrides the modelled one "
                          "or adds one (sitl_plant.params)")
    flt.add_argument("--param-loss", type=_probability, default=0.0, metavar="P",
                     help="each PARAM_VALUE of a PARAM_REQUEST_LIST reply lost with probability P")
    flt.add_argument("--ekf-delay", type=_non_negative, default=0.0, metavar="S",
                     help="no EKF origin, no position estimate and no arming for the first S s "
                          "of vehicle time (ArduPilot SITL: about 20 s to an origin)")
    flt.add_argument("--gps-glitch", type=_gps_fault("glitch"), action="append", default=[],
                     metavar="AT,DURATION[,METRES]", dest="gps_faults",
                     help="from AT s of vehicle time for DURATION s the EKF reports GPS "
                          "glitching (0x833f) and LOCAL_POSITION_NED is METRES (default 14) north "
                          "of the truth (repeatable)")
    flt.add_argument("--gps-loss", type=_gps_fault("loss"), action="append", dest="gps_faults",
                     metavar="AT,DURATION",
                     help="from AT s for DURATION s the EKF has no absolute position (0x27) "
                          "and GPS_RAW_INT no fix")
    flt.add_argument("--gps-float", type=_gps_fault("float"), action="append", dest="gps_faults",
                     metavar="AT,DURATION[,METRES]",
                     help="from AT s for DURATION s the receiver is in RTK float (GPS_RAW_INT "
                          "fix type 5, 0.4 m) and LOCAL_POSITION_NED METRES (default 0.3) north "
                          "of the truth, the EKF unflagged (repeatable)")
    flt.add_argument("--gps-jump", type=_gps_fault("jump"), action="append", dest="gps_faults",
                     metavar="AT,DURATION[,METRES]",
                     help="from AT s for DURATION s multipath moves the receiver METRES (default "
                          "0.25) north while it says RTK fixed; LOCAL_POSITION_NED slides after it "
                          "(and back) over 0.7 s, the EKF unflagged (repeatable)")
    flt.add_argument("--mav-type", type=_mav_type, metavar="N",
                     help="the heartbeat's MAV_TYPE (default 10 rover, 11 with FRAME_CLASS 2); "
                          "another imitates a vehicle that is not a rover")
    flt.add_argument("--mavlink1", action="store_true",
                     help="send MAVLink 1 frames (a port set to SERIALn_PROTOCOL 1)")
    flt.add_argument("--mission-drop-item", type=int, metavar="N", dest="mission_drop_item",
                     help="never answer a request for stored mission item N (a partial "
                          "transfer, for tests)")
    flt.add_argument("--signing-key", metavar="FILE", dest="signing_key",
                     help="MAVLink 2 signing: 32-byte secret (raw or 64 hex digits, mode 600); "
                          "unsigned commands and setpoints are ignored")


FLOAT_OFFSET = 0.3     # m: --gps-float's default, a float solution's typical wander
JUMP_SIZE = 0.25       # m: --gps-jump's default, a multipath jump of a "fixed" receiver


def _gps_fault(kind: str):
    def parse(text: str) -> GpsFault:
        parts = text.split(",")
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise argparse.ArgumentTypeError(f"not numbers: {text!r}") from None
        sized = kind in ("glitch", "float", "jump")
        wanted = (2, 3) if sized else (2,)
        if len(values) not in wanted or not all(math.isfinite(v) for v in values) \
                or values[0] < 0 or values[1] <= 0:
            raise argparse.ArgumentTypeError(
                f"{text!r}: want AT,DURATION{'[,METRES]' if sized else ''} "
                "(AT >= 0, DURATION > 0, finite)")
        if kind in ("float", "jump") and len(values) == 2:
            values.append(FLOAT_OFFSET if kind == "float" else JUMP_SIZE)
        return GpsFault(kind, *values)
    return parse


def config_from_args(args: argparse.Namespace) -> PlantConfig:
    params = load_vehicle(args.vehicle).params if args.vehicle else preset(args.preset)
    overrides = {name: getattr(args, name) for name in
                 ("d_cen", "w_c", "w_c_yaw", "max_speed", "max_yaw_rate", "max_accel", "max_decel",
                  "max_yaw_accel", "speed_delay", "yaw_delay", "turn_speed_coupling",
                  "speed_turn_coupling")
                 if getattr(args, name) is not None}
    params = params.with_(**overrides)
    # no arming before the EKF runs, as on SITL
    vehicle = VehicleConfig(params=params, autopilot=profiles.autopilot_named(args.autopilot),
                            arm_delay=max(args.arm_delay, args.ekf_delay), start=tuple(args.start))
    telemetry = TelemetryConfig(noise_pos=args.noise_pos, noise_yaw=args.noise_yaw,
                                latency=args.latency, dropout=args.dropout,
                                seed=args.sysid if args.seed is None else args.seed,
                                duplicate=args.duplicate, reorder=args.reorder, burst=args.burst)
    if args.battery_low_at is not None and vehicle.autopilot.plant.battery_text is None:
        from companion.errors import UserError
        raise UserError(f"--battery-low-at: the battery failsafe is not modelled for "
                        f"--autopilot {args.autopilot}")
    key = None
    if args.signing_key is not None:
        from companion.mav.signing import load_key
        key = load_key(args.signing_key)
    return PlantConfig(connect=args.connect, sysid=args.sysid, loop_rate=args.loop_rate,
                       speedup=args.speedup, lockstep=args.lockstep,
                       lockstep_timeout=args.lockstep_timeout, physics_dt=args.physics_dt,
                       duration=args.duration, preset=args.preset, vehicle=vehicle,
                       tick_aligned=(args.tick_aligned if args.tick_aligned is not None
                                     else args.preset == "ardupilot-skid"),
                       telemetry=telemetry, takeover_at=args.takeover_at,
                       battery_low_at=args.battery_low_at, signing_key=key,
                       origin=OriginConfig(args.origin[0], args.origin[1], args.origin[2],
                                           delay=max(args.origin_delay, args.ekf_delay)),
                       global_position_rate=args.global_position_rate,
                       params=tuple(args.param), param_loss=args.param_loss,
                       ekf_delay=args.ekf_delay, mav_type=args.mav_type, mavlink1=args.mavlink1,
                       gps_faults=tuple(args.gps_faults),
                       gcs=args.gcs, mission_drop_item=args.mission_drop_item)


def _install_signals(server) -> tuple[socket.socket, socket.socket]:
    """SIGTERM / SIGINT end the run cleanly; the wake-up socket interrupts the loop's wait.
    The caller keeps the returned pair open for as long as the handlers are installed."""
    wake_r, wake_w = socket.socketpair()
    wake_r.setblocking(False)
    wake_w.setblocking(False)
    signal.set_wakeup_fd(wake_w.fileno(), warn_on_full_buffer=False)

    def stop(signum, frame):
        server.stopping = True

    def takeover(signum, frame):
        server.takeover_requested = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGUSR1, takeover)
    server.wake = wake_r
    return wake_r, wake_w


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from companion.errors import UserError
    try:
        config = config_from_args(args)
    except UserError as err:
        print(f"sitl-plant: error: {err}", file=sys.stderr)
        return 2
    from .link import Link, LinkError
    from .server import PlantServer
    try:
        link = Link(config.connect, config.sysid, config.compid, config.signing_key,
                    mavlink1=config.mavlink1)
    except LinkError as err:
        print(f"sitl-plant: error: {err}", file=sys.stderr)
        return 2
    gcs = None
    if config.gcs is not None:
        try:
            gcs = Link(config.gcs, config.sysid, config.compid, config.signing_key,
                       mavlink1=config.mavlink1)
        except LinkError as err:
            link.close()
            print(f"sitl-plant: error: --gcs: {err}", file=sys.stderr)
            return 2
    server = PlantServer(config, link, gcs=gcs)
    wake = _install_signals(server)
    clock = "lockstep" if config.lockstep else "paced"
    print(f"sitl-plant: sysid {config.sysid} on {config.connect}, preset {config.preset}, "
          f"{config.vehicle.autopilot.name}, {clock} x{config.speedup:g}",
          file=sys.stderr, flush=True)
    try:
        server.run()
    finally:
        link.close()
        if gcs is not None:
            gcs.close()
        signal.set_wakeup_fd(-1)
        for sock in wake:
            sock.close()
    v = server.vehicle
    ignored = sum(v.setpoints_ignored.values())
    print(f"sitl-plant: sysid {config.sysid} stopped at t={server.t_us / 1e6:.3f} s: "
          f"{link.received} messages in, {link.bad_data} bad, {v.setpoints_used} setpoints used, "
          f"{ignored} ignored {dict(sorted(v.setpoints_ignored.items()))}, "
          f"{server.foreign} for other systems, {server.gate.timeouts} lockstep timeouts, "
          f"{link.signing_rejected} refused for their signature, "
          f"{server.handler_errors} handler errors; telemetry faults: "
          f"{server.telemetry.dropped} dropped, {server.telemetry.duplicated} duplicated, "
          f"{server.telemetry.reordered} reordered, {server.telemetry.bursts} bursts",
          file=sys.stderr, flush=True)
    if link.peer_closed:
        print("sitl-plant: the TCP peer closed the connection", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
