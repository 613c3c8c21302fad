"""The signals that flow one way through the tracker: measurement -> estimate -> command.

Every field is a float (one vehicle) or a numpy array of shape (n,) (n vehicles at once).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

Num = Any  # float or numpy.ndarray


@dataclass(slots=True)
class Measurement:
    """One pose sample in the local frame (x north, y east, yaw from north towards east).

    ``vx, vy, yaw_rate`` are the vehicle's own velocity estimates (LOCAL_POSITION_NED vx/vy and
    ATTITUDE yawspeed); only the PID baseline uses them, the PZC tracker needs position and yaw only.
    """

    x: Num
    y: Num
    yaw: Num
    vx: Num = 0.0
    vy: Num = 0.0
    yaw_rate: Num = 0.0


@dataclass(slots=True)
class Estimate:
    """Filtered pose (the paper's p-hat, phi-hat) and the filter's rate states (Delta p-hat_v)."""

    x: Num
    y: Num
    yaw: Num
    vx: Num
    vy: Num
    yaw_rate: Num


@dataclass(slots=True)
class Reference:
    """Reference trajectory sample: position p_ref, velocity and acceleration (for feed-forward)."""

    x: Num
    y: Num
    vx: Num = 0.0
    vy: Num = 0.0
    ax: Num = 0.0
    ay: Num = 0.0


@dataclass(slots=True)
class Command:
    """What the tracker asks of the vehicle.

    ``speed`` and ``yaw_rate`` are the paper's (v_ref, omega_phi_ref): ArduPilot's BODY_NED
    vx + yaw_rate. ``ux, uy`` is the paper's u_p, the velocity vector PX4 is sent in LOCAL_NED.
    """

    speed: Num
    yaw_rate: Num
    ux: Num
    uy: Num
