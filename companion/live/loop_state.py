"""The live loop's state: its states, and the records it keeps in the pieces that change together.

:class:`companion.live.runner.core.LoopCore` makes one of each record and owns them; nothing else
writes them. Plain data, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from ..errors import ExitCode


class State(str, Enum):  # noqa: UP042  (StrEnum changes str(): a behaviour change, not a lint fix)
    WAITING = "waiting"
    ENGAGING = "engaging"
    READY = "ready"
    TRACKING = "tracking"
    PAUSED = "paused"
    FAILSAFE = "failsafe"
    DONE = "done"


ACTIVE = (State.ENGAGING, State.READY, State.TRACKING, State.PAUSED)


@dataclass
class Outcome:
    reason: str
    exit_code: ExitCode
    hold_confirmed: bool
    failsafes: int


# The loop's state, in the pieces that change together (Runner.__init__ makes one of each).

@dataclass(slots=True)
class Heard:
    """What the vehicle last said, and when: wall s on the companion's clock, vehicle s on its."""
    sample_wall: float = 0.0              # the last valid pose sample arrived
    heartbeat_wall: float = 0.0           # the last heartbeat of our vehicle arrived
    heartbeat_lost_said: bool = False     # "no vehicle heartbeat" logged, "back" not yet
    vehicle_t: float = 0.0                # the last valid sample's vehicle time
    pose: tuple[float, float, float] | None = None   # the last valid sample's x, y, yaw
    velocity: tuple[float, float] = (0.0, 0.0)        # and its vx, vy
    waited: bool = True                   # idle since the last position sample was handled
    loop_wall: float = 0.0                # the loop's last turn
    # After the companion's own stall, the silence is not judged until the socket has been
    # read empty (what the vehicle sent meanwhile is waiting in it) or this wall time passes.
    catch_up_until: float = 0.0


@dataclass(slots=True)
class MissionClock:
    """Mission time: 0 at the first tracking sample, standing still outside TRACKING. A segment
    is a run of tracked samples with no gap longer than ``max_gap`` vehicle s."""
    max_gap: float
    time: float = 0.0                     # the mission time of the last tracked sample
    offset: float = 0.0                   # the mission time at the segment's start
    segment_t0: float | None = None       # its first sample's vehicle time; None: the next
    #                                       tracked sample starts a segment
    rate: float = 1.0                     # mission s per vehicle s (below 1: slowed down)
    ramp_s: float = 0.0                   # the segment's rate ramps from 0 over this (pacing)
    rejoin: bool = False                  # the rover stood still: the next segment rejoins
    #                                       the path where it stands, and ramps up

    def restart(self) -> None:
        """A new mission: its time 0 at the next tracked sample."""
        self.time, self.offset, self.segment_t0 = 0.0, 0.0, None
        self.ramp_s, self.rejoin = 0.0, False


@dataclass(slots=True)
class Engagement:
    """Getting the vehicle into the track mode and armed (ENGAGING), and where that leads."""
    after: State                          # TRACKING, PAUSED or READY once engaged
    since: float = 0.0                    # wall s engaging began
    mode_seen: bool = False               # a heartbeat since then showed the track mode
    warm_t0: float | None = None          # vehicle s the offboard warm-up's stream began
    next_arm_try: float = 0.0             # wall s
    said_arm_wait: bool = False
    need_ack: bool = False                # a heartbeat counts only after a mode ACK (see top)
    after_failsafe: bool = False          # re-engaging after a failsafe (not the first time)
    said_estimate_wait: bool = False      # "waiting for a healthy estimate" logged
    estimate_waited: bool = False         # engaging stood still for the estimate
    # the mode the vehicle was in when the companion first looked (or the first it settled
    # in, after a boot mode), before it asked for any: another one before the first engagement
    # is someone else's choice (Runner._on_heartbeat)
    start_mode: str | None = None

    def first(self, state: State) -> bool:
        """Engaging for the first time (not back from a failsafe): the vehicle is not ours
        yet, and an estimate that is not ready is a reason to wait, not a fault."""
        return state is State.ENGAGING and not self.after_failsafe


@dataclass(slots=True)
class ModeRequest:
    """The last mode asked for (the track mode, or the hold mode) and when to ask again."""
    name: str | None = None
    next_try: float = 0.0                 # wall s


@dataclass(slots=True)
class Stopping:
    """Failsafe and the end: a stop asked for, the failsafe's start and what it interrupted,
    whether the end wants the hold mode and whether the vehicle confirmed it."""
    requested: str | None = None          # request_stop's reason (a signal handler's)
    failsafe_since: float = 0.0           # wall s
    resume_to: State = State.WAITING      # the state the failsafe interrupted
    wants_hold: bool = False              # _finish asked for the hold mode
    hold_confirmed: bool = False          # by an ACK or a heartbeat
    cause: str = "telemetry"              # the failsafe's: telemetry, heartbeat, estimate,
    #                                       link (the autopilot's setpoint-loss), setpoints
    #                                       (the vehicle says ours stopped arriving), autopilot
    autopilot: str | None = None          # the autopilot's failsafe holding the vehicle (why)
    unjudged: str | None = None           # a pilot's doing? (why) until the clock is read
    ask_clock: bool = False               # the vehicle was silent then: its clock may be asked


@dataclass(slots=True)
class Timers:
    """Wall-clock deadlines of the loop."""
    started: float = 0.0                  # run() began
    next_timer: float = 0.0               # _timers runs at least this often
    next_heartbeat: float = 0.0           # the companion's own heartbeat, 1 Hz
    next_refusal_log: float = 0.0         # at most one "refused telemetry" line a second
    next_stall_log: float = 0.0           # at most one "was not running" line in 10 s


@dataclass(slots=True)
class Counters:
    failsafes: int = 0
    sink_errors: int = 0
    tracker_resets: int = 0
    stalls: int = 0                       # the companion's own stalls (runner.loop.STALL)
    refusals_logged: dict[str, int] = field(default_factory=dict)   # as last logged


@dataclass(slots=True)
class GroundStation:
    """What a ground station adds to the loop: its commands and STATUSTEXT
    (:mod:`companion.live.gcs`) and, with ``--handover``, the segments inside AUTO
    (:mod:`companion.live.handover`); None where the run has none."""
    gcs: Any = None
    handover: Any = None
