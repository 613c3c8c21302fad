"""The one exception type for a user's mistake (bad file, bad flag, unreachable vehicle), and the
exit codes every command returns.

Raised anywhere, caught once in :mod:`companion.cli`, printed as a single line and turned into a
non-zero exit code: never a traceback for a user's error.
"""

import math
from enum import IntEnum


class ExitCode(IntEnum):
    """What a ``companion`` process's exit status means, stated once (docs/flying.md lists it).

    The systemd unit (``deploy/pzc-rover.service``) restarts on none of the codes a run means
    to return (USER_ERROR, FAULT and the named stops 4-7): ``RestartPreventExitStatus`` names
    exactly :data:`NO_RESTART` (``tests/project/test_deploy.py`` holds it). Each stop names its cause in
    the log, the JSON's ``reason`` and ``stop_cause``, and the Zenoh status as well.
    """

    OK = 0              # mission done, or stopped on request (SIGTERM, Ctrl-C, abort) after
                        # stopping the rover; a check that passed
    CHECK_FAILED = 1    # preflight or pki found a problem (the report says which)
    USER_ERROR = 2      # a user's mistake: bad flag or file, no vehicle, no telemetry, a
                        # mission the vehicle cannot start; nothing moved because of it
    FAULT = 3           # a run stopped by the companion's own failsafe: telemetry lost, mode
                        # or arming refused, a non-finite command, an internal error
    OUT_OF_REACH = 3    # `mission check --vehicle`: the mission asks more than the vehicle can
    PILOT_OVERRIDE = 4  # a pilot or a ground station changed the mode or disarmed: the
                        # companion let go at once
    AUTOPILOT_FAILSAFE = 5   # the autopilot's own failsafe (EKF, GCS, battery, fence, radio,
                        # crash) took the vehicle out of GUIDED / OFFBOARD: not taken back
    ESTIMATE_UNHEALTHY = 6   # the position estimate was flagged or stepped (GPS glitch or loss,
                        # EKF reset) and --on-bad-estimate end, or it stayed unhealthy (or the
                        # receiver below the run's class: docs/gnss.md) for --lost-timeout
    VEHICLE_RESTARTED = 7    # the autopilot rebooted mid-mission (its clock went back): never
                        # resumed on a rebooted vehicle
    INTERRUPTED = 130   # Ctrl-C before anything was flying (128 + SIGINT, as a shell reports)


# The codes the service never restarts on (everything `run` means to return but OK).
NO_RESTART = (ExitCode.USER_ERROR, ExitCode.FAULT, ExitCode.PILOT_OVERRIDE,
              ExitCode.AUTOPILOT_FAILSAFE, ExitCode.ESTIMATE_UNHEALTHY,
              ExitCode.VEHICLE_RESTARTED)


class UserError(Exception):
    """A problem the user can fix; ``str(err)`` is the one-line message, ``exit_code`` the code."""

    def __init__(self, message: str, exit_code: int = ExitCode.USER_ERROR):
        super().__init__(message)
        self.exit_code = exit_code


def require_positive(flag: str, value: float | None, minimum: float = 0.0) -> None:
    """A flag's number must be finite and above ``minimum`` (``None``: not given, fine)."""
    if value is not None and not (math.isfinite(value) and value > minimum):
        raise UserError(f"{flag} must be a number > {minimum:g}, not {value!r}")
