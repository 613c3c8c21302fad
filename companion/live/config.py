"""The live loop's settings, as plain dataclasses: the one place their defaults are stated.

Light on purpose (no pymavlink, nothing of the loop): the command line reads its flags' defaults
from here when it builds its parsers, so ``companion --help`` stays instant and a default is
written once. :mod:`companion.live.link` and :mod:`companion.live.runner` use them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MAV_COMP_ID_ONBOARD_COMPUTER = 191    # pymavlink's mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
DEFAULT_RATE = 40.0    # Hz: the telemetry / control rate asked for when nobody says (a stock
                       # ArduPilot's); the policy (companion.live.policy) decides the rest
MAX_RATE = 1000.0      # Hz
PLACEHOLDER_SYSID = 255   # the connection's system id until the vehicle's is known (nothing
                          # is sent before then)
GCS_REPORT_HZ = 4.0    # NAMED_VALUE_FLOAT values to the ground station (companion.live.gcs)


@dataclass(frozen=True)
class LinkConfig:
    url: str
    sysid: int | None = None          # vehicle to follow; None: the first vehicle heartbeat's
    # The companion's own MAVLink identity, by the onboard-computer conventions (mavlink.io,
    # "MAVLink routing" / "onboard computer"): the vehicle's system id, component 191. None:
    # take the vehicle's system id from its first heartbeat (docs/ground-station.md says why
    # not 255, a ground station's id: ArduPilot's GCS failsafe would take the companion's
    # heartbeat for the ground station's and never fire when the real one is lost).
    source_system: int | None = None
    source_component: int = MAV_COMP_ID_ONBOARD_COMPUTER
    heartbeat_timeout: float = 10.0   # s to wait for the vehicle's first heartbeat
    ack_timeout: float = 1.0          # s to wait for one COMMAND_ACK
    signing_key: bytes | None = None  # 32 bytes: sign outgoing, refuse unsigned
    tlog: str | None = None           # path of a .tlog to record (pymavlink's format)
    baud: int | None = None           # serial devices only; None: DEVICE,BAUD's or 115200


@dataclass(frozen=True)
class RunnerConfig:
    stale_timeout: float = 0.5        # wall s without a valid sample -> failsafe
    arm: bool = False                 # arm the vehicle ourselves (else wait for it)
    autostart: bool = True            # track as soon as engaged (else wait for `start`)
    telemetry_timeout: float = 10.0   # wall s for the first valid sample
    mode_timeout: float = 10.0        # wall s to get into GUIDED / OFFBOARD
    arm_timeout: float = 60.0         # wall s to see the vehicle armed
    lost_timeout: float = 30.0        # wall s in failsafe before giving up
    retry_interval: float = 1.0       # wall s between mode / arm / HOLD requests
    hold_timeout: float = 2.0         # wall s to see HOLD confirmed when stopping
    period: float | None = None       # nominal telemetry period, for missed-cycle counts
    heartbeat_lost: float = 3.0       # wall s without a vehicle heartbeat -> failsafe
    max_gap: float = 0.5              # vehicle s between tracked samples -> reset the tracker
    # m: a mission whose reference at time 0 is further than this from the rover is refused
    # before anything moves (inf: no limit); the first point of a far mission would otherwise
    # be chased in a straight line, across whatever lies between
    max_start_distance: float = math.inf
    # The estimate's health and the autopilot's failsafes (companion.live.health)
    on_bad_estimate: str = "pause"    # "pause": hold until healthy again; "end": end the run
    estimate_healthy_for: float = 3.0  # wall s of a healthy estimate before resuming
    estimate_step: float = 1.0        # m of LOCAL_POSITION_NED step its velocity does not explain
    # the estimator's normalised test ratios (1 = its own gate); ArduPilot's EKF failsafe
    # threshold FS_EKF_THRESH defaults to 0.8 too
    estimate_variance: float = 0.8
    retake_after_failsafe: bool = False   # re-engage once the autopilot's failsafe has cleared
    # wall s to wait at start for a healthy position estimate before engaging: a vehicle just
    # powered on has no GPS fix or EKF position for tens of seconds (SITL: about 45 s after
    # boot); that is not yet a fault, so nothing is asked of the vehicle until it is healthy
    estimate_wait: float = 120.0
    # --start-on-guided: never ask for the track mode nor arm; wait (without a timeout) until
    # the pilot or a ground station switches the vehicle into it, armed, then track
    wait_for_mode: bool = False
    # m/s^2: after standing still (a failsafe, a pause) the reference accelerates from the
    # rover's place on the path at this (companion.core.pacing), not leaping off at full speed;
    # gentle, so the rover follows it on the path (1 m/s^2 left ArduPilot's skid rover 0.3 m
    # behind on a ramp to 2 m/s: docs/gnss.md)
    rejoin_accel: float = 0.5
    # the mode the pilot leaves the vehicle in while the companion tracks (None: the profile's
    # track mode); --handover: its AUTO, whose guided sub-mode takes the setpoints
    track_mode: str | None = None


def segment_gap(max_gap: float, period: float | None) -> float:
    """Vehicle s between two tracked samples that ends a segment of the mission clock (and
    resets the tracker): ``max_gap``, but at least 5 telemetry periods. The live loop's rule, and
    the one ``companion plot`` replays a .tlog's mission clock with."""
    return max(max_gap, 5.0 * (period or 0.0))


@dataclass(frozen=True)
class OriginConfig:
    """Where a mission placed by latitude / longitude goes (:mod:`companion.live.origin`)."""

    expected: tuple[float, float] | None = None   # --origin: checked against the vehicle's
    timeout: float = 60.0             # wall s to wait for the vehicle's EKF origin


LINK = LinkConfig(url="udpin:0.0.0.0:14550")    # the defaults, for the command line to show
RUNNER = RunnerConfig()
BAD_ESTIMATE_ACTIONS = ("pause", "end")
ORIGIN = OriginConfig()
