"""``sitl-plant``: a software rover that speaks MAVLink 2 like an ArduPilot Rover (or PX4).

The dynamics are the paper's (:mod:`companion.sim.plant`, eqs. (1)-(2) with first-order actuators);
this package adds what a companion computer sees of a real vehicle: heartbeat and modes, arming,
message-rate requests with ArduPilot's cap, SET_POSITION_TARGET_LOCAL_NED handling with the guided
timeout, noisy / late / lossy telemetry, and real-time, accelerated or lockstep clocks.

Which autopilot it imitates is a profile of :mod:`companion.profiles` (ids, modes, setpoint
reading, parameters, texts). Modules: ``modes`` (the profile's modes the plant has), ``setpoint`` (target decoding), ``guidance`` (the autopilot's
inner steering), ``vehicle`` (state machine + dynamics, pure), ``streams`` (message intervals),
``telemetry`` (noise, latency, dropout), ``params`` (the parameters it serves), ``status`` (EKF
status, origin, pre-arm), ``clock`` (pacing, lockstep), ``link`` (pymavlink),
``server`` (the loop), ``cli``.
"""
