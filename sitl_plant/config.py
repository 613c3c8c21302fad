"""Everything one plant process is configured with (built by :mod:`sitl_plant.cli`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .earth import OriginConfig
from .status import GpsFault
from .telemetry import TelemetryConfig
from .vehicle import VehicleConfig

DEFAULT_URL = "udpout:127.0.0.1:14550"


@dataclass(frozen=True)
class PlantConfig:
    connect: str = DEFAULT_URL
    sysid: int = 1
    compid: int = 1
    loop_rate: float = 50.0          # Hz, SCHED_LOOP_RATE: caps message rates at 0.8 x this
    speedup: float = 1.0             # vehicle seconds per wall second when paced
    lockstep: bool = False
    lockstep_timeout: float = 0.25   # wall s to wait for a setpoint before running on
    physics_dt: float = 0.001        # s of vehicle time per integration step
    duration: float | None = None    # s of vehicle time, None: until a signal
    preset: str = "paper"
    tick_aligned: bool = False       # telemetry on scheduler ticks (ArduPilot's 20/20/20/40 ms)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    telemetry: TelemetryConfig = field(default_factory=TelemetryConfig)
    takeover_at: float | None = None  # vehicle s at which a "pilot" switches to HOLD
    battery_low_at: float | None = None  # vehicle s of the autopilot's battery failsafe (HOLD)
    signing_key: bytes | None = None  # MAVLink 2 signing: 32-byte secret
    origin: OriginConfig = field(default_factory=OriginConfig)   # EKF origin (lat, lon, alt)
    global_position_rate: float = 0.0  # Hz of GLOBAL_POSITION_INT at boot (0: until asked)
    # Served parameters and estimator status (sitl_plant.params / status): --param overrides,
    # the share of a PARAM_REQUEST_LIST reply lost, the EKF's start-up time, the heartbeat's
    # MAV_TYPE (None: from FRAME_CLASS), MAVLink 1 frames out.
    params: tuple[tuple[str, float], ...] = ()
    param_loss: float = 0.0
    ekf_delay: float = 0.0
    mav_type: int | None = None
    mavlink1: bool = False
    gps_faults: tuple[GpsFault, ...] = ()   # --gps-glitch / --gps-loss (sitl_plant.status)
    gcs: str | None = None             # --gcs URL: a ground station's second link
    mission_drop_item: int | None = None   # --mission-drop-item N: never answer item N
