"""``sitl-plant``: a software rover that speaks MAVLink 2 like an ArduPilot Rover (or PX4).

The dynamics are the vehicle model of :mod:`companion.sim.plant` (the paper's eqs. (1)-(2) behind
an autopilot's inner loops: the paper's actuators, or a skid-steer or Ackermann rover from a
vehicle file); this package adds what a companion computer sees of a real vehicle: heartbeat and
modes, arming, message-rate requests with ArduPilot's cap, SET_POSITION_TARGET_LOCAL_NED handling
with the guided timeout, noisy / late / lossy telemetry, and real-time, accelerated or lockstep
clocks.

Which autopilot it imitates is a profile of :mod:`companion.profiles` (ids, modes, setpoint
reading, parameters, texts). Modules: ``modes`` (the profile's modes the plant has), ``setpoint``
(target decoding), ``guidance`` (the autopilot's inner steering), ``vehicle`` (state machine +
dynamics, pure), ``streams`` (message intervals), ``telemetry`` (noise, latency, dropout),
``params`` (the parameters it serves), ``status`` (EKF status, origin, pre-arm), ``earth`` (EKF
origin, home, latitude / longitude), ``mission`` and ``auto`` (the stored mission, its protocol,
and AUTO flying it), ``clock`` (pacing, lockstep), ``link`` (pymavlink), ``server`` (the loop),
``config`` and ``cli``; ``testing`` drives a real plant process for tests.

May import: ``companion``'s ``core``, ``sim``, ``mission`` (geodesy only), ``mav``, ``profiles`` and
``errors``; never the live loop, the bus or the commands: the plant is what tests the
companion's loop, so it must not run that loop's code.
"""
